"""Acquisition of a repeat's radiance samples (stages/precompute/btf.py, seed 002 §4).

References: a brute-force coverage test for vertical rays (a vertical line meets a capsule iff the
distance in the xy plane from the line to the segment's projection is at most its radius), over every
fibre segment of the exemplar and its 3 x 3 periodic copies, at the very points the acquisition casts
(the same counter-based random numbers): alpha is that fraction exactly, and a texel whose rays all miss
(a hole of the loose tiny weave) returns alpha 0 and zero radiance; the light grid's own reciprocity is
not assumed. Determinism: the same bytes at 1 and 2 threads. Light from below (a sphere table): a white furnace
(white Lambertian fibres under a unit sky return 1 over both halves). The texture's plane: alpha on the middle
plane and on a plane per texel against brute-force ray-capsule intersection of the rays through their points; the
surface plane's heights against the slab and the vertical coverage; the relief's heights against brute-force first
hits of vertical rays.
"""
import numba
import numpy as np
import pytest
from numba import njit

from stages.core.btf import HEMISPHERE
from stages.core.geometry.capsule import capsule_intersect
from stages.core.rng import uniform
from stages.precompute.btf import acquire_texels, hit_heights, texel_frames
from stages.precompute.iirtf import exemplar_slabs
from stages.precompute.periodic import periodic_scene

RES = 16
SPP = 2


def _segments_2d(art, k):
    """(a (S, 2), b (S, 2), r (S,)) of exemplar k's fibre segments projected on xy."""
    f0, f1 = int(art["ex_fibers"][k]), int(art["ex_fibers"][k + 1])
    off = art["ex_offsets"]
    P = art["ex_points"]
    R = art["ex_radius"]
    a, b, r = [], [], []
    for f in range(f0, f1):
        i0, i1 = int(off[f]), int(off[f + 1])
        a.append(P[i0:i1 - 1, :2])
        b.append(P[i0 + 1:i1, :2])
        r.append(np.maximum(R[i0:i1 - 1], R[i0 + 1:i1]))
    return np.concatenate(a), np.concatenate(b), np.concatenate(r)


def _covered(x, y, a, b, r, W, H):
    best = np.inf
    for sx in (-W, 0.0, W):
        for sy in (-H, 0.0, H):
            p = np.array([x - sx, y - sy])
            d = b - a
            t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0, 1)
            q = a + t[:, None] * d
            best = min(best, float(np.min(np.linalg.norm(p - q, axis=1) - r)))
    return best


@pytest.fixture(scope="module")
def acquired(tiny_tiling):
    from pipeline.runners.precompute import tiling_materials
    from pipeline.scene import load_scene
    from tests.helpers import ROOT

    path, sc, art = tiny_tiling
    k = 0
    slab = exemplar_slabs(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"])[k]
    W, H = (float(v) for v in art["ex_period"][k])
    mof, mats = tiling_materials(load_scene(ROOT / "data/scenes/flat_satin.toml"), art, {"tint": "yarn"})
    views = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    lights = np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [-0.8, 0.0, 0.6]])
    args = (periodic_scene(sc, k), float(slab[0]), float(slab[1]), W, H, mof, mats, RES, 0, RES * RES, views, lights,
            SPP, 5, 6, 3, 64.0 * max(W, H), 1e-9, (0, 0), (0, 0), HEMISPHERE)
    return art, k, W, H, args


def test_alpha_is_the_brute_force_coverage_and_holes_are_empty(acquired):
    art, k, W, H, args = acquired
    rad, alpha, nsum, rays = acquire_texels(*args)
    a, b, r = _segments_2d(art, k)
    seed = args[13]
    holes = 0
    for texel in range(RES * RES):
        iy, ix = divmod(texel, RES)
        key0 = (texel * 2 + 0) * SPP          # view 0: straight down
        hits = 0
        rims = 0
        for s in range(SPP):
            x = (ix + uniform(seed, key0 + s, 0)) * W / RES
            y = (iy + uniform(seed, key0 + s, 1)) * H / RES
            m = _covered(x, y, a, b, r, W, H)
            if abs(m) < 1e-9 * W:            # grazing a capsule's rim: either answer is right
                rims += 1
            else:
                hits += m < 0
        assert hits / SPP - 1e-12 <= alpha[texel, 0] <= (hits + rims) / SPP + 1e-12, texel
        if hits + rims == 0:
            holes += 1
            assert np.all(rad[texel, 0] == 0.0)
    assert holes > 0, "the tiny weave should leave holes seen straight down"
    assert np.all(alpha >= 0) and np.all(alpha <= 1) and np.all(np.isfinite(rad)) and np.all(rad >= 0)
    frames = texel_frames(nsum)
    assert np.allclose(np.linalg.norm(frames, axis=2), 1.0) and np.allclose(np.einsum("ij,ij->i", frames[:, 0],
                                                                                       frames[:, 1]), 0, atol=1e-9)


