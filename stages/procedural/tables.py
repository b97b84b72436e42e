"""Realization-minimizing tables (seed 000 §4): what a lookup needs besides the yarn curves.

Regular fibres (§4.3, Fig. 7, footnote 2), per yarn type and ply: each fibre's trajectory in the
twist-compensated unit disc, T_j = {R (cos theta_j, sin theta_j): R in [rho_min R_j, rho_max R_j]},
stored as (R_j, theta_j, theta0_j) plus the radial interval [r_lo, r_hi] grown by the fibre-radius
margin m; the azimuth [0, 2 pi) is cut into B equal bins and bin b lists (CSR, ascending fibre
index; also as a bit mask per fibre) every fibre whose trajectory comes within m of the bin's
wedge. m = K (r_fibre + pad) / min(e_short, e_long) in unit-disc units, with K bounding the ratio
between a point's cross-sectional distance to a fibre and its true distance
(model.reach_factor, from the largest transverse fibre speed and the yarn's smallest axial
stretch g_min) and pad (``type_pad``) the slack of the lookups' sampled frames.

Loops (§4.4.1, §5.3): every migration cycle's mutation is a consistent random number of (yarn,
ply, fibre, cycle) (model.loop_unit_radius). A loop leaves its fibre's [r_lo, r_hi], so per
yarn and ply the mutated cycles are listed (fibre, U_loop; ascending fibre) in fixed-width z-bins
(half a migration cycle) holding every loop whose cycle, grown by the lookups' z window, meets
the bin: a lookup tests the loops of its z-bin whose fibre is in its azimuth bin.

Hairs (§4.4.2), per yarn and ply: hybrid mode stores (z1, ze) and the shape (r0, r1, theta1,
pe) of every hair and cuts z at the ends min(z1, z2) - m_z, max(z1, z2) + m_z of every hair; each
z-bin lists (ascending hair index) the hairs active across the whole bin. The realization-free mode
stores nothing per hair (hair_free.active_hairs). Both come from the same quad-tree, so they hold
the same hairs.

The layout (``Tables``, stored and derived fields) is ``stages.core.yarn.tables``; the derived
fields are filled at load by ``stages.core.yarn.accel.derive_lookup_accel``.
"""
import math

import numpy as np
from numba import njit

from stages.core.curves.frames import curve_frame_at
from stages.core.rng import hash_u64
from stages.core.yarn import hair_free
from stages.core.yarn.model import (
    ALPHA,
    E_LONG,
    E_SHORT,
    FIBER_NUM,
    FIBER_RADIUS,
    HAIR_DENSITY,
    P_LOOP,
    PLY_NUM,
    RHO_MAX,
    RHO_MIN,
    S_MIG,
    USE_FLYAWAYS,
    USE_MIGRATION,
    ZE_MU,
    ZE_SIG,
    cycle_of,
    extent_bound,
    hair_params,
    loop_unit_radius,
    reach_factor,
    sample_regular_fibers,
    transverse_speed_bound,
)
from stages.core.yarn.tables import DERIVED_FIELDS, PAD_FRACTION, Tables, empty_accel, hair_node_seed_nb

# A yarn whose curvature x fibre extent reaches FOLD_CAP has its axial stretch bound g_min capped at
# 1 - FOLD_CAP and is flagged folded (lookups not guaranteed exact). Below it g_min = 1 - kappa x extent
# > 0.1 is a true bound: the map of Eq. 7 has no fold (that needs kappa x extent >= 1); the reach
# factor and the z windows grow as 1 / g_min, so lookups in tightly bent yarns test more fibres.
FOLD_CAP = 0.9


def type_key(seed: int, t: int) -> int:
    return int(hash_u64(seed, 7919, t))


def yarn_key(seed: int, c: int) -> int:
    return int(hash_u64(seed, 104729, c) >> np.uint64(1))  # fits int64


