"""The IIRTF precompute (stages.precompute.iirtf, seed 001 §4.2) on the tiny two-exemplar tiling.

References: brute force (cell boxes, best cell counts over every n, a free-path walk through explicit
periodic copies of the capsules), an independent Monte Carlo estimate of the same band-limited
quantities (different direction densities, stratified segments, no Russian roulette, numpy random
numbers), the SH addition theorem (Legendre polynomials) for the reconstruction, and exact physical
orderings and bounds (black fibres: zero; channel order of the albedo; the maximum principle of a
non-absorbing fabric)."""
import math

import numpy as np
import pytest
from numba import njit
from scipy import stats

from stages.core.geometry.capsule import capsule_intersect
from stages.core.sh import sh_eval
from stages.core.shading.bcsdf import pack_bcsdf
from stages.core.shading.material import (
    CTX_SIZE,
    material_eval_pdf,
    material_prepare,
    material_sample,
    pack_material_bcsdf,
    pack_material_lambert,
)
from stages.precompute.iirtf import (
    build_cells,
    cell_box,
    cells_per_side,
    exemplar_slabs,
    iirtf_chunk,
    iirtf_reconstruct,
    mean_free_path,
)
from stages.precompute.periodic import periodic_hit, periodic_scene, slab_length

MAX_DEPTH = 8  # kept short so the independent estimator (no roulette) stays cheap; both use the same


@pytest.fixture(scope="module")
def tiny(tiny_tiling):
    _, sc, art = tiny_tiling
    P, R, O, Fb = (np.asarray(art[n]) for n in ("ex_points", "ex_radius", "ex_offsets", "ex_fibers"))
    slabs = exemplar_slabs(P, R, O, Fb)
    mof = np.zeros(len(O) - 1, np.int32)
    # C_R grey, C_TT: red non-absorbing (white), green and blue absorbing
    mats = pack_material_bcsdf(pack_bcsdf([0.2] * 3, [1.0, 0.6, 0.3], 15.0, 20.0, 40.0))[None]
    cells = build_cells(P, O, Fb, art["ex_period"], art["ex_nblocks"], art["block_size"], slabs, 0.06)
    return dict(sc=sc, art=art, P=P, R=R, O=O, Fb=Fb, slabs=slabs, mof=mof, mats=mats, cells=cells)


def _busiest_cell(cells, k):
    cnt = np.diff(cells.cell_offsets)[cells.ex_cells[k]:cells.ex_cells[k + 1]]
    return int(cells.ex_cells[k] + np.argmax(cnt))


# ------------------------------------------------------------------------------------------------
# cells
def test_cells_hold_their_midpoints_and_have_the_closest_sides(tiny):
    """Brute force: every segment's midpoint (recomputed here, wrapped into the period) lies in the box
    of its cell; per axis the cell count is the n >= 1 whose side / n is nearest the target (all n
    tried); the grid covers the period and the slab; the CSR lists each segment once, by cell."""
    P, O, Fb, art = tiny["P"], tiny["O"], tiny["Fb"], tiny["art"]
    bs = np.asarray(art["block_size"])
    for target in (0.06, np.array([0.031, 0.047])):
        cells = build_cells(P, O, Fb, art["ex_period"], art["ex_nblocks"], bs, tiny["slabs"], target)
        tg = np.broadcast_to(target, (2,))
        for k in range(2):
            thick = tiny["slabs"][k, 1] - tiny["slabs"][k, 0]
            for side, n in zip((bs[0], bs[1], thick), cells.block_cells[k]):
                best = min(range(1, 1000), key=lambda m: (abs(side / m - tg[k]), m))
                assert n == best, (side, tg[k], n, best)
            W, H = art["ex_period"][k]
            NX, NY, NZ = cells.ex_grid[k]
            assert np.allclose(cells.cell_size[k] * (NX, NY, NZ), (W, H, thick), rtol=1e-12)
            assert cells.ex_cells[k + 1] - cells.ex_cells[k] == NX * NY * NZ
        s = 0
        for f in range(len(O) - 1):
            k = int(np.searchsorted(Fb, f, side="right") - 1)
            W, H = art["ex_period"][k]
            for i in range(O[f], O[f + 1] - 1):
                m = 0.5 * (P[i] + P[i + 1])
                m[0] %= W
                m[1] %= H
                kc, lo, hi = cell_box(cells, cells.seg_cell[s])
                assert kc == k and cells.seg_fibre[s] == f
                assert np.all(m >= lo - 1e-12) and np.all(m <= hi + 1e-12), (s, m, lo, hi)
                assert np.allclose(cells.seg_mid[s], m, atol=1e-12)
                s += 1
        assert s == len(cells.seg_cell)
        assert sorted(cells.cell_segments) == list(range(s))
        assert np.array_equal(cells.cell_count, np.bincount(cells.seg_cell, minlength=len(cells.cell_count)))
        for c in range(len(cells.cell_offsets) - 1):
            segs = cells.cell_segments[cells.cell_offsets[c]:cells.cell_offsets[c + 1]]
            assert np.all(cells.seg_cell[segs] == c) and np.all(np.diff(segs) > 0)
    # round(side / target) is not always the closest: 1 / 0.408 = 2.45 -> 3 cells (0.333 is nearer than 0.5)
    assert cells_per_side(1.0, 0.408) == 3 and cells_per_side(1.0, 5.0) == 1


