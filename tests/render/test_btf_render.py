"""``loomlight render --method btf`` (stages/render/integrators/btf.py, pipeline/renderers/btf.py; seed 002 §6) on small
synthetic textures (btf artifacts written by hand: a Lambertian texture is rho = albedo / pi, no lobes,
T = 1, alpha = 1) dressed on flat quads and on a flat tiling's base surface.

What is compared with what (each test names its reference):
- ray-triangle queries (``stages.core.geometry.triangles``) against brute force over every triangle;
  dP/du, dP/dv against the triangles' own edges (round trip);
- the packed texel model (``stages.render.integrators.btf.texel_f1_rgb`` / ``view_lookup``) against
  ``stages.core.btf.texel_f1`` / ``table_lookup`` on random texels;
- a Lambertian quad under a directional light against the closed form E a / pi cos(theta) in every
  pixel, under a constant light against L a (the light grid's quadrature of cos is exact);
- holes: partial and zero alpha against alpha C_front + (1 - alpha) C_behind in closed form, two layers
  of the mesh and the ground behind; shadow rays through the same holes;
- mip: a spatially uniform texture renders the same with mip on and off; levels of distinct colours
  give the blend of the two levels the closed-form footprint selects, on the exact camera rays;
- the texture's repeat: uv shifted by one period gives the same bytes (by half a period, not);
- a tiling's base surface equals the same surface written as an OBJ with repeat = flat size / period; on a
  tiling of two exemplars each pixel is the one or the other exemplar's render where the block map says;
- relief (``--plane relief``): a height field of one height h renders as the plain texture on the surface moved h
  along its normal; on a random field the texel walk meets the ray's first crossing, against a brute-force march
  of 20,000 steps;
- the same bytes at 1 and 2 threads; bad settings and a texture of another repeat: exit 2, nothing
  written.
"""
import math
import shutil
from collections import namedtuple

import numpy as np
import pytest
from numba import njit

from pipeline.artifacts import ArtifactWriter, read_meta
from pipeline.images import read_exr
from stages.core.btf import grid_weights, hemisphere_grid, table_lookup, texel_f1
from stages.core.geometry.triangles import (
    area_weighted_normals,
    build_triangle_mesh,
    mesh_intersect,
    mesh_intersect_brute,
    mesh_occluded,
    uv_derivatives,
)
from stages.render.integrators.btf import texel_f1_rgb, view_lookup

VIEW_GRID = (4, 8)
LIGHT_GRID = (8, 8)

SCENE = """
[scene]
name = "btf-quad"
seed = 5
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 2
picks = 2
spacing = 0.1
yarn_radius = 0.045
[camera]
origin = {origin}
target = {target}
up = [0.0, 1.0, 0.0]
fov = 40.0
width = {width}
height = {height}
{lights}
{render}
"""
SUN = """
[[lights]]
type = "directional"
direction = [{d}]
irradiance = {e}
"""
SKY = """
[[lights]]
type = "constant"
radiance = {l}
"""
SGL = """
[[lights]]
type = "sg"
axis = [{a}]
sharpness = {lam}
power = {p}
"""


def _cli(*args):
    """The loomlight CLI in-process: (exit code, stdout, stderr)."""
    import contextlib
    import io

    from pipeline.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def write_btf(path, res=4, levels=3, lobes=1, rho=(0.5, 0.5, 0.5), alpha=1.0, table=None, lobe_params=None,
              period=(0.5, 0.5), source_hash="none", source="none", frame=None, exemplars=(0,), tabulated=None,
              half=None, sphere=False, heights=None):
    """A btf artifact of the tiling exemplars ``exemplars``. ``rho``: an rgb (every texel of every level) or a
    function (level, r) -> (r, r, 3), or a list of those, one per exemplar; ``alpha``: a number or a function
    (level, r, views) -> (r, r, V); ``table``: None (T = 1) or a function (level, r, views) -> (r, r, V, 3);
    ``lobe_params`` None (no lobes: C = 0) or (r, r, K, 3, 4) per level via a function (level, r); ``period``
    one [W, H] for every exemplar or a list of them; ``tabulated`` None or a function (views, lights) -> (V, L, 3):
    every texel's table r(l, v), compressed by ``compress_texels`` (1 cluster, 1 component) into ``tabulated/``;
    ``half`` None or (nx, ny): the table's lights are half-vector cells (``--light-coords half``), ``tabulated`` then
    a function (views, valid fractions (V, L)) -> (V, L, 3); ``sphere``: the table's lights are the light grid and its
    mirror below the fabric (``--light-domain sphere``), ``tabulated`` then a function of those 2 L lights;
    ``heights`` None or (res, res) level 0's heights over the surface plane (``--plane relief``, plane_z 0)."""
    from pipeline.runners.precompute_btf import write_tables
    from stages.precompute.btf_compress import compress_texels

    path = str(path)
    shutil.rmtree(path, ignore_errors=True)
    views = hemisphere_grid(*VIEW_GRID)
    V = len(views)
    E = len(exemplars)
    rhos = rho if isinstance(rho, list) else [rho] * E
    periods = [list(p) for p in period] if isinstance(period[0], (list, tuple)) else [list(period)] * E

    def each(per_exemplar):
        return np.stack(per_exemplar).astype(np.float32)
    with ArtifactWriter(path, kind="btf", stage="precompute btf", params={"test": 1}, inputs={}) as w:
        w.write("view_dirs", views)
        w.write("light_dirs", hemisphere_grid(*LIGHT_GRID))
        for lv in range(levels):
            r = res >> lv
            w.write(f"level_{lv}/rho", each([c(lv, r) if callable(c) else np.broadcast_to(c, (r, r, 3)) for c in rhos]))
            lob = np.zeros((r, r, lobes, 3, 4), np.float32)
            lob[..., 3] = 1.0
            if lobe_params is not None:
                lob[...] = lobe_params(lv, r)
            w.write(f"level_{lv}/lobes", each([lob] * E))
            tb = np.ones((r, r, V, 4), np.float32)
            if table is not None:
                tb[..., :3] = table(lv, r, views)
            tb[..., 3] = alpha(lv, r, views) if callable(alpha) else alpha
            w.write(f"level_{lv}/table", each([tb] * E))
            fr = np.zeros((r, r, 2, 3), np.float32)
            fr[..., 0, 2] = 1.0
            fr[..., 1, 0] = 1.0
            if frame is not None:
                fr[...] = frame(lv, r)
            w.write(f"level_{lv}/frame", each([fr] * E))
        if half is not None:
            from stages.core.btf import half_cell_geometry, half_grid

            w.write("half_dirs", half_grid(*half))
        if tabulated is not None:
            lights = hemisphere_grid(*LIGHT_GRID) if half is None else half_cell_geometry(*VIEW_GRID, *half, True).valid
            if sphere:
                lights = np.concatenate([lights, lights * np.array([1.0, 1.0, -1.0])])
            row = np.asarray(tabulated(views, lights), np.float32).reshape(1, -1)
            rows = np.repeat(row, sum((res >> lv) ** 2 for lv in range(levels)), axis=0)
            write_tables(w, [compress_texels(rows, 1, 1)] * E, V, len(row[0]) // (3 * V))
        w.summary.update(kind="btf", source=source, source_hash=source_hash, exemplars=list(exemplars),
                         exemplar_names=[f"test {k}" if E > 1 else "test" for k in exemplars], periods=periods,
                         resolution=res, levels=levels, lobes=lobes, view_grid=list(VIEW_GRID),
                         light_grid=list(LIGHT_GRID if half is None else half))
        if sphere:
            w.summary.update(light_domain="sphere")
        if heights is not None:
            w.write("heights", each([np.asarray(heights, np.float32)] * E))
            w.summary.update(plane="relief", plane_z=0.0)
        if half is not None:
            w.summary.update(light_coords="half", fit_light_grid=list(LIGHT_GRID), directions="cell")
    return path


def write_obj(path, V, UV, F, normals=None):
    def num(x):
        return repr(float(x))   # shortest round-trip text of the double
    lines = [f"v {num(x)} {num(y)} {num(z)}" for x, y, z in V] + [f"vt {num(u)} {num(v)}" for u, v in UV]
    if normals is not None:
        lines += [f"vn {num(x)} {num(y)} {num(z)}" for x, y, z in normals]
        lines += [f"f {a + 1}/{a + 1}/{a + 1} {b + 1}/{b + 1}/{b + 1} {c + 1}/{c + 1}/{c + 1}" for a, b, c in F]
    else:
        lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in F]
    path.write_text("\n".join(lines) + "\n")
    return path


