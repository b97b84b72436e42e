"""Lookup acceleration derived whenever procedural tables are loaded (never stored).

``derive_lookup_accel(cv, tab)`` fills ``Tables``' derived fields (``stages.core.yarn.tables``):
frame samples, coarse knots and the chord grid (``frame_samples``), the scan bounds
(``scan_bounds``: per-ply and per-loop-z-bin unit-disc radius ranges, per-fibre speed bounds), the
per-hair z/radius boxes, the fringe occupancy (``fringe_occupancy``): per yarn, bits over (z-bin,
radial shell, azimuth sector) of yarn space marking where a loop or a stored hair can come close
enough to cover a point, so that lookups far from every loop and hair skip those tests, and lookups
beyond the core skip the yarn) and the chord gates (``chord_gates``). Everything here is a
deterministic function of the curves and the stored tables. Paged (``derive_lookup_accel(paged=True)``),
every field but the frame samples themselves is derived, chunk by chunk of yarns, to the same numbers;
``frame_pool`` makes a yarn's samples when a lookup asks for them.
"""
import math

import numpy as np
from numba import njit

from stages.core.geometry.bvh import round_down32, round_up32
from stages.core.threads import chunk_kernel, for_chunks

from .fibre_tests import stored_hair
from .frame_samples import FRAME_COLS, chord_grid, coarse_knots, sample_all, sample_counts
from .model import (
    E_LONG,
    E_SHORT,
    FIBER_NUM,
    FIBER_RADIUS,
    PLY_NUM,
    PLY_RADIUS,
    RHO_MAX,
    RHO_MIN,
    USE_MIGRATION,
    hair_point,
    hair_speed_bound,
    regular_xy,
    transverse_speed,
    transverse_speed_bound,
)
from .tables import (
    FO_SECTORS,
    FO_SHELLS,
    FO_WORDS,
    FO_ZBIN_EXTENTS,
    FRAME_TOLERANCE,
    Tables,
    fringe_reach,
    fringe_window,
    loop_fibre,
)


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
    lz_rr = _loop_bin_ranges(tab.yarn_ply_off, tab.yarn_type, tab.type_fib_off, N, tab.lz_off, tab.lz_start,
                             tab.lz_items, tab.lp_off, tab.lp_fib, tab.lp_U, tab.fib_rlo)
    return ply_rr, fib_v, lz_rr


@njit(cache=True)
def _loop_bin_ranges(yarn_ply_off, yarn_type, type_fib_off, N, lz_off, lz_start, lz_items, lp_off, lp_fib, lp_U,
                     fib_rlo):
    """lz_rr of scan_bounds: per loop z-bin, [smallest r_lo of its loops' fibres, largest U_loop]."""
    nz = max(len(lz_start) - 1, 0)
    lz_rr = np.empty((nz, 2))
    lz_rr[:, 0] = np.inf
    lz_rr[:, 1] = -np.inf
    c = 0
    for g in range(len(lp_off) - 1):
        while c + 1 < len(yarn_ply_off) - 1 and yarn_ply_off[c + 1] <= g:  # the yarn of ply g
            c += 1
        t = yarn_type[c]
        fo = type_fib_off[t] + (g - yarn_ply_off[c]) * N[t]
        for zb in range(lz_off[g], lz_off[g + 1]):
            for q in range(lz_start[zb], lz_start[zb + 1]):
                le = lp_off[g] + lz_items[q]
                lz_rr[zb, 0] = min(lz_rr[zb, 0], fib_rlo[fo + lp_fib[le]])
                lz_rr[zb, 1] = max(lz_rr[zb, 1], lp_U[le])
    return lz_rr


FRINGE_STEP_REACHES = 2.0   # fringe walk: loops and hairs sampled every this many fringe reaches of yarn-space arc


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


def fringe_occupancy(tab, fo_off, fo_geom):
    """Fringe occupancy bits of every yarn, one set for loops and one for hairs: cell (z-bin, shell,
    sector) of yarn c is set when a loop (its fibre's trajectory over the loop's cycle grown by the
    largest z window, fringe_window) or a stored hair (hybrid mode) comes within fringe_reach of
    the cell in yarn space. Each curve is sampled at steps of at most FRINGE_STEP_REACHES fringe reaches of
    yarn-space arc (its speed bound), and every sample marks the cells within fringe_reach plus half a step
    (2 reaches: half the walk of 1, a few more cells set, the lookups' answers the same: a set cell only
    costs a scan that finds nothing).
    A lookup point in no set loop cell needs no loop scan, one in no set hair cell no hair test;
    one in neither, farther than type_rcore from the axis, is covered by no fibre of the yarn.
    Yarns on threads (each writes only its own rows; ``stages.core.threads``)."""
    bits = np.zeros((fo_off[-1], 2 * FO_WORDS), np.uint64)
    for_chunks(_fringe_yarns, len(tab.yarn_type), tab, fo_off, fo_geom, bits)
    return bits