# ------------------------------------------------------------------------------------------------
# mean free path
@njit
def _copies_hit(P, R, O, f0, f1, W, H, lo, hi, o, d, ign, L):
    """Brute force: nearest capsule of the explicit periodic copies of fibres f0..f1-1 (the copies whose
    box, the exemplar's (lo, hi) in x, y shifted by whole periods, meets the ray's box)."""
    x0, x1 = min(o[0], o[0] + L * d[0]), max(o[0], o[0] + L * d[0])
    y0, y1 = min(o[1], o[1] + L * d[1]), max(o[1], o[1] + L * d[1])
    best, fib, seg = L, -1, -1
    for a in range(int(math.floor((x0 - hi[0]) / W)), int(math.ceil((x1 - lo[0]) / W)) + 1):
        for b in range(int(math.floor((y0 - hi[1]) / H)), int(math.ceil((y1 - lo[1]) / H)) + 1):
            for f in range(f0, f1):
                if f == ign:
                    continue
                for i in range(O[f], O[f + 1] - 1):
                    t = capsule_intersect(o[0], o[1], o[2], d[0], d[1], d[2],
                                          P[i, 0] + a * W, P[i, 1] + b * H, P[i, 2],
                                          P[i + 1, 0] + a * W, P[i + 1, 1] + b * H, P[i + 1, 2],
                                          max(R[i], R[i + 1]), 0.0)
                    if t < best:
                        best, fib, seg = t, f, i
    return best, fib, seg


@njit
def _brute_free_paths(P, R, O, f0, f1, W, H, lo, hi, z_lo, z_hi, mats, mof, U0, U, max_dist, S, N):
    """The estimator of mean_free_path, written again on explicit copies with numpy's uniforms (U0 the
    entry point and direction, U the scattering of each event)."""
    n_paths, max_depth = U.shape[0], U.shape[1]
    ctx = np.empty(CTX_SIZE)
    t = np.empty(3)
    nrm = np.zeros(3)
    wi = np.empty(3)
    wo = np.empty(3)
    for p in range(n_paths):
        o = np.array([W * U0[p, 0], H * U0[p, 1], z_hi])
        z = U0[p, 2]
        r = math.sqrt(1.0 - z * z)
        d = np.array([r * math.cos(2 * math.pi * U0[p, 3]), r * math.sin(2 * math.pi * U0[p, 3]), -z])
        tt, f, i = _copies_hit(P, R, O, f0, f1, W, H, lo, hi, o, d, -1,
                               slab_length(o[2], d[2], z_lo, z_hi, max_dist))
        for depth in range(max_depth):
            if f < 0:
                break
            o = o + tt * d
            t[:] = P[i + 1] - P[i]
            t /= math.sqrt((t * t).sum())
            wi[:] = -d
            mat = mats[mof[f]]
            material_prepare(mat, t, nrm, wi, ctx)
            _a, _b, _c, pf = material_sample(mat, ctx, t, nrm, wi, U[p, depth, 0], U[p, depth, 1], U[p, depth, 2], wo)
            if pf <= 0.0:
                break
            d = wo.copy()
            tt, f, i = _copies_hit(P, R, O, f0, f1, W, H, lo, hi, o, d, f,
                                   slab_length(o[2], d[2], z_lo, z_hi, max_dist))
            if f >= 0:
                S[p] += tt
                N[p] += 1


