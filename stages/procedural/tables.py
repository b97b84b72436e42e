"""Realization-minimizing tables (seed 000 §4): what a lookup needs besides the yarn curves.

Regular fibres (§4.3, Fig. 7, footnote 2), per yarn type and ply: each fibre's trajectory in the
twist-compensated unit disc, T_j = {R (cos theta_j, sin theta_j): R in [rho_min R_j, R_hi]}
(R_hi = rho_max R_j, or the loop bound when loops can occur), stored as (R_j, theta_j, theta0_j)
plus the radial interval [r_lo, r_hi] grown by the fibre-radius margin m; the azimuth [0, 2 pi) is
cut into B equal bins and bin b lists (CSR, ascending fibre index) every fibre whose trajectory
comes within m of the bin's wedge. m = K (r_fibre + pad) / min(e_short, e_long) in unit-disc units,
with K bounding the ratio between a point's cross-sectional distance to a fibre and its true
distance and pad (``type_pad``) the slack of the lookups' sampled frames.

Loops (§4.4.1, §5.3) need no storage: every migration cycle's mutation is a consistent random
number of (yarn, ply, fibre, cycle) evaluated on the fly (yarn_model.loop_unit_radius).

Hairs (§4.4.2), per yarn and ply: hybrid mode stores (z1, ze) of every hair and cuts z at the ends
min(z1, z2) - m_z, max(z1, z2) + m_z of every hair; each z-bin lists (ascending hair index) the
hairs active across the whole bin. The realization-free mode stores nothing per hair
(hair_free.active_hairs). Both come from the same quad-tree, so they hold the same hairs.

``Tables`` is a namedtuple of flat arrays usable inside numba kernels (see lookup.py).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.rng import hash_u64

from . import hair_free
from .frame_samples import sample_all
from stages.core.curves import curve_frame_at

from .yarn_model import (E_LONG, E_SHORT, FIBER_RADIUS, HAIR_DENSITY, PLY_NUM, RHO_MAX,
                         RHO_MIN, U_MAX, USE_FLYAWAYS, USE_MIGRATION, P_LOOP, ZE_MU, ZE_SIG, extent_bound,
                         sample_regular_fibers, transverse_speed_bound)

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
    "hb_zoff",          # (S+1,) int64: breakpoints of slot g at hb_z[hb_zoff[g]:hb_zoff[g+1]]
    "hb_z",             # float64 breakpoints
    "hb_start",         # CSR over bins (bin (g, b) at hb_zoff[g] - g + b), into hb_items
    "hb_items",         # int32 hair index
    "hair_mode",        # (1,) int64: 0 hybrid, 1 realization-free
    "yarn_length",      # (Y,) float64 arc length of each yarn curve (yarn-space z range)
    "max_extent",       # (1,) float64 largest yarn_extent (candidate-yarn search radius)
    "fs_off",           # (Y+1,) int64: frame samples of yarn c at fs_off[c]:fs_off[c+1] (frame_samples.py)
    "fs_s",             # float64 arc length of each frame sample
    "fs_frame",         # (M, 12) float32 position, tangent, normal, binormal
    "seg_fs",           # int64 per spline segment (global index): its first frame sample
    "seg_fs_end",       # int64 per spline segment: its last frame sample (the next knot)
    "yarn_eps",         # (Y,) float64 bound of |Eq. 7 with sampled frames - Eq. 7| within the extent
    "type_pad",         # (T,) float64 slack (beyond the fibre radius) the azimuth bins' margin allows for
])


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
    loops = tp[USE_FLYAWAYS] and tp[P_LOOP] > 0 and tp[USE_MIGRATION]
    hi = np.maximum(hi_reg, tp[U_MAX]) if loops else hi_reg
    reach = np.where(lo > m, np.arcsin(np.minimum(1.0, m / np.maximum(lo, 1e-300))), np.pi)
    width = 2 * np.pi / nbins
    centers = (np.arange(nbins) + 0.5) * width
    starts = [0]
    items = []
    for k in range(P):
        # circular distance from theta_j to the wedge of bin b
        d = np.abs((th[k][None, :] - centers[:, None] + np.pi) % (2 * np.pi) - np.pi) - 0.5 * width
        inc = d <= reach[k][None, :] + 1e-12
        for b in range(nbins):
            js = np.nonzero(inc[b])[0]
            items.append(js.astype(np.int32))
            starts.append(starts[-1] + len(js))
    return (R.ravel(), th.ravel(), th0.ravel(), (lo - m).ravel(), (hi + m).ravel(),
            np.asarray(starts[1:], np.int64), np.concatenate(items) if items else np.zeros(0, np.int32))


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
    counts = np.zeros(nb + 1, np.int64)
    np.add.at(counts, b0, 1)
    np.add.at(counts, b1 + 1, -1)
    per_bin = np.cumsum(counts)[:nb]
    start = np.zeros(nb + 1, np.int64)
    start[1:] = np.cumsum(per_bin)
    return z1, ze, bp, start, _hair_items(b0, b1, start)


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
def hair_node_seed_nb(yarn_seed, k):
    return hash_u64(yarn_seed, k, 31)


def table_bytes(tab: Tables) -> dict:
    """Bytes of the tables by part: regular (fibre trajectories and bins), hair, loop (none)."""
    reg = sum(getattr(tab, n).nbytes for n in ("fib_R", "fib_th", "fib_th0", "fib_rlo", "fib_rhi",
                                                "bin_start", "bin_items", "tparams", "type_K", "type_mz",
                                                "type_fib_off", "type_nbins", "type_bin_off"))
    hair = sum(getattr(tab, n).nbytes for n in ("hair_count", "hair_off", "hair_z1", "hair_ze", "hb_zoff",
                                                 "hb_z", "hb_start", "hb_items"))
    yarn = sum(getattr(tab, n).nbytes for n in ("yarn_type", "yarn_seed", "yarn_extent", "yarn_gmin",
                                                 "yarn_albedo", "yarn_ply_off", "yarn_length", "max_extent",
                                                 "yarn_eps", "hair_mode"))
    frames = sum(getattr(tab, n).nbytes for n in ("fs_off", "fs_s", "fs_frame", "seg_fs", "seg_fs_end"))
    return {"regular": int(reg), "hair": int(hair), "loop": 0, "per_yarn": int(yarn), "frames": int(frames)}


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


def build_tables(cv, tparams, yarn_type, yarn_albedo, seed, nbins=32, hair_mode=0, fold_cap=0.5,
                 frame_samples=False, frame_tolerance=0.1):
    """Tables for all yarns. tparams (T, NPARAM) packed types (U_MAX, HAIR_RMAX filled in),
    yarn_type (Y,), yarn_albedo (Y, 3); frame_samples: also store sampled yarn frames
    (frame_samples.py; faster lookups, more memory) with the error bound frame_tolerance aimed at,
    in fibre radii (smaller: more samples, fewer exact fall-backs in the lookups).
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
    gmax = 1.0 + kr
    type_K = np.ones(T)
    type_mz = np.zeros(T)
    for t in range(T):
        sel = yarn_type == t
        if not sel.any():
            type_K[t] = 2.0
            type_mz[t] = tparams[t, FIBER_RADIUS]
            continue
        v = transverse_speed_bound(tparams[t])
        K = (1.0 + np.sqrt(gmax[sel] ** 2 + v * v) / gmin[sel]).max() * 1.05
        type_K[t] = K
        type_mz[t] = 1.1 * tparams[t, FIBER_RADIUS] / gmin[sel].min()
    # frame samples: step from the curvature so the sampling error stays near frame_tolerance fibre
    # radii; the error is second order in the step, so steps are rescaled to the target (<= 3 rounds)
    rf_y = np.array([tparams[yarn_type[c], FIBER_RADIUS] for c in range(Y)])
    target = frame_tolerance * rf_y
    k2 = kap * kap * ext + kap
    rmin = 1e-3 * np.asarray(cv.radius[:Y], np.float64)
    deltas = np.maximum(np.minimum(0.5 * np.asarray(cv.radius[:Y], np.float64),
                                   np.sqrt(8.0 * target / np.maximum(k2, 1e-12))), rmin)
    if frame_samples:
        for attempt in range(3):
            fs_off, fs_s, fs_fr, seg_fs, err = sample_all(cv, deltas, ext)
            scale = np.array([float(np.abs(fs_fr[fs_off[c]:fs_off[c + 1], :3]).max()) for c in range(Y)]) + ext
            yeps = 2.0 * err + 1.25 * kap * deltas * deltas / 8.0 + 8.0 * np.finfo(np.float32).eps * scale
            over = (yeps > target) & (deltas > rmin)
            if not over.any():
                break
            deltas = np.where(over, np.maximum(0.9 * deltas * np.sqrt(target / np.maximum(yeps, 1e-300)), rmin), deltas)
    else:
        fs_off, fs_s, fs_fr = np.zeros(Y + 1, np.int64), np.zeros(0), np.zeros((0, 12), np.float32)
        seg_fs, yeps = np.zeros(0, np.int64), np.zeros(Y)
    seg_fs_end = np.zeros_like(seg_fs)
    for c in range(Y if frame_samples else 0):
        lo, hi = cv.offsets[c], cv.offsets[c + 1]
        first = seg_fs[lo:hi]
        used = first >= 0
        nxt = np.concatenate([first[1:], [-1]])
        end = np.where(nxt >= 0, nxt, fs_off[c + 1] - 1)
        seg_fs[lo:hi] = np.where(used, first, fs_off[c + 1] - 1)
        seg_fs_end[lo:hi] = np.where(used, end, fs_off[c + 1] - 1)
    fib = []
    type_pad = np.zeros(T)
    for t in range(T):
        sel = yarn_type == t
        type_pad[t] = (3.0 * float(yeps[sel].max()) if sel.any() else 0.0) + 0.01 * tparams[t, FIBER_RADIUS]
        fib.append(regular_tables(tparams[t], type_key(seed, t), type_K[t], nbins, type_pad[t]))
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
    tab = Tables(
        np.ascontiguousarray(tparams, np.float64), type_K, type_mz, type_fib_off,
        cat([f[0] for f in fib], np.float64), cat([f[1] for f in fib], np.float64), cat([f[2] for f in fib], np.float64),
        cat([f[3] for f in fib], np.float64), cat([f[4] for f in fib], np.float64),
        np.full(T, nbins, np.int64), type_bin_off, cat(starts, np.int64), cat(items, np.int32),
        np.ascontiguousarray(yarn_type, np.int32), ykeys, ext, gmin, np.ascontiguousarray(yarn_albedo, np.float64),
        ply_off, hcount, hoff, cat(z1s, np.float64), cat(zes, np.float64), hzoff, cat(bps, np.float64),
        cat(hstarts, np.int64), cat(hitems, np.int32), np.array([hair_mode], np.int64),
        np.ascontiguousarray(cv.curve_length[:Y], np.float64), np.array([ext.max() if Y else 0.0]),
        fs_off, fs_s, fs_fr, seg_fs, seg_fs_end, yeps, type_pad)
    info = {"curvature_max": kap, "g_raw": g_raw, "extent": ext, "folded": kap * ext >= fold_cap, "eps": yeps}
    return tab, info
