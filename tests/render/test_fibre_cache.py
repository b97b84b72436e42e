"""The procedural source's render-time fibre cache (``stages.render.media.fibre_cache``, ``pipeline.fibre_cache``).

Contracts: in a cached brick the cache answers exactly as the realized fibres' BVH does (the cached
segments are the full realization's, same floats), so both describe the procedural fabric; outside
cached bricks the exact lookups answer; the budget bounds what is cached; the same scene gives the
same cache and the same image bytes at 1 and 2 threads, and images at cache 0 (lookups only), a
small and a large cache agree within Monte Carlo error.
"""
import numpy as np
import pytest
from numba import njit

from pipeline.artifacts import Artifact
from pipeline.fibre_cache import build_fibre_cache
from pipeline.renderers.volpath import procedural_majorant
from pipeline.runners.realize import run_realize
from pipeline.runners.tables import build
from pipeline.scene import camera_array
from stages.core.geometry.bvh import build_fiber_bvh
from stages.procedural.realized_reference import build_segment_grid, query_realized, segment_fiber
from stages.render.media.fibre_cache import fibre_ids
from stages.render.media.medium import medium_lookup
from stages.render.media.procedural_medium import ProceduralMedium
from stages.render.media.realized_medium import RealizedMedium
from tests.helpers import EXACTNESS_SWATCH, closed_ring_scene, seam_points

SPACING = 0.002
CAMERA = {"origin": [0.35, -0.6, 0.5], "target": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0], "fov": 50.0}


@njit(cache=True)
def _lookups_skipping(med, Q, skip):
    """(den, yarn, fibre, tx, ty, tz) of medium_lookup at every row of Q, fibre skip[i] counting as empty."""
    out = np.empty((Q.shape[0], 6))
    for i in range(Q.shape[0]):
        m = medium_lookup(med, Q[i, 0], Q[i, 1], Q[i, 2], skip[i])
        out[i, 0] = m.den
        out[i, 1] = m.yarn
        out[i, 2] = m.fibre
        out[i, 3] = m.tx
        out[i, 4] = m.ty
        out[i, 5] = m.tz
    return out


def _lookups(med, Q, skip=None):
    return _lookups_skipping(med, Q, np.full(len(Q), -1, np.int64) if skip is None else skip.astype(np.int64))


def _fabric(tmp, toml, seed=3):
    from pipeline.cli import main

    (tmp / "s.toml").write_text(toml)
    assert main(["ingest", str(tmp / "s.toml"), "-o", str(tmp / "yarns.zarr")]) == 0
    run_realize(tmp / "yarns.zarr", tmp / "fibers.zarr", seed=seed, spacing=SPACING)
    fib = Artifact(tmp / "fibers.zarr", kind="fibers")
    cv, tab, info, _, _ = build(tmp / "yarns.zarr", seed=seed, hair_mode="hybrid")
    return fib, cv, tab, info


def _realized(fib, tab):
    pts = np.asarray(fib["points"], np.float64)
    bvh, _ = build_fiber_bvh(pts, np.asarray(fib["fiber_offsets"]), np.asarray(fib["point_radius"], np.float64))
    from stages.core.yarn.model import DENSITY, ROUGHNESS

    yt = tab.yarn_type
    ids = fibre_ids(*(np.asarray(fib[k]) for k in ("fiber_yarn", "fiber_ply", "fiber_kind", "fiber_index")))
    return RealizedMedium(bvh, np.asarray(fib["fiber_yarn"], np.int32), tab.tparams[yt, DENSITY].copy(),
                          np.ascontiguousarray(tab.yarn_albedo), tab.tparams[yt, ROUGHNESS].copy(), ids)


def _points(fib, n_uniform, n_near, seed=0):
    pts = np.asarray(fib["points"], np.float64)
    rng = np.random.default_rng(seed)
    lo, hi = pts.min(0) - 0.01, pts.max(0) + 0.01
    rf = float(np.max(fib["point_radius"]))
    return np.concatenate([rng.uniform(lo, hi, (n_uniform, 3)),
                           pts[rng.integers(0, len(pts), n_near)] + rng.normal(0.0, 1.5 * rf, (n_near, 3))])