def _at_1_and_2_threads(args):
    """``acquire_texels(*args)`` on 1 thread, after asserting that 2 threads give the same bytes."""
    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = acquire_texels(*args)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = acquire_texels(*args)
    finally:
        numba.set_num_threads(n)
    for x, y in zip(one, two):
        assert np.array_equal(x, y)
    return one


def test_same_bytes_at_1_and_2_threads(acquired):
    *_, args = acquired
    _at_1_and_2_threads(args)


def test_half_vector_cells_are_the_mirror_lights_of_the_view(acquired):
    """Reference: the same acquisition on explicit lights (exact equality). Half-vector light cells without cell
    averages (``light_coords`` HALF, view grid (0, 0)) light the view from its cells' centres mirrored about it
    (``stages.core.btf.half_cell_direction``), the invalid ones not at all: the bytes of the hemisphere path given
    those directions as its light list (the invalid ones as (0, 0, -1), which it skips), at 1 and 2 threads alike;
    the invalid cells hold exactly 0."""
    from stages.core.btf import HALF, half_cell_direction

    *_, args = acquired
    nx, ny = 5, 4
    v = args[10][1]                                      # the oblique view, alone (the random keys count views)
    lights = np.array([half_cell_direction(j, nx, ny, 0.5, 0.5, *v) for j in range(nx * ny)])
    invalid = lights[:, 2] <= 0.0
    assert invalid.any() and (~invalid).any()
    base = list(args)
    base[10] = args[10][1:2]
    ref = acquire_texels(*base[:11], lights, *base[12:])
    base[11] = np.zeros((nx * ny, 3))                     # only the count is read
    base[19], base[20] = (nx, ny), HALF
    half = _at_1_and_2_threads(base)
    for x, z in zip(half, ref):
        assert np.array_equal(x, z)
    assert np.all(half[0][:, 0, invalid] == 0.0) and np.any(half[0][:, 0, ~invalid] > 0.0)


def test_cell_direction_covers_its_grid_cell():
    """``cell_direction``: (0.5, 0.5) is the grid direction (``hemisphere_grid``); uniform (u0, u1) give unit
    directions inside the cell (ring's cos theta range, azimuth range) whose cos theta is uniform (equal
    solid angle): its mean is the ring's middle and its variance (width^2 / 12)."""
    from stages.core.btf import cell_direction, hemisphere_grid

    nt, nph = 4, 6
    grid = hemisphere_grid(nt, nph)
    rng = np.random.default_rng(3)
    for idx in range(nt * nph):
        assert np.allclose(cell_direction(idx, nt, nph, 0.5, 0.5), grid[idx], atol=1e-15)
        i, j = divmod(idx, nph)
        u = rng.random((4000, 2))
        d = np.array([cell_direction(idx, nt, nph, a, b) for a, b in u])
        assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
        ct = d[:, 2]
        assert np.all((ct >= 1 - (i + 1) / nt - 1e-12) & (ct <= 1 - i / nt + 1e-12))
        phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
        assert np.all((phi >= 2 * np.pi * j / nph - 1e-9) & (phi <= 2 * np.pi * (j + 1) / nph + 1e-9))
        assert abs(ct.mean() - (1 - (i + 0.5) / nt)) < 4 * (1 / nt) / np.sqrt(12 * len(ct))
        assert abs(ct.var() - (1 / nt) ** 2 / 12) < 0.1 * (1 / nt) ** 2 / 12


