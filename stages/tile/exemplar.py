"""Exemplars: one periodic repeat of a woven fabric realized to explicit fibres (seed 001 §2).

An exemplar is the fabric of one weave repeat of ``E`` ends x ``P`` picks (the interlacement
``over`` of ``stages.ingest.weave``) with warp spacing ``sx`` and weft spacing ``sy``. Exemplar
space: x in [0, W = E sx), y in [0, H = P sy), z up; warp end e lies at x = (e + 1/2) sx, weft pick p
at y = (p + 1/2) sy. The exemplar is periodic in x and y: a copy shifted by (W, 0) or (0, H) meets it
without a seam, fibre for fibre.

Periodic yarn centrelines
    ``periodic_centreline``: the ingest stage's woven centrelines (``stages.core.curves.woven``, half-cosine
    crimp) of the repeat tiled 3 x 3, shifted so that the middle repeat covers the exemplar box; the
    middle repeat's yarns are then exactly periodic along their length (c(s + L) = c(s) + (0, H, 0) for a
    warp end, + (W, 0, 0) for a weft pick, L the yarn's arc length over one repeat). Frame: n is the
    component of +z normal to the tangent, b = t x n; a woven centreline is planar, so this frame is
    the rotation-minimising one and it is periodic too.

Periodic fibres
    The procedural yarn model of seed 000 §3.2 (``stages.core.yarn.model.regular_xy``, the
    procedural engineer's kernel) gives each regular fibre's yarn-space offset (x, y) at arc length z.
    To make the fibres periodic over one repeat, the pitches are snapped (``snap_periodic``): the ply
    pitch and the fibre pitch become L / round(L / pitch) and the migration frequency s becomes
    round(s n) / n (n fibre turns per repeat), so every fibre returns to its start after L. Flyaway
    loops and hairs (random per migration cycle / per hair, not periodic) are not realized in an
    exemplar. A fibre is sampled at z_m = m L / n_seg, m = 0..n_seg, and placed by seed 000 Eq. 7:
    p = c(z) + x n(z) + y b(z). Its last point is its first point shifted by one period.
    ``periodic_yarn_fibres`` does this for one yarn; the knitted exemplars (``stages.tile.knit_exemplar``)
    use it, and ``wrap_pieces`` and ``segment_blocks`` below, for their periodic courses.

Blocks
    The exemplar is cut into blocks of ``bcx`` x ``bcy`` weave cells (block size bw = bcx sx, bh =
    bcy sy); E and P must be multiples. Fibres are not cut: ``wrap_pieces`` makes the copies of the
    fibres shifted by (a W, b H), a, b in {-1, 0, 1}, and keeps the runs of segments whose capsules
    reach into the exemplar box, so a ray piece clipped to any block of the box meets every capsule
    that touches it, whichever period it came from (the periodic wrap-around of blocks). Each wrapped
    segment remembers its source segment in the exemplar (``piece_seg0``): hits report exemplar
    segment ids, which precomputed data is indexed by.

Pure numpy / numba; invalid parameters raise ValueError (the pipeline turns it into a LoomError).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from stages.core.curves.woven import woven_curves
from stages.core.rng import hash_u64
from stages.core.yarn.model import (
    ALPHA,
    FIBER_NUM,
    FIBER_RADIUS,
    PLY_NUM,
    S_MIG,
    USE_FLYAWAYS,
    YARN_ALPHA,
    regular_xy,
    sample_regular_fibers,
)

DENSE = 32  # centreline samples per weave cell


def periodic_centreline(over, sx, sy, r_warp, r_weft, crimp, warp: bool, index: int):
    """Dense samples of one yarn of the middle repeat: (s (M,), pos (M, 3), L) with s = 0 at the
    exemplar's lower edge (y = 0 for warp, x = 0 for weft) and L the arc length of one repeat."""
    E, P = over.shape
    W, H = E * sx, P * sy
    warp_pts, weft_pts = woven_curves(np.tile(over, (3, 3)), sx, sy, r_warp, r_weft, crimp, DENSE)
    shift = np.array([0.5 * W, 0.5 * H, 0.0])
    pts = (warp_pts[E + index] if warp else weft_pts[P + index]) + shift
    along = 1 if warp else 0
    q = pts[:, along]
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    period = H if warp else W
    s0 = np.interp(0.0, q, s)
    L = np.interp(period, q, s) - s0
    return s - s0, pts, float(L)