def _clear(fib, Q):
    """Points farther than the realization's tolerance from every fibre surface (and no kind tie):
    there the procedural lookup must equal the realized fibres (tests/core/yarn/test_lookup_exactness)."""
    pts32 = np.asarray(fib["points"])
    rad = np.asarray(fib["point_radius"])
    off = np.asarray(fib["fiber_offsets"])
    tol = 2.0 * fib.summary["max_chord_error"] + 4 * np.finfo(np.float32).eps * float(np.abs(pts32).max())
    lo, cell, dims, start, items = build_segment_grid(pts32, off, rad, tol)
    ref = query_realized(pts32, rad, segment_fiber(off), np.asarray(fib["fiber_yarn"]), np.asarray(fib["fiber_ply"]),
                         np.asarray(fib["fiber_kind"]), np.asarray(fib["fiber_index"]), lo, cell, dims, start, items,
                         Q, tol)
    return (ref.surface_gap > tol) & ~ref.kind_tie


def _check_exact(fib, cv, tab, budget_mib, Q, W=64, H=48):
    """Cache lookups: equal to the realized BVH's in cached bricks (all fields), equal to the procedural
    lookups everywhere away from surfaces (inside, yarn, fibre number)."""
    maj = procedural_majorant(cv, tab)
    built = build_fibre_cache(cv, tab, maj, camera_array(CAMERA, W, H), W, H, budget_mib, spacing=SPACING)
    med = built.medium
    got = _lookups(med, Q)
    real = _lookups(_realized(fib, tab), Q)
    b = np.floor((Q - med.brick_lo) * med.brick_inv).astype(np.int64)
    ok = np.all((b >= 0) & (b < med.brick_res), axis=1)
    flat = np.full(len(Q), -1)
    flat[ok] = (b[ok, 2] * med.brick_res[1] + b[ok, 1]) * med.brick_res[0] + b[ok, 0]
    in_cache = flat >= 0
    in_cache[in_cache] = med.cached[flat[in_cache]] == 1
    # the realized fibres' BVH (numbered as the lookups number fibres): the same answer, bit for bit
    assert np.array_equal(got[in_cache], real[in_cache])
    # the procedural lookups, away from surfaces, cached or not
    proc = _lookups(ProceduralMedium(cv, tab), Q)
    clear = _clear(fib, Q)
    assert clear.mean() > 0.85  # the band is wider than at the exactness test's spacing of 0.001
    inside = got[:, 0] > 0
    assert np.array_equal(inside[clear], proc[clear, 0] > 0)
    both = clear & inside
    assert np.array_equal(got[both, 1:3], proc[both, 1:3])  # yarn and the fibre's number
    # every fibre but the one that answered (a ray leaving it): the next covering fibre, if any, in
    # the same order, from the cache, the realized fibres and the lookups alike
    got2 = _lookups(med, Q, got[:, 2])
    real2 = _lookups(_realized(fib, tab), Q, real[:, 2])
    assert np.array_equal(got2[in_cache], real2[in_cache])
    proc2 = _lookups(ProceduralMedium(cv, tab), Q, proc[:, 2])
    inside2 = got2[:, 0] > 0
    assert np.array_equal(inside2[clear], proc2[clear, 0] > 0)
    assert np.array_equal(got2[clear & inside2, 1:3], proc2[clear & inside2, 1:3])
    assert inside2[clear].sum() > 0.1 * inside[clear].sum()  # overlaps were exercised
    assert not np.any(inside2 & (got2[:, 2] == got[:, 2]))
    return built, in_cache, inside


@pytest.fixture(scope="module")
def swatch(tmp_path_factory):
    fib, cv, tab, info = _fabric(tmp_path_factory.mktemp("cache"), EXACTNESS_SWATCH)
    assert not info["folded"].any()
    return fib, cv, tab


def test_cache_answers_as_the_realized_fibres_and_the_lookups(swatch):
    fib, cv, tab = swatch
    Q = _points(fib, 20000, 80000)
    built, in_cache, inside = _check_exact(fib, cv, tab, 512.0, Q)
    assert built.info["cache_complete"] and built.info["cache_bricks_cached"] == built.info["cache_bricks_occupied"]
    assert in_cache[inside].all() and inside.sum() > 20000  # every fibre point was answered by the cache
    assert set(np.unique(np.asarray(fib["fiber_kind"]))) == {1, 2, 3}


def test_small_budget_caches_the_nearest_bricks_and_stays_exact(swatch):
    fib, cv, tab = swatch
    full = build_fibre_cache(cv, tab, procedural_majorant(cv, tab), camera_array(CAMERA, 64, 48), 64, 48, 512.0,
                             spacing=SPACING).info
    budget = 0.3 * full["cache_estimate_bytes"] / 2**20
    Q = _points(fib, 10000, 40000, seed=1)
    built, in_cache, inside = _check_exact(fib, cv, tab, budget, Q)
    info = built.info
    assert 0 < info["cache_bricks_cached"] < full["cache_bricks_cached"]
    assert info["cache_estimate_bytes"] <= budget * 2**20
    assert 0 < in_cache[inside].mean() < 1  # some fibre points from the cache, some from the lookups
    # the bricks are taken in the pilot's order
    from stages.render.media.fibre_cache import PILOT_DEPTH, pilot_bricks

    med = built.medium
    maj = procedural_majorant(cv, tab)
    steps, _ = pilot_bricks(maj, camera_array(CAMERA, 64, 48), 64, 48, 1, med.brick_lo, 1.0 / med.brick_inv[0],
                            med.brick_res, PILOT_DEPTH)
    assert steps[med.cached == 1].max() == steps.max() > 0  # the brick seen longest comes first