def test_cell_averages_are_the_mean_over_the_cell(acquired):
    """Monte Carlo against quadrature: with the grids given, a texel's sample for (view cell, light cell)
    estimates the mean of the point-sampled radiance over both cells. Reference: the point samples
    (grid mode) at a 3 x 3 midpoint sub-grid of each cell (equal solid angle: uniform in cos theta and
    phi), averaged. Lambertian fibres (smooth in l and v, so 9 x 9 quadrature points suffice); a 2 x 2 view
    grid and a 2 x 2 light grid (cells of a quarter hemisphere: wide enough that the average and the
    cell's centre differ); the whole 4 x 4-texel repeat pooled. Agreement within 4 standard errors of
    the difference plus 3 % (the quadrature), while the cells' centre directions alone miss the mean by more
    than 30 % for some pairs (measured: up to 80 %)."""
    from pipeline.renderers.fiberpath import fiber_materials, tiling_fibers
    from pipeline.scene import load_scene
    from stages.core.btf import cell_direction, hemisphere_grid
    from tests.helpers import ROOT

    art, k, W, H, args = acquired
    scene = load_scene(ROOT / "data/scenes/flat_satin.toml")
    mof, mats = fiber_materials(scene, tiling_fibers(scene, art), {"material": "lambert", "bcsdf": None,
                                                                   "extra": {"tint": "yarn"}})
    mof = np.ascontiguousarray(mof, np.int32)
    mats = np.ascontiguousarray(mats, np.float64)
    res = 4
    grid = hemisphere_grid(2, 2)
    base = list(args)
    base[5], base[6], base[7], base[9] = mof, mats, res, res * res
    base[12] = 512                                              # spp
    cell = acquire_texels(*base[:10], grid, grid, *base[12:18], (2, 2), (2, 2), HEMISPHERE)
    sub = np.array([[cell_direction(c, 2, 2, (a + 0.5) / 3, (b + 0.5) / 3) for a in range(3) for b in range(3)]
                    for c in range(4)])                          # (4 cells, 9, 3)
    base[12] = 64
    point = acquire_texels(*base[:10], sub.reshape(-1, 3), sub.reshape(-1, 3), *base[12:])
    pr = point[0].astype(np.float64).reshape(res * res, 4, 9, 4, 9, 3)
    pa = point[1].astype(np.float64).reshape(res * res, 4, 9)
    # pooled over texels and the sub-grid, alpha-weighted (the samples are means over the rays that hit)
    ref = np.einsum("tvaldc,tva->vlc", pr, pa) / 9 / pa.sum(axis=(0, 2))[:, None, None]
    cr, ca = cell[0].astype(np.float64), cell[1].astype(np.float64)
    got = np.einsum("tvlc,tv->vlc", cr, ca) / ca.sum(axis=0)[:, None, None]
    centre = acquire_texels(*base[:10], grid, grid, *base[12:])
    cen = np.einsum("tvlc,tv->vlc", centre[0].astype(np.float64), centre[1].astype(np.float64)) / \
        centre[1].astype(np.float64).sum(axis=0)[:, None, None]
    # standard error of the pooled cell estimate from its per-texel spread (texels are independent)
    per = cr * ca[..., None, None] / ca.mean(axis=0)[None, :, None, None]
    se = per.std(axis=0, ddof=1) / np.sqrt(res * res)
    pref = np.einsum("tvaldc,tva->tvlc", pr, pa) / 9 / pa.sum(axis=(0, 2))[None, :, None, None] * res * res
    se_ref = pref.std(axis=0, ddof=1) / np.sqrt(res * res)
    tol = 4 * np.sqrt(se ** 2 + se_ref ** 2) + 0.03 * np.abs(ref)   # 3 %: the 3 x 3 quadrature of each cell
    assert np.all(np.abs(got - ref) <= tol), np.max(np.abs(got - ref) / tol)
    assert np.max(np.abs(cen - ref) / np.maximum(np.abs(ref), 1e-9)) > 0.3