def quad(size=2.0, z=0.0, n=2, uv_shift=(0.0, 0.0)):
    """A flat square [-size/2, size/2]^2 at height z, n x n cells, uv in [0, 1]^2 (+ shift)."""
    g = np.linspace(0.0, 1.0, n + 1)
    u, v = np.meshgrid(g, g, indexing="ij")
    UV = np.stack([u.ravel(), v.ravel()], 1)
    V = np.stack([(UV[:, 0] - 0.5) * size, (UV[:, 1] - 0.5) * size, np.full(len(UV), z)], 1)
    F = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
            F += [(a, b, c), (a, c, d)]
    return V, UV + np.asarray(uv_shift), np.asarray(F)


class Bench:
    """Writes scenes, meshes and textures into one directory and renders them."""

    def __init__(self, d):
        self.d = d
        self.n = 0

    def name(self, stem):
        self.n += 1
        return self.d / f"{stem}{self.n}"

    def scene(self, lights, origin=(0.4, -0.6, 3.0), target=(0.0, 0.0, 0.0), width=40, height=30, render=""):
        p = self.name("scene").with_suffix(".toml")
        p.write_text(SCENE.format(lights=lights, origin=list(origin), target=list(target), width=width, height=height,
                                  render=render))
        return p

    def render(self, scene, *args, threads=2):
        """(rgb float64 (H, W, 3), extra channels, exr path) of a render that must succeed."""
        out = self.name("r").with_suffix(".exr")
        code, _, err = _cli("render", scene, "-o", out, "--method", "btf", "--spp", "1", "--threads", threads, *args)
        assert code == 0, err
        rgb, ch = read_exr(out)
        return rgb.astype(np.float64), ch, out


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    return Bench(tmp_path_factory.mktemp("btf"))


# ------------------------------------------------------------------------------------------------ geometry
@njit
def _all_hits(mesh, O, D, tmin, brute):
    out = np.empty((len(O), 4))
    for k in range(len(O)):
        if brute:
            h = mesh_intersect_brute(mesh, O[k, 0], O[k, 1], O[k, 2], D[k, 0], D[k, 1], D[k, 2], tmin[k], np.inf)
        else:
            h = mesh_intersect(mesh, O[k, 0], O[k, 1], O[k, 2], D[k, 0], D[k, 1], D[k, 2], tmin[k], np.inf)
        out[k, 0] = h.t
        out[k, 1] = h.tri
        out[k, 2] = h.b1
        out[k, 3] = h.b2
    return out


@njit
def _all_occluded(mesh, O, D, tmax):
    out = np.empty(len(O), np.bool_)
    for k in range(len(O)):
        out[k] = mesh_occluded(mesh, O[k, 0], O[k, 1], O[k, 2], D[k, 0], D[k, 1], D[k, 2], 0.0, tmax[k])
    return out


def test_triangle_queries_against_brute_force():
    """Reference: every triangle tested in order (``mesh_intersect_brute``). 400 random triangles in a
    unit box plus a 12 x 12 grid (shared edges and vertices), 4000 rays: random ones, rays aimed at
    grid vertices and edge midpoints (every one inside the grid finds it: no cracks), and the same rays
    again from just behind their first hit (tmin = that t): the BVH's nearest hit (t, triangle,
    barycentrics) is identical, and any-hit agrees with 'nearest t < tmax'."""
    rng = np.random.default_rng(4)
    A = rng.uniform(-1, 1, (400, 3))
    tri = A[:, None, :] + rng.normal(0, 0.15, (400, 3, 3))
    Vg, _, Fg = quad(size=2.0, z=0.3, n=12)
    V = np.concatenate([tri.reshape(-1, 3), Vg])
    F = np.concatenate([np.arange(1200).reshape(-1, 3), Fg + 1200])
    mesh = build_triangle_mesh(V, F)
    O = rng.uniform(-2, 2, (4000, 3))
    O[:, 2] = rng.uniform(1.5, 3.0, 4000)
    target = rng.uniform(-1, 1, (4000, 3))
    target[:1000] = Vg[rng.integers(0, len(Vg), 1000)]                                  # grid vertices
    e = Fg[rng.integers(0, len(Fg), 1000)]
    target[1000:2000] = 0.5 * (Vg[e[:, 0]] + Vg[e[:, 1]])                                # grid edges
    D = target - O
    D /= np.linalg.norm(D, axis=1)[:, None]
    zero = np.zeros(len(O))
    got = _all_hits(mesh, O, D, zero, False)
    assert np.array_equal(got, _all_hits(mesh, O, D, zero, True))
    inner = np.abs(target[:2000, :2]).max(axis=1) < 0.99                    # no cracks at the grid's inner
    assert np.mean(got[:, 1] >= 0) > 0.5 and np.all(got[:2000][inner, 1] >= 0)  # vertices and edges
    hit = got[:, 1] >= 0
    behind = np.where(hit, got[:, 0] + 1e-9, 0.0)                          # the next surface behind each hit
    nxt = _all_hits(mesh, O, D, behind, False)
    assert np.array_equal(nxt, _all_hits(mesh, O, D, behind, True))
    assert np.all(nxt[hit, 0] > got[hit, 0])
    tmax = np.where(hit, got[:, 0] * rng.uniform(0.5, 1.5, 4000), rng.uniform(0.5, 5, 4000))
    assert np.array_equal(_all_occluded(mesh, O, D, tmax), got[:, 0] < tmax)


