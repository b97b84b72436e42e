"""Volumetric path tracer: tracking, white furnace, homogeneous slab, determinism.

References: Beer-Lambert transmittance exp(-tau) with tau by quadrature (heterogeneous grid) or in
closed form (slab); the white furnace (albedo 1 under a uniform environment returns the environment
radiance, Jakob 2010 / any unbiased volumetric integrator); single scattering from a homogeneous
slab under a directional light in closed form. Tolerances: 5 standard errors estimated from the
samples themselves.
"""
import math

import numba
import numpy as np
import pytest
from numba import njit

from stages.core.dispatch import runtime_value
from stages.core.rng import uniform
from stages.core.shading.material import MAT_SIZE
from stages.core.shading.sggx import fiber_sggx, phase_eval, projected_area
from stages.render.camera import camera_ray, pack_camera
from stages.render.film import F_B, F_HIT, F_R, VARIANCE_LUMINANCE, finalize, new_film, tile_grid
from stages.render.integrators.volpath import VolpathIntegrator
from stages.render.lights import LightTable, envmap_tables, pack_light
from stages.render.media.grid_medium import GridMedium, grid_lookup
from stages.render.media.medium import HomogeneousMedium, extinction
from stages.render.media.tracking import majorants_from_voxels, make_majorant_grid, track
from stages.render.meshes import no_meshes
from stages.render.tiles import render_tiles
from tests.helpers import compiled_typings

Z = 5.0  # standard errors allowed


@njit
def _track_many(med, maj, o, d, tmax, n, seed):
    """(escape indicator of delta tracking, ratio-tracking estimate) for n independent paths."""
    esc = np.empty(n)
    rat = np.empty(n)
    for k in range(n):
        r = track(med, maj, o[0], o[1], o[2], d[0], d[1], d[2], tmax, seed, k, np.int64(0), runtime_value(False),
                  np.int64(-1))
        esc[k] = 0.0 if r.collided else 1.0
        r2 = track(med, maj, o[0], o[1], o[2], d[0], d[1], d[2], tmax, seed + 1, k, np.int64(0), runtime_value(True),
                   np.int64(-1))
        rat[k] = r2.transmittance
    return esc, rat


@njit
def _optical_depth_grid(med, o, d, t0, t1, m):
    h = (t1 - t0) / m
    tau = 0.0
    for i in range(m):
        t = t0 + (i + 0.5) * h
        m = grid_lookup(med, o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])
        tau += extinction(m.den, m.tx, m.ty, m.tz, m.roughness, d[0], d[1], d[2]) * h
    return tau


def _check_transmittance(med, maj, o, d, tmax, T_exact, n=40000):
    esc, rat = _track_many(med, maj, o, d, tmax, n, 5)
    se_d = math.sqrt(max(T_exact * (1 - T_exact), 1e-12) / n)
    assert abs(esc.mean() - T_exact) < Z * se_d, (esc.mean(), T_exact)
    se_r = max(rat.std(ddof=1), 1e-12) / math.sqrt(n)
    assert abs(rat.mean() - T_exact) < Z * se_r + 1e-12, (rat.mean(), T_exact)


def _random_grid(rng, shape, empty, layer=None):
    """(GridMedium, density, lo, hi): random anisotropic voxels over [0,1]x[0,0.8]x[0,0.6], a share
    ``empty`` of them empty, and every voxel from z index ``layer`` up when given."""
    den = (6.0 * rng.random(shape) * (rng.random(shape) > empty)).astype(np.float32)
    if layer is not None:
        den[layer:] = 0.0
    dirs = rng.normal(size=(*shape, 3))
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.8, 0.6])
    g = GridMedium(lo, hi, den, dirs.astype(np.float32), np.ones((*shape, 3), np.float32),
                   (0.2 + 0.8 * rng.random(shape)).astype(np.float32))
    return g, den, lo, hi