def test_white_furnace_with_light_from_below(acquired):
    """Furnace (exact): fibres of white Lambertian surfaces (albedo 1) under a sky of unit radiance from every
    direction send radiance 1 towards every view, all of it scattered light; so wherever a sample hits, a sphere
    table's cells (``light_coords`` SPHERE: the light grid and its mirror below the fabric, cell averages) sum to
    sum_k (2 pi / n) r_k(v) = 1 in expectation, each (texel, view) on its own. Pooled over the texels and views
    that hit, within 4 standard errors of 1 (their spread); the n cells above alone keep strictly less (the light
    through the cloth, more than 4 of its standard errors above 0, is missing: seed 002's reflectance; measured
    0.95 kept by this tiny weave), every channel alike; the same bytes at 1 and 2
    threads."""
    from stages.core.btf import SPHERE, hemisphere_grid
    from stages.core.shading.material import pack_material_lambert

    *_, args = acquired
    views, lights = (2, 4), (2, 4)
    n = lights[0] * lights[1]
    upper = hemisphere_grid(*lights)
    base = list(args)
    base[5] = np.zeros_like(args[5])                                   # every fibre: material 0
    base[6] = pack_material_lambert([1.0, 1.0, 1.0])[None]
    res = 8
    base[7], base[9] = res, res * res
    base[10] = hemisphere_grid(*views)
    base[11] = np.concatenate([upper, upper * np.array([1.0, 1.0, -1.0])])
    base[12], base[14], base[15] = 8, 256, 5                            # spp, max depth, roulette from
    base[18:] = views, lights, SPHERE
    rad, alpha, _nsum, _rays = _at_1_and_2_threads(base)
    hit = alpha > 0
    r = rad.astype(np.float64)[hit]                                     # (hits, 2 n, 3)
    both = r.sum(axis=1) * (2.0 * np.pi / n)
    above = r[:, :n].sum(axis=1) * (2.0 * np.pi / n)
    se = both.std(axis=0, ddof=1) / np.sqrt(len(both))
    assert len(both) > 100
    assert np.all(np.abs(both.mean(axis=0) - 1.0) < 4.0 * se), (both.mean(axis=0), se)
    below = both - above                                                # paired: the light through the cloth
    assert np.all(below.mean(axis=0) > 4.0 * below.std(axis=0, ddof=1) / np.sqrt(len(below))), below.mean(axis=0)
    assert np.allclose(both.mean(axis=0), both.mean(axis=0)[0]) and np.all(r[:, n:] >= 0.0)


@njit
def _ray_hits(ox, oy, oz, dx, dy, dz, tmax, P, R, O, f0, f1, W, H, scale):
    """Does the ray o + t d, 0 < t < tmax, meet a capsule of fibres f0..f1-1 (radius the larger end's, times
    ``scale``) or of their periodic copies within 3 periods? Brute force over every segment and copy."""
    for sx in range(-3, 4):
        for sy in range(-3, 4):
            for f in range(f0, f1):
                for i in range(O[f], O[f + 1] - 1):
                    r = max(R[i], R[i + 1]) * scale
                    t = capsule_intersect(ox, oy, oz, dx, dy, dz, P[i, 0] + sx * W, P[i, 1] + sy * H, P[i, 2],
                                          P[i + 1, 0] + sx * W, P[i + 1, 1] + sy * H, P[i + 1, 2], r, 0.0)
                    if t < tmax:
                        return True
    return False


