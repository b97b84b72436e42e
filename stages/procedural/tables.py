"""Realization-minimizing tables (seed 000 §4): what a lookup needs besides the yarn curves.

Regular fibres (§4.3, Fig. 7, footnote 2), per yarn type and ply: each fibre's trajectory in the
twist-compensated unit disc, T_j = {R (cos theta_j, sin theta_j): R in [rho_min R_j, rho_max R_j]},
stored as (R_j, theta_j, theta0_j) plus the radial interval [r_lo, r_hi] grown by the fibre-radius
margin m; the azimuth [0, 2 pi) is cut into B equal bins and bin b lists (CSR, ascending fibre
index; also as a bit mask per fibre) every fibre whose trajectory comes within m of the bin's
wedge. m = K (r_fibre + pad) / min(e_short, e_long) in unit-disc units, with K bounding the ratio
between a point's cross-sectional distance to a fibre and its true distance
(yarn_model.reach_factor, from the largest transverse fibre speed and the yarn's smallest axial
stretch g_min) and pad (``type_pad``) the slack of the lookups' sampled frames.

Loops (§4.4.1, §5.3): every migration cycle's mutation is a consistent random number of (yarn,
ply, fibre, cycle) (yarn_model.loop_unit_radius). A loop leaves its fibre's [r_lo, r_hi], so per
yarn and ply the mutated cycles are listed (fibre, U_loop; ascending fibre) in fixed-width z-bins
(half a migration cycle) holding every loop whose cycle, grown by the lookups' z window, meets
the bin: a lookup tests the loops of its z-bin whose fibre is in its azimuth bin.

Hairs (§4.4.2), per yarn and ply: hybrid mode stores (z1, ze) and the shape (r0, r1, theta1,
pe) of every hair and cuts z at the ends min(z1, z2) - m_z, max(z1, z2) + m_z of every hair; each
z-bin lists (ascending hair index) the hairs active across the whole bin. The realization-free mode stores nothing per hair
(hair_free.active_hairs). Both come from the same quad-tree, so they hold the same hairs.

Derived when loaded (never stored, ``derive_lookup_accel``): frame samples and the chord grid
(frame_samples.py), the scan bounds (``scan_bounds``) and the fringe occupancy
(``fringe_occupancy``): per yarn, bits over (z-bin, radial shell, azimuth sector) of yarn space
marking where a loop or a stored hair can come close enough to cover a point, so that lookups
far from every loop and hair skip those tests, and lookups beyond the core skip the yarn.

``Tables`` is a namedtuple of flat arrays usable inside numba kernels (see lookup.py).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.rng import hash_u64

from stages.core.curves import curve_frame_at

from . import hair_free
from .yarn_model import (ALPHA, E_LONG, E_SHORT, FIBER_NUM, FIBER_RADIUS, HAIR_DENSITY, P_LOOP, PLY_NUM, PLY_RADIUS,
                         RHO_MAX, RHO_MIN, S_MIG, USE_FLYAWAYS, USE_MIGRATION, ZE_MU, ZE_SIG, cycle_of, extent_bound,
                         hair_params, hair_point, hair_speed_bound, loop_unit_radius, reach_factor, regular_xy,
                         sample_regular_fibers, transverse_speed, transverse_speed_bound)

Tables = namedtuple("Tables", [
    "tparams",          # (T, NPARAM) float64 packed yarn types (yarn_model indices)
    "type_K",           # (T,) cross-section distance / true distance bound
    "type_mz",          # (T,) yarn-space z margin of hair activity (>= fibre radius / g_min)
    "type_fib_off",     # (T+1,) int64: fibres of type t, ply k, fibre j at type_fib_off[t] + k N + j
    "fib_R", "fib_th", "fib_th0", "fib_rlo", "fib_rhi",   # float64 per fibre
    "type_nbins",       # (T,) int64 azimuth bins B_t
    "type_bin_off",     # (T+1,) int64: bin (t, k, b) at type_bin_off[t] + k B_t + b
    "bin_start",        # (nbins_total+1,) int64 CSR into bin_items
    "bin_items",        # int32 fibre index within the ply
    "yarn_type",        # (Y,) int32
    "yarn_seed",        # (Y,) int64 per-yarn random key
    "yarn_extent",      # (Y,) float64 radius bound of all fibre surfaces around the yarn axis
    "yarn_gmin",        # (Y,) float64 smallest axial stretch 1 - kappa rho of the yarn-space map
    "yarn_albedo",      # (Y, 3) float64
    "yarn_ply_off",     # (Y+1,) int64 slot g = yarn_ply_off[c] + k
    "hair_count",       # (S,) int64 hairs of slot g
    "hair_off",         # (S+1,) int64 hybrid: hair h of slot g at hair_off[g] + h
    "hair_z1", "hair_ze",   # float64 hybrid: pre-generated z extents
    "hair_r0", "hair_r1", "hair_th1", "hair_pe",   # float64 hybrid: pre-generated shape (yarn_model.hair_params)
    "hb_zoff",          # (S+1,) int64: breakpoints of slot g at hb_z[hb_zoff[g]:hb_zoff[g+1]]
    "hb_z",             # float64 breakpoints
    "hb_start",         # CSR over bins (bin (g, b) at hb_zoff[g] - g + b), into hb_items
    "hb_items",         # int32 hair index
    "hair_mode",        # (1,) int64: 0 hybrid, 1 realization-free
    "yarn_length",      # (Y,) float64 arc length of each yarn curve (yarn-space z range)
    "max_extent",       # (1,) float64 largest yarn_extent (candidate-yarn search radius)
    "fib_mask",         # (F,) uint64 bit b set when the fibre is listed in azimuth bin b (all set for > 64 bins)
    "lp_off",           # (S+1,) int64: loops (mutated migration cycles) of slot g at lp_off[g]:lp_off[g+1]
    "lp_fib", "lp_U",   # int32 fibre index within the ply, float64 the cycle's U_loop (ascending fibre, cycle)
    "lp_cyc",           # int32 the loop's migration cycle
    "lz_off",           # (S+1,) int64: loop z-bins of slot g are lz_off[g] .. lz_off[g+1]-1
    "lz_h",             # (S,) float64 z-bin width of slot g
    "lz_start",         # CSR over loop z-bins (global bin index), into lz_items
    "lz_items",         # int32 loop index within the slot (ascending)
    "type_pad",         # (T,) float64 slack (beyond the fibre radius) the azimuth bins' margin allows for
    "yarn_kappa",       # (Y,) float64 curvature bound of each yarn curve (x 1.25 margin)
    # ---- derived when loaded (derive_lookup_accel; never stored): frame samples and chord grid
    "fs_off",           # (Y+1,) int64: frame samples of yarn c at fs_off[c]:fs_off[c+1] (frame_samples.py)
    "fs_s",             # float64 arc length of each frame sample
    "fs_frame",         # (M, 12) float64 position, tangent, normal, binormal
    "yarn_eps",         # (Y,) float64 bound of |Eq. 7 with sampled frames - Eq. 7| within the extent
    "kn_off",           # (Y+1,) int64: coarse knots of yarn c at kn_off[c]:kn_off[c+1]
    "kn_idx",           # int64 frame-sample index of each coarse knot
    "kn_sag",           # float64 sag bound of the coarse chord starting at each knot
    "fg_lo", "fg_cell", "fg_dims",   # (3,), (1,), (3,) chord grid geometry
    "fg_start",         # (cells+1,) int64 CSR into the runs
    "fg_yarn", "fg_a", "fg_b",       # runs: yarn, coarse chords [a, b)
    "ply_rr",           # (T, max plies, 2) float64 (min r_lo, max r_hi) over the ply's fibres (unit disc)
    "fib_v",            # (F,) float64 transverse speed bound of each fibre outside loop cycles
    "hair_box",         # (H, 4) float64 hybrid: each hair's z range and radius range (zlo, zhi, Rlo, Rhi)
    "lz_rr",            # (loop z-bins, 2) float64 (min r_lo, max U_loop) over each loop z-bin's loops
    "type_rcore",       # (T,) float64 yarn-space radius beyond which no regular (non-loop) fibre is in reach
    "fo_off",           # (Y+1,) int64: fringe z-bins of yarn c at fo_off[c]:fo_off[c+1]
    "fo_geom",          # (Y, 2) float64 fringe z-bin width and shell width of yarn c
    "fo_bits",          # (fringe z-bins, 2 FO_WORDS) uint64 fringe occupancy of loops, then hairs (fringe_occupancy)
    "kn_rgate",         # (coarse knots,) float64 axis distance beyond which a visit near the chord finds nothing
])
DERIVED_FIELDS = ("fs_off", "fs_s", "fs_frame", "yarn_eps", "kn_off", "kn_idx", "kn_sag", "fg_lo", "fg_cell",
                  "fg_dims", "fg_start", "fg_yarn", "fg_a", "fg_b", "ply_rr", "fib_v", "hair_box", "lz_rr",
                  "type_rcore", "fo_off", "fo_geom", "fo_bits", "kn_rgate")
STORED_FIELDS = tuple(f for f in Tables._fields if f not in DERIVED_FIELDS)
PAD_FRACTION = 0.05      # type_pad in fibre radii: the bins' slack for the sampled frames' error
FRAME_TOLERANCE = 0.01   # frame-sample error aimed at, in fibre radii (<= PAD_FRACTION / 3 keeps lookups binned)
FO_SECTORS = 32          # fringe occupancy: azimuth sectors around the yarn axis
FO_SHELLS = 8            # fringe occupancy: radial shells (the last one open-ended)
FO_WORDS = FO_SECTORS * FO_SHELLS // 64
FO_ZBIN_EXTENTS = 0.25   # fringe z-bin width in yarn extents


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
    clipped to [0, L]. Same random numbers as yarn_model.loop_unit_radius, so lookups and
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
def hair_node_seed_nb(yarn_seed, k):
    return hash_u64(yarn_seed, k, 31)


def table_bytes(tab: Tables) -> dict:
    """Bytes of the tables by part: regular (fibre trajectories and bins), hair, loop (none)."""
    reg = sum(getattr(tab, n).nbytes for n in ("fib_R", "fib_th", "fib_th0", "fib_rlo", "fib_rhi", "fib_mask",
                                                "bin_start", "bin_items", "tparams", "type_K", "type_mz",
                                                "type_fib_off", "type_nbins", "type_bin_off"))
    hair = sum(getattr(tab, n).nbytes for n in ("hair_count", "hair_off", "hair_z1", "hair_ze", "hb_zoff",
                                                 "hb_z", "hb_start", "hb_items", "hair_r0", "hair_r1", "hair_th1",
                                                 "hair_pe"))
    loop = sum(getattr(tab, n).nbytes for n in ("lp_off", "lp_fib", "lp_U", "lp_cyc", "lz_off", "lz_h", "lz_start",
                                                 "lz_items"))
    yarn = sum(getattr(tab, n).nbytes for n in ("yarn_type", "yarn_seed", "yarn_extent", "yarn_gmin",
                                                 "yarn_albedo", "yarn_ply_off", "yarn_length", "max_extent",
                                                 "yarn_kappa", "hair_mode", "type_pad"))
    return {"regular": int(reg), "hair": int(hair), "loop": int(loop), "per_yarn": int(yarn)}


def accel_bytes(tab: Tables) -> int:
    """Bytes of the structures derived at load time (frame samples, coarse knots, chord grid)."""
    return int(sum(getattr(tab, n).nbytes for n in DERIVED_FIELDS))


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


def build_tables(cv, tparams, yarn_type, yarn_albedo, seed, nbins=32, hair_mode=0, fold_cap=0.5):
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
    # the bounds below are capped there and lookups are no longer exact (reported as 'folded')
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
    starts = [np.zeros(1, np.int64)]
    items = []
    item_base = 0
    for t in range(T):
        type_fib_off[t + 1] = type_fib_off[t] + len(fib[t][0])
        nb = int(tparams[t, PLY_NUM]) * nbins
        type_bin_off[t + 1] = type_bin_off[t] + nb
        starts.append(fib[t][5] + item_base)
        items.append(fib[t][6])
        item_base += len(fib[t][6])
    ykeys = np.array([yarn_key(seed, c) for c in range(Y)], np.int64)
    ply_off = np.zeros(Y + 1, np.int64)
    for c in range(Y):
        ply_off[c + 1] = ply_off[c] + int(tparams[yarn_type[c], PLY_NUM])
    S = int(ply_off[-1])
    hcount = np.zeros(S, np.int64)
    hoff = np.zeros(S + 1, np.int64)
    hzoff = np.zeros(S + 1, np.int64)
    z1s, zes, bps, hstarts, hitems = [], [], [], [np.zeros(1, np.int64)], []
    hshape = [np.zeros((0, 4))]
    lp_off = np.zeros(S + 1, np.int64)
    lz_off = np.zeros(S + 1, np.int64)
    lz_h = np.zeros(S)
    lfib, lU, lcyc, lstarts, litems = [], [], [], [np.zeros(1, np.int64)], []
    litem_base = 0
    hitem_base = 0
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
            lstarts.append(lst[1:] + litem_base)
            litems.append(lit)
            litem_base += len(lit)
            hzoff[g + 1] = hzoff[g] + len(bp) if len(bp) else hzoff[g] + 1
            if not len(bp):
                bp = np.zeros(1)  # one breakpoint, no bins
            z1s.append(z1)
            zes.append(ze)
            bps.append(bp)
            hstarts.append(st[1:] + hitem_base)
            hitems.append(it)
            hitem_base += len(it)
    cat = lambda xs, dt: np.ascontiguousarray(np.concatenate(xs) if xs else np.zeros(0), dtype=dt)
    shape = np.ascontiguousarray(np.concatenate(hshape), np.float64)
    stored = dict(
        tparams=np.ascontiguousarray(tparams, np.float64), type_K=type_K, type_mz=type_mz, type_fib_off=type_fib_off,
        fib_R=cat([f[0] for f in fib], np.float64), fib_th=cat([f[1] for f in fib], np.float64),
        fib_th0=cat([f[2] for f in fib], np.float64), fib_rlo=cat([f[3] for f in fib], np.float64),
        fib_rhi=cat([f[4] for f in fib], np.float64), type_nbins=np.full(T, nbins, np.int64),
        type_bin_off=type_bin_off, bin_start=cat(starts, np.int64), bin_items=cat(items, np.int32),
        yarn_type=np.ascontiguousarray(yarn_type, np.int32), yarn_seed=ykeys, yarn_extent=ext, yarn_gmin=gmin,
        yarn_albedo=np.ascontiguousarray(yarn_albedo, np.float64), yarn_ply_off=ply_off, hair_count=hcount,
        hair_off=hoff, hair_z1=cat(z1s, np.float64), hair_ze=cat(zes, np.float64),
        hair_r0=np.ascontiguousarray(shape[:, 0]), hair_r1=np.ascontiguousarray(shape[:, 1]),
        hair_th1=np.ascontiguousarray(shape[:, 2]), hair_pe=np.ascontiguousarray(shape[:, 3]),
        hb_zoff=hzoff, hb_z=cat(bps, np.float64), hb_start=cat(hstarts, np.int64), hb_items=cat(hitems, np.int32),
        hair_mode=np.array([hair_mode], np.int64), yarn_length=np.ascontiguousarray(cv.curve_length[:Y], np.float64),
        max_extent=np.array([ext.max() if Y else 0.0]), fib_mask=cat([f[7] for f in fib], np.uint64),
        lp_off=lp_off, lp_fib=cat(lfib, np.int32), lp_U=cat(lU, np.float64), lp_cyc=cat(lcyc, np.int32), lz_off=lz_off, lz_h=lz_h,
        lz_start=cat(lstarts, np.int64), lz_items=cat(litems, np.int32),
        type_pad=type_pad, yarn_kappa=np.ascontiguousarray(kap, np.float64))
    tab = Tables(**stored, **dict(zip(DERIVED_FIELDS, _empty_accel(Y))))
    info = {"curvature_max": kap, "g_raw": g_raw, "extent": ext, "folded": kap * ext >= fold_cap}
    return tab, info


def _empty_accel(Y):
    z, zi = np.zeros(0), np.zeros(0, np.int64)
    return (np.zeros(Y + 1, np.int64), z, np.zeros((0, 12)), np.zeros(Y), np.zeros(Y + 1, np.int64), zi, z,
            np.zeros(3), np.ones(1), np.ones(3, np.int64), np.zeros(2, np.int64), np.zeros(0, np.int32), zi, zi,
            np.zeros((0, 1, 2)), np.zeros(0), np.zeros((0, 4)), np.zeros((0, 2)), np.zeros(0),
            np.zeros(Y + 1, np.int64), np.ones((Y, 2)), np.zeros((0, 2 * FO_WORDS), np.uint64), np.zeros(0))


def scan_bounds(tab: Tables):
    """(ply_rr, fib_v, lz_rr): the unit-disc radius range any fibre of a ply, or any loop of a loop
    z-bin, can cover (its items' [r_lo, r_hi] and [r_lo, U_loop] joined; empty: (inf, -inf)): a
    point outside the range skips the ply's bin scan or the z-bin's loop scan at once; and each
    fibre's transverse speed bound outside loop cycles (radius in [rho_min R_j, rho_max R_j]),
    for its own reach factor (reach_factor) in the bin scan."""
    T = len(tab.type_K)
    P = tab.tparams[:, PLY_NUM].astype(np.int64)
    N = tab.tparams[:, FIBER_NUM].astype(np.int64)
    ply_rr = np.empty((T, max(1, int(P.max(initial=1))), 2))
    ply_rr[..., 0] = np.inf
    ply_rr[..., 1] = -np.inf
    fib_v = np.zeros(len(tab.fib_R))
    for t in range(T):
        tp = tab.tparams[t]
        mig = tp[USE_MIGRATION] != 0.0
        for k in range(P[t]):
            f = slice(tab.type_fib_off[t] + k * N[t], tab.type_fib_off[t] + (k + 1) * N[t])
            if N[t] > 0:
                ply_rr[t, k] = tab.fib_rlo[f].min(), tab.fib_rhi[f].max()
            R = tab.fib_R[f]
            hi = R * tp[RHO_MAX] if mig else R
            lo = R * tp[RHO_MIN] if mig else R
            fib_v[f] = [transverse_speed(tp, a, b) for a, b in zip(hi, lo)]
    nz = len(tab.lz_start) - 1
    lz_rr = np.empty((max(nz, 0), 2))
    lz_rr[:, 0] = np.inf
    lz_rr[:, 1] = -np.inf
    S = len(tab.lp_off) - 1
    for g in range(S):
        c = int(np.searchsorted(tab.yarn_ply_off, g, side="right")) - 1
        t = tab.yarn_type[c]
        fo = tab.type_fib_off[t] + (g - tab.yarn_ply_off[c]) * N[t]
        for zb in range(tab.lz_off[g], tab.lz_off[g + 1]):
            le = tab.lp_off[g] + tab.lz_items[tab.lz_start[zb]:tab.lz_start[zb + 1]]
            if len(le):
                lz_rr[zb] = tab.fib_rlo[fo + tab.lp_fib[le]].min(), tab.lp_U[le].max()
    return ply_rr, fib_v, lz_rr


@njit(cache=True)
def loop_fibre(tab, tp, c, k, e):
    """Loop e of ply k of yarn c (tp its type's parameters): (j its fibre's index in the ply, fi that
    fibre's row in the type's fibre tables, [z0, z1] the z range of its migration cycle lp_cyc[e],
    clipped to the yarn)."""
    j = tab.lp_fib[e]
    fi = tab.type_fib_off[tab.yarn_type[c]] + k * int(tp[FIBER_NUM]) + j
    w = tp[S_MIG] * 2.0 * math.pi / tp[ALPHA]  # migration phase per unit z
    cyc = tab.lp_cyc[e]
    th0 = tab.fib_th0[fi]
    z0 = max(0.0, (2.0 * math.pi * cyc - math.pi - th0) / w)
    z1 = min(tab.yarn_length[c], (2.0 * math.pi * cyc + math.pi - th0) / w)
    return j, fi, z0, z1


@njit(cache=True, inline="always")
def yarn_space_limit(rf, w, eps, gmin):
    """Yarn-space distance within which a fibre point must lie to cover a point with tangential
    residual w (1.1 (r_f + w + 2 eps_c) / g_min; the lookups' hair and loop limit)."""
    return 1.1 * (rf + w + 2.0 * eps) / gmin


@njit(cache=True, inline="always")
def z_window(K, mz, rf, w, eps, gmin):
    """Half width of a yarn visit's z window: every fibre point within r_f of a point with tangential
    residual w lies within it of the foot point s (|z - s| <= yarn-space distance / g_min)."""
    return (max((1.0 + K) * (rf + w + eps), mz) + w + 2.0 * eps) / gmin


@njit(cache=True, inline="always")
def fringe_reach(rf, eps, gmin):
    """yarn_space_limit at the largest tangential residual a yarn visit goes on with (w < r_f + 2 eps_c)."""
    return yarn_space_limit(rf, rf + 2.0 * eps, eps, gmin)


@njit(cache=True, inline="always")
def fringe_window(K, mz, rf, eps, gmin):
    """z_window at the largest tangential residual a yarn visit goes on with (w < r_f + 2 eps_c)."""
    return z_window(K, mz, rf, rf + 2.0 * eps, eps, gmin)


@njit(cache=True, inline="always")
def fringe_bits(tab, c, s, x, y, rho):
    """(loop bit, hair bit) of the fringe cell of yarn-space point (x, y, s) in yarn c."""
    base = tab.fo_off[c]
    nb = tab.fo_off[c + 1] - base
    zb = min(max(int(s / tab.fo_geom[c, 0]), 0), nb - 1)
    sh = min(int(rho / tab.fo_geom[c, 1]), FO_SHELLS - 1)
    q = min(int((math.atan2(y, x) + math.pi) * (FO_SECTORS / (2.0 * math.pi))), FO_SECTORS - 1)
    idx = sh * FO_SECTORS + q
    w = idx >> 6
    b = np.uint64(idx & 63)
    one = np.uint64(1)
    return ((tab.fo_bits[base + zb, w] >> b) & one) != 0, ((tab.fo_bits[base + zb, FO_WORDS + w] >> b) & one) != 0


@njit(cache=True)
def _mark_ball(bits, base, nb, h, rw, x, y, z, r, w0):
    """Set every fringe cell (z-bin, shell, sector) that meets the yarn-space ball of radius r at
    (x, y, z) (in the words from w0 on); balls beyond a yarn end mark the end bin."""
    b0 = min(max(int(math.floor((z - r) / h)), 0), nb - 1)
    b1 = max(min(int(math.floor((z + r) / h)), nb - 1), 0)
    rho = math.sqrt(x * x + y * y)
    s0 = min(int(max(rho - r, 0.0) / rw), FO_SHELLS - 1)
    s1 = min(int((rho + r) / rw), FO_SHELLS - 1)
    q0 = 0
    q1 = FO_SECTORS - 1
    if rho > r:
        half = math.asin(min(1.0, r / rho)) + 1e-9  # the ball's half angle seen from the axis
        phi = math.atan2(y, x) + math.pi
        a = int(math.floor((phi - half) * FO_SECTORS / (2.0 * math.pi)))
        b = int(math.floor((phi + half) * FO_SECTORS / (2.0 * math.pi)))
        if b - a + 1 < FO_SECTORS:
            q0, q1 = a, b
    for zb in range(b0, b1 + 1):
        for sh in range(s0, s1 + 1):
            for qq in range(q0, q1 + 1):
                idx = sh * FO_SECTORS + qq % FO_SECTORS
                bits[base + zb, w0 + (idx >> 6)] |= np.uint64(1) << np.uint64(idx & 63)


@njit(cache=True)
def fringe_occupancy(tab, fo_off, fo_geom):
    """Fringe occupancy bits of every yarn, one set for loops and one for hairs: cell (z-bin, shell,
    sector) of yarn c is set when a loop (its fibre's trajectory over the loop's cycle grown by the
    largest z window, fringe_window) or a stored hair (hybrid mode) comes within fringe_reach of
    the cell in yarn space. Each curve is sampled at steps of at most fringe_reach of yarn-space
    arc (its speed bound), and every sample marks the cells within fringe_reach plus half a step.
    A lookup point in no set loop cell needs no loop scan, one in no set hair cell no hair test;
    one in neither, farther than type_rcore from the axis, is covered by no fibre of the yarn."""
    bits = np.zeros((fo_off[-1], 2 * FO_WORDS), np.uint64)
    for c in range(tab.yarn_type.shape[0]):
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        base = fo_off[c]
        nb = fo_off[c + 1] - base
        h = fo_geom[c, 0]
        rw = fo_geom[c, 1]
        rf = tp[FIBER_RADIUS]
        eps = tab.yarn_eps[c]
        gmin = tab.yarn_gmin[c]
        r = fringe_reach(rf, eps, gmin)
        win = fringe_window(tab.type_K[t], tab.type_mz[t], rf, eps, gmin)
        L = tab.yarn_length[c]
        yseed = np.uint64(tab.yarn_seed[c])
        v = math.sqrt(1.0 + transverse_speed_bound(tp) ** 2)  # yarn-space speed per unit z
        for k in range(int(tp[PLY_NUM])):
            g = tab.yarn_ply_off[c] + k
            for e in range(tab.lp_off[g], tab.lp_off[g + 1]):
                j, fi, z0, z1 = loop_fibre(tab, tp, c, k, e)
                z0 = max(0.0, z0 - win)
                z1 = min(L, z1 + win)
                n = max(1, int(math.ceil((z1 - z0) * v / r)))
                dz = (z1 - z0) / n
                for q in range(n + 1):
                    z = min(z0 + q * dz, z1)
                    x, y, kd = regular_xy(tp, yseed, k, j, tab.fib_R[fi], tab.fib_th[fi], tab.fib_th0[fi], z)
                    _mark_ball(bits, base, nb, h, rw, x, y, z, r + 0.5 * dz * v, 0)
            if tab.hair_mode[0] != 0:
                continue
            for hh in range(tab.hair_off[g], tab.hair_off[g] + tab.hair_count[g]):
                r0 = tab.hair_r0[hh]
                r1 = tab.hair_r1[hh]
                th1 = tab.hair_th1[hh]
                pe = tab.hair_pe[hh]
                z1_ = tab.hair_z1[hh]
                ze = tab.hair_ze[hh]
                speed = hair_speed_bound(tp, r0, r1, pe, ze)
                n = max(1, int(math.ceil(speed / r)))
                for q in range(n + 1):
                    x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1_, ze, q / n)
                    _mark_ball(bits, base, nb, h, rw, x, y, z, r + 0.5 * speed / n, FO_WORDS)
    return bits


def fringe_tables(tab: Tables):
    """(type_rcore, fo_off, fo_geom, fo_bits): see fringe_occupancy. type_rcore: a point farther than
    this from the axis is outside every ply's unit-disc radius range (ply_rr) whatever its ply."""
    T = len(tab.type_K)
    rcore = np.empty(T)
    for t in range(T):
        tp = tab.tparams[t]
        P = int(tp[PLY_NUM])
        hi = float(tab.ply_rr[t, :P, 1].max()) if P else -np.inf
        rcore[t] = tp[PLY_RADIUS] + max(hi, 0.0) * max(tp[E_SHORT], tp[E_LONG])
    ext = np.asarray(tab.yarn_extent, np.float64)
    L = np.asarray(tab.yarn_length, np.float64)
    h = np.maximum(FO_ZBIN_EXTENTS * ext, 1e-12)
    nb = np.maximum(1, np.ceil(L / h)).astype(np.int64)
    fo_off = np.concatenate([[0], np.cumsum(nb)]).astype(np.int64)
    fo_geom = np.ascontiguousarray(np.stack([h, np.maximum(ext / FO_SHELLS, 1e-12)], axis=1))
    return rcore, fo_off, fo_geom, fringe_occupancy(tab, fo_off, fo_geom)


def chord_gates(tab: Tables):
    """Per coarse chord q (from knot q to q + 1) of yarn c: an axis distance R such that a point whose
    foot point lies on chords q-1 .. q+2 (the lookups' bracket) and whose distance from the axis
    exceeds R is covered by no fibre of c: the largest of type_rcore widened by the margin of an
    unbinned visit (K (r_f + 2 eps_c) max(e) / min(e)) and the outer radius of the set fringe
    shells over the bracket's z-bins (infinite where the last, open shell is set or, in the
    realization-free mode, where hairs are not stored). Lookups skip such a yarn before its foot
    point: p's axis distance is at least sqrt(lb^2 - w^2) for the chord lower bound lb."""
    gate = np.full(len(tab.kn_idx), np.inf)
    bits = np.unpackbits(tab.fo_bits.view(np.uint8), axis=1, bitorder="little")
    bits = bits.reshape(len(tab.fo_bits), 2, FO_SHELLS, FO_SECTORS).any(axis=(1, 3))  # (bins, shells)
    top = np.where(bits.any(axis=1), FO_SHELLS - 1 - np.argmax(bits[:, ::-1], axis=1), -1)
    for c in range(len(tab.yarn_type)):
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        if tab.hair_mode[0] != 0 and tab.hair_count[tab.yarn_ply_off[c]:tab.yarn_ply_off[c + 1]].sum() > 0:
            continue
        es, el = tp[E_SHORT], tp[E_LONG]
        rcore = tab.type_rcore[t] + tab.type_K[t] * (tp[FIBER_RADIUS] + 2.0 * tab.yarn_eps[c]) * max(es, el) / min(es, el)
        k0, k1 = tab.kn_off[c], tab.kn_off[c + 1]
        base, nb = tab.fo_off[c], tab.fo_off[c + 1] - tab.fo_off[c]
        h, rw = tab.fo_geom[c]
        for q in range(k0, k1 - 1):
            sa = tab.fs_s[tab.kn_idx[max(q - 1, k0)]]
            sb = tab.fs_s[tab.kn_idx[min(q + 2, k1 - 1)]]
            b0 = min(max(int(math.floor(sa / h)), 0), nb - 1)
            b1 = min(max(int(math.floor(sb / h)), 0), nb - 1)
            sh = int(top[base + b0:base + b1 + 1].max())
            rf_ = np.inf if sh == FO_SHELLS - 1 else (sh + 1) * rw
            gate[q] = max(rcore, rf_)
    return gate


def derive_lookup_accel(cv, tab: Tables, tolerance: float = FRAME_TOLERANCE, max_cells: int = 1 << 23) -> Tables:
    """Tables with the derived fields filled (frame_samples.py): frame samples whose error bound
    eps_c stays near ``tolerance`` fibre radii (steps from the curvature bound, rescaled on the
    measured error, <= 3 rounds; the error is second order in the step), coarse knots about half
    an extent apart, and the chord grid (cells half the largest extent, grown to stay under
    max_cells). Deterministic: depends on the curves and the stored tables only."""
    from .frame_samples import chord_grid, coarse_knots, sample_all

    Y = len(tab.yarn_type)
    if Y == 0:
        return tab
    ext = np.asarray(tab.yarn_extent, np.float64)
    kap = np.asarray(tab.yarn_kappa, np.float64)
    rf_y = tab.tparams[tab.yarn_type, FIBER_RADIUS]
    target = tolerance * rf_y
    k2 = kap * kap * ext + kap
    radius = np.asarray(cv.radius[:Y], np.float64)
    rmin = 1e-3 * radius
    deltas = np.maximum(np.minimum(0.5 * radius, np.sqrt(8.0 * target / np.maximum(k2, 1e-12))), rmin)
    for attempt in range(3):
        fs_off, fs_s, fs_fr, err = sample_all(cv, deltas, ext)
        scale = np.array([float(np.abs(fs_fr[fs_off[c]:fs_off[c + 1], :3]).max()) for c in range(Y)]) + ext
        yeps = 2.0 * err + 1e-12 * scale
        over = (yeps > target) & (deltas > rmin)
        if not over.any():
            break
        deltas = np.where(over, np.maximum(0.9 * deltas * np.sqrt(target / np.maximum(yeps, 1e-300)), rmin), deltas)
    mean_step = float(np.mean(deltas))
    stride = max(1, int(0.5 * float(ext.min()) / mean_step))
    kn_off, kn_idx, kn_sag = coarse_knots(fs_s, fs_fr, fs_off, stride)
    lo, hi = fs_fr[:, :3].min(0) - ext.max(), fs_fr[:, :3].max(0) + ext.max()
    cell = 0.5 * float(ext.max())
    while np.prod(np.ceil((hi - lo) / cell)) > max_cells:
        cell *= 1.25
    glo, gcell, gdims, gstart, gyarn, ga, gb = chord_grid(fs_fr, kn_off, kn_idx, kn_sag, ext + yeps, cell)
    ply_rr, fib_v, lz_rr = scan_bounds(tab)
    z2 = tab.hair_z1 + tab.hair_ze
    hair_box = np.stack([np.minimum(tab.hair_z1, z2), np.maximum(tab.hair_z1, z2),
                         np.minimum(tab.hair_r0, tab.hair_r1), np.maximum(tab.hair_r0, tab.hair_r1)], axis=1)
    tab = tab._replace(ply_rr=ply_rr, fib_v=fib_v, hair_box=np.ascontiguousarray(hair_box), lz_rr=lz_rr,
                       fs_off=fs_off, fs_s=fs_s, fs_frame=fs_fr, yarn_eps=yeps, kn_off=kn_off, kn_idx=kn_idx,
                       kn_sag=kn_sag, fg_lo=glo, fg_cell=np.array([gcell]), fg_dims=gdims, fg_start=gstart,
                       fg_yarn=gyarn, fg_a=ga, fg_b=gb)
    rcore, fo_off, fo_geom, fo_bits = fringe_tables(tab)
    tab = tab._replace(type_rcore=rcore, fo_off=fo_off, fo_geom=fo_geom, fo_bits=fo_bits)
    return tab._replace(kn_rgate=chord_gates(tab))