def test_transmittance_heterogeneous_grid():
    """Delta-tracking escape probability and the ratio-tracking mean equal exp(-tau), tau by quadrature
    of sigma_t(w) = den x SGGX projected area through a random anisotropic grid with empty cells."""
    g, den, lo, hi = _random_grid(np.random.default_rng(4), (5, 6, 7), 0.4)
    res = np.array([4, 3, 3])
    maj = make_majorant_grid(lo, hi, res, majorants_from_voxels(den, lo, hi, res))
    o = np.array([-0.3, 0.1, 0.05])
    d = np.array([1.0, 0.5, 0.35])
    d /= np.linalg.norm(d)
    tau = _optical_depth_grid(g, o, d, 0.0, 3.0, 400000)
    _check_transmittance(g, maj, o, d, np.inf, math.exp(-tau))
    # a finite tmax inside the medium: exp(-tau(0, tmax))
    tau_half = _optical_depth_grid(g, o, d, 0.0, 0.9, 400000)
    _check_transmittance(g, maj, o, d, 0.9, math.exp(-tau_half))


def test_delta_and_ratio_tracking_share_one_compiled_track():
    """Issue 55: ``track``'s mode reaches it as a runtime value (``runtime_value``), so delta and ratio
    tracking through one medium class are one compilation, not one per literal (each 3-4 s on 2 cores)."""
    g, den, lo, hi = _random_grid(np.random.default_rng(5), (3, 3, 3), 0.3)
    res = np.array([2, 2, 2])
    maj = make_majorant_grid(lo, hi, res, majorants_from_voxels(den, lo, hi, res))
    d = np.array([1.0, 0.2, 0.1]) / math.sqrt(1.05)
    _track_many(g, maj, np.array([-0.2, 0.3, 0.3]), d, np.inf, 4, 1)
    grid_typings = [t for t in compiled_typings(track) if t.startswith("(GridMedium(")]
    assert len(grid_typings) == 1, grid_typings


def _refine(den, lo, hi, res, k, which):
    """The grid's majorants with the cells ``which`` (bool nz, ny, nx) refined into k^3 sub-cells whose
    majorants are those of the grid k times finer (``majorants_from_voxels``)."""
    fine_full = majorants_from_voxels(den, lo, hi, np.asarray(res) * k)
    fine = np.full(which.shape, -1, np.int32)
    cells = np.argwhere(which)
    fine[which] = np.arange(len(cells), dtype=np.int32)
    fine_mu = np.stack([fine_full[z * k:(z + 1) * k, y * k:(y + 1) * k, x * k:(x + 1) * k] for z, y, x in cells])
    return make_majorant_grid(lo, hi, res, majorants_from_voxels(den, lo, hi, res), fine, fine_mu)


@njit
def _tentative(med, maj, o, d, n, seed):
    total = 0
    for k in range(n):
        total += track(med, maj, o[0], o[1], o[2], d[0], d[1], d[2], np.inf, seed, k, np.int64(0),
                       runtime_value(True), np.int64(-1)).lookups
    return total


def test_transmittance_through_refined_cells():
    """A grid whose cells are partly refined into 3^3 sub-cells (the fibre cache's refinement of a coarse
    grid, ``tracking`` module doc): delta and ratio tracking still estimate exp(-tau), with fewer
    tentative collisions than the coarse grid's."""
    rng = np.random.default_rng(9)
    g, den, lo, hi = _random_grid(rng, (9, 12, 14), 0.6, layer=4)  # fibres below, empty space above
    res = np.array([4, 3, 3])
    coarse = make_majorant_grid(lo, hi, res, majorants_from_voxels(den, lo, hi, res))
    which = rng.random((3, 3, 4)) < 0.8
    maj = _refine(den, lo, hi, res, 3, which)
    assert np.all(maj.fine_mu.max(axis=(1, 2, 3)) <= coarse.mu[which])
    fewer = coarse_n = 0
    for o, d in (([-0.3, 0.1, 0.05], [1.0, 0.5, 0.35]), ([1.2, 0.9, 0.7], [-1.0, -0.7, -0.55]),
                 ([0.5, -0.2, 0.3], [0.0, 1.0, 0.0])):
        o, d = np.array(o), np.array(d) / np.linalg.norm(d)
        tau = _optical_depth_grid(g, o, d, 0.0, 3.0, 400000)
        _check_transmittance(g, maj, o, d, np.inf, math.exp(-tau))
        fewer += _tentative(g, maj, o, d, 2000, 3)
        coarse_n += _tentative(g, coarse, o, d, 2000, 3)
    assert fewer < 0.9 * coarse_n


def _slab(density, tangent, rough, albedo, h=1.0):
    med = HomogeneousMedium(np.array([-50.0, -50.0, 0.0]), np.array([50.0, 50.0, h]), density,
                            np.asarray(tangent, float), rough, np.asarray(albedo, float))
    maj = make_majorant_grid(med.lo, med.hi, [1, 1, 1], np.full((1, 1, 1), density))
    return med, maj