def test_samples_pass_through_the_texture_plane(acquired):
    """Reference: brute force. With the texture on the slab's middle plane (``z_plane``), sample s of texel (iy, ix)
    seen from the oblique view v is the ray through ((ix + u0) W / res, (iy + u1) H / res, z_plane) along -v: its
    alpha is the fraction of those rays that meet a fibre capsule (every segment and periodic copy, ray-capsule
    intersection), up to rims (capsules 1e-6 thinner and thicker bound it); seen straight down the plane changes no
    byte; at the top face (the default) the same bytes as without the argument."""
    art, k, W, H, args = acquired
    z_lo, z_hi = args[1], args[2]
    z_mid = 0.5 * (z_lo + z_hi)
    rad_top, alpha_top, *_ = acquire_texels(*args)
    rad, alpha, *_ = acquire_texels(*args, z_mid)
    assert np.array_equal(alpha[:, 0], alpha_top[:, 0]) and np.array_equal(rad[:, 0], rad_top[:, 0])
    same = acquire_texels(*args, z_hi)
    assert np.array_equal(same[0], rad_top) and np.array_equal(same[1], alpha_top)
    P, R, O = (np.asarray(art[n]) for n in ("ex_points", "ex_radius", "ex_offsets"))
    f0, f1 = int(art["ex_fibers"][k]), int(art["ex_fibers"][k + 1])
    v = args[10][1]
    seed = args[13]
    moved = 0
    for texel in range(RES * RES):
        iy, ix = divmod(texel, RES)
        lo = hi = 0
        for s in range(SPP):
            key = (texel * 2 + 1) * SPP + s
            x = (ix + uniform(seed, key, 0)) * W / RES + (z_hi - z_mid) / v[2] * v[0]
            y = (iy + uniform(seed, key, 1)) * H / RES + (z_hi - z_mid) / v[2] * v[1]
            tmax = (z_hi - z_lo) / v[2]
            lo += _ray_hits(x, y, z_hi, -v[0], -v[1], -v[2], tmax, P, R, O, f0, f1, W, H, 1.0 - 1e-6)
            hi += _ray_hits(x, y, z_hi, -v[0], -v[1], -v[2], tmax, P, R, O, f0, f1, W, H, 1.0 + 1e-6)
        assert lo / SPP - 1e-12 <= alpha[texel, 1] <= hi / SPP + 1e-12, texel
        moved += not np.array_equal(rad[texel, 1], rad_top[texel, 1])
    assert moved > RES * RES // 2, "the middle plane sees the tiny weave through other points than the top face"


def test_surface_plane_is_where_the_views_meet_the_fibres(acquired):
    """Contract (``hit_heights``, ``precompute btf --plane surface``): every first hit of the views' rays lies in the
    slab; straight down, the share of rays that hit is the brute-force coverage of the same points (the vertical
    line test of ``_covered``), and the surface plane, their median, lies strictly inside the slab."""
    from stages.precompute.periodic import PeriodicPaths

    art, k, W, H, args = acquired
    sc, z_lo, z_hi = args[0], args[1], args[2]
    paths = PeriodicPaths(sc, z_lo, z_hi, W, H, args[5], args[6], 1, 1, args[16], args[17])
    views = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    n = 64
    z = hit_heights(paths, views, n, 3).reshape(-1)
    hit = np.isfinite(z)
    assert np.all((z[hit] >= z_lo - 1e-9) & (z[hit] <= z_hi + 1e-9))
    a, b, r = _segments_2d(art, k)
    lo = hi = 0
    for s in range(n):
        m = _covered(uniform(3, s, 0) * W, uniform(3, s, 1) * H, a, b, r, W, H)
        lo += m < -1e-9 * W
        hi += m < 1e-9 * W
    assert lo <= hit[:n].sum() <= hi
    assert z_lo < np.median(z[hit]) < z_hi


@njit
def _first_hit_z(x, y, z_top, P, R, O, f0, f1, W, H):
    """Height of the first capsule (of fibres f0..f1-1 and their copies within 3 periods) that the ray from (x, y,
    z_top) straight down meets; NaN if none. Brute force over every segment and copy."""
    best = np.inf
    for sx in range(-3, 4):
        for sy in range(-3, 4):
            for f in range(f0, f1):
                for i in range(O[f], O[f + 1] - 1):
                    t = capsule_intersect(x, y, z_top, 0.0, 0.0, -1.0, P[i, 0] + sx * W, P[i, 1] + sy * H, P[i, 2],
                                          P[i + 1, 0] + sx * W, P[i + 1, 1] + sy * H, P[i + 1, 2],
                                          max(R[i], R[i + 1]), 0.0)
                    best = min(best, t)
    return z_top - best if best < np.inf else np.nan