def test_uv_derivatives_and_normals_round_trip():
    """Reference: each triangle's own edges. dP/du du + dP/dv dv of its two uv edges gives back its two
    edges; area-weighted normals of a flat mesh are its plane's normal, of a closed box point outwards."""
    rng = np.random.default_rng(2)
    V = rng.normal(size=(30, 3))
    UV = rng.uniform(size=(30, 2))
    F = rng.integers(0, 30, (50, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    du, dv = uv_derivatives(V, UV, F)
    for k in (1, 2):
        a = UV[F[:, k]] - UV[F[:, 0]]
        assert np.allclose(du * a[:, :1] + dv * a[:, 1:], V[F[:, k]] - V[F[:, 0]], atol=1e-9)
    Vq, _, Fq = quad(n=3)
    assert np.allclose(area_weighted_normals(Vq, Fq), [0, 0, 1])
    box = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6),
             (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    N = area_weighted_normals(box, np.asarray(faces))
    assert np.all(np.einsum("ij,ij->i", N, box - 0.5) > 0)


@njit
def _packed_vs_core(texels, table, rho, lobes, frame, tab, L, Vd, nt, nph):
    err = 0.0
    K = lobes.shape[1]
    for i in range(len(rho)):
        for j in range(len(L)):
            lx, ly, lz = L[j, 0], L[j, 1], L[j, 2]
            vx, vy, vz = Vd[j, 0], Vd[j, 1], Vd[j, 2]
            f = texel_f1_rgb(texels, K, i, lx, ly, lz, vx, vy, vz)
            i0, i1, i2, i3, w0, w1, w2, w3 = grid_weights(nt, nph, vx, vy, vz)
            for c in range(3):
                ref = texel_f1(rho[i], lobes[i], frame[i], c, lx, ly, lz, vx, vy, vz)
                err = max(err, abs(f[c] - ref) / max(abs(ref), 1e-12))
            for c in range(4):
                ref = table_lookup(tab[i], nt, nph, vx, vy, vz, c)
                err = max(err, abs(view_lookup(table, i, i0, i1, i2, i3, w0, w1, w2, w3, c) - ref))
    return err


@njit
def _sky_brute(rho, lobes, frame, L, Vd):
    """sum_j (2 pi / L) f_1(l_j, v_i) per texel, view and channel by ``stages.core.btf.texel_f1``."""
    out = np.zeros((len(rho), len(Vd), 3))
    dw = 2.0 * np.pi / len(L)
    for i in range(len(rho)):
        for v in range(len(Vd)):
            for j in range(len(L)):
                for c in range(3):
                    out[i, v, c] += dw * texel_f1(rho[i], lobes[i], frame[i], c, L[j, 0], L[j, 1], L[j, 2],
                                                  Vd[v, 0], Vd[v, 1], Vd[v, 2])
    return out


def test_packed_texels_equal_the_core_model(tmp_path):
    """Reference: ``stages.core.btf.texel_f1`` and ``table_lookup`` (Eq. 1-2 as the fit reads it) on the
    artifact's own arrays: the renderer's packed texels (``pipeline.renderers.btf.load_btf``) give the
    same f_1 (relative 1e-12) and T(v), alpha (1e-6, float32 table) for random texels with two
    anisotropic lobes and tilted frames, random lights and views of the upper hemisphere. The constant
    sky's table (``sky_table``) is the light grid's quadrature of that f_1 at every grid view (float32:
    relative 1e-6)."""
    from pipeline.renderers.btf import load_btf
    from stages.render.integrators.btf import sky_table

    rng = np.random.default_rng(7)

    def lobes(lv, r):
        p = rng.uniform(-1.0, 1.0, (r, r, 2, 3, 4))
        p[..., 3] = rng.uniform(1, 20, (r, r, 2, 3))
        return p

    def frame(lv, r):
        n = rng.normal(0, 0.3, (r, r, 3)) + [0, 0, 1]
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        t = np.cross(np.cross(n, [1.0, 0.0, 0.0]), n)
        return np.stack([n, t / np.linalg.norm(t, axis=-1, keepdims=True)], -2)

    path = write_btf(tmp_path / "b.zarr", res=4, levels=2, lobes=2, rho=lambda lv, r: rng.uniform(0, 0.3, (r, r, 3)),
                     lobe_params=lobes, frame=frame, table=lambda lv, r, v: rng.uniform(0.5, 1.5, (r, r, len(v), 3)),
                     alpha=lambda lv, r, v: rng.uniform(0, 1, (r, r, len(v))))
    tex = load_btf(path)
    from pipeline.artifacts import Artifact

    art = Artifact(path)
    cat = np.concatenate
    def g(a):
        return cat([np.asarray(art[f"level_{lv}/{a}"], np.float64).reshape((-1,) + art[f"level_{lv}/{a}"].shape[3:])
                    for lv in range(2)])

    L = rng.normal(size=(60, 3))
    L[:, 2] = np.abs(L[:, 2])
    Vd = rng.normal(size=(60, 3))
    Vd[:, 2] = np.abs(Vd[:, 2])
    L /= np.linalg.norm(L, axis=1)[:, None]
    Vd /= np.linalg.norm(Vd, axis=1)[:, None]
    err = _packed_vs_core(tex.texels, tex.table, g("rho"), g("lobes"), g("frame"), g("table"), L, Vd, *VIEW_GRID)
    assert err < 1e-6
    views = hemisphere_grid(*VIEW_GRID)
    sky = sky_table(tex.texels, tex.light_dirs, views)
    ref = _sky_brute(g("rho"), g("lobes"), g("frame"), tex.light_dirs, views)
    assert sky.shape == ref.shape and sky.dtype == np.float32
    assert np.max(np.abs(sky - ref) / np.maximum(np.abs(ref), 1e-6)) < 1e-6
    assert tex.fit_bytes == sum(a.nbytes for name, a in art.arrays().items()
                                if name.startswith(("level_", "view_", "light_")))


# ------------------------------------------------------------------------------------------------ shading
def _lambertian_setup(bench, albedo=(0.6, 0.4, 0.2)):
    btf = write_btf(bench.name("lambert").with_suffix(".zarr"), rho=np.asarray(albedo) / math.pi)
    V, UV, F = quad()
    mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
    return btf, mesh, np.asarray(albedo)


def test_lambertian_quad_closed_form(bench):
    """Reference: closed form. A flat quad with a Lambertian texture (f_1 = l_z rho, rho = a / pi, T = 1)
    under a directional light of irradiance E from theta: every pixel that sees the quad is
    E a / pi cos(theta) (float32 EXR: 1e-6); under a constant light L (the light grid's equal-area
    quadrature, exact for cos): L a; under both, their sum. Mip on (the default) with every level alike.
    An OBJ with its own normals (vn, tilted by 17 degrees) is shaded with them: E a / pi (l . n_obj)."""
    btf, mesh, a = _lambertian_setup(bench)
    d = np.array([-0.3, 0.2, -0.8])
    cos = -d[2] / np.linalg.norm(d)
    args = ("--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=3")
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0)), *args)
    hit = ch["A"] > 0
    assert hit.mean() > 0.5
    assert np.allclose(rgb[hit], 2.0 * a / math.pi * cos, rtol=1e-6, atol=0)
    rgb, ch, _ = bench.render(bench.scene(SKY.format(l=0.7)), *args)
    assert np.allclose(rgb[ch["A"] > 0], 0.7 * a, rtol=1e-6)
    assert np.allclose(rgb[ch["A"] == 0], 0.7, rtol=1e-6)            # the sky behind
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0) + SKY.format(l=0.7)), *args)
    assert np.allclose(rgb[ch["A"] > 0], 2.0 * a / math.pi * cos + 0.7 * a, rtol=1e-6)
    V, UV, F = quad()
    n = np.array([0.3, 0.0, 1.0]) / math.sqrt(1.09)                  # the OBJ's own (tilted) normals shade
    tilted = write_obj(bench.name("tilted").with_suffix(".obj"), V, UV, F, normals=np.tile(n, (len(V), 1)))
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0)), "--set", f"btf={btf}",
                              "--set", f"mesh={tilted}")
    assert np.allclose(rgb[ch["A"] > 0], 2.0 * a / math.pi * float(-d @ n / np.linalg.norm(d)), rtol=1e-6)