def regular_tables(tp: np.ndarray, type_seed: int, K: float, nbins: int, pad: float = 0.0):
    """Per-type fibres and azimuth bins: (R, th, th0, rlo, rhi) flat (P N,), bin ends, bin_items.
    The margin is K (r_fibre + pad) in cross-section lengths (pad: the lookups' frame-sampling slack)."""
    R, th, th0 = sample_regular_fibers(tp, np.uint64(type_seed))
    P, N = R.shape
    m = K * (tp[FIBER_RADIUS] + pad) / min(tp[E_SHORT], tp[E_LONG])
    lo = (tp[RHO_MIN] if tp[USE_MIGRATION] else 1.0) * R
    hi_reg = (tp[RHO_MAX] if tp[USE_MIGRATION] else 1.0) * R
    hi = hi_reg  # loops (beyond R_hi) are found through the per-yarn loop lists
    reach = np.where(lo > m, np.arcsin(np.minimum(1.0, m / np.maximum(lo, 1e-300))), np.pi)
    width = 2 * np.pi / nbins
    centers = (np.arange(nbins) + 0.5) * width
    starts = [0]
    items = []
    mask = np.zeros((P, N), np.uint64)
    for k in range(P):
        # circular distance from theta_j to the wedge of bin b
        d = np.abs((th[k][None, :] - centers[:, None] + np.pi) % (2 * np.pi) - np.pi) - 0.5 * width
        inc = d <= reach[k][None, :] + 1e-12
        for b in range(nbins):
            js = np.nonzero(inc[b])[0]
            items.append(js.astype(np.int32))
            starts.append(starts[-1] + len(js))
            if nbins <= 64:
                mask[k, js] |= np.uint64(1) << np.uint64(b)
    if nbins > 64:
        mask[:] = np.uint64(0xFFFFFFFFFFFFFFFF)
    return (R.ravel(), th.ravel(), th0.ravel(), (lo - m).ravel(), (hi + m).ravel(),
            np.asarray(starts[1:], np.int64), np.concatenate(items) if items else np.zeros(0, np.int32), mask.ravel())


def hair_count(tp, L: float) -> int:
    if not tp[USE_FLYAWAYS]:
        return 0
    return int(round(tp[HAIR_DENSITY] * L))


def hybrid_hairs(tp, L: float, yarn_seed: int, k: int, margin: float):
    """(z1, ze, breakpoints, bin_start (relative), items) for one ply of one yarn."""
    n = hair_count(tp, L)
    node_seed = np.uint64(hair_node_seed_nb(np.uint64(yarn_seed), k))
    z1, ze = hair_free.all_hairs(L, n, tp[ZE_MU], tp[ZE_SIG], node_seed)
    if n == 0:
        return z1, ze, np.zeros(0), np.zeros(1, np.int64), np.zeros(0, np.int32)
    z2 = z1 + ze
    lo = np.minimum(z1, z2) - margin
    hi = np.maximum(z1, z2) + margin
    bp = np.unique(np.concatenate([lo, hi]))
    nb = len(bp) - 1
    # hair h is active over bin b when lo_h <= bp[b] and hi_h >= bp[b + 1]
    b0 = np.searchsorted(bp, lo)            # first bin starting at lo
    b1 = np.searchsorted(bp, hi) - 1        # last bin ending at hi
    start, items = _bin_ranges_csr(b0, b1, nb)
    return z1, ze, bp, start, items


@njit(cache=True)
def _hair_items(b0, b1, start):
    """Active lists of the z-bins: hair h in bins b0[h]..b1[h], ascending hair index in every bin."""
    items = np.empty(start[-1], np.int32)
    cursor = start[:-1].copy()
    for h in range(b0.shape[0]):
        for b in range(b0[h], b1[h] + 1):
            items[cursor[b]] = h
            cursor[b] += 1
    return items