@chunk_kernel
def _fringe_yarns(tab, fo_off, fo_geom, bits, c0, c1):
    """``fringe_occupancy`` of yarns c0 .. c1 - 1."""
    for c in range(c0, c1):
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
                n = max(1, int(math.ceil((z1 - z0) * v / (FRINGE_STEP_REACHES * r))))
                dz = (z1 - z0) / n
                for q in range(n + 1):
                    z = min(z0 + q * dz, z1)
                    x, y, kd = regular_xy(tp, yseed, k, j, tab.fib_R[fi], tab.fib_th[fi], tab.fib_th0[fi], z)
                    _mark_ball(bits, base, nb, h, rw, x, y, z, r + 0.5 * dz * v, 0)
            if tab.hair_mode[0] != 0:
                continue
            for hh in range(tab.hair_off[g], tab.hair_off[g] + tab.hair_count[g]):
                hs = stored_hair(tab, hh)
                speed = hair_speed_bound(tp, hs.r0, hs.r1, hs.pe, hs.ze)
                n = max(1, int(math.ceil(speed / (FRINGE_STEP_REACHES * r))))
                for q in range(n + 1):
                    x, y, z = hair_point(tp, k, hs.r0, hs.r1, hs.th1, hs.pe, hs.z1, hs.ze, q / n)
                    _mark_ball(bits, base, nb, h, rw, x, y, z, r + 0.5 * speed / n, FO_WORDS)


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
    return _gates(tab, _top_shells(tab.fo_bits))


@njit(cache=True)
def _top_shells(fo_bits):
    """The highest fringe shell with a bit set (loops or hairs, any sector) per z-bin row of fo_bits,
    -1 where none: bit (set * FO_SHELLS + shell) * FO_SECTORS + sector of a row, little-endian words
    (tables.fringe_bits), read in place (unpacked, the bits of a 1,000-yarn cloth took 1.3 GB)."""
    top = np.full(fo_bits.shape[0], -1, np.int64)
    for i in range(fo_bits.shape[0]):
        for sh in range(FO_SHELLS - 1, -1, -1):
            hit = False
            for st in range(2):
                for sec in range(FO_SECTORS):
                    k = (st * FO_SHELLS + sh) * FO_SECTORS + sec
                    if (fo_bits[i, k >> 6] >> np.uint64(k & 63)) & np.uint64(1):
                        hit = True
            if hit:
                top[i] = sh
                break
    return top


@njit(cache=True)
def _gates(tab, top):
    """chord_gates' loop over yarns and chords, top: the highest set fringe shell per z-bin (-1: none)."""
    gate = np.full(len(tab.kn_idx), np.inf)
    for c in range(len(tab.yarn_type)):
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        if tab.hair_mode[0] != 0 and tab.hair_count[tab.yarn_ply_off[c]:tab.yarn_ply_off[c + 1]].sum() > 0:
            continue
        es, el = tp[E_SHORT], tp[E_LONG]
        rcore = (tab.type_rcore[t]
                 + tab.type_K[t] * (tp[FIBER_RADIUS] + 2.0 * tab.yarn_eps[c]) * max(es, el) / min(es, el))
        k0, k1 = tab.kn_off[c], tab.kn_off[c + 1]
        base, nb = tab.fo_off[c], tab.fo_off[c + 1] - tab.fo_off[c]
        h = tab.fo_geom[c, 0]
        rw = tab.fo_geom[c, 1]
        for q in range(k0, k1 - 1):
            sa = tab.kn_s[max(q - 1, k0)]
            sb = tab.kn_s[min(q + 2, k1 - 1)]
            b0 = min(max(int(math.floor(sa / h)), 0), nb - 1)
            b1 = min(max(int(math.floor(sb / h)), 0), nb - 1)
            sh = top[base + b0:base + b1 + 1].max()
            rf_ = np.inf if sh == FO_SHELLS - 1 else (sh + 1) * rw
            gate[q] = max(rcore, rf_)
    return gate


