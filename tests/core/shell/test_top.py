"""The shell's top surface above a texture coordinate (u, v) (stages/core/shell/top.py, seed 001 §5.2.1
Fig. 5: the global-visibility shadow ray starts at x_, the top-surface point above the fibre hit).

References: on a flat tiling (an artifact of ``loomlight tile``, surface kind flat, read as the prt
renderer reads it) the closed form base point + thickness x normal; on a cylinder and a sphere drape
(the tile stage's own base surfaces and smoothed vertex normals) a brute force over every triangle of
the barycentric interpolation of the top vertices V + T N and of the vertex normals, and on the
cylinder's interior vertices the closed form radius r + T; outside the uv domain the point at the
clamped (u, v); in a hole of the uv layout a point on the top surface at the hole's rim."""
import math

import numpy as np
import pytest

from stages.core.shell.top import base_point, build_top_surface, top_point
from stages.tile import base_surfaces as bs

FLAT = """
seed = 2
[yarn]
fibers_per_ply = 1
[weave]
spacing = [0.1, 0.12]
[[exemplars]]
pattern = "plain"
[tiling]
repeat = [2, 1]
[surface]
kind = "flat"
resolution = [3, 2]
offset = [0.5, -0.2, 0.3]
"""


def _queries(seed, n):
    """Random (u, v) in the unit square, plus the corners, edge midpoints and grid-line points."""
    rng = np.random.default_rng(seed)
    uv = [rng.uniform(0.0, 1.0, size=(n, 2))]
    g = np.array([0.0, 1.0 / 3.0, 0.5, 2.0 / 3.0, 1.0])
    uv.append(np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2))
    return np.concatenate(uv)


def _top(ts, u, v):
    found, x, y, z, nx, ny, nz = top_point(ts, float(u), float(v))
    return found, np.array([x, y, z]), np.array([nx, ny, nz])


def test_flat_tiling_top_is_base_plus_thickness_normal(tmp_path):
    """A flat tiling's top surface, built from the artifact's arrays as ``pipeline.renderers.prt`` builds
    it: above (u, v) lies (offset_x + u W, offset_y + v H, offset_z + T) with the normal +z, W x H the
    tiling's flat size and T its shell thickness, to 1e-12 everywhere in the domain (vertices and
    triangle edges included)."""
    from pipeline.runners.tile import load_tiling, run_tile

    (tmp_path / "t.toml").write_text(FLAT)
    run_tile(tmp_path / "t.toml", tmp_path / "t.zarr")
    _, art = load_tiling(tmp_path / "t.zarr")
    assert art.summary["surface"] == "flat"
    T = float(art.summary["thickness"])
    W, H = art.summary["flat_size"]
    assert T > 0 and W != H
    ts = build_top_surface(art["base_uv"], art["base_triangles"], art["base_vertices"], art["base_normals"], T)
    for u, v in _queries(1, 300):
        found, p, n = _top(ts, u, v)
        assert found
        np.testing.assert_allclose(p, [0.5 + u * W, -0.2 + v * H, 0.3 + T], rtol=0, atol=1e-12)
        np.testing.assert_allclose(n, [0.0, 0.0, 1.0], rtol=0, atol=1e-12)


def _mesh(kind):
    if kind == "cylinder":
        V, UV, F = bs.cylinder(1.0, 2.0, 120.0, 12, 5)
    else:
        V, UV, F = bs.sphere_drape(4.0, 1.0, 10, 10, folds=6, fold_amplitude=0.25)
    return V, UV, F, bs.vertex_normals(V, F)


def _brute_force(V, UV, F, N, T, u, v):
    """The barycentric interpolation of V + T N and N over the triangle containing (u, v) (the one whose
    least barycentric coordinate is largest), every triangle tried."""
    best, bw, bt = -np.inf, None, -1
    for t, (a, b, c) in enumerate(F):
        m = np.array([UV[b] - UV[a], UV[c] - UV[a]]).T
        b1, b2 = np.linalg.solve(m, np.array([u, v]) - UV[a])
        w = np.array([1.0 - b1 - b2, b1, b2])
        if w.min() > best:
            best, bw, bt = w.min(), w, t
    assert best > -1e-12   # the uv domain is covered
    tri = F[bt]
    p = bw @ (V[tri] + T * N[tri])
    n = bw @ N[tri]
    return p, n / np.linalg.norm(n)