def centreline_frames(s, pts, z):
    """Position, tangent, normal, binormal at arc lengths z (linear in the dense samples)."""
    pos = np.stack([np.interp(z, s, pts[:, k]) for k in range(3)], axis=1)
    d = np.gradient(pts, s, axis=0)
    t = np.stack([np.interp(z, s, d[:, k]) for k in range(3)], axis=1)
    t /= np.linalg.norm(t, axis=1)[:, None]
    up = np.array([0.0, 0.0, 1.0])
    n = up[None, :] - t * (t @ up)[:, None]
    n /= np.linalg.norm(n, axis=1)[:, None]
    b = np.cross(t, n)
    return pos, t, n, b


def snap_periodic(tp, L):
    """A copy of the packed yarn parameters whose fibres are periodic with period L (see module doc);
    loops and hairs switched off."""
    tp = tp.copy()
    n_f = max(1, int(round(L / tp[ALPHA])))
    tp[ALPHA] = L / n_f
    n_y = max(1, int(round(L / tp[YARN_ALPHA])))
    tp[YARN_ALPHA] = L / n_y
    tp[S_MIG] = max(1, int(round(tp[S_MIG] * n_f))) / n_f
    tp[USE_FLYAWAYS] = 0.0
    return tp


@njit(cache=True)
def periodic_fiber_points(tp, type_key, yarn_seed, z, pos, nrm, bnm, out, out_r):
    """Fill out[(k N + j) M + m] with fibre (k, j) at z[m] (seed 000 Eq. 7 with regular_xy)."""
    R, th, th0 = sample_regular_fibers(tp, type_key)
    P = int(tp[PLY_NUM])
    N = int(tp[FIBER_NUM])
    M = z.shape[0]
    for k in range(P):
        for j in range(N):
            base = (k * N + j) * M
            for m in range(M):
                x, y, kind = regular_xy(tp, yarn_seed, k, j, R[k, j], th[k, j], th0[k, j], z[m])
                for c in range(3):
                    out[base + m, c] = pos[m, c] + x * nrm[m, c] + y * bnm[m, c]
                out_r[base + m] = tp[FIBER_RADIUS]


class YarnFibres(NamedTuple):
    points: np.ndarray   # (n_fibres n_points, 3) the fibre polylines, one after the other
    radius: np.ndarray   # (n_fibres n_points,) fibre radius at each point
    n_fibres: int        # plies x fibres per ply
    n_points: int        # points per fibre: n_seg + 1, the last = the first + one period


def periodic_yarn_fibres(s, cl, L, tp, type_key, yarn_key, segment_length) -> YarnFibres:
    """The fibres of one periodic yarn: dense centreline samples ``cl`` at arc lengths ``s`` (s = 0 at
    the period's start), period ``L`` along it; pitches snapped (``snap_periodic``), n_seg = ceil(L /
    segment_length) (at least 4) equal steps z_m = m L / n_seg, seed 000 Eq. 7 in the +z frame."""
    tp = snap_periodic(tp, L)
    nseg = max(4, int(math.ceil(L / segment_length)))
    z = np.arange(nseg + 1) * (L / nseg)
    pos, t, n, b = centreline_frames(s, cl, z)
    nf = int(tp[PLY_NUM]) * int(tp[FIBER_NUM])
    out = np.empty((nf * (nseg + 1), 3))
    out_r = np.empty(nf * (nseg + 1))
    periodic_fiber_points(tp, type_key, yarn_key, z, np.ascontiguousarray(pos), np.ascontiguousarray(n),
                          np.ascontiguousarray(b), out, out_r)
    return YarnFibres(out, out_r, nf, nseg + 1)


def realize_exemplar(over, sx, sy, tp_warp, tp_weft, r_warp, r_weft, crimp, seed, segment_length):
    """Explicit periodic fibres of one repeat.

    Returns dict: points (M, 3), radius (M,), offsets (F+1,), fiber_yarn (F,) (yarn index: ends
    0..E-1, then picks E..E+P-1), yarn_group (E+P,) 0 warp / 1 weft, period (W, H)."""
    over = np.asarray(over, dtype=bool)
    E, P = over.shape
    pts, rads, counts, fy = [], [], [], []
    for yarn in range(E + P):
        warp = yarn < E
        idx = yarn if warp else yarn - E
        s, cl, L = periodic_centreline(over, sx, sy, r_warp, r_weft, crimp, warp, idx)
        tkey = int(hash_u64(seed, 1 if warp else 2, 7) >> np.uint64(1))
        ykey = int(hash_u64(seed, yarn, 11) >> np.uint64(1))
        yf = periodic_yarn_fibres(s, cl, L, tp_warp if warp else tp_weft, tkey, ykey, segment_length)
        pts.append(yf.points)
        rads.append(yf.radius)
        counts += [yf.n_points] * yf.n_fibres
        fy += [yarn] * yf.n_fibres
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return {"points": np.concatenate(pts), "radius": np.concatenate(rads), "offsets": offsets,
            "fiber_yarn": np.asarray(fy, np.int32),
            "yarn_group": np.array([0] * E + [1] * P, np.int8), "period": (E * sx, P * sy)}