def test_tabulated_lambertian_quad_closed_form(bench):
    """Reference: closed form, as ``test_lambertian_quad_closed_form``, for the tabulated model (``--set
    model=tabulated``): a table r(l, v) = l_z a / pi at every grid direction (``compress_texels``, one cluster, one
    component: the rows are equal, so the table is its mean) under a directional light whose l_z lies between the
    light grid's first and last rings (the rings are equally spaced in cos theta, so bilinear interpolation of l_z
    is exact there) gives E a / pi cos(theta) in every pixel, and under a constant light L a (float32 EXR: 1e-6).
    The texture's Lafortune fit is zero (rho = 0): every pixel comes from the table."""
    a = np.array([0.6, 0.4, 0.2])

    def lambert(views, lights):
        return np.broadcast_to(lights[None, :, 2, None] * a[None, None, :] / math.pi,
                               (len(views), len(lights), 3))
    btf = write_btf(bench.name("tab").with_suffix(".zarr"), rho=(0.0, 0.0, 0.0), tabulated=lambert)
    V, UV, F = quad()
    mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
    d = np.array([-0.5, 0.3, -0.6])
    cos = -d[2] / np.linalg.norm(d)
    assert 0.5 / LIGHT_GRID[0] < cos < 1.0 - 0.5 / LIGHT_GRID[0]
    args = ("--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=3", "--set", "model=tabulated")
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.5, 0.3, -0.6", e=2.0)), *args)
    hit = ch["A"] > 0
    assert hit.mean() > 0.5
    assert np.allclose(rgb[hit], 2.0 * a / math.pi * cos, rtol=1e-6, atol=0)
    rgb, ch, _ = bench.render(bench.scene(SKY.format(l=0.7)), *args)
    assert np.allclose(rgb[ch["A"] > 0], 0.7 * a, rtol=1e-6)
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.5, 0.3, -0.6", e=2.0)), *args[:-2])
    assert np.all(rgb[ch["A"] > 0] == 0.0)                             # the Lafortune fit of the same artifact


def test_tabulated_light_from_below_closed_form(bench):
    """Reference: closed form. A sphere table (``precompute btf --light-domain sphere``) r(l, v) = |l_z| a / pi for the
    lights above and |l_z| b / pi for their mirrors below (a Lambertian reflection and a Lambertian transmission) on
    a flat quad seen from above: a directional light from below gives E b / pi |cos| in every pixel, shadows on or
    off (the quad is lit through itself: the table holds its own shadow); a constant light L gives L (a + b) (the
    sky below counts); the light mirrored above E a / pi cos (float32 EXR: 1e-6). The same table without its lower
    half (a hemisphere table) and the artifact's Lafortune fit give 0 under the light from below."""
    a = np.array([0.6, 0.4, 0.2])
    b = np.array([0.1, 0.15, 0.3])

    def two_sided(views, lights):
        c = np.where(lights[:, 2:3] > 0, a[None, :], b[None, :])
        return np.broadcast_to(np.abs(lights[None, :, 2, None]) * c[None] / math.pi, (len(views), len(lights), 3))
    sphere = write_btf(bench.name("sphere").with_suffix(".zarr"), rho=(0.0, 0.0, 0.0), tabulated=two_sided,
                       sphere=True)
    upper = write_btf(bench.name("upper").with_suffix(".zarr"), rho=(0.0, 0.0, 0.0), tabulated=two_sided)
    V, UV, F = quad()
    mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
    d = np.array([-0.5, 0.3, 0.6])                                     # travelling up: the light is below
    cos = d[2] / np.linalg.norm(d)
    args = ("--set", f"mesh={mesh}", "--set", "repeat=3", "--set", "model=tabulated")
    below = SUN.format(d="-0.5, 0.3, 0.6", e=2.0)
    for shadows in ("off", "on"):
        rgb, ch, _ = bench.render(bench.scene(below), "--set", f"btf={sphere}", *args, "--set", f"shadows={shadows}")
        hit = ch["A"] > 0
        assert hit.mean() > 0.5
        assert np.allclose(rgb[hit], 2.0 * b / math.pi * cos, rtol=1e-6, atol=0)
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.5, 0.3, -0.6", e=2.0)), "--set", f"btf={sphere}", *args)
    assert np.allclose(rgb[ch["A"] > 0], 2.0 * a / math.pi * cos, rtol=1e-6, atol=0)
    rgb, ch, _ = bench.render(bench.scene(SKY.format(l=0.7)), "--set", f"btf={sphere}", *args)
    assert np.allclose(rgb[ch["A"] > 0], 0.7 * (a + b), rtol=1e-6)
    rgb, ch, _ = bench.render(bench.scene(below), "--set", f"btf={upper}", *args)
    assert np.all(rgb[ch["A"] > 0] == 0.0)
    rgb, ch, _ = bench.render(bench.scene(below), "--set", f"btf={sphere}", *args[:-2])
    assert np.all(rgb[ch["A"] > 0] == 0.0)