@njit(cache=True)
def hair_boxes(z1, ze, r0, r1):
    """(H, 4) float32 per hair: its z range and radius range (zlo, zhi, Rlo, Rhi), rounded outward to
    float32 (the lookups' quick reject stays conservative at half the bytes)."""
    box = np.empty((z1.shape[0], 4), np.float32)
    for h in range(z1.shape[0]):
        z2 = z1[h] + ze[h]
        box[h, 0] = round_down32(min(z1[h], z2))
        box[h, 1] = round_up32(max(z1[h], z2))
        box[h, 2] = round_down32(min(r0[h], r1[h]))
        box[h, 3] = round_up32(max(r0[h], r1[h]))
    return box


def frame_steps(kappa, extent, radius, fiber_radius, tolerance: float = FRAME_TOLERANCE):
    """First guess of each yarn's frame-sample step (``derive_lookup_accel`` rescales it on the measured
    error): the Hermite error h^4 / 384 |f^(4)| of the position and of rho x the frame, with
    |f^(4)| ~ kappa^3 + rho kappa^4, at ``tolerance`` fibre radii; at most half the yarn radius."""
    k4 = kappa ** 4 * extent + kappa ** 3
    step = (384.0 * tolerance * fiber_radius / np.maximum(k4, 1e-12)) ** 0.25
    return np.maximum(np.minimum(0.5 * radius, step), 1e-3 * radius)


CHORD_GRID_MAX_CELLS = 1 << 23  # derive_lookup_accel's chord grid grows its cell to stay under this
PAGE_CHUNK_SAMPLES = 1 << 20    # paged frame samples are made in chunks of yarns of about this many (~140 MB)


def chord_grid_cell(box, max_extent: float, max_cells: int = CHORD_GRID_MAX_CELLS) -> float:
    """The chord grid's cell over a box of size ``box`` (3,): half the largest yarn extent, grown by
    1.25 until the grid has at most max_cells cells."""
    cell = 0.5 * float(max_extent)
    while np.prod(np.ceil(np.asarray(box) / cell)) > max_cells:
        cell *= 1.25
    return cell


def derive_lookup_accel(cv, tab: Tables, tolerance: float = FRAME_TOLERANCE,
                        max_cells: int = CHORD_GRID_MAX_CELLS, paged: bool = False,
                        chunk_samples: int = PAGE_CHUNK_SAMPLES) -> Tables:
    """Tables with the derived fields filled (frame_samples.py): frame samples whose error bound
    eps_c stays near ``tolerance`` fibre radii (steps from the curvature bound, rescaled on the
    measured error, <= 3 rounds; the error is fourth order in the step), coarse knots about half
    an extent apart, and the chord grid (cells half the largest extent, grown to stay under
    max_cells). ``paged``: no frame samples kept (``fs_at`` -1: a render pages them in per yarn,
    ``frame_pool.FramePool``); they are made in chunks of yarns of about ``chunk_samples`` samples, once
    for the steps and once more for the coarse knots, so memory holds one chunk's, never every yarn's.
    Deterministic: depends on the curves and the stored tables only; paged or not, the same numbers."""
    Y = len(tab.yarn_type)
    if Y == 0:
        return tab
    ext = np.asarray(tab.yarn_extent, np.float64)
    kap = np.asarray(tab.yarn_kappa, np.float64)
    rf_y = tab.tparams[tab.yarn_type, FIBER_RADIUS]
    target = tolerance * rf_y
    radius = np.asarray(cv.radius[:Y], np.float64)
    deltas = frame_steps(kap, ext, radius, rf_y, tolerance)
    chunks = yarn_chunks(cv, deltas, chunk_samples) if paged else [np.arange(Y, dtype=np.int64)]
    step = np.empty(Y)      # the step each yarn's samples are made at
    final = np.empty(Y)     # the step after the last rescale (the coarse knots' stride takes their mean)
    yeps = np.empty(Y)
    count = np.empty(Y, np.int64)
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for ys in chunks:
        off, fs_s, fs_fr, ye, step[ys], final[ys] = _refined_samples(cv, ys, deltas, ext, target, 1e-3 * radius)
        yeps[ys] = ye
        count[ys] = np.diff(off)
        lo = np.minimum(lo, fs_fr[:, :3].min(0))
        hi = np.maximum(hi, fs_fr[:, :3].max(0))
        if paged:
            del off, fs_s, fs_fr
    mean_step = float(np.mean(final))
    stride = max(1, int(0.5 * float(ext.min()) / mean_step))
    if paged:
        kn = _paged_knots(cv, chunks, step, ext, stride, Y)
        fs_at = np.full(Y, -1, np.int64)
        fs_s = np.zeros(0)
        fs_fr = np.zeros((0, FRAME_COLS))
    else:
        kn = coarse_knots(fs_s, fs_fr, off, stride)
        fs_at = off[:-1].copy()
    kn_off, kn_idx, kn_s, kn_pos, kn_sag = kn
    lo, hi = lo - ext.max(), hi + ext.max()
    cell = chord_grid_cell(hi - lo, float(ext.max()), max_cells)
    glo, gcell, gdims, gstart, gyarn, ga, gb = chord_grid(kn_pos, kn_off, kn_sag, ext + yeps, cell)
    ply_rr, fib_v, lz_rr = scan_bounds(tab)
    hair_box = hair_boxes(tab.hair_z1, tab.hair_ze, tab.hair_r0, tab.hair_r1)
    tab = tab._replace(ply_rr=ply_rr, fib_v=fib_v, hair_box=hair_box, lz_rr=lz_rr,
                       fs_at=fs_at, fs_n=count, fs_step=step, fs_s=fs_s, fs_frame=fs_fr,
                       fs_want=np.zeros(Y, np.uint8), fs_miss=np.zeros(1, np.int64), yarn_eps=yeps, kn_off=kn_off,
                       kn_idx=kn_idx, kn_s=kn_s, kn_pos=kn_pos, kn_sag=kn_sag, fg_lo=glo, fg_cell=np.array([gcell]),
                       fg_dims=gdims, fg_start=gstart, fg_yarn=gyarn, fg_a=ga, fg_b=gb)
    rcore, fo_off, fo_geom, fo_bits = fringe_tables(tab)
    tab = tab._replace(type_rcore=rcore, fo_off=fo_off, fo_geom=fo_geom, fo_bits=fo_bits)
    return tab._replace(kn_rgate=chord_gates(tab))