def check_periodic_draft(over_big, E, P):
    """True when the interlacement ``over_big`` (at least 2E x 2P) repeats every E ends and P picks."""
    A, B = over_big.shape
    if A % E or B % P:
        return False
    return bool(np.array_equal(over_big, np.tile(over_big[:E, :P], (A // E, B // P))))


@njit(cache=True)
def _wrap_count(points, radius, offsets, W, H, pad, shift_x, shift_y, keep):
    """Mark segments of the shifted copy whose capsule box meets [0, W] x [0, H] (grown by pad)."""
    n = 0
    F = offsets.shape[0] - 1
    for f in range(F):
        for i in range(offsets[f], offsets[f + 1] - 1):
            r = max(radius[i], radius[i + 1]) + pad
            x0 = min(points[i, 0], points[i + 1, 0]) + shift_x - r
            x1 = max(points[i, 0], points[i + 1, 0]) + shift_x + r
            y0 = min(points[i, 1], points[i + 1, 1]) + shift_y - r
            y1 = max(points[i, 1], points[i + 1, 1]) + shift_y + r
            k = x1 >= 0.0 and x0 <= W and y1 >= 0.0 and y0 <= H
            keep[i] = k
            if k:
                n += 1
    return n


def wrap_pieces(ex, pad=0.0):
    """Polyline pieces of the 3 x 3 shifted copies that touch the exemplar box (see module doc).

    Returns dict: points, radius, offsets (pieces CSR), piece_fiber (exemplar fibre id),
    piece_seg0 (exemplar segment id of the piece's first segment; segments of fibre f are numbered
    consecutively over fibres, fibre f's first segment is offsets[f] - f)."""
    W, H = ex["period"]
    P, R, O = ex["points"], ex["radius"], ex["offsets"]
    out_p, out_r, counts, pf, ps = [], [], [], [], []
    keep = np.zeros(len(P), np.bool_)
    for a in (-1, 0, 1):
        for b in (-1, 0, 1):
            keep[:] = False
            if _wrap_count(P, R, O, W, H, pad, a * W, b * H, keep) == 0:
                continue
            shift = np.array([a * W, b * H, 0.0])
            for f in range(len(O) - 1):
                lo, hi = int(O[f]), int(O[f + 1])
                k = keep[lo:hi - 1]
                if not k.any():
                    continue
                # runs of kept segments
                d = np.diff(np.concatenate([[0], k.astype(np.int8), [0]]))
                starts = np.flatnonzero(d == 1)
                ends = np.flatnonzero(d == -1)
                for s0, s1 in zip(starts, ends):  # segments s0..s1-1 -> points s0..s1
                    out_p.append(P[lo + s0: lo + s1 + 1] + shift)
                    out_r.append(R[lo + s0: lo + s1 + 1])
                    counts.append(s1 - s0 + 1)
                    pf.append(f)
                    ps.append(lo - f + s0)
    return {"points": np.concatenate(out_p), "radius": np.concatenate(out_r),
            "offsets": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            "piece_fiber": np.asarray(pf, np.int32), "piece_seg0": np.asarray(ps, np.int64)}


def segment_blocks(ex, bw, bh):
    """Block id (bx + nbx by) of every exemplar segment's midpoint, wrapped into the exemplar."""
    W, H = ex["period"]
    nbx = int(round(W / bw))
    P, O = ex["points"], ex["offsets"]
    ids = []
    for f in range(len(O) - 1):
        a = P[O[f]:O[f + 1] - 1]
        b = P[O[f] + 1:O[f + 1]]
        m = 0.5 * (a + b)
        bx = np.floor(np.mod(m[:, 0], W) / bw).astype(np.int64)
        by = np.floor(np.mod(m[:, 1], H) / bh).astype(np.int64)
        ids.append(bx + nbx * by)
    return np.concatenate(ids).astype(np.int32)
