"""The realized reference: point queries against realized fibre polylines (chains of capsules).

A uniform grid lists, per cell, the segments whose boxes (grown by the fibre radius plus a band
``pad``) touch the cell. ``query_realized`` answers the same question as lookup.lookup_point by
brute force over the segments of p's cell: p is inside a fibre when its distance to one of the
fibre's segments is below the segment's radius; among covering fibres the first in the order
(yarn, ply, regular/loop before hair, fibre index) answers, and for a regular fibre the kind and
direction are those of its nearest covering segment. It also reports the smallest |distance -
radius| over all segments within the band (how close p is to any fibre surface) and whether the
winning fibre's nearest regular and loop pieces are within ``pad`` of each other (a kind tie).
Used by the exactness test (reference) and the lookup benchmark (realized baseline).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

from stages.core.sampling import NO_HIT
from stages.core.yarn.lookup import point_answer_arrays, store_point_answer

ReferenceLookup = namedtuple("ReferenceLookup", ["inside", "yarn", "kind", "dir_x", "dir_y", "dir_z", "surface_gap",
                                                 "kind_tie"])
ReferenceLookup.__doc__ = """query_one's answer at p (module doc); surface_gap NO_HIT outside the grid."""
ReferenceLookups = namedtuple("ReferenceLookups", ["inside", "yarn", "kind", "direction", "surface_gap", "kind_tie"])
ReferenceLookups.__doc__ = """query_realized's answers: inside, yarn (int32), kind (int8), direction (N, 3),
surface_gap, kind_tie."""


def build_segment_grid(points, offsets, radius, pad, target_per_cell=8.0):
    """(lo, cell, dims, cell_start, items) over the segments of the polylines (numpy)."""
    P = np.asarray(points, np.float64)
    seg_ok = np.ones(len(P) - 1 if len(P) else 0, bool)
    seg_ok[offsets[1:-1] - 1] = False
    sid = np.nonzero(seg_ok)[0]
    a, b = P[sid], P[sid + 1]
    g = float(np.max(radius)) + pad
    blo = np.minimum(a, b) - g
    bhi = np.maximum(a, b) + g
    lo = blo.min(axis=0)
    hi = bhi.max(axis=0)
    ext = np.maximum(hi - lo, 1e-9)
    seglen = np.linalg.norm(b - a, axis=1)
    cell = max(float(np.median(seglen) + 2 * g) * 2.0,
               float((np.prod(ext) * target_per_cell / max(len(sid), 1)) ** (1 / 3)))
    dims = np.maximum(1, np.ceil(ext / cell).astype(np.int64))
    g0 = np.clip(((blo - lo) / cell).astype(np.int64), 0, dims - 1)
    g1 = np.clip(((bhi - lo) / cell).astype(np.int64), 0, dims - 1)
    return lo, cell, dims, *_fill_grid(sid.astype(np.int64), g0, g1, dims)


@njit(cache=True)
def _fill_grid(sid, g0, g1, dims):
    ncell = dims[0] * dims[1] * dims[2]
    counts = np.zeros(ncell + 1, np.int64)
    for q in range(sid.shape[0]):
        for i in range(g0[q, 0], g1[q, 0] + 1):
            for j in range(g0[q, 1], g1[q, 1] + 1):
                for k in range(g0[q, 2], g1[q, 2] + 1):
                    counts[(i * dims[1] + j) * dims[2] + k + 1] += 1
    start = np.cumsum(counts)
    items = np.empty(start[-1], np.int64)
    cur = start[:-1].copy()
    for q in range(sid.shape[0]):
        for i in range(g0[q, 0], g1[q, 0] + 1):
            for j in range(g0[q, 1], g1[q, 1] + 1):
                for k in range(g0[q, 2], g1[q, 2] + 1):
                    c = (i * dims[1] + j) * dims[2] + k
                    items[cur[c]] = sid[q]
                    cur[c] += 1
    return start, items


@njit(cache=True)
def _seg_dist(p, a, b):
    ab = b - a
    L2 = np.dot(ab, ab)
    t = 0.0 if L2 <= 0.0 else min(1.0, max(0.0, np.dot(p - a, ab) / L2))
    d = p - (a + t * ab)
    return math.sqrt(np.dot(d, d))