def test_tabulated_half_vector_constant_closed_form(bench):
    """Reference: closed form. A half-vector table (``precompute btf --light-coords half``) of the same radiance c in
    every cell, written as the acquisition averages it (the cell's valid fraction times c: ``stages.core.btf``
    module doc), renders E c in every pixel under a directional light of irradiance E and 2 pi c L under a constant
    light L (its solid angles over valid fractions; float32 EXR: 1e-6). The Lafortune fit of the artifact is 0."""
    c = np.array([0.05, 0.08, 0.11])
    btf = write_btf(bench.name("half").with_suffix(".zarr"), rho=(0.0, 0.0, 0.0), half=(9, 7),
                    tabulated=lambda views, valid: valid[:, :, None] * c[None, None, :])
    V, UV, F = quad()
    mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
    args = ("--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=3", "--set", "model=tabulated")
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.5, 0.3, -0.6", e=2.0)), *args)
    hit = ch["A"] > 0
    assert hit.mean() > 0.5
    assert np.allclose(rgb[hit], 2.0 * c, rtol=1e-6, atol=0)
    rgb, ch, _ = bench.render(bench.scene(SKY.format(l=0.7)), *args)
    assert np.allclose(rgb[ch["A"] > 0], 0.7 * 2 * math.pi * c, rtol=1e-6)
    rgb, ch, _ = bench.render(bench.scene(SUN.format(d="-0.5, 0.3, -0.6", e=2.0)), *args[:-2])
    assert np.all(rgb[ch["A"] > 0] == 0.0)


def test_sg_light_limits(bench):
    """Reference: closed forms of an SG light of power P on a Lambertian texture (f_1 = l_z a / pi): sharp
    (lambda 1e4, narrower than any light grid) -> the directional light of irradiance P along the axis
    (to the lobe's width, 1e-3); lambda -> 0 over the upper hemisphere -> the SG's cosine-weighted
    integral, P a / pi int G cos / M over the hemisphere = P a / pi (pi / 4 pi) for lambda = 1e-4 (G -> 1)
    (the fixed stratified points integrate cos exactly only in the limit: 1 %)."""
    btf, mesh, a = _lambertian_setup(bench)
    args = ("--set", f"btf={btf}", "--set", f"mesh={mesh}")
    axis = np.array([0.3, -0.2, 0.8])
    cos = axis[2] / np.linalg.norm(axis)
    rgb, ch, _ = bench.render(bench.scene(SGL.format(a="0.3, -0.2, 0.8", lam=1e4, p=2.0)), *args)
    hit = ch["A"] > 0
    assert hit.mean() > 0.5
    assert np.allclose(rgb[hit], 2.0 * a / math.pi * cos, rtol=1e-3)
    rgb, ch, _ = bench.render(bench.scene(SGL.format(a="0.0, 0.0, 1.0", lam=1e-4, p=2.0)), *args)
    assert np.allclose(rgb[ch["A"] > 0], 2.0 * a / math.pi * 0.25, rtol=1e-2)


GROUND = """
[render.ground]
height = -0.5
albedo = [0.2, 0.5, 0.3]
"""


@pytest.mark.parametrize("alpha", [0.0, 0.3])
def test_holes_show_what_lies_behind(bench, alpha):
    """Reference: closed form of alpha C_front + (1 - alpha) C_behind. A Lambertian quad of coverage alpha
    (every view) over a Lambertian ground (albedo g), directional light E from theta: the pixel is
    alpha E a / pi cos + (1 - alpha) E g / pi cos; alpha 0 shows the ground alone. Two such quads
    stacked: alpha C + alpha (1 - alpha) C + (1 - alpha)^2 ground (the ray goes through both). With
    shadows on, the ground's light passes the quads with (1 - alpha) each."""
    a = np.array([0.6, 0.4, 0.2])
    g = np.array([0.2, 0.5, 0.3])
    btf = write_btf(bench.name("hole").with_suffix(".zarr"), rho=a / math.pi, alpha=alpha)
    V, UV, F = quad(size=4.0)
    one = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
    V2, UV2, F2 = quad(size=4.0, z=0.25)
    two = write_obj(bench.name("quads").with_suffix(".obj"), np.concatenate([V, V2]), np.concatenate([UV, UV2]),
                    np.concatenate([F, F2 + len(V)]))
    E, cos = 2.0, 0.8 / math.sqrt(0.77)
    scene = bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=E), width=24, height=18, render=GROUND)
    front, behind = E * a / math.pi * cos, E * g / math.pi * cos
    rgb, ch, _ = bench.render(scene, "--set", f"btf={btf}", "--set", f"mesh={one}")
    assert ch["A"].min() == 1.0                                       # quad or ground everywhere
    centre = rgb[6:12, 8:16].reshape(-1, 3)                           # through the quad
    assert np.allclose(centre, alpha * front + (1 - alpha) * behind, rtol=1e-6)
    rgb, _, _ = bench.render(scene, "--set", f"btf={btf}", "--set", f"mesh={two}")
    want = alpha * front + alpha * (1 - alpha) * front + (1 - alpha) ** 2 * behind
    assert np.allclose(rgb[6:12, 8:16].reshape(-1, 3), want, rtol=1e-6)
    rgb, _, _ = bench.render(scene, "--set", f"btf={btf}", "--set", f"mesh={two}", "--set", "shadows=on")
    tr = 1 - alpha
    want = alpha * front + alpha * tr * front * tr + tr ** 2 * behind * tr ** 2   # the lower quad is shadowed once
    assert np.allclose(rgb[6:12, 8:16].reshape(-1, 3), want, rtol=1e-6)