@pytest.mark.parametrize("rough", [1.0, 0.3])
def test_slab_transmittance_closed_form(rough):
    """Slab of thickness h: T = exp(-den sigma(d) h / |d_z|) (Beer-Lambert with directional sigma_t)."""
    t = np.array([0.8, 0.0, 0.6])
    med, maj = _slab(1.3, t, rough, [1, 1, 1])
    d = np.array([0.3, -0.2, -1.0])
    d /= np.linalg.norm(d)
    o = np.array([0.0, 0.0, 2.0])
    sig = projected_area(fiber_sggx(*t, rough), *d)
    _check_transmittance(med, maj, o, d, np.inf, math.exp(-1.3 * sig * 1.0 / abs(d[2])))


def _lights(*rows):
    return LightTable(np.array(rows), *envmap_tables())


def _render(med, maj, lt, cam, spp, max_depth=1000, rr_depth=5, ground=None, seed=3, tile=8):
    """(H, W, 6): mean R, G, B, alpha, (unused), variance of the mean luminance -- from the shared film."""
    W, H = int(cam[13]), int(cam[14])
    g = np.zeros(4) if ground is None else np.asarray(ground, float)
    integ = VolpathIntegrator(med, maj, lt, g, ground is not None, no_meshes(), max_depth, rr_depth,
                              np.zeros((0, MAT_SIZE)))
    film = render_tiles(integ, cam, seed, spp, 0, spp, tile_grid(W, H, tile), new_film(W, H))
    img = finalize(film, spp, VARIANCE_LUMINANCE)
    out = np.zeros((H, W, 6))
    out[..., :3] = film[..., F_R:F_B + 1] / spp
    out[..., 3] = film[..., F_HIT] / spp
    out[..., 5] = img.variance
    return out