@pytest.mark.slow
def test_mean_free_path_agrees_with_a_brute_force_walk(tiny):
    """Reference: the same estimator on explicit periodic copies of every capsule (brute-force
    intersection, numpy random numbers, other seed); the two ratio estimates agree within 4 combined
    standard errors, the estimate is positive and its standard error small enough to make that sharp."""
    sc, art, slabs, P, R, O, Fb = (tiny[n] for n in ("sc", "art", "slabs", "P", "R", "O", "Fb"))
    k = 0
    W, H = art["ex_period"][k]
    max_dist = 2.0 * W
    ell, se, nseg = mean_free_path(sc, k, *slabs[k], (W, H), tiny["mof"], tiny["mats"], n_paths=1500, seed=3,
                                   max_depth=16, max_dist=max_dist)
    assert ell > 0 and nseg > 5000 and se < 0.03 * ell
    assert ell < slabs[k, 1] - slabs[k, 0]
    n = 1500
    rng = np.random.default_rng(11)
    U0, U = rng.random((n, 4)), rng.random((n, 16, 3))
    S, N = np.zeros(n), np.zeros(n, np.int64)
    pts = P[O[Fb[k]]:O[Fb[k + 1]]]
    r = R[O[Fb[k]]:O[Fb[k + 1]]].max()
    _brute_free_paths(P, R, O, Fb[k], Fb[k + 1], W, H, pts[:, :2].min(0) - r, pts[:, :2].max(0) + r,
                      slabs[k, 0], slabs[k, 1], tiny["mats"], tiny["mof"], U0, U, max_dist, S, N)
    ref = S.sum() / N.sum()
    se_ref = math.sqrt(((S - ref * N) ** 2).sum() / (n * (n - 1))) / N.mean()
    assert abs(ell - ref) < 4.0 * math.hypot(se, se_ref), (ell, se, ref, se_ref)


# ------------------------------------------------------------------------------------------------
# the transfer matrix against an independent estimate
@njit
def _independent_T(sc, z_lo, z_hi, mof, mats, mids, fibres, w0s, w1s, U, max_dist, out):
    """T(w0, w1, mid) per sample without Russian roulette (every path runs to MAX_DEPTH fibre vertices or
    leaves the slab): NEE to the unit-irradiance light along w0 at each vertex, BCSDF sampling onwards."""
    ctx = np.empty(CTX_SIZE)
    t = np.empty(3)
    nrm = np.zeros(3)
    wi = np.empty(3)
    wo = np.empty(3)
    for s in range(mids.shape[0]):
        h = periodic_hit(sc, z_lo, z_hi, mids[s, 0], mids[s, 1], mids[s, 2], w1s[s, 0], w1s[s, 1], w1s[s, 2],
                         fibres[s], max_dist)
        tp = np.ones(3)
        acc = np.zeros(3)
        d = w1s[s].copy()
        for depth in range(U.shape[1]):
            if math.isinf(h.t):
                break
            t[0], t[1], t[2] = h.tx, h.ty, h.tz
            wi[:] = -d
            mat = mats[mof[h.fibre]]
            material_prepare(mat, t, nrm, wi, ctx)
            f0, f1, f2, _ = material_eval_pdf(mat, ctx, t, nrm, wi, w0s[s])
            hs = periodic_hit(sc, z_lo, z_hi, h.x, h.y, h.z, w0s[s, 0], w0s[s, 1], w0s[s, 2], h.fibre, max_dist)
            if math.isinf(hs.t):
                acc[0] += tp[0] * f0
                acc[1] += tp[1] * f1
                acc[2] += tp[2] * f2
            if depth == U.shape[1] - 1:
                break
            g0, g1, g2, pf = material_sample(mat, ctx, t, nrm, wi, U[s, depth, 0], U[s, depth, 1], U[s, depth, 2], wo)
            if pf <= 0.0:
                break
            tp[0] *= g0
            tp[1] *= g1
            tp[2] *= g2
            d[:] = wo
            h = periodic_hit(sc, z_lo, z_hi, h.x, h.y, h.z, d[0], d[1], d[2], h.fibre, max_dist)
        out[s] = acc