def test_mip_of_a_uniform_texture_is_level_0(bench):
    """Reference: the same render with mip off (level 0 everywhere). Every texel of every level holds the
    same non-trivial BRDF (two lobes, a view-dependent T and alpha 1): mip on, seen from far enough that
    the footprint reaches the top levels, gives the same image to 1e-6 (blending equal values); levels of
    different colours in the same view do not (the view does select coarser levels)."""
    rng = np.random.default_rng(3)
    lob = np.tile(np.array([[-0.8, -0.9, 0.7, 8.0], [-0.5, -0.4, 0.9, 3.0]])[:, None, :], (1, 3, 1))
    table = 0.7 + 0.5 * hemisphere_grid(*VIEW_GRID)[:, :1] * rng.uniform(0.5, 1.0, 3)
    btf = write_btf(bench.name("uniform").with_suffix(".zarr"), res=16, levels=5, lobes=2, rho=(0.1, 0.08, 0.05),
                    lobe_params=lambda lv, r: np.broadcast_to(lob, (r, r, 2, 3, 4)),
                    table=lambda lv, r, v: np.broadcast_to(table, (r, r, len(v), 3)))
    V, UV, F = quad(size=2.0)
    mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
    scene = bench.scene(SUN.format(d="0.5, -0.4, -0.7", e=3.0), origin=(0.6, -2.5, 1.4), width=32, height=24)
    args = ("--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=40")
    on, ch, _ = bench.render(scene, *args)
    off, _, _ = bench.render(scene, *args, "--set", "mip=off")
    assert (ch["A"] > 0).mean() > 0.3 and on.max() > 0
    assert np.allclose(on, off, rtol=1e-6, atol=1e-9)
    levels = write_btf(bench.name("levels").with_suffix(".zarr"), res=16, levels=5,
                       rho=lambda lv, r: np.full((r, r, 3), 0.05 * (lv + 1)))
    args = ("--set", f"btf={levels}", "--set", f"mesh={mesh}", "--set", "repeat=40")
    # mip acts here
    assert not np.allclose(bench.render(scene, *args)[0], bench.render(scene, *args, "--set", "mip=off")[0])


def test_mip_level_follows_the_footprint(bench):
    """Reference: closed form on the exact camera rays (the tile loop's jitter, ``stages.core.rng``).
    Level l of a 32-texel, 6-level texture is Lambertian with pi rho_l = 0.02 (l + 1) (per channel
    scaled); the camera looks straight down on a flat quad lit from above (E = pi: the pixel is pi rho). The
    pixel's footprint is t pixel_angle c^1.5 / cos_i (c: cosine off the camera axis, cos_i: incidence),
    a level-0 texel is size / (repeat 32) wide, lambda = log2(footprint / texel), clamped to [0, 5]:
    the image is pi ((1 - f) rho_floor(lambda) + f rho_floor(lambda)+1) (1e-5). Mip off: pi rho_0."""
    from stages.core.rng import uniform
    from stages.render.camera import camera_ray, pack_camera

    size, repeat, W, H, h = 3.0, 24, 48, 36, 3.0
    scale = np.array([1.0, 0.8, 0.6])
    btf = write_btf(bench.name("levels").with_suffix(".zarr"), res=32, levels=6,
                    rho=lambda lv, r: np.broadcast_to(0.02 * (lv + 1) * scale / math.pi, (r, r, 3)))
    V, UV, F = quad(size=size)
    mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
    scene = bench.scene(SUN.format(d="0.0, 0.0, -1.0", e=math.pi), origin=(0.0, 0.0, h), width=W, height=H)
    args = ("--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", f"repeat={repeat}")
    rgb, ch, _ = bench.render(scene, *args, "--seed", "9")
    cam = pack_camera(np.array([0.0, 0.0, h]), np.zeros(3), np.array([0.0, 1.0, 0.0]), 40.0, W, H)
    pa = 2.0 * math.tan(math.radians(20.0)) / W
    texel = size / (repeat * 32)
    want = np.zeros((H, W, 3))
    lams = []
    for row in range(H):
        for col in range(W):
            idx = row * W + col
            _, d = camera_ray(cam, row, col, uniform(9, idx, 0), uniform(9, idx, 1))
            c = -d[2]
            t = h / c
            lam = min(max(math.log2(t * pa * c * math.sqrt(c) / c / texel), 0.0), 5.0)
            lams.append(lam)
            l0 = int(math.floor(lam))
            f = lam - l0
            l1 = min(l0 + 1, 5)
            want[row, col] = ((1 - f) * 0.02 * (l0 + 1) + f * 0.02 * (l1 + 1)) * scale
    hit = ch["A"] > 0
    assert hit.mean() > 0.9 and 0.5 < min(lams) < max(lams) < 4.5     # several levels in view, none clamped
    assert np.allclose(rgb[hit], want[hit], rtol=1e-5)
    off, _, _ = bench.render(scene, *args, "--seed", "9", "--set", "mip=off")
    assert np.allclose(off[hit], 0.02 * scale, rtol=1e-6)


def _checker(lv, r):
    """A texture whose texels all differ (per level)."""
    i, j = np.meshgrid(np.arange(r), np.arange(r), indexing="ij")
    return np.stack([0.05 + 0.2 * (i / r), 0.05 + 0.2 * (j / r), 0.05 + 0.1 * ((i + j) % 2)], -1)


def test_repeat_shifted_by_one_period_is_the_same_image(bench):
    """Reference: the texture's periodicity. The same quad with uv shifted by 1 / repeat (one period:
    pattern coordinate + 1) renders the same bytes; shifted by half a period it does not (the test can
    fail). A texture whose texels all differ, seen at mip level 0 and above."""
    btf = write_btf(bench.name("checker").with_suffix(".zarr"), res=8, levels=4, rho=_checker)
    scene = bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0), width=48, height=36)
    out = []
    for shift in (0.0, 0.25, 0.125):
        V, UV, F = quad(size=2.0, uv_shift=(shift, shift))
        mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
        out.append(bench.render(scene, "--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=4")[0])
    assert np.array_equal(out[0], out[1])
    assert not np.allclose(out[0], out[2])