def test_relief_heights_are_the_first_hits_straight_down(acquired, tiny_tiling):
    """Reference: brute force (``--plane relief``). ``hit_heights`` on a cells x cells grid straight down: ray s of
    cell (iy, ix) enters at ((ix + u0) W / cells, (iy + u1) H / cells) with key cell n + s; its height is the first
    capsule it meets (every segment and periodic copy), NaN where it passes through -- up to the BVH's capsule
    tolerance. ``relief_heights`` is each texel's median where at least half of them hit, the slab's bottom
    elsewhere."""
    from pipeline.runners.precompute_btf import RELIEF_RAYS, relief_heights
    from stages.precompute.periodic import PeriodicPaths

    art, k, W, H, args = acquired
    sc, z_lo, z_hi = args[0], args[1], args[2]
    paths = PeriodicPaths(sc, z_lo, z_hi, W, H, args[5], args[6], 1, 1, args[16], args[17])
    cells, n, seed = 4, 8, 3
    z = hit_heights(paths, np.array([[0.0, 0.0, 1.0]]), n, seed, cells)[0]
    P, R, O = (np.asarray(art[a]) for a in ("ex_points", "ex_radius", "ex_offsets"))
    f0, f1 = int(art["ex_fibers"][k]), int(art["ex_fibers"][k + 1])
    for cell in range(cells * cells):
        iy, ix = divmod(cell, cells)
        for s in range(n):
            key = cell * n + s
            ref = _first_hit_z((ix + uniform(seed, key, 0)) * W / cells, (iy + uniform(seed, key, 1)) * H / cells,
                               z_hi, P, R, O, f0, f1, W, H)
            assert np.isnan(ref) == np.isnan(z[cell, s]), (cell, s)
            assert np.isnan(ref) or abs(ref - z[cell, s]) < 1e-6 * W, (cell, s, ref, z[cell, s])
    slabs = {k: (z_lo, z_hi)}
    h = relief_heights(tiny_tiling[1], [k], slabs, [(W, H)], args[5], args[6], RES, seed)
    z = hit_heights(paths, np.array([[0.0, 0.0, 1.0]]), RELIEF_RAYS, seed, RES)[0]
    covered = np.isfinite(z).mean(axis=1) >= 0.5
    assert covered.any() and (~covered).any(), "the tiny weave has texels over yarn and over holes"
    want = np.where(covered, np.nanmedian(np.where(covered[:, None], z, 0.0), axis=1), z_lo)
    assert np.allclose(h[0].ravel(), want.astype(np.float32))


def test_samples_pass_through_each_texels_plane(acquired):
    """Reference: brute force (``--plane relief``). With a plane per texel (random heights in the slab), sample s of
    texel (iy, ix) seen from the oblique view v is the ray through ((ix + u0) W / res, (iy + u1) H / res, z_texel)
    along -v: alpha is the fraction of those rays that meet a fibre capsule, up to rims; planes all at one height
    give the bytes of that one plane."""
    art, k, W, H, args = acquired
    z_lo, z_hi = args[1], args[2]
    z_mid = 0.5 * (z_lo + z_hi)
    same = acquire_texels(*args, np.full(RES * RES, z_mid))
    one = acquire_texels(*args, z_mid)
    assert all(np.array_equal(a, b) for a, b in zip(same, one))
    planes = z_lo + (z_hi - z_lo) * np.random.default_rng(7).random(RES * RES)
    _rad, alpha, *_ = acquire_texels(*args, planes)
    P, R, O = (np.asarray(art[n]) for n in ("ex_points", "ex_radius", "ex_offsets"))
    f0, f1 = int(art["ex_fibers"][k]), int(art["ex_fibers"][k + 1])
    v = args[10][1]
    seed = args[13]
    for texel in range(RES * RES):
        iy, ix = divmod(texel, RES)
        up = (z_hi - planes[texel]) / v[2]
        lo = hi = 0
        for s in range(SPP):
            key = (texel * 2 + 1) * SPP + s
            x = (ix + uniform(seed, key, 0)) * W / RES + up * v[0]
            y = (iy + uniform(seed, key, 1)) * H / RES + up * v[1]
            tmax = (z_hi - z_lo) / v[2]
            lo += _ray_hits(x, y, z_hi, -v[0], -v[1], -v[2], tmax, P, R, O, f0, f1, W, H, 1.0 - 1e-6)
            hi += _ray_hits(x, y, z_hi, -v[0], -v[1], -v[2], tmax, P, R, O, f0, f1, W, H, 1.0 + 1e-6)
        assert lo / SPP - 1e-12 <= alpha[texel, 1] <= hi / SPP + 1e-12, texel