def _sh_rows(L, w):
    Y = np.empty(((L + 1) ** 2, len(w)))
    y = np.empty((L + 1) ** 2)
    for i, v in enumerate(w):
        sh_eval(L, v[0], v[1], v[2], y)
        Y[:, i] = y
    return Y


def _reproducing_kernel(L, mu):
    """sum_j Y_j(a) Y_j(b) = sum_l (2l + 1) / (4 pi) P_l(a . b) (the addition theorem)."""
    return np.polynomial.legendre.legval(mu, [(2 * l + 1) / (4 * math.pi) for l in range(L + 1)])


@pytest.fixture(scope="module", params=["hemisphere", "sphere"])
def independent(tiny, request):
    """The reference samples of the busiest cell of exemplar 0: segments in turn (stratified), w0 from the
    density (1 + cos theta) / (3 pi) on the upper hemisphere (light domain "hemisphere", the paper's) or
    (2 + cos theta) / (8 pi) on the whole sphere ("sphere": light from below crosses the fabric), w1 from
    normalised Gaussians, T traced without Russian roulette, numpy random numbers. Returns (cell, w0, w1,
    T / (p0 p1), max_dist, light domain)."""
    sc, cells, slabs = tiny["sc"], tiny["cells"], tiny["slabs"]
    k, n = 0, 12000
    c = _busiest_cell(cells, k)
    segs = cells.cell_segments[cells.cell_offsets[c]:cells.cell_offsets[c + 1]]
    assert len(segs) >= 10
    max_dist = 20.0 * tiny["art"]["ex_period"][k][0]
    rng = np.random.default_rng(2024)
    s = segs[np.arange(n) % len(segs)]
    if request.param == "hemisphere":
        mu = -1.0 + np.sqrt(1.0 + 3.0 * rng.random(n))
        p0 = (1.0 + mu) / (3 * math.pi)
    else:
        mu = -2.0 + np.sqrt(1.0 + 8.0 * rng.random(n))
        p0 = (2.0 + mu) / (8 * math.pi)
    ph = 2 * math.pi * rng.random(n)
    st = np.sqrt(1 - mu * mu)
    w0 = np.stack([st * np.cos(ph), st * np.sin(ph), mu], 1)
    g = rng.normal(size=(n, 3))
    w1 = g / np.linalg.norm(g, axis=1, keepdims=True)
    p1 = 1.0 / (4 * math.pi)
    T = np.empty((n, 3))
    _independent_T(periodic_scene(sc, k), slabs[k, 0], slabs[k, 1], tiny["mof"], tiny["mats"],
                   cells.seg_mid[s], cells.seg_fibre[s], w0, w1, rng.random((n, MAX_DEPTH, 3)), max_dist, T)
    return c, w0, w1, T / (p0 * p1)[:, None], max_dist, request.param