def test_threads_and_tiles_do_not_change_the_bytes(bench):
    """Reference: the render at 1 thread. 2 threads give the same EXR image bytes (textured quads with
    holes over a ground, shadows on, mip on, a directional and a constant light), and so do the house's
    16-pixel tiles (``[render] tile_size = 16``) in place of btf's own default of 64 (the registry's)."""
    from pipeline.renderers import method

    assert method("btf").default("tile_size") == 64
    btf = write_btf(bench.name("checker").with_suffix(".zarr"), res=8, levels=4, rho=_checker,
                    alpha=lambda lv, r, v: np.where(v[:, 2] > 0.5, 0.4, 1.0)[None, None, :] * np.ones((r, r, 1)))
    V, UV, F = quad(size=3.0)
    V2, UV2, F2 = quad(size=1.0, z=0.4)
    mesh = write_obj(bench.name("quads").with_suffix(".obj"), np.concatenate([V, V2]), np.concatenate([UV, UV2]),
                     np.concatenate([F, F2 + len(V)]))
    scene = bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0) + SKY.format(l=0.3), width=40, height=30,
                        render=GROUND)
    args = ("--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=3", "--set", "shadows=on")
    a, _, _ = bench.render(scene, *args, threads=1)
    b, _, _ = bench.render(scene, *args, threads=2)
    assert np.array_equal(a, b) and a.max() > 0
    small = bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0) + SKY.format(l=0.3), width=40, height=30,
                        render="[render]\ntile_size = 16\n" + GROUND)
    c, _, _ = bench.render(small, *args, threads=2)
    assert np.array_equal(a, c)


# ------------------------------------------------------------------------------------------------ tiling
TILING = """
seed = 3
[yarn]
fibers_per_ply = 2
[weave]
spacing = [0.1, 0.1]
[[exemplars]]
name = "plain"
pattern = "plain"
[tiling]
repeat = [2, 2]
[surface]
kind = "flat"
resolution = [3, 3]
"""


def test_tiling_base_surface_and_foreign_texture(bench):
    """Reference: the same surface as an OBJ. A flat tiling (0.4 x 0.4, exemplar period 0.2): the btf
    rendered on its base surface (--fibers) equals the render of its base mesh written as an OBJ with
    repeat = flat size / period = 2 (same bytes). A texture whose source hash is not the tiling's:
    exit 2, naming both files and exemplars, nothing written."""
    from pipeline.artifacts import Artifact

    (bench.d / "tiling.toml").write_text(TILING)
    tiling = bench.d / "tiling.zarr"
    code, _, err = _cli("tile", bench.d / "tiling.toml", "-o", tiling)
    assert code == 0, err
    art = Artifact(tiling)
    btf = write_btf(bench.name("own").with_suffix(".zarr"), res=8, levels=4, rho=_checker, period=(0.2, 0.2),
                    source=str(tiling), source_hash=art.meta["content_hash"])
    mesh = write_obj(bench.name("base").with_suffix(".obj"), art["base_vertices"], art["base_uv"],
                     art["base_triangles"])
    scene = bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0), origin=(0.22, 0.16, 0.6), target=(0.2, 0.2, 0.0),
                        width=32, height=24)
    on_tiling, ch, _ = bench.render(scene, "--set", f"btf={btf}", "--fibers", tiling)
    on_obj, _, _ = bench.render(scene, "--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=2")
    assert (ch["A"] > 0).mean() > 0.5
    assert np.array_equal(on_tiling, on_obj)
    other = write_btf(bench.name("other").with_suffix(".zarr"), period=(0.2, 0.2), source="elsewhere.zarr",
                      source_hash="0" * 64)
    out = bench.d / "foreign.exr"
    code, _, err = _cli("render", scene, "-o", out, "--method", "btf", "--set", f"btf={other}", "--fibers", tiling)
    assert code == 2, err
    assert "a BTF from a different repeat than the scene names" in err and "elsewhere.zarr" in err
    assert str(tiling) in err and "'plain'" in err and "'test'" in err
    assert not out.exists()


# the tiling above with a second exemplar on the right half of its block map
TWO_EXEMPLARS = TILING.replace("[tiling]\n", '[[exemplars]]\nname = "right"\npattern = "plain"\n[tiling]\n'
                               "block_map = [[0, 1]]\n")


def test_tiling_of_two_exemplars_reads_each_texture_where_the_block_map_places_it(bench):
    """Reference: the tiling's base surface as an OBJ dressed with one exemplar's texture alone (the test above:
    the same bytes as the tiling). A flat tiling of two exemplars, the block map's left half exemplar 0 and
    its right half exemplar 1, dressed with a texture of both (red, blue Lambertian): every pixel equals, to
    the byte, the red-only or the blue-only render, red on the left of each image row and blue on its right
    (the camera looks straight down, image x along the flat u), about half each. A texture that lacks an
    exemplar the map uses: exit 2 naming it, nothing written."""
    from pipeline.artifacts import Artifact

    (bench.d / "two.toml").write_text(TWO_EXEMPLARS)
    tiling = bench.d / "two.zarr"
    code, _, err = _cli("tile", bench.d / "two.toml", "-o", tiling)
    assert code == 0, err
    art = Artifact(tiling)
    bm = np.asarray(art["block_map"])
    assert set(np.unique(bm)) == {0, 1} and np.all(bm[: bm.shape[0] // 2] == 0) and np.all(bm[bm.shape[0] // 2:] == 1)
    red, blue = (0.6, 0.1, 0.1), (0.1, 0.1, 0.6)
    both = write_btf(bench.name("both").with_suffix(".zarr"), res=8, levels=4, rho=[red, blue], period=(0.2, 0.2),
                     exemplars=(0, 1), source=str(tiling), source_hash=art.meta["content_hash"])
    mesh = write_obj(bench.name("base").with_suffix(".obj"), art["base_vertices"], art["base_uv"],
                     art["base_triangles"])
    scene = bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0), origin=(0.2, 0.2, 0.4), target=(0.2, 0.2, 0.0),
                        width=32, height=24)
    on_tiling, ch, _ = bench.render(scene, "--set", f"btf={both}", "--fibers", tiling)
    alone = []
    for c in (red, blue):
        one = write_btf(bench.name("one").with_suffix(".zarr"), res=8, levels=4, rho=c, period=(0.2, 0.2))
        alone.append(bench.render(scene, "--set", f"btf={one}", "--set", f"mesh={mesh}", "--set", "repeat=2")[0])
    cloth = ch["A"] > 0
    assert cloth.mean() > 0.9
    is_red = np.all(on_tiling == alone[0], axis=-1) & cloth
    is_blue = np.all(on_tiling == alone[1], axis=-1) & cloth
    assert np.all(is_red | is_blue | ~cloth)
    assert 0.3 < is_red.sum() / cloth.sum() < 0.7
    for row in range(on_tiling.shape[0]):      # left to right: red, then blue
        cols = np.flatnonzero(cloth[row])
        kinds = is_blue[row, cols].astype(int)
        assert np.all(np.diff(kinds) >= 0), (row, kinds)
    first = write_btf(bench.name("first").with_suffix(".zarr"), period=(0.2, 0.2), source=str(tiling),
                      source_hash=art.meta["content_hash"])
    out = bench.d / "lacking.exr"
    code, _, err = _cli("render", scene, "-o", out, "--method", "btf", "--set", f"btf={first}", "--fibers", tiling)
    assert code == 2, err
    assert "has no texture of exemplar 1 ('right')" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