@njit(cache=True)
def yarn_loops(tp, yarn_seed, k, R, th, th0, L):
    """Every mutated migration cycle (loop, §4.4.1) of ply k along a yarn of length L, ascending by
    (fibre, cycle): (fibre (n,), U_loop (n,), z0 (n,), z1 (n,), cycle (n,)) with [z0, z1] the cycle's z range
    clipped to [0, L]. Same random numbers as model.loop_unit_radius, so lookups and
    realization see the same loops."""
    N = R.shape[0]
    cap = 16
    fib = np.empty(cap, np.int32)
    cy = np.empty(cap, np.int32)
    U = np.empty(cap)
    z0 = np.empty(cap)
    z1 = np.empty(cap)
    n = 0
    if tp[USE_FLYAWAYS] == 0.0 or tp[P_LOOP] <= 0.0 or tp[USE_MIGRATION] == 0.0:
        return fib[:0], U[:0], z0[:0], z1[:0], cy[:0]
    w = tp[S_MIG] * 2.0 * math.pi / tp[ALPHA]  # migration phase per unit z
    for j in range(N):
        c0 = cycle_of(th0[j])
        c1 = cycle_of(w * L + th0[j])
        for cyc in range(c0, c1 + 1):
            u = loop_unit_radius(tp, yarn_seed, k, j, R[j], th[j], th0[j], cyc)
            if u <= 0.0:
                continue
            if n == cap:
                cap *= 2
                fib = _grow(fib, cap)
                cy = _grow(cy, cap)
                U = _grow(U, cap)
                z0 = _grow(z0, cap)
                z1 = _grow(z1, cap)
            fib[n] = j
            cy[n] = cyc
            U[n] = u
            z0[n] = max(0.0, (2.0 * math.pi * cyc - math.pi - th0[j]) / w)
            z1[n] = min(L, (2.0 * math.pi * cyc + math.pi - th0[j]) / w)
            n += 1
    return fib[:n], U[:n], z0[:n], z1[:n], cy[:n]


@njit(cache=True)
def _grow(a, cap):
    b = np.empty(cap, a.dtype)
    b[:a.shape[0]] = a
    return b


class CsrParts:
    """Bin lists built part by part into one CSR: the bin starts (a leading 0, then each part's bin ends shifted by
    the items of the parts before it) and the items (``build_tables``: regular-fibre bins, hair and loop z-bins)."""

    def __init__(self):
        self.starts = [np.zeros(1, np.int64)]
        self.items = []
        self.count = 0

    def add(self, ends, items):
        """Appends a part: its bins' ends (offsets into ``items``, its leading 0 left off) and its items."""
        self.starts.append(ends + self.count)
        self.items.append(items)
        self.count += len(items)


def uniform_zbins(lo, hi, L, h):
    """Fixed-width z-bins [b h, (b+1) h) over [0, L]; bin b lists (CSR, ascending) every entry whose
    [lo, hi] meets it. Returns (nbins, start (nbins+1,), items int32)."""
    nb = max(1, int(math.ceil(L / h)))
    b0 = np.clip(np.floor(lo / h).astype(np.int64), 0, nb - 1)
    b1 = np.clip(np.floor(hi / h).astype(np.int64), 0, nb - 1)
    start, items = _bin_ranges_csr(b0, b1, nb)
    return nb, start, items


def _bin_ranges_csr(b0, b1, nb):
    """CSR (start (nb+1,), items int32) of entries listed in every bin b0[e]..b1[e], ascending."""
    counts = np.zeros(nb + 1, np.int64)
    np.add.at(counts, b0, 1)
    np.add.at(counts, b1 + 1, -1)
    start = np.zeros(nb + 1, np.int64)
    start[1:] = np.cumsum(np.cumsum(counts)[:nb])
    return start, _hair_items(b0, b1, start)


@njit(cache=True)
def curvature_max(cv, c, step):
    """Largest curvature of yarn curve c, from tangent turning over arc-length steps (x 1.25 margin)."""
    L = cv.curve_length[c]
    n = max(2, int(math.ceil(L / step)) + 1)
    h = L / (n - 1)
    best = 0.0
    pos, t0, nn, bb = curve_frame_at(cv, c, 0.0)
    for i in range(1, n):
        pos, t1, nn, bb = curve_frame_at(cv, c, i * h)
        d = min(1.0, max(-1.0, t0[0] * t1[0] + t0[1] * t1[1] + t0[2] * t1[2]))
        k = math.acos(d) / h
        if k > best:
            best = k
        t0 = t1
    return 1.25 * best