@pytest.mark.parametrize("light_sampling", ["uniform", "mis"])
def test_transfer_matrix_agrees_with_an_independent_estimate(tiny, independent, light_sampling):
    """Reference: an independent Monte Carlo estimate of the same band-limited quantities (fixture
    ``independent``: other direction densities, stratified segments, no Russian roulette, numpy random
    numbers), for both estimators of the light integral (the paper's uniform w0, and MIS) and both light
    domains (the paper's upper hemisphere, and the whole sphere).
    (1) Entries a[j0, j1] of orders l <= 1 (both arguments, all channels): z-scores against the stored
    standard error combined with the reference's (its i.i.d. formula, conservative under
    stratification), none beyond the Sidak limit of tests/chisquare.py's z_score_test. (2) The
    reconstruction sum a Y(w0) Y(w1) at four direction pairs against the reference's integral of T
    times the reproducing kernels (Legendre form, no sh_eval) within 4 combined standard errors, the
    reconstruction's taken as sum |Y Y| se (an upper bound: the standard deviation of a sum is at
    most the sum of theirs)."""
    c, w0, w1, wt, max_dist, domain = independent
    L, n = 2, len(wt)
    res = iirtf_chunk(tiny["sc"], tiny["cells"], c, c + 1, tiny["mof"], tiny["mats"], order=L, n_paths=n, seed=5,
                      max_depth=MAX_DEPTH, rr_depth=3, light_sampling=light_sampling, max_dist=max_dist,
                      light_domain=domain)
    a, se = res.a[0], res.se[0]
    assert res.rays[0] > n

    # (1) entries
    Y0, Y1 = _sh_rows(L, w0), _sh_rows(L, w1)
    z = []
    for j0 in range(4):
        for j1 in range(4):
            x = wt * (Y0[j0] * Y1[j1])[:, None]
            ref, se_ref = x.mean(0), x.std(0, ddof=1) / math.sqrt(n)
            z.extend((a[:, j0, j1] - ref) / np.hypot(se[:, j0, j1], se_ref))
    # the z are correlated (the channels and entries share their paths), which over-disperses their sum
    # of squares: only the harness's largest-|z| limit (Sidak over len(z) tests) is a valid test here
    zmax = stats.norm.isf(0.5 * (1.0 - (1.0 - 1e-3) ** (1.0 / len(z))))
    assert np.abs(z).max() < zmax, (np.round(z, 2), zmax)
    assert np.all(se[:, 0, 0] < 0.1 * a[:, 0, 0])  # sharp enough to see a 30 % error

    # (2) reconstruction at direction pairs
    pairs = [((0, 0, 1), (0, 0, -1)), ((0.6, 0, 0.8), (-0.6, 0, 0.8)), ((0, 0.8, 0.6), (1, 0, 0)),
             ((-0.28, -0.96, 0.0), (0, 0.6, -0.8)), ((0, -0.6, -0.8), (0.6, 0, 0.8))]
    for v0, v1 in pairs:
        v0, v1 = np.array(v0, float), np.array(v1, float)
        got = iirtf_reconstruct(a, v0, v1)[0]
        x = wt * (_reproducing_kernel(L, w0 @ v0) * _reproducing_kernel(L, w1 @ v1))[:, None]
        ref, se_ref = x.mean(0), x.std(0, ddof=1) / math.sqrt(n)
        yy = np.abs(np.outer(_sh_rows(L, [v0])[:, 0], _sh_rows(L, [v1])[:, 0]))
        bound = (se * yy).sum(axis=(1, 2))
        assert np.all(np.abs(got - ref) < 4.0 * np.hypot(bound, se_ref)), (v0, v1, got, ref, bound, se_ref)


# ------------------------------------------------------------------------------------------------
# physics of the whole matrix
def test_black_fibres_transfer_nothing(tiny):
    """Exact: fibres of albedo 0 (Lambertian rows) scatter nothing, so every entry and its error are 0."""
    cells = tiny["cells"]
    black = pack_material_lambert([0.0, 0.0, 0.0])[None]
    c = _busiest_cell(cells, 1)
    res = iirtf_chunk(tiny["sc"], cells, c - 2, c + 2, tiny["mof"], black, order=3, n_paths=400)
    full = np.diff(cells.cell_offsets)[c - 2:c + 2] > 0
    assert np.all(res.a == 0.0) and np.all(res.se == 0.0) and np.all(res.rays[full] > 0)