def _refined_samples(cv, ys, deltas, ext, target, rmin):
    """Frame samples of yarns ``ys`` whose error bound eps_c is near ``target`` (derive_lookup_accel): steps
    rescaled on the measured error, <= 3 rounds, each yarn on its own (its numbers do not depend on the
    others listed with it). (offsets, s, frames, eps_c, the steps sampled, the steps after the last rescale)."""
    d = np.array(deltas[ys], np.float64)
    full = np.array(deltas, np.float64)
    for attempt in range(3):
        full[ys] = d
        off, fs_s, fs_fr, err = sample_all(cv, full, ext, ys)
        scale = np.array([float(np.abs(fs_fr[off[k]:off[k + 1], :3]).max()) for k in range(len(ys))]) + ext[ys]
        yeps = 2.0 * err + 1e-12 * scale
        sampled = d
        over = (yeps > target[ys]) & (d > rmin[ys])
        if not over.any():
            break
        d = np.where(over, np.maximum(0.9 * d * (target[ys] / np.maximum(yeps, 1e-300)) ** 0.25, rmin[ys]), d)
        if attempt < 2:  # resampled next: let this round's samples go first (they are GB on a large fabric)
            del off, fs_s, fs_fr, err
    return off, fs_s, fs_fr, yeps, sampled, d


def _paged_knots(cv, chunks, step, ext, stride, Y):
    """coarse_knots of every yarn, its frame samples made again chunk by chunk (derive_lookup_accel, paged)."""
    parts = [None] * len(chunks)
    for i, ys in enumerate(chunks):
        off, fs_s, fs_fr, _ = sample_all(cv, step, ext, ys, errors=False)
        parts[i] = coarse_knots(fs_s, fs_fr, off, stride)
        del off, fs_s, fs_fr
    order = np.concatenate(chunks)
    if not np.array_equal(order, np.arange(Y)):
        raise ValueError("paged frame samples: chunks must list the yarns in order")
    koff = np.zeros(Y + 1, np.int64)
    koff[1:] = np.cumsum(np.concatenate([np.diff(p[0]) for p in parts]))
    return (koff, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]),
            np.concatenate([p[3] for p in parts]), np.concatenate([p[4] for p in parts]))


def yarn_chunks(cv, deltas, chunk_samples: int) -> list:
    """Runs of consecutive yarns whose frame samples at ``deltas`` (their first-guess count, ``sample_counts``)
    stay near ``chunk_samples`` (a yarn with more is a run of its own)."""
    counts = sample_counts(cv.offsets, cv.closed, cv.seg_arclen, cv.frame_offsets, cv.frame_s, cv.curve_length,
                           np.ascontiguousarray(deltas, np.float64))
    out, start, acc = [], 0, 0
    for c, n in enumerate(counts):
        if acc and acc + n > chunk_samples:
            out.append(np.arange(start, c, dtype=np.int64))
            start, acc = c, 0
        acc += int(n)
    out.append(np.arange(start, len(counts), dtype=np.int64))
    return out