def build_tables(cv, tparams, yarn_type, yarn_albedo, seed, nbins=32, hair_mode=0, fold_cap=FOLD_CAP):
    """Tables for all yarns. tparams (T, NPARAM) packed types (U_MAX, HAIR_RMAX filled in),
    yarn_type (Y,), yarn_albedo (Y, 3). The derived fields (DERIVED_FIELDS) are empty: fill them
    with derive_lookup_accel before looking anything up.
    Returns (Tables, info dict with per-yarn diagnostics)."""
    T = tparams.shape[0]
    Y = len(yarn_type)
    ext = np.array([extent_bound(tparams[yarn_type[c]]) for c in range(Y)])
    kap = np.array([curvature_max(cv, c, max(cv.radius[c] * 0.25, cv.curve_length[c] / 4000)) for c in range(Y)])
    g_raw = 1.0 - kap * ext
    # where kappa * extent >= fold_cap the yarn-space map folds (or nearly) within the fibre extent:
    # the bounds below are capped there and lookups are no longer exact (reported as 'folded', FOLD_CAP)
    kr = np.minimum(kap * ext, fold_cap)
    gmin = 1.0 - kr
    type_K = np.ones(T)
    type_mz = np.zeros(T)
    for t in range(T):
        sel = yarn_type == t
        if not sel.any():
            type_K[t] = 2.0
            type_mz[t] = tparams[t, FIBER_RADIUS]
            continue
        v = transverse_speed_bound(tparams[t])
        K = max(reach_factor(v, g) for g in gmin[sel])
        type_K[t] = K
        type_mz[t] = 1.1 * tparams[t, FIBER_RADIUS] / gmin[sel].min()
    fib = []
    type_pad = np.zeros(T)
    for t in range(T):
        sel = yarn_type == t
        type_pad[t] = PAD_FRACTION * tparams[t, FIBER_RADIUS]
        fib.append(regular_tables(tparams[t], type_key(seed, t), type_K[t], nbins, type_pad[t]))
    # z margin of loop activity: with w + eps <= pad (binned lookups) every fibre point within the
    # fibre radius of p has |z - s| <= hwin <= (max((1 + K)(rf + pad), m_z) + 2 pad) / g_min
    loop_margin = np.array([(max((1.0 + type_K[t]) * (tparams[t, FIBER_RADIUS] + type_pad[t]), type_mz[t])
                             + 2.0 * type_pad[t]) / gmin[c] for c, t in enumerate(yarn_type)])
    type_fib_off = np.zeros(T + 1, np.int64)
    type_bin_off = np.zeros(T + 1, np.int64)
    bins = CsrParts()
    for t in range(T):
        type_fib_off[t + 1] = type_fib_off[t] + len(fib[t][0])
        nb = int(tparams[t, PLY_NUM]) * nbins
        type_bin_off[t + 1] = type_bin_off[t] + nb
        bins.add(fib[t][5], fib[t][6])
    ykeys = np.array([yarn_key(seed, c) for c in range(Y)], np.int64)
    ply_off = np.zeros(Y + 1, np.int64)
    for c in range(Y):
        ply_off[c + 1] = ply_off[c] + int(tparams[yarn_type[c], PLY_NUM])
    S = int(ply_off[-1])
    hcount = np.zeros(S, np.int64)
    hoff = np.zeros(S + 1, np.int64)
    hzoff = np.zeros(S + 1, np.int64)
    z1s, zes, bps, hair_bins = [], [], [], CsrParts()
    hshape = [np.zeros((0, 4))]
    lp_off = np.zeros(S + 1, np.int64)
    lz_off = np.zeros(S + 1, np.int64)
    lz_h = np.zeros(S)
    lfib, lU, lcyc, loop_bins = [], [], [], CsrParts()
    for c in range(Y):
        tp = tparams[yarn_type[c]]
        L = float(cv.curve_length[c])
        for k in range(int(tp[PLY_NUM])):
            g = ply_off[c] + k
            hcount[g] = hair_count(tp, L)
            if hair_mode == 0:
                z1, ze, bp, st, it = hybrid_hairs(tp, L, int(ykeys[c]), k, float(type_mz[yarn_type[c]]))
            else:
                z1 = ze = bp = np.zeros(0)
                st, it = np.zeros(1, np.int64), np.zeros(0, np.int32)
            hoff[g + 1] = hoff[g] + len(z1)
            if len(z1):
                hshape.append(np.array([hair_params(tp, np.uint64(ykeys[c]), k, h) for h in range(len(z1))]))
            # loops of ply k, binned in z (fixed width: half a migration cycle)
            t = yarn_type[c]
            N = int(tp[FIBER_NUM])
            fl = fib[t]
            lf, lu, lz0, lz1, lcy = yarn_loops(tp, np.uint64(ykeys[c]), k, fl[0][k * N:(k + 1) * N],
                                          fl[1][k * N:(k + 1) * N], fl[2][k * N:(k + 1) * N], L)
            hz = 0.5 * tp[ALPHA] / max(tp[S_MIG], 1e-12)
            lnb, lst, lit = uniform_zbins(lz0 - loop_margin[c], lz1 + loop_margin[c], L, hz)
            lp_off[g + 1] = lp_off[g] + len(lf)
            lz_off[g + 1] = lz_off[g] + lnb
            lz_h[g] = hz
            lfib.append(lf)
            lU.append(lu)
            lcyc.append(lcy)
            loop_bins.add(lst[1:], lit)
            hzoff[g + 1] = hzoff[g] + len(bp) if len(bp) else hzoff[g] + 1
            if not len(bp):
                bp = np.zeros(1)  # one breakpoint, no bins
            z1s.append(z1)
            zes.append(ze)
            bps.append(bp)
            hair_bins.add(st[1:], it)
    def cat(xs, dt):
        return np.ascontiguousarray(np.concatenate(xs) if xs else np.zeros(0), dtype=dt)
    shape = np.ascontiguousarray(np.concatenate(hshape), np.float64)
    stored = dict(
        tparams=np.ascontiguousarray(tparams, np.float64), type_K=type_K, type_mz=type_mz, type_fib_off=type_fib_off,
        fib_R=cat([f[0] for f in fib], np.float64), fib_th=cat([f[1] for f in fib], np.float64),
        fib_th0=cat([f[2] for f in fib], np.float64), fib_rlo=cat([f[3] for f in fib], np.float64),
        fib_rhi=cat([f[4] for f in fib], np.float64), type_nbins=np.full(T, nbins, np.int64),
        type_bin_off=type_bin_off, bin_start=cat(bins.starts, np.int64), bin_items=cat(bins.items, np.int32),
        yarn_type=np.ascontiguousarray(yarn_type, np.int32), yarn_seed=ykeys, yarn_extent=ext, yarn_gmin=gmin,
        yarn_albedo=np.ascontiguousarray(yarn_albedo, np.float64), yarn_ply_off=ply_off, hair_count=hcount,
        hair_off=hoff, hair_z1=cat(z1s, np.float64), hair_ze=cat(zes, np.float64),
        hair_r0=np.ascontiguousarray(shape[:, 0]), hair_r1=np.ascontiguousarray(shape[:, 1]),
        hair_th1=np.ascontiguousarray(shape[:, 2]), hair_pe=np.ascontiguousarray(shape[:, 3]),
        hb_zoff=hzoff, hb_z=cat(bps, np.float64), hb_start=cat(hair_bins.starts, np.int64),
        hb_items=cat(hair_bins.items, np.int32),
        hair_mode=np.array([hair_mode], np.int64), yarn_length=np.ascontiguousarray(cv.curve_length[:Y], np.float64),
        max_extent=np.array([ext.max() if Y else 0.0]), fib_mask=cat([f[7] for f in fib], np.uint64),
        lp_off=lp_off, lp_fib=cat(lfib, np.int32), lp_U=cat(lU, np.float64), lp_cyc=cat(lcyc, np.int32),
        lz_off=lz_off, lz_h=lz_h, lz_start=cat(loop_bins.starts, np.int64),
        lz_items=cat(loop_bins.items, np.int32),
        type_pad=type_pad, yarn_kappa=np.ascontiguousarray(kap, np.float64))
    tab = Tables(**stored, **dict(zip(DERIVED_FIELDS, empty_accel(Y))))
    info = {"curvature_max": kap, "g_raw": g_raw, "extent": ext, "folded": kap * ext >= fold_cap}
    return tab, info