@pytest.mark.parametrize("kind", ["cylinder", "drape"])
def test_curved_top_is_barycentric_interpolation(kind):
    """Cylinder (r = 1, 120 degrees, 12 x 5 quads) and sphere drape (10 x 10 quads, folds): top_point
    against the brute force over all triangles, 1e-12 in position and normal, at random (u, v) and on
    the grid lines (where two or six triangles meet and any of them gives the same point); base_point
    against the same brute force at thickness 0 (the base surface itself), with the same normal."""
    V, UV, F, N = _mesh(kind)
    T = 0.05
    ts = build_top_surface(UV, F, V, N, T)
    for u, v in _queries(2, 300):
        found, p, n = _top(ts, u, v)
        assert found
        q, m = _brute_force(V, UV, F, N, T, u, v)
        np.testing.assert_allclose(p, q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(n, m, rtol=0, atol=1e-12)
        found, *bn = base_point(ts, float(u), float(v))
        q, m = _brute_force(V, UV, F, N, 0.0, u, v)
        assert found
        np.testing.assert_allclose(bn[:3], q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(bn[3:], m, rtol=0, atol=1e-12)


def test_cylinder_interior_vertices_at_radius_plus_thickness():
    """Closed form: the smoothed normal of an interior vertex of the uniform cylinder grid is radial
    (its faces are symmetric about it), so the top point above it is at radius r + T, y = v L."""
    r, L, T = 1.0, 2.0, 0.07
    V, UV, F = bs.cylinder(r, L, 120.0, 12, 5)
    ts = build_top_surface(UV, F, V, bs.vertex_normals(V, F), T)
    inner = (UV[:, 0] > 0) & (UV[:, 0] < 1)
    assert inner.sum() == 11 * 6
    for u, v in UV[inner]:
        found, p, n = _top(ts, u, v)
        assert found
        assert abs(math.hypot(p[0], p[2]) - (r + T)) < 1e-12 and abs(p[1] - v * L) < 1e-12
        np.testing.assert_allclose(n, [p[0] / (r + T), 0.0, p[2] / (r + T)], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", ["cylinder", "drape"])
def test_outside_the_domain_clamps(kind):
    """(u, v) outside the uv domain's box gives the top point at (u, v) clamped into it: below 0, above
    1 and far out, on either axis or both (against the brute force at the clamped point)."""
    V, UV, F, N = _mesh(kind)
    T = 0.05
    ts = build_top_surface(UV, F, V, N, T)
    for u, v in [(-0.3, 0.4), (1.5, 0.25), (0.6, -2.0), (0.35, 7.0), (-1e6, -1e6), (3.0, -0.01), (1.0 + 1e-9, 0.5)]:
        found, p, n = _top(ts, u, v)
        assert found
        q, m = _brute_force(V, UV, F, N, T, min(max(u, 0.0), 1.0), min(max(v, 0.0), 1.0))
        np.testing.assert_allclose(p, q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(n, m, rtol=0, atol=1e-12)


def test_hole_in_the_uv_layout_takes_its_rim():
    """A flat 4 x 4 grid with the two triangles of one inner quad removed: points inside the hole come
    back found, on the top surface (z = T, normal +z) and on the hole's closed square (its rim: the
    least-negative triangle's weights clamped), never inside the hole nor far from it."""
    V, UV, F = bs.flat_rectangle(1.0, 1.0, 4, 4)
    # quad (1, 2): u in [0.25, 0.5], v in [0.5, 0.75]; its two triangles are 1 * 4 + 2 and 16 + 1 * 4 + 2
    keep = np.ones(len(F), bool)
    keep[[6, 22]] = False
    F = F[keep]
    T = 0.1
    ts = build_top_surface(UV, F, V, bs.vertex_normals(V, F), T)
    rng = np.random.default_rng(3)
    for u, v in np.stack([rng.uniform(0.26, 0.49, 40), rng.uniform(0.51, 0.74, 40)], 1):
        found, p, n = _top(ts, u, v)
        assert found
        assert abs(p[2] - T) < 1e-12
        np.testing.assert_allclose(n, [0.0, 0.0, 1.0], rtol=0, atol=1e-12)
        x, y = p[0], p[1]
        assert 0.25 - 1e-12 <= x <= 0.5 + 1e-12 and 0.5 - 1e-12 <= y <= 0.75 + 1e-12
        rim = min(x - 0.25, 0.5 - x, y - 0.5, 0.75 - y)
        assert rim < 1e-12, (u, v, x, y)