# ------------------------------------------------------------------------------------------------ errors
@pytest.mark.parametrize("case,needle", [
    ("no uv", "texture coordinate"),
    ("repeat=0", "--set repeat"),
    ("repeat=-2", "--set repeat"),
    ("repeat=many", "--set repeat"),
    ("mip=maybe", "unknown mip"),
    ("shadows=yes", "unknown shadows"),
    ("colour=red", "no setting 'colour'"),
    ("model=neural", "unknown model"),
    ("model=tabulated", "tabulated/weights"),
    ("no btf", "--set btf"),
    ("no mesh", "--set mesh"),
    ("btf is not a btf", "expected a 'btf' artifact"),
    ("relief of another shape", "array heights"),
])
def test_bad_settings_exit_2(bench, case, needle):
    """Reference: the contract for bad input: exit code 2, one line naming the place, nothing written."""
    btf, mesh, _ = _lambertian_setup(bench)
    scene = bench.scene(SUN.format(d="0, 0, -1", e=1.0), width=8, height=6)
    args = ["--set", f"btf={btf}", "--set", f"mesh={mesh}"]
    if case == "no uv":
        V, _, F = quad()
        p = bench.name("nouv").with_suffix(".obj")
        p.write_text("\n".join([f"v {x} {y} {z}" for x, y, z in V] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]))
        args = ["--set", f"btf={btf}", "--set", f"mesh={p}"]
    elif case == "no btf":
        args = ["--set", f"mesh={mesh}"]
    elif case == "no mesh":
        args = ["--set", f"btf={btf}"]
    elif case == "btf is not a btf":
        code, _, err = _cli("render", scene, "-o", bench.d / "lam.exr", "--method", "btf", *args, "--spp", "1")
        assert code == 0, err
        args = ["--set", f"btf={bench.d / 'lam.zarr'}", "--set", f"mesh={mesh}"]
    elif case == "relief of another shape":     # heights (1, 5, 5) for a texture of 4 x 4 texels
        btf = write_btf(bench.name("relief").with_suffix(".zarr"), rho=np.full(3, 0.1), heights=np.zeros((5, 5)))
        args = ["--set", f"btf={btf}", "--set", f"mesh={mesh}"]
    else:
        args += ["--set", case]
    out = bench.name("bad").with_suffix(".exr")
    code, _, err = _cli("render", scene, "-o", out, "--method", "btf", *args, "--spp", "1")
    assert code == 2, (case, err)
    assert needle in err, (case, err)
    assert len(err.strip().splitlines()) == 1, err
    assert not out.exists() and not out.with_suffix(".zarr").exists()
    assert read_meta(btf)["kind"] == "btf"


def test_relief_of_one_height_is_the_surface_moved_there(bench):
    """Reference: the plain texture on a moved surface. A relief texture (``--plane relief``) whose every texel is at
    height h over the surface renders as the same texture without relief on the quad moved h along its normal (mip
    off: the footprint changes with the distance); but for texels whose edge a ray meets within rounding (at most
    1 % of the pixels), the same values. Without the relief the pictures differ (the test can fail)."""
    h = 0.15
    scene = bench.scene(SUN.format(d="-0.3, 0.2, -0.8", e=2.0), origin=(1.2, -1.6, 2.0), width=48, height=36)
    relief = write_btf(bench.name("relief").with_suffix(".zarr"), res=8, levels=4, rho=_checker,
                       heights=np.full((8, 8), h))
    plain = write_btf(bench.name("plain").with_suffix(".zarr"), res=8, levels=4, rho=_checker)
    out = []
    for btf, z in ((relief, 0.0), (plain, h), (plain, 0.0)):
        V, UV, F = quad(size=20.0, z=z)     # filling the frame: no silhouette moves with it
        mesh = write_obj(bench.name("quad").with_suffix(".obj"), V, UV, F)
        out.append(bench.render(scene, "--set", f"btf={btf}", "--set", f"mesh={mesh}", "--set", "repeat=40",
                                "--set", "mip=off")[0])
    same = np.all(out[0] == out[1], axis=-1)
    assert same.mean() >= 0.99, same.mean()
    assert np.all(out[0] == out[1], axis=-1).sum() > np.all(out[0] == out[2], axis=-1).sum() + out[0].size // 30


RandomField = namedtuple("RandomField", ["heights", "levels", "block_map", "block_size", "flat_period",
                                         "exemplar_scale", "relief_span", "inv_period"])


def test_relief_march_meets_the_first_crossing():
    """Reference: brute force. On a random 8 x 8 height field (one exemplar, period 0.5 x 0.4, heights in [-0.2,
    0.1]) and random rays (views down to 80 degrees from the normal, from anywhere on the surface), ``relief_point``
    returns the point of the ray at the first crossing that a march of 20,000 steps finds (the height d of the
    ray's first point at or below the field), to that march's step."""
    from stages.render.integrators.btf import relief_height, relief_point

    rng = np.random.default_rng(11)
    res, period = 8, np.array([0.5, 0.4])
    field = RandomField(rng.uniform(-0.2, 0.1, res * res), np.array([[[0, res]]], np.int64), np.zeros((1, 1), np.int64),
                        np.ones(2), np.zeros(2), np.ones((1, 2)), np.array([0.1, -0.2]), 1.0 / period)
    top, bottom = field.relief_span
    n_bf = 20000
    for _ in range(300):
        pu, pv = rng.uniform(-2.0, 2.0, 2)
        ct = rng.uniform(math.cos(math.radians(80.0)), 1.0)
        ph = rng.uniform(0.0, 2.0 * math.pi)
        v = (math.sqrt(1.0 - ct * ct) * math.cos(ph), math.sqrt(1.0 - ct * ct) * math.sin(ph), ct)
        su, sv = v[0] / v[2] / period[0], v[1] / v[2] / period[1]
        qu, qv = relief_point(field, pu, pv, *v)
        d = (qu - pu) / su if abs(su) > abs(sv) else (qv - pv) / sv
        assert abs(pu + d * su - qu) < 1e-9 and abs(pv + d * sv - qv) < 1e-9   # on the ray
        d_bf = bottom
        for i in range(n_bf + 1):
            x = top + (bottom - top) * i / n_bf
            if x <= relief_height(field, pu + x * su, pv + x * sv):
                d_bf = x
                break
        assert abs(d - d_bf) <= (top - bottom) / n_bf + 1e-9, (d, d_bf)