@njit(cache=True)
def query_one(points, radius, seg_fiber, fiber_yarn, fiber_ply, fiber_kind, fiber_index,
              lo, cell, dims, start, items, p, pad):
    """``ReferenceLookup`` (inside, yarn, kind, dir_x, dir_y, dir_z, surface_gap, kind_tie) for one point.
    14 parameters: the realized fibres' arrays and the uniform grid of a brute-force reference built in Python
    (``RealizedReference``'s fields), and the point."""
    ijk = np.empty(3, np.int64)
    for d in range(3):
        g = int(math.floor((p[d] - lo[d]) / cell))
        if g < 0 or g >= dims[d]:
            return ReferenceLookup(False, -1, 0, 0.0, 0.0, 0.0, NO_HIT, False)
        ijk[d] = g
    c = (ijk[0] * dims[1] + ijk[1]) * dims[2] + ijk[2]
    gap = NO_HIT
    best_key0 = 1 << 62
    best_key1 = 1 << 62
    bk = -1
    bd = NO_HIT
    bseg = -1
    d_reg = NO_HIT
    d_loop = NO_HIT
    for q in range(start[c], start[c + 1]):
        s = items[q]
        f = seg_fiber[s]
        a = points[s].astype(np.float64)
        b = points[s + 1].astype(np.float64)
        dist = _seg_dist(p, a, b)
        r = radius[s]
        gap = min(gap, abs(dist - r))
        if dist >= r:
            continue
        cls = 1 if fiber_kind[f] == 3 else 0
        k0 = (np.int64(fiber_yarn[f]) << 20) + (np.int64(fiber_ply[f]) << 1) + cls
        k1 = np.int64(fiber_index[f])
        if k0 < best_key0 or (k0 == best_key0 and k1 < best_key1):
            best_key0 = k0
            best_key1 = k1
            bd = NO_HIT
            d_reg = NO_HIT
            d_loop = NO_HIT
        if k0 == best_key0 and k1 == best_key1:
            if fiber_kind[f] == 1:
                d_reg = min(d_reg, dist)
            elif fiber_kind[f] == 2:
                d_loop = min(d_loop, dist)
            if dist < bd:
                bd = dist
                bseg = s
                bk = fiber_kind[f]
    if bseg < 0:
        return ReferenceLookup(False, -1, 0, 0.0, 0.0, 0.0, gap, False)
    a = points[bseg].astype(np.float64)
    b = points[bseg + 1].astype(np.float64)
    t = b - a
    t = t / math.sqrt(np.dot(t, t))
    tie = d_reg < 1e299 and d_loop < 1e299 and abs(d_reg - d_loop) < pad
    return ReferenceLookup(True, np.int64(fiber_yarn[seg_fiber[bseg]]), np.int64(bk), t[0], t[1], t[2], gap, tie)


@njit(cache=True, parallel=True)
def query_realized(points, radius, seg_fiber, fiber_yarn, fiber_ply, fiber_kind, fiber_index,
                   lo, cell, dims, start, items, pts, pad):
    """``query_one`` for every point of ``pts`` (N, 3), in parallel. 14 parameters: ``query_one``'s, for an
    array of points."""
    N = pts.shape[0]
    inside, yarn, kind, direction = point_answer_arrays(N)
    gap = np.zeros(N)
    tie = np.zeros(N, np.bool_)
    for i in prange(N):
        p = pts[i].astype(np.float64)
        res = query_one(points, radius, seg_fiber, fiber_yarn, fiber_ply, fiber_kind, fiber_index,
                        lo, cell, dims, start, items, p, pad)
        store_point_answer(res, i, inside, yarn, kind, direction)
        gap[i] = res.surface_gap
        tie[i] = res.kind_tie
    return ReferenceLookups(inside, yarn, kind, direction, gap, tie)


def segment_fiber(offsets):
    """Fibre of every vertex-start segment (the last vertex of a polyline maps to its own fibre)."""
    n = int(offsets[-1])
    out = np.repeat(np.arange(len(offsets) - 1, dtype=np.int64), np.diff(offsets))
    return out[:n]