def test_a_partial_cache_is_kept(swatch):
    """A budget for part of the view caches the bricks it can hold (seen longest first) and leaves the rest
    to the lookups: no share of the view is required (a held brick only saves lookups)."""
    fib, cv, tab = swatch
    maj = procedural_majorant(cv, tab)
    cam = camera_array(CAMERA, 64, 48)
    full = build_fibre_cache(cv, tab, maj, cam, 64, 48, 512.0).info
    small_mib = 0.3 * full["cache_estimate_bytes"] / 2**20
    part = build_fibre_cache(cv, tab, maj, cam, 64, 48, small_mib)
    assert part.medium.cached.any()
    assert 0 < part.info["cache_bricks_cached"] < full["cache_bricks_cached"]
    assert 0.0 < part.info["cache_seen_share"] < 1.0


def test_refined_majorant_cells_bound_the_cached_fibres(swatch):
    """Where the majorant grid is coarser than the fine cell asked for, the cells inside cached bricks are
    refined (``cached_majorant``): each sub-cell's majorant equals the cached capsules' majorant on the
    grid k times finer (the brute-force raster of every capsule, ``majorants_from_prims``), cells outside
    cached bricks stay unrefined, and every cached fibre point lies in a sub-cell whose majorant is at
    least its density."""
    from pipeline.fibre_cache import cached_majorant
    from stages.render.media.tracking import majorants_from_prims

    fib, cv, tab = swatch
    maj = procedural_majorant(cv, tab)
    cam = camera_array(CAMERA, 32, 24)
    full = build_fibre_cache(cv, tab, maj, cam, 32, 24, 512.0, spacing=SPACING).info
    built = build_fibre_cache(cv, tab, maj, cam, 32, 24, 0.3 * full["cache_estimate_bytes"] / 2**20, spacing=SPACING)
    med = built.medium
    assert built.info["majorant_fine_cells"] == 0  # the swatch's grid is as fine as asked: nothing to refine
    cs = float(np.max((maj.hi - maj.lo) / maj.res))
    grid, info = cached_majorant(med, maj, cs / 3.0)
    k = info["majorant_fine_k"]
    assert k == 3 and info["majorant_fine_cells"] > 0
    brute = majorants_from_prims(med.prims, med.seg_fiber, med.fibre_yarn, med.yarn_density, maj.lo, maj.hi,
                                 maj.res * k)
    refined = np.argwhere(grid.fine >= 0)
    assert 0 < len(refined) < np.sum(grid.mu > 0)  # a partial cache: some occupied cells stay coarse
    for z, y, x in refined:
        b = grid.fine[z, y, x]
        assert np.array_equal(grid.fine_mu[b], brute[z * k:(z + 1) * k, y * k:(y + 1) * k, x * k:(x + 1) * k])
        assert grid.fine_mu[b].max() <= grid.mu[z, y, x]
    Q = _points(fib, 0, 40000, seed=2)
    got = _lookups(med, Q)
    cell = np.floor((Q - maj.lo) / ((maj.hi - maj.lo) / (maj.res * k))).astype(np.int64)
    ok = np.all((cell >= 0) & (cell < maj.res * k), axis=1) & (got[:, 0] > 0)
    c = cell[ok]
    blk = grid.fine[c[:, 2] // k, c[:, 1] // k, c[:, 0] // k]
    sub = blk >= 0
    assert sub.sum() > 1000
    bound = grid.fine_mu[blk[sub], c[sub, 2] % k, c[sub, 1] % k, c[sub, 0] % k]
    assert np.all(bound >= got[ok][sub, 0])


def test_zero_budget_caches_nothing(swatch):
    """Budget 0: a cache of no bricks (one medium type for the integrator whatever the budget), whose every
    lookup is the bare procedural one, bit for bit, skipping a fibre or not."""
    fib, cv, tab = swatch
    built = build_fibre_cache(cv, tab, procedural_majorant(cv, tab), camera_array(CAMERA, 32, 24), 32, 24, 0.0)
    med = built.medium
    assert built.info["cache_bricks_cached"] == 0 and not med.cached.any() and len(med.fibre_id) == 0
    assert type(med) is type(build_fibre_cache(cv, tab, procedural_majorant(cv, tab), camera_array(CAMERA, 32, 24),
                                               32, 24, 512.0, spacing=SPACING).medium)
    Q = _points(fib, 5000, 20000, seed=4)
    got, proc = _lookups(med, Q), _lookups(ProceduralMedium(cv, tab), Q)
    assert np.array_equal(got, proc) and (got[:, 0] > 0).sum() > 2000
    assert np.array_equal(_lookups(med, Q, got[:, 2]), _lookups(ProceduralMedium(cv, tab), Q, proc[:, 2]))


def test_free_hair_mode_tables_are_never_cached(swatch):
    """Tables of the realization-free hair mode store no hairs (their hair arrays are empty while every ply
    counts its hairs): the cache would realize hairs from memory past those arrays, a different fabric in
    every process. It caches nothing and says why; the bare lookups answer."""
    fib, _cv, _tab = swatch
    cv, tab, _info, _, _ = build(fib.path.parent / "yarns.zarr", seed=3, hair_mode="free")   # the swatch's yarns
    assert tab.hair_mode[0] != 0 and tab.hair_count.sum() > 0 and len(tab.hair_ze) == 0
    built = build_fibre_cache(cv, tab, procedural_majorant(cv, tab), camera_array(CAMERA, 32, 24), 32, 24, 2048.0)
    assert not built.medium.cached.any() and built.info["cache_bricks_cached"] == 0
    assert "hair mode free" in built.info["cache_skipped"]


@pytest.mark.slow
def test_closed_yarn_cache_is_exact_at_the_seam(tmp_path):
    """A closed ring (tests/core/yarn/test_lookup_exactness): the cached pieces at both ends of the
    seam and the hairs that cross it are the realized ones."""
    ring, scene = closed_ring_scene(tmp_path)
    fib, cv, tab, info = _fabric(tmp_path, scene)
    assert bool(cv.closed[0]) and not info["folded"].any()
    Q = seam_points(fib, ring, 40000, 10000)
    built, in_cache, inside = _check_exact(fib, cv, tab, 512.0, Q)
    assert in_cache[inside].all()


VIEW = f"""
[camera]
origin = {CAMERA["origin"]}
target = {CAMERA["target"]}
fov = 24.0
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
max_depth = 4
rr_depth = 3
"""


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """The exactness swatch seen by CAMERA at 8 x 8 pixels: scene, yarns and tables."""
    from tests.render.test_volpath import _cli

    d = tmp_path_factory.mktemp("cache_small")
    (d / "s.toml").write_text(EXACTNESS_SWATCH + VIEW)
    for args in (("ingest", d / "s.toml", "-o", d / "y.zarr"), ("tables", d / "y.zarr", "-o", d / "t.zarr")):
        code, out, err = _cli(*args)
        assert code == 0, err
    return d


def _render(small, cache, seed, threads=None):
    import numba

    from pipeline.renderers.volpath import render
    from pipeline.scene import load_scene

    scene = load_scene(small / "s.toml")
    opts = {"width": 8, "height": 8, "spp": 16, "max_depth": 4, "rr_depth": 3, "tile_size": 4, "extra": {},
            "seed": seed, "source": "procedural", "tables": str(small / "t.zarr"), "cache": cache}
    n0 = numba.get_num_threads()
    try:
        numba.set_num_threads(threads or n0)
        return render(scene, opts)
    finally:
        numba.set_num_threads(n0)


def _partial_budget(small, full) -> float:
    """A budget (MiB) that caches some of the bricks the full cache holds, not all."""
    from pipeline.runners.tables import load_tables
    from pipeline.scene import load_scene

    scene = load_scene(small / "s.toml")
    cv, tab, _ = load_tables(small / "t.zarr")
    maj = procedural_majorant(cv, tab)
    for f in (0.3, 0.5, 0.7, 0.8, 0.9, 0.95):
        mib = f * full["cache_estimate_bytes"] / 2**20
        info = build_fibre_cache(cv, tab, maj, camera_array(scene.camera, 8, 8), 8, 8, mib).info
        if 0 < info["cache_bricks_cached"] < full["cache_bricks_cached"]:
            return mib
    raise AssertionError("no budget caches part of the bricks")


@pytest.mark.slow  # compiles the procedural volpath integrator (minutes on a cold cache): make test-all
def test_images_agree_whatever_the_cache_and_threads(small):
    """Cache 0 (lookups only), a cache of some bricks and a complete cache render one fabric: per
    2 x 2 pixel block the difference of the means over its standard error (independent seeds) passes
    the z-score test (tests/chisquare.py); and a given cache gives the same bytes at 1 and 2 threads."""
    from tests.chisquare import z_score_test

    full = _render(small, 512.0, 3)
    assert full.stats["cache_complete"] and full.stats["cache_bricks_cached"] > 1
    part_mib = _partial_budget(small, full.stats)
    part = _render(small, part_mib, 2)
    assert 0 < part.stats["cache_bricks_cached"] < full.stats["cache_bricks_cached"]
    none = _render(small, 0.0, 1)
    assert none.stats["cache_bricks_cached"] == 0 and none.extra["A"].mean() > 0.3  # the fabric fills the view

    def blocks(a):
        return a.reshape(4, 2, 4, 2).sum(axis=(1, 3))

    lum = np.array([0.2126, 0.7152, 0.0722])
    for other in (full, part):
        d = (blocks(other.rgb @ lum) - blocks(none.rgb @ lum)) / 4.0
        se = np.sqrt(blocks(other.extra["variance"]) + blocks(none.extra["variance"])) / 4.0
        assert np.all(se > 0)
        res = z_score_test((d / se).ravel(), alpha=1e-3)
        assert res.passed, res.message
    for cache, seed, img in ((512.0, 3, full), (part_mib, 2, part)):
        one = _render(small, cache, seed, threads=1)
        two = _render(small, cache, seed, threads=2)
        assert one.rgb.tobytes() == two.rgb.tobytes() == img.rgb.tobytes()


def test_cache_budget_bad_input(small, tmp_path, capsys):
    """A negative or non-finite budget: exit 2 with a one-line reason and nothing written; one past the
    available memory: a warning and the available memory instead."""
    from pipeline.fibre_cache import cache_budget_mib
    from pipeline.memory import available_bytes
    from tests.render.test_volpath import _cli

    out = tmp_path / "v.exr"
    for bad in ("-5", "nan", "inf"):
        code, _, err = _cli("render", small / "s.toml", "--method", "volpath", "--source", "procedural", "--tables",
                            small / "t.zarr", "--cache", bad, "-o", out)
        assert code == 2, err
        assert err.strip().count("\n") == 0 and "--cache" in err and "Traceback" not in err
        assert not out.exists() and not out.with_suffix(".zarr").exists()
    capsys.readouterr()
    got = cache_budget_mib(1e12)
    assert got <= available_bytes() / 2**20
    assert "available memory" in capsys.readouterr().err
    assert cache_budget_mib(0) == 0.0


@pytest.mark.slow  # compiles the procedural volpath integrator (minutes on a cold cache): make test-all
def test_refined_majorant_renders_the_same_fabric(small, monkeypatch):
    """With the majorant grid capped at a few cells (as a large cloth's is), the cached cells are refined
    (``cached_majorant``): the image agrees with the uncapped grid's within Monte Carlo error per 2 x 2
    pixel block (z-score test, independent seeds) and is the same bytes at 1 and 2 threads."""
    import pipeline.fibre_cache
    import pipeline.renderers.volpath as volpath
    from tests.chisquare import z_score_test

    plain = _render(small, 512.0, 5)
    assert plain.stats["majorant_fine_cells"] == 0
    monkeypatch.setattr(volpath, "MAX_MAJORANT_CELLS", 6 ** 3)
    refined = _render(small, 512.0, 6)
    assert refined.stats["majorant_fine_cells"] > 0 and refined.stats["majorant_fine_k"] >= 2

    def blocks(a):
        return a.reshape(4, 2, 4, 2).sum(axis=(1, 3))

    lum = np.array([0.2126, 0.7152, 0.0722])
    d = (blocks(refined.rgb @ lum) - blocks(plain.rgb @ lum)) / 4.0
    se = np.sqrt(blocks(refined.extra["variance"]) + blocks(plain.extra["variance"])) / 4.0
    assert np.all(se > 0)
    res = z_score_test((d / se).ravel(), alpha=1e-3)
    assert res.passed, res.message
    one = _render(small, 512.0, 6, threads=1)
    assert one.rgb.tobytes() == refined.rgb.tobytes()
    monkeypatch.setattr(pipeline.fibre_cache, "MAX_FINE_K", 1)
    capped = _render(small, 512.0, 6)  # the capped grid unrefined: 212k lookups against 19k refined
    assert capped.stats["majorant_fine_cells"] == 0
    assert refined.stats["medium_lookups"] < 0.5 * capped.stats["medium_lookups"]