@pytest.mark.parametrize("ground, split", [(None, False), ([-1.2, 1.0, 1.0, 1.0], False), (None, True)])
def test_white_furnace(ground, split):
    """Albedo 1 under a uniform environment L: every pixel's expectation is L (with a white ground too).
    split: L is the sum of a constant light and a uniform lat-long envmap, so light selection, the
    envmap's importance sampling and the per-light MIS weights all take part."""
    med = HomogeneousMedium(np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0]), 4.0,
                            np.array([0.0, 0.6, 0.8]), 0.3, np.ones(3))
    maj = make_majorant_grid(med.lo, med.hi, [3, 3, 3], np.full((3, 3, 3), 4.0))
    L = np.array([0.7, 0.5, 1.2])
    if split:
        img = np.broadcast_to((0.6 * L).astype(np.float32), (8, 16, 3))
        lt = LightTable(np.array([pack_light("constant", 0.4 * L), pack_light("envmap", [1.0, 1.0, 1.0])]),
                        *envmap_tables(img))
    else:
        lt = _lights(pack_light("constant", L))
    cam = pack_camera(np.array([0.3, -4.0, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 40.0, 12, 12)
    out = _render(med, maj, lt, cam, spp=12, ground=ground)
    assert out[..., 3].mean() > 0.5  # the medium (or ground) covers most pixels
    X = out[..., :3].mean(axis=(0, 1)) / L  # every channel is L_c times the same path weight
    Y = float(L @ [0.2126, 0.7152, 0.0722])
    se = math.sqrt(out[..., 5].sum()) / out[..., 0].size / Y
    np.testing.assert_allclose(X, 1.0, atol=Z * se)
    assert se < 0.02


def _camera_dirs(cam, spp, seed):
    W, H = int(cam[13]), int(cam[14])
    dirs = np.empty((H, W, spp, 3))
    for row in range(H):
        for col in range(W):
            for s in range(spp):
                idx = (row * W + col) * spp + s
                dirs[row, col, s] = camera_ray(cam, row, col, uniform(seed, idx, 0), uniform(seed, idx, 1))[1]
    return dirs


@pytest.mark.parametrize("rough, tangent", [(1.0, (0.0, 0.0, 1.0)), (0.4, (1.0, 0.0, 0.0)), (0.3, (0.6, 0.8, 0.0))])
def test_slab_single_scattering_closed_form(rough, tangent):
    """max_depth = 2 keeps single scattering only. For a slab of thickness h, density den, albedo a under
    a directional light of irradiance E from w_l, seen along v (both upward, cosines mu, mu0):
        L = a E sigma(v) f(v, w_l) (1 - exp(-den h (sigma(v)/mu + sigma(w_l)/mu0))) / (sigma(v) + sigma(w_l) mu/mu0)
    (integral of the in-scattered, doubly attenuated light over depth)."""
    den, h, a, E = 2.0, 0.7, 0.8, 3.0
    t = np.asarray(tangent, float)
    med, maj = _slab(den, t, rough, [a, a, a], h)
    travel = np.array([0.3, 0.4, -1.0])
    travel /= np.linalg.norm(travel)
    wl = -travel
    lt = _lights(pack_light("directional", [E, E, E], direction=travel))
    cam = pack_camera(np.array([0.0, -2.0, 4.0]), np.array([0.0, 0.0, h / 2]), np.array([0.0, 0.0, 1.0]), 3.0, 10, 10)
    spp, seed = 48, 9
    out = _render(med, maj, lt, cam, spp, max_depth=2, seed=seed)
    S = fiber_sggx(*t, rough)
    sl = projected_area(S, *wl)
    expect = []
    for d in _camera_dirs(cam, spp, seed).reshape(-1, 3):
        v = -d
        sv = projected_area(S, *v)
        mu, mu0 = v[2], wl[2]
        f = phase_eval(S, *v, *wl)
        expect.append(a * E * sv * f * (1 - math.exp(-den * h * (sv / mu + sl / mu0))) / (sv + sl * mu / mu0))
    expect = float(np.mean(expect))
    got = out[..., 0].mean()
    se = math.sqrt(out[..., 5].sum()) / out[..., 0].size
    assert expect > 0.01
    assert abs(got - expect) < Z * se, (got, expect, se)
    np.testing.assert_array_equal(out[..., 0], out[..., 2])  # grey albedo and light: grey image


def test_same_bytes_whatever_threads_and_tiles():
    med = HomogeneousMedium(np.array([-1.0, -1.0, -0.2]), np.array([1.0, 1.0, 0.2]), 6.0,
                            np.array([1.0, 0.0, 0.0]), 0.3, np.array([0.9, 0.6, 0.3]))
    maj = make_majorant_grid(med.lo, med.hi, [2, 2, 1], np.full((1, 2, 2), 6.0))
    lt = _lights(pack_light("directional", [2.0, 2.0, 2.0], direction=[0.2, 0.1, -1.0]),
                 pack_light("constant", [0.2, 0.3, 0.4]))
    cam = pack_camera(np.array([0.0, -3.0, 2.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 50.0, 9, 7)
    n0 = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = _render(med, maj, lt, cam, 4, ground=[-0.5, 0.4, 0.4, 0.4], tile=4)
    finally:
        numba.set_num_threads(n0)
    b = _render(med, maj, lt, cam, 4, ground=[-0.5, 0.4, 0.4, 0.4], tile=5)
    assert a.tobytes() == b.tobytes()
    assert a[..., 0].max() > 0


SMALL_SCENE = """
[scene]
name = "volpath-sources"
seed = 3

[fabric]
source = "generator"

[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 2
picks = 2
spacing = 0.1
yarn_radius = 0.045
samples_per_cell = 4

[yarns.default]
preset = "cotton1"
radius = 0.045
density = 150.0
roughness = 0.3

[yarns.weft]
preset = "cotton1"
radius = 0.045
density = 150.0
roughness = 0.3
color = [0.2, 0.3, 0.7]

[camera]
origin = [0.02, -0.05, 0.6]
target = [0.0, 0.0, 0.0]
fov = 14.0
width = 8
height = 8

[[lights]]
type = "directional"
direction = [-0.3, 0.4, -1.0]
irradiance = 3.0

[[lights]]
type = "constant"
radiance = 0.3

[render]
method = "volpath"
spp = 24
max_depth = 4
rr_depth = 3
tile_size = 4
"""


def _cli(*args):
    import contextlib
    import io

    from pipeline.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """The small two-by-two weave: scene file, yarns, tables and realized fibres."""
    d = tmp_path_factory.mktemp("volpath_small")
    scene_path = d / "s.toml"
    scene_path.write_text(SMALL_SCENE)
    for args in (("ingest", scene_path, "-o", d / "y.zarr"), ("tables", d / "y.zarr", "-o", d / "t.zarr"),
                 ("realize", d / "y.zarr", "-o", d / "f.zarr")):
        code, out, err = _cli(*args)
        assert code == 0, err
    return d


@pytest.mark.slow  # compiles the procedural volpath integrator (~3.3 min of one core on a cold cache): make test-all
def test_procedural_and_realized_sources_agree(small):
    """The same fabric through on-the-fly lookups and through realized fibres in a BVH: per 2 x 2
    pixel block the difference of the means over its standard error (independent seeds) is
    standard normal; the sum of squares is chi-square with one degree per block (p > 0.001)
    and no block deviates by more than the Sidak-corrected 0.001 two-sided normal quantile
    (tests/chisquare.py: z_score_test)."""
    from pipeline.renderers.volpath import render
    from pipeline.scene import load_scene
    from tests.chisquare import z_score_test

    scene = load_scene(small / "s.toml")
    base = {"width": 8, "height": 8, "spp": 16, "max_depth": 4, "rr_depth": 3, "tile_size": 4, "extra": {}}
    proc = render(scene, {**base, "seed": 1, "source": "procedural", "tables": str(small / "t.zarr"), "cache": 0.0})
    real = render(scene, {**base, "seed": 2, "source": "realized", "fibers": str(small / "f.zarr")})
    assert proc.stats["medium_lookups"] > 0 and real.stats["medium_lookups"] > 0
    assert proc.extra["A"].mean() > 0.5  # the fabric fills most of the view

    def blocks(a):
        return a.reshape(4, 2, 4, 2).sum(axis=(1, 3))

    lum = np.array([0.2126, 0.7152, 0.0722])
    yp, yr = proc.rgb @ lum, real.rgb @ lum
    d = (blocks(yp) - blocks(yr)) / 4.0
    se = np.sqrt(blocks(proc.extra["variance"]) + blocks(real.extra["variance"])) / 4.0
    assert np.all(se > 0)
    z = (d / se).ravel()
    res = z_score_test(z, alpha=1e-3)
    assert res.passed, (res.message, z)
    # the image is not trivially equal: both sources carry their own noise
    assert not np.array_equal(yp, yr)


@pytest.mark.slow  # compiles the procedural volpath integrator (~3.3 min of one core on a cold cache): make test-all
def test_paged_frame_samples_render_the_same_bytes(small, monkeypatch):
    """Frame samples paged in as rays reach each yarn (stages.core.yarn.frame_pool): pixels whose lookups
    missed a yarn are rendered again after it is paged in, so the picture is the resident tables', byte for
    byte, on one thread or two (fibre cache off: every lookup procedural)."""
    import pipeline.renderers.volpath as V
    from pipeline.scene import load_scene

    scene = load_scene(small / "s.toml")
    base = {"width": 8, "height": 8, "spp": 4, "max_depth": 4, "rr_depth": 3, "tile_size": 4, "extra": {}, "seed": 3,
            "source": "procedural", "tables": str(small / "t.zarr"), "cache": 0.0}
    monkeypatch.setattr(V, "PAGE_FRAME_BYTES", float("inf"))
    whole = V.render(scene, base)
    assert not whole.stats["frame_samples_paged"]
    monkeypatch.setattr(V, "PAGE_FRAME_BYTES", 0.0)
    for threads in (1, 2):
        paged = V.render(scene, {**base, "threads": threads})
        st = paged.stats
        assert st["frame_samples_paged"] and st["frame_pool_rounds"] >= 1 and st["frame_pool_pixels_again"] >= 1
        assert 0 < st["frame_pool_yarns"] <= st["frame_pool_of_yarns"]
        assert np.array_equal(paged.rgb, whole.rgb) and np.array_equal(paged.extra["variance"], whole.extra["variance"])


def test_z_score_harness_rejects_biased_blocks():
    """The z-score test above must be able to fail: 16 standard normal scores pass (seeded), the same scores
    shifted by 1.5 standard errors fail the sum of squares, and one block 5 errors off fails the maximum."""
    from tests.chisquare import z_score_test

    z = np.random.default_rng(4).normal(size=16)
    assert z_score_test(z, alpha=1e-3).passed
    assert not z_score_test(z + 1.5, alpha=1e-3).passed
    z[3] = 5.0
    assert not z_score_test(z, alpha=1e-3).passed


@pytest.mark.parametrize("cell", [None, 0.002])
def test_procedural_majorant_covers_every_fibre(small, cell):
    """Delta tracking is unbiased only where the majorant bounds the density: at 60,000 points next
    to the realized fibre vertices (jittered by 1.5 fibre radii) every point the procedural lookup
    puts inside a fibre lies in a majorant cell of at least that density; and the fibre-aware
    capsules (core tube, loops, hairs) occupy fewer cells than the full extent tube would. With the
    default cell and with one so small that the grid is capped (a large cloth's case: the extent tubes'
    box, cells coarsened along the cloth)."""
    from pipeline.artifacts import Artifact
    from pipeline.renderers.volpath import MAX_MAJORANT_CELLS, _capped, procedural_source
    from stages.core.yarn.lookup import lookup_points

    med, maj = procedural_source(str(small / "t.zarr"), cell)[:2]
    if cell is not None:
        assert _capped(maj.lo, maj.hi, cell) and np.prod(maj.res) <= MAX_MAJORANT_CELLS
    fib = Artifact(small / "f.zarr", kind="fibers")
    pts = np.asarray(fib["points"], np.float64)
    rf = float(np.max(fib["point_radius"]))
    rng = np.random.default_rng(11)
    Q = pts[rng.integers(0, len(pts), 60000)] + rng.normal(0, 1.5 * rf, (60000, 3))
    r = lookup_points(med.cv, med.tab, Q)
    inside, kind, den = r.inside, r.kind, r.density
    assert inside.sum() > 5000 and set(np.unique(kind[inside])) == {1, 2, 3}
    ijk = np.floor((Q - maj.lo) / (maj.hi - maj.lo) * maj.res).astype(int)
    ok = np.all((ijk >= 0) & (ijk < maj.res), axis=1)
    assert ok[inside].all()
    mu = maj.mu[ijk[inside, 2], ijk[inside, 1], ijk[inside, 0]]
    assert np.all(mu >= den[inside])
    assert 0.0 < float(np.mean(maj.mu > 0)) < 0.9


def test_procedural_majorant_does_not_depend_on_workers(small):
    """The capsules are walked, not listed, and rastered into one grid per worker merged by maximum:
    1 or 3 workers give the grid procedural_source built, bit for bit. The box walk and the raster walk
    share one compiled walk (one typing of _walk_yarn)."""
    from pipeline.renderers.volpath import MAJORANT_STEP, procedural_source
    from stages.render.media.procedural_medium import _walk_yarn, capsule_majorants

    med, maj = procedural_source(str(small / "t.zarr"))[:2]
    for workers in (1, 3):
        mu = capsule_majorants(med.cv, med.tab, MAJORANT_STEP, maj.lo, maj.hi, maj.res, workers)
        assert np.array_equal(mu, maj.mu)
    assert len(compiled_typings(_walk_yarn)) == 1, compiled_typings(_walk_yarn)


def test_majorant_cells_follow_a_flat_cloth():
    """A 50 cm cloth 0.2 cm thick keeps the asked cell across its thickness (10 layers of 0.02) within the cell
    budget, coarser along it (not one layer of 128 x 128, nor 3 or 4 cubic layers); a small box keeps the asked
    cell exactly."""
    from pipeline.renderers.volpath import MAX_MAJORANT_CELLS, _capped, _majorant_res

    lo, hi = np.array([-25.0, -25.0, -0.1]), np.array([25.0, 25.0, 0.1])
    res = _majorant_res(lo, hi, 0.02)
    assert np.prod(res) <= MAX_MAJORANT_CELLS and res[2] == 10 and res[0] == res[1] > 128 and _capped(lo, hi, 0.02)
    assert list(_majorant_res(np.zeros(3), np.array([0.8, 0.8, 0.1]), 0.01)) == [80, 80, 10]
    assert not _capped(np.zeros(3), np.array([0.8, 0.8, 0.1]), 0.01)


def test_the_extent_tubes_hold_every_fibre(small):
    """tube_box (a large cloth's majorant box, from the yarns' axes and extents alone) holds every realized fibre
    vertex grown by its radius -- nothing the grid must bound falls outside it -- and is looser than they are by
    less than two yarn extents a side."""
    from pipeline.artifacts import Artifact
    from pipeline.renderers.volpath import MAJORANT_STEP
    from pipeline.runners.tables import load_tables
    from stages.render.media.procedural_medium import tube_box

    cv, tab, _ = load_tables(small / "t.zarr")
    lo, hi = tube_box(cv, tab, MAJORANT_STEP)
    fib = Artifact(small / "f.zarr", kind="fibers")
    pts, r = np.asarray(fib["points"], np.float64), np.asarray(fib["point_radius"], np.float64)[:, None]
    assert np.all(pts - r >= lo) and np.all(pts + r <= hi)
    assert np.all(hi - lo < (pts + r).max(axis=0) - (pts - r).min(axis=0) + 4.0 * float(tab.yarn_extent.max()))


def test_centred_bricks_split_a_flat_cloth_at_its_middle():
    """A capped grid's bricks are centred on the box: a cloth two bricks thick is split at z = its middle."""
    from stages.render.media.fibre_cache import brick_grid

    g = brick_grid(np.array([-25.0, -25.0, -0.1]), np.array([25.0, 25.0, 0.1]), 0.098, centred=True)
    assert g.res[2] == 2 and abs(g.lo[2] + g.size) < 1e-12
    assert np.allclose(brick_grid(np.zeros(3), np.ones(3), 0.1).lo, 0.0)


def test_render_cli_outputs_and_statistics(small, tmp_path):
    """loomlight render --method volpath writes EXR (RGB + A, depth, variance), PNG and a render artifact
    whose statistics include paths/s and medium lookups/s; the same seed gives the same bytes."""
    from pipeline.artifacts import Artifact
    from pipeline.images import read_exr

    outs = []
    for k in range(2):
        exr = tmp_path / f"r{k}.exr"
        code, out, err = _cli("render", small / "s.toml", "--method", "volpath", "--source", "realized",
                              "--fibers", small / "f.zarr", "-o", exr, "--width", 6, "--height", 5, "--spp", 2,
                              "--seed", 4, "--threads", k + 1)
        assert code == 0, err
        assert exr.exists() and exr.with_suffix(".png").exists()
        rgb, ch = read_exr(exr)
        assert rgb.shape == (5, 6, 3) and {"A", "depth", "variance"} <= set(ch)
        outs.append(rgb.tobytes())
    assert outs[0] == outs[1]
    s = Artifact(tmp_path / "r0.zarr").summary
    assert s["paths"] == 60 and s["paths_per_s"] > 0
    assert s["method_stats"]["medium_lookups_per_s"] > 0 and s["method_stats"]["source"] == "realized"


def test_render_bad_input(small, tmp_path):
    """Unknown source, non-positive size or spp, missing or incomplete tables: exit 2 with the reason."""
    import shutil

    base = ("render", small / "s.toml", "--method", "volpath", "-o", tmp_path / "x.exr")
    code, _, err = _cli(*base, "--source", "voxels")
    assert code == 2 and "source" in err
    code, _, err = _cli(*base, "--method", "nosuch")
    assert code == 2 and "method" in err
    for opt in ("--width", "--height", "--spp"):
        code, _, err = _cli(*base, opt, 0)
        assert code == 2 and opt in err
    code, _, err = _cli(*base, "--source", "procedural", "--no-build")   # (else render builds the tables)
    assert code == 2 and "tables" in err
    code, _, err = _cli(*base, "--source", "procedural", "--set", f"tables={tmp_path / 'missing.zarr'}")
    assert code == 2 and "not found" in err
    broken = tmp_path / "broken.zarr"
    shutil.copytree(small / "t.zarr", broken)
    meta = (broken / "zarr.json").read_text().replace('"complete": true', '"complete": false')
    (broken / "zarr.json").write_text(meta)
    code, _, err = _cli(*base, "--source", "procedural", "--set", f"tables={broken}")
    assert code == 2 and "incomplete" in err
    assert not (tmp_path / "x.exr").exists()


def test_camera_seeing_no_fabric_warns_and_renders(small, tmp_path):
    text = (small / "s.toml").read_text().replace("target = [0.0, 0.0, 0.0]", "target = [0.0, 0.0, 1.6]")
    scene = tmp_path / "away.toml"
    scene.write_text(text)
    code, out, err = _cli("render", scene, "--method", "volpath", "--source", "realized", "--fibers",
                          small / "f.zarr", "-o", tmp_path / "a.exr", "--width", 4, "--height", 4, "--spp", 1)
    assert code == 0, err
    assert "sees no fabric" in err
    assert (tmp_path / "a.exr").exists()
