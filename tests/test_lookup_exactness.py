"""Exactness of the realization-minimizing lookups (seed 000 §4) against brute force on the realized fibres.

Swatch: a 2 x 2 plain weave of cotton2 yarns (all three fibre kinds), realized at spacing 0.001.
Reference: ``stages.procedural.realized_reference`` -- the distance from every point to every realized
segment of its grid cell (chains of capsules), the same covering rule (first fibre in the order
yarn, ply, regular/loop before hair, index).

Tolerance. The realized polylines join points that lie exactly on the fibre centre curves (up to
float32 rounding), so a polyline strays from its curve by at most the sagitta of a chord,
kappa l^2 / 8 for a chord of length l on a curve of curvature kappa. The realization measures it
(``max_chord_error``: l theta / 8 at every vertex, theta the turning angle between its segments,
i.e. kappa l^2 / 8 with kappa = theta / l). tol = 2 x max_chord_error (margin for the discrete
curvature estimate) + float32 rounding of the vertices (4 ulp of the largest coordinate). Points
within tol of any fibre surface, and points where a fibre's regular and loop pieces are within tol
of each other (a kind tie at a piece joint), are not compared; all others must agree exactly in
inside/outside, yarn and kind, and in direction to 1 degree (chord vs tangent: at most
theta / 2, reported by the realization as ``max_turn_rad``).
"""
import numpy as np
import pytest

from conftest import EXACTNESS_SWATCH as SCENE
from pipeline.artifacts import Artifact
from pipeline.procedural_runner import build, run_realize
from stages.procedural.lookup import lookup_points
from stages.procedural.realized_reference import build_segment_grid, query_realized, segment_fiber


@pytest.fixture(scope="module")
def swatch(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("exact")
    (d / "s.toml").write_text(SCENE)
    assert main(["ingest", str(d / "s.toml"), "-o", str(d / "yarns.zarr")]) == 0
    run_realize(d / "yarns.zarr", d / "fibers.zarr", seed=3, spacing=0.001)
    fib = Artifact(d / "fibers.zarr", kind="fibers")
    cv, tab, info, _, _ = build(d / "yarns.zarr", seed=3, hair_mode="hybrid")
    cv2, tab_free, _, _, _ = build(d / "yarns.zarr", seed=3, hair_mode="free")
    assert not info["folded"].any()
    return d, fib, cv, {"hybrid": tab, "free": tab_free}


def _points(fib, n_uniform=30000, n_near=90000, seed=0):
    pts = np.asarray(fib["points"], np.float64)
    rng = np.random.default_rng(seed)
    lo, hi = pts.min(0) - 0.01, pts.max(0) + 0.01
    rf = float(np.max(fib["point_radius"]))
    q1 = rng.uniform(lo, hi, (n_uniform, 3))
    q2 = pts[rng.integers(0, len(pts), n_near)] + rng.normal(0.0, 1.5 * rf, (n_near, 3))
    return np.concatenate([q1, q2])


def test_lookup_equals_brute_force_on_realized_fibres(swatch):
    d, fib, cv, tabs = swatch
    tab = tabs["hybrid"]
    pts32 = np.asarray(fib["points"])
    rad = np.asarray(fib["point_radius"])
    off = np.asarray(fib["fiber_offsets"])
    kinds = np.asarray(fib["fiber_kind"])
    assert set(np.unique(kinds)) == {1, 2, 3}
    chord = fib.summary["max_chord_error"]
    tol = 2.0 * chord + 4 * np.finfo(np.float32).eps * float(np.abs(pts32).max())
    assert tol < 0.05 * float(rad.max())  # the band is thin next to the fibre radius
    Q = _points(fib)
    assert len(Q) >= 100_000
    lo, cell, dims, start, items = build_segment_grid(pts32, off, rad, tol)
    ref = query_realized(pts32, rad, segment_fiber(off), np.asarray(fib["fiber_yarn"]), np.asarray(fib["fiber_ply"]),
                         kinds, np.asarray(fib["fiber_index"]), lo, cell, dims, start, items, Q, tol)
    got = lookup_points(cv, tab, Q)
    clear = (ref[4] > tol) & ~ref[5]
    assert clear.mean() > 0.95
    inside_ref = ref[0][clear]
    assert inside_ref.sum() > 5000  # many points inside fibres take part
    assert np.array_equal(got[0][clear], inside_ref)
    both = clear & ref[0]
    assert np.array_equal(got[1][both], ref[1][both])
    assert np.array_equal(got[2][both], ref[2][both])
    assert set(np.unique(got[2][both])) == {1, 2, 3}
    cosang = np.einsum("ij,ij->i", got[3][both], ref[3][both])
    assert np.degrees(np.arccos(np.clip(cosang, -1, 1))).max() < 1.0
    assert np.all(got[1][~got[0]] == -1) and np.all(got[2][~got[0]] == 0)
    np.testing.assert_allclose(np.linalg.norm(got[3][got[0]], axis=1), 1.0, rtol=1e-9)


def test_hybrid_and_realization_free_hairs_agree(swatch):
    d, fib, cv, tabs = swatch
    tab, tab_free = tabs["hybrid"], tabs["free"]
    assert len(tab_free.hair_z1) == 0 and len(tab.hair_z1) > 0  # the free mode stores no hair data
    Q = _points(fib, 5000, 25000, seed=1)
    a = lookup_points(cv, tab, Q)
    b = lookup_points(cv, tab_free, Q)
    assert (a[2] == 3).sum() > 100
    for x, y in zip(a, b):
        assert np.array_equal(x, y)