def _escape_fraction(tiny, k, c, seed, m=4000):
    """(mean, standard error) of the share of uniform rays from cell c's segment midpoints (in turn) that leave
    the slab of exemplar k without meeting a fibre (rays run at most 20 periods)."""
    sc, cells, slabs = tiny["sc"], tiny["cells"], tiny["slabs"]
    W = tiny["art"]["ex_period"][k][0]
    segs = cells.cell_segments[cells.cell_offsets[c]:cells.cell_offsets[c + 1]]
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(m, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    s = segs[np.arange(m) % len(segs)]
    psc = periodic_scene(sc, k)
    esc = np.array([math.isinf(periodic_hit(psc, slabs[k, 0], slabs[k, 1], *cells.seg_mid[q], *d,
                                    int(cells.seg_fibre[q]), 20.0 * W).t) for q, d in zip(s, g)], float)
    return esc.mean(), esc.std(ddof=1) / math.sqrt(m)


def test_albedo_order_and_the_non_absorbing_bound(tiny):
    """Exact order: with C_R equal and C_TT = (1, 0.6, 0.3) every path's transfer is ordered r >= g >= b
    (shared directions, monotone weights), so a_00 is too, cell by cell, for both estimators. Bound
    (maximum principle of a non-absorbing fabric under a unit-radiance sky over the upper hemisphere):
    the integral over w0 of T is at most 1 where the ray from mu_k along w1 meets a fibre and 0 where it
    escapes, so the white channel's a_00 = (1/4pi) int int T <= 1 - (the cell's mean escape fraction),
    estimated here by casting uniform rays from the cell's midpoints; and a_00 > 0. The same bound
    holds for fibres of white Lambertian surfaces (albedo 1: the opaque-surface branch, rays leaving
    off the capsule)."""
    sc, cells = tiny["sc"], tiny["cells"]
    k = 1
    c = _busiest_cell(cells, k)
    W = tiny["art"]["ex_period"][k][0]
    res = iirtf_chunk(sc, cells, c - 3, c + 3, tiny["mof"], tiny["mats"], order=2, n_paths=1500, seed=9,
                      max_dist=20.0 * W)
    mis = iirtf_chunk(sc, cells, c - 3, c + 3, tiny["mof"], tiny["mats"], order=2, n_paths=300, seed=9,
                      max_dist=20.0 * W, light_sampling="mis").a[:, :, 0, 0]
    assert np.all(mis[:, 0] >= mis[:, 1]) and np.all(mis[:, 1] >= mis[:, 2])
    a00 = res.a[:, :, 0, 0]
    assert np.all(a00[:, 0] >= a00[:, 1]) and np.all(a00[:, 1] >= a00[:, 2])
    i = c - (c - 3)
    assert a00[i, 0] > 0
    e, se_e = _escape_fraction(tiny, k, c, 7)
    assert a00[i, 0] <= 1.0 - e + 4.0 * math.hypot(res.se[i, 0, 0, 0], se_e), (a00[i], e)
    white = pack_material_lambert([1.0, 1.0, 1.0])[None]
    lam = iirtf_chunk(sc, cells, c, c + 1, tiny["mof"], white, order=2, n_paths=1500, seed=9, max_dist=20.0 * W)
    assert lam.a[0, 0, 0, 0] > 0 and np.all(lam.a[0, :, 0, 0] == lam.a[0, 0, 0, 0])
    assert lam.a[0, 0, 0, 0] <= 1.0 - e + 4.0 * math.hypot(lam.se[0, 0, 0, 0], se_e), (lam.a[0, :, 0, 0], e)


def test_white_furnace_with_light_from_both_sides(tiny):
    """Furnace (exact): under a sky of unit radiance all round, fibres of white Lambertian surfaces (albedo 1)
    send radiance 1 towards every direction, all of it scattered light; so with the light domain "sphere"
    the integral over w0 of T(w0, w1) is 1 where the ray from mu_k along w1 meets a fibre and 0 where it
    escapes, and a_00 = 1 - (the cell's mean escape fraction), estimated as in the bound above. Paths run
    to depth 256 (what roulette leaves of a non-absorbing path at depth 32 is not negligible). The
    paper's hemisphere keeps strictly less (the light from below is missing)."""
    sc, cells = tiny["sc"], tiny["cells"]
    k = 1
    c = _busiest_cell(cells, k)
    W = tiny["art"]["ex_period"][k][0]
    white = pack_material_lambert([1.0, 1.0, 1.0])[None]
    kw = dict(order=1, n_paths=1500, seed=9, max_dist=20.0 * W, max_depth=256)
    both = iirtf_chunk(sc, cells, c, c + 1, tiny["mof"], white, light_domain="sphere", light_sampling="mis", **kw)
    above = iirtf_chunk(sc, cells, c, c + 1, tiny["mof"], white, light_sampling="mis", **kw)
    e, se_e = _escape_fraction(tiny, k, c, 8)
    a, se = both.a[0, 0, 0, 0], both.se[0, 0, 0, 0]
    assert abs(a - (1.0 - e)) < 4.0 * math.hypot(se, se_e), (a, 1.0 - e, se, se_e)
    assert above.a[0, 0, 0, 0] < a - 4.0 * math.hypot(se, above.se[0, 0, 0, 0]), (above.a[0, 0, 0, 0], a)


def test_same_bytes_for_any_thread_count_and_chunking(tiny):
    """Contract: counter-based random numbers keyed by (seed, cell, path): one thread, two threads, and
    two different splits of the cells (across the exemplar boundary) give identical bytes."""
    import numba

    sc, cells, mof, mats = tiny["sc"], tiny["cells"], tiny["mof"], tiny["mats"]
    c0, c1 = int(cells.ex_cells[1]) - 5, int(cells.ex_cells[1]) + 5
    kw = dict(order=2, n_paths=150, seed=1)
    n0 = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = iirtf_chunk(sc, cells, c0, c1, mof, mats, **kw)
        ell1 = mean_free_path(sc, 0, *tiny["slabs"][0], tiny["art"]["ex_period"][0], mof, mats, n_paths=200)
        numba.set_num_threads(max(2, n0) if numba.config.NUMBA_NUM_THREADS >= 2 else 1)
        two = iirtf_chunk(sc, cells, c0, c1, mof, mats, **kw)
        ell2 = mean_free_path(sc, 0, *tiny["slabs"][0], tiny["art"]["ex_period"][0], mof, mats, n_paths=200)
    finally:
        numba.set_num_threads(n0)
    parts = [iirtf_chunk(sc, cells, lo, hi, mof, mats, **kw) for lo, hi in ((c0, c0 + 3), (c0 + 3, c1))]
    m1 = iirtf_chunk(sc, cells, c0, c1, mof, mats, light_sampling="mis", **kw)
    m2 = [iirtf_chunk(sc, cells, lo, hi, mof, mats, light_sampling="mis", **kw)
          for lo, hi in ((c0, c1 - 2), (c1 - 2, c1))]
    assert m1.a.tobytes() == np.concatenate([p.a for p in m2]).tobytes() and m1.a.tobytes() != one.a.tobytes()
    split = np.concatenate([p.a for p in parts]), np.concatenate([p.se for p in parts])
    assert one.a.max() > 0 and ell1 == ell2
    for b in (two, ):
        assert one.a.tobytes() == b.a.tobytes() and one.se.tobytes() == b.se.tobytes()
        assert one.rays.tobytes() == b.rays.tobytes()
    assert one.a.tobytes() == split[0].tobytes() and one.se.tobytes() == split[1].tobytes()
