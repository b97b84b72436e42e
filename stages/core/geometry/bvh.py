"""A SAH bounding-volume hierarchy over fibre segments (capsules), built and traversed in numba.

Segments
--------
Fibre f's polyline has points ``fiber_offsets[f] .. fiber_offsets[f+1]-1``; its n - 1 segments are
numbered consecutively, so the segments of one fibre are a contiguous range and neighbours along the
chain differ by one. ``segments_from_fibers`` gives per segment: ``seg_a`` (index of its first point;
the second is seg_a + 1), ``seg_r`` (capsule radius: mean of its two point radii) and ``seg_fiber``.

Build
-----
Top-down binned SAH (16 bins per axis, all three axes), leaves of at most ``LEAF_MAX`` segments unless
splitting is no cheaper; segments whose centroids coincide are split by count. Boxes are the
capsules' exact bounds padded by a relative 1e-9 so rounding never culls a true hit, rounded outward
to float32 (``segment_bounds32``: the wide nodes are float32 anyway, and the build's boxes and binary
nodes take half the memory). The queries are exact whatever the tree, so a different tree changes
no hit, only the order nodes are visited in.

Nodes (``FiberBVH``): the binary tree the builder makes -- ``node_lo``/``node_hi`` (N, 3) float32
bounds, ``node_left``/``node_right`` child indices (-1 at leaves), ``node_start``/``node_count`` the
leaf's range in ``prim`` (segment indices), node 0 the root; all empty when built with
``keep_binary=False`` -- and the form the queries walk:

Wide nodes
----------
``collapse_wide`` turns the binary tree into a 4-wide one: a wide node takes its binary node's two
children and opens the largest-area inner one among them until it holds four (or only leaves are
left), so a query visits about a third as many nodes and tests four child boxes per visit.
``wide_box`` (M, 24) float32 per node: lo x of children 0-3, lo y, lo z, hi x, hi y, hi z (4 each),
rounded outward to float32 (a box never shrinks, so no true hit is culled; the box test itself runs
in float64); unused slots hold an empty box (lo = +inf, hi = -inf) that no ray enters.
``wide_child`` (M, 4) int64: a child >= 0 is a wide node; a leaf is -1 - (first * LEAF_CODE + count),
its segments ``prims[first : first + count]``. Wide node 0 is the root. Both arrays start on a
64-byte boundary. ``prims`` (S, 8) float64 in leaf order = capsule end points a(3), b(3), radius,
segment index. ``fiber_seg_offsets`` (F + 1) is the CSR of segments per fibre.

The box test picks each slab's near plane by the sign of the ray's direction (``direction_signs``),
so it takes no min / max per axis; the nearest-hit query sorts the entered children by a
5-comparator network and visits them nearest first, skipping a popped node that starts beyond the
best hit found since it was pushed; the any-hit query visits nearest first too (in dense cloth it
meets an occluder sooner: 8 % faster fiberpath renders than visiting children in slot order).
Traversal stacks live on the machine stack (``stages.core.geometry.stack``). The walk itself is
written once (``stages.core.geometry.wide_walk``: the nearest-hit and any-hit walks, the child sort,
``LEAF_CODE``), with a leaf test per tree: this module's packed capsules (``PackedLeaves``), the shell's
exemplar queries (``stages.core.shell.traversal``) and the SVF's periodic any-hit
(``stages.precompute.svf.visibility``); the realized volume's point queries
(``stages.render.media.realized_medium``) walk the same nodes.

Traversal
---------
``intersect`` returns the nearest entering capsule hit (t, segment), ties broken by the lower
segment index, identical to testing every segment (``intersect_brute``). ``occluded`` is the any-hit
query for shadow rays. Both skip the segments of fibre ``ign_fiber`` within ``ign_window`` of segment
``ign_seg`` along the chain: a ray leaving a fibre through its BCSDF does not hit the fibre it leaves
(the BCSDF accounts for the fibre's own cross-section). Pass ign_fiber = -1 to test everything.
"""
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.geometry.capsule import capsule_intersect
from stages.core.geometry.wide_walk import LEAF_CODE, Ray, leaf_test, wide_any, wide_nearest

LEAF_MAX = 2
N_BINS = 16
EMPTY_BOX = (np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf)   # (lo, hi) of no box: what a sweep grows from
EMPTY = -1       # an unused slot of a wide node (an empty leaf behind an empty box)

FiberBVH = namedtuple("FiberBVH", ["points", "seg_a", "seg_r", "seg_fiber",
                                   "node_lo", "node_hi", "node_left", "node_right", "node_start", "node_count", "prim",
                                   "fiber_seg_offsets", "prims", "wide_box", "wide_child"])


@njit(cache=True)
def segments_from_fibers(fiber_offsets, point_radius):
    """(seg_a, seg_r, seg_fiber, fiber_seg_offsets) for CSR fibre polylines."""
    F = fiber_offsets.shape[0] - 1
    S = 0
    for f in range(F):
        n = fiber_offsets[f + 1] - fiber_offsets[f]
        if n > 1:
            S += n - 1
    seg_a = np.empty(S, np.int64)
    seg_r = np.empty(S, np.float64)
    seg_fiber = np.empty(S, np.int32)
    fso = np.zeros(F + 1, np.int64)
    k = 0
    for f in range(F):
        for i in range(fiber_offsets[f], fiber_offsets[f + 1] - 1):
            seg_a[k] = i
            seg_r[k] = 0.5 * (point_radius[i] + point_radius[i + 1])
            seg_fiber[k] = f
            k += 1
        fso[f + 1] = k
    return seg_a, seg_r, seg_fiber, fso


@njit(cache=True, inline="always")
def _capsule_bound(points, seg_a, seg_r, s, k):
    """(lo, hi) of segment s's capsule along axis k, padded by a relative 1e-9 (module doc)."""
    i = seg_a[s]
    r = seg_r[s]
    a = points[i, k]
    b = points[i + 1, k]
    pad = r + 1e-9 * (abs(a) + abs(b) + r)
    return min(a, b) - pad, max(a, b) + pad


@njit(cache=True)
def segment_bounds(points, seg_a, seg_r):
    """float64 (S, 3) lo and hi of every segment's capsule."""
    S = seg_a.shape[0]
    lo = np.empty((S, 3))
    hi = np.empty((S, 3))
    for s in range(S):
        for k in range(3):
            lo[s, k], hi[s, k] = _capsule_bound(points, seg_a, seg_r, s, k)
    return lo, hi


@njit(cache=True)
def segment_bounds32(points, seg_a, seg_r):
    """``segment_bounds`` rounded outward to float32 (half the bytes; the SAH build's input): the wide
    nodes round their boxes outward to float32 anyway, so they still hold every capsule."""
    S = seg_a.shape[0]
    lo = np.empty((S, 3), np.float32)
    hi = np.empty((S, 3), np.float32)
    for s in range(S):
        for k in range(3):
            l, h = _capsule_bound(points, seg_a, seg_r, s, k)
            lo[s, k] = round_down32(l)
            hi[s, k] = round_up32(h)
    return lo, hi


@njit(cache=True)
def _area(lx, ly, lz, hx, hy, hz):
    dx = max(hx - lx, 0.0)
    dy = max(hy - ly, 0.0)
    dz = max(hz - lz, 0.0)
    return dx * dy + dy * dz + dz * dx


@njit(cache=True)
def _grow_by_bin(box, bin_lo, bin_hi, b):
    """The box (lo x, y, z, hi x, y, z) grown by bin b's box (``bin_lo[b]``, ``bin_hi[b]``)."""
    return (min(box[0], bin_lo[b, 0]), min(box[1], bin_lo[b, 1]), min(box[2], bin_lo[b, 2]),
            max(box[3], bin_hi[b, 0]), max(box[4], bin_hi[b, 1]), max(box[5], bin_hi[b, 2]))


@njit(cache=True)
def _grow_nodes(nlo, nhi, left, right, start, count, cap):
    """The node arrays with room for ``cap`` nodes (the first len(nlo) copied; bounds of nlo's dtype)."""
    n = nlo.shape[0]
    nlo2 = np.empty((cap, 3), nlo.dtype)
    nhi2 = np.empty((cap, 3), nhi.dtype)
    left2 = np.full(cap, -1, np.int32)
    right2 = np.full(cap, -1, np.int32)
    start2 = np.zeros(cap, np.int64)
    count2 = np.zeros(cap, np.int64)
    nlo2[:n] = nlo
    nhi2[:n] = nhi
    left2[:n] = left
    right2[:n] = right
    start2[:n] = start
    count2[:n] = count
    return nlo2, nhi2, left2, right2, start2, count2


@njit(cache=True)
def build_bvh_nodes(lo, hi):
    """Binned-SAH BVH over boxes (S, 3): returns (node_lo, node_hi, left, right, start, count, prim),
    node bounds of the boxes' dtype (float32 boxes: float32 nodes, exactly their mins and maxes).
    Memory: the centroids are computed where they are read (0.5 (lo + hi), the same bits as an array
    of them), and the node arrays start with room for 1.25 S nodes (a tree with leaves of up to
    ``LEAF_MAX`` has ~1.2 S; at most 2 S - 1), grow by half when full and are returned as views of
    their first nodes instead of being allocated for 2 S - 1 nodes and copied (part of the 1,000-yarn
    close-up's lower peak, README *Status*)."""
    S = lo.shape[0]
    prim = np.arange(S).astype(np.int64)
    maxn = max(1, 2 * S - 1)
    nlo, nhi, left, right, start, count = _grow_nodes(lo[:0], hi[:0], np.empty(0, np.int32), np.empty(0, np.int32),
                                                      np.empty(0, np.int64), np.empty(0, np.int64),
                                                      min(maxn, S + S // 4 + 16))
    stack_node = np.empty(256, np.int64)
    stack_s = np.empty(256, np.int64)
    stack_e = np.empty(256, np.int64)
    sp = 0
    nn = 1
    stack_node[0] = 0
    stack_s[0] = 0
    stack_e[0] = S
    sp = 1
    bin_cnt = np.zeros(N_BINS, np.int64)
    bin_lo = np.empty((N_BINS, 3))
    bin_hi = np.empty((N_BINS, 3))
    right_area = np.empty(N_BINS)
    right_cnt = np.empty(N_BINS, np.int64)
    while sp > 0:
        sp -= 1
        node = stack_node[sp]
        s0 = stack_s[sp]
        s1 = stack_e[sp]
        n = s1 - s0
        # node bounds and centroid bounds
        blo = (np.inf, np.inf, np.inf)
        bhi = (-np.inf, -np.inf, -np.inf)
        clo = (np.inf, np.inf, np.inf)
        chi = (-np.inf, -np.inf, -np.inf)
        for j in range(s0, s1):
            p = prim[j]
            blo = (min(blo[0], lo[p, 0]), min(blo[1], lo[p, 1]), min(blo[2], lo[p, 2]))
            bhi = (max(bhi[0], hi[p, 0]), max(bhi[1], hi[p, 1]), max(bhi[2], hi[p, 2]))
            c0 = 0.5 * (lo[p, 0] + hi[p, 0])
            c1 = 0.5 * (lo[p, 1] + hi[p, 1])
            c2 = 0.5 * (lo[p, 2] + hi[p, 2])
            clo = (min(clo[0], c0), min(clo[1], c1), min(clo[2], c2))
            chi = (max(chi[0], c0), max(chi[1], c1), max(chi[2], c2))
        for k in range(3):
            nlo[node, k] = blo[k]
            nhi[node, k] = bhi[k]
        start[node] = s0
        count[node] = n
        if n <= LEAF_MAX:
            continue
        parent_area = _area(blo[0], blo[1], blo[2], bhi[0], bhi[1], bhi[2])
        best_cost = np.inf
        best_axis = -1
        best_bin = -1
        for ax in range(3):
            ext = chi[ax] - clo[ax]
            if ext <= 0.0:
                continue
            scale = N_BINS / ext
            bin_cnt[:] = 0
            bin_lo[:] = np.inf
            bin_hi[:] = -np.inf
            for j in range(s0, s1):
                p = prim[j]
                b = int((0.5 * (lo[p, ax] + hi[p, ax]) - clo[ax]) * scale)
                if b >= N_BINS:
                    b = N_BINS - 1
                bin_cnt[b] += 1
                for k in range(3):
                    bin_lo[b, k] = min(bin_lo[b, k], lo[p, k])
                    bin_hi[b, k] = max(bin_hi[b, k], hi[p, k])
            # sweep from the right
            rbox = EMPTY_BOX
            rc = 0
            for b in range(N_BINS - 1, 0, -1):
                rc += bin_cnt[b]
                if bin_cnt[b] > 0:
                    rbox = _grow_by_bin(rbox, bin_lo, bin_hi, b)
                right_cnt[b] = rc
                right_area[b] = _area(*rbox) if rc > 0 else 0.0
            lbox = EMPTY_BOX
            lc = 0
            for b in range(N_BINS - 1):
                lc += bin_cnt[b]
                if bin_cnt[b] > 0:
                    lbox = _grow_by_bin(lbox, bin_lo, bin_hi, b)
                if lc == 0 or right_cnt[b + 1] == 0:
                    continue
                cost = lc * _area(*lbox) + right_cnt[b + 1] * right_area[b + 1]
                if cost < best_cost:
                    best_cost = cost
                    best_axis = ax
                    best_bin = b
        mid = s0
        if best_axis >= 0:
            if best_cost >= n * parent_area and n <= 4 * LEAF_MAX:
                continue  # a leaf is no more expensive than the best split
            ax = best_axis
            scale = N_BINS / (chi[ax] - clo[ax])
            i = s0
            j = s1 - 1
            while i <= j:
                b = int((0.5 * (lo[prim[i], ax] + hi[prim[i], ax]) - clo[ax]) * scale)
                if b >= N_BINS:
                    b = N_BINS - 1
                if b <= best_bin:
                    i += 1
                else:
                    tmp = prim[i]
                    prim[i] = prim[j]
                    prim[j] = tmp
                    j -= 1
            mid = i
        if mid == s0 or mid == s1:
            mid = s0 + n // 2  # coincident centroids: split by count
        if nn + 2 > nlo.shape[0]:
            nlo, nhi, left, right, start, count = _grow_nodes(nlo[:nn], nhi[:nn], left[:nn], right[:nn], start[:nn],
                                                              count[:nn], min(maxn, nn + nn // 2 + 16))
        l = nn
        r = nn + 1
        nn += 2
        left[node] = l
        right[node] = r
        stack_node[sp] = r
        stack_s[sp] = mid
        stack_e[sp] = s1
        sp += 1
        stack_node[sp] = l
        stack_s[sp] = s0
        stack_e[sp] = mid
        sp += 1
    return nlo[:nn], nhi[:nn], left[:nn], right[:nn], start[:nn], count[:nn], prim


@njit(cache=True)
def pack_prims(prim, points, seg_a, seg_r):
    """(S, 8) float64 in leaf order: capsule end points a(3), b(3), radius, segment index."""
    S = prim.shape[0]
    prims = np.empty((S, 8))
    for j in range(S):
        s = prim[j]
        i = seg_a[s]
        for k in range(3):
            prims[j, k] = points[i, k]
            prims[j, 3 + k] = points[i + 1, k]
        prims[j, 6] = seg_r[s]
        prims[j, 7] = s
    return prims


@njit(cache=True)
def round_down32(x):
    """The largest float32 <= x (as float64): a box rounded outward never culls a true hit."""
    f = np.float32(x)
    if np.float64(f) > x:
        f = np.nextafter(f, np.float32(-np.inf))
    return f


@njit(cache=True)
def round_up32(x):
    f = np.float32(x)
    if np.float64(f) < x:
        f = np.nextafter(f, np.float32(np.inf))
    return f


@njit(cache=True)
def collapse_wide(nlo, nhi, left, right, start, count, box, child, fill):
    """The 4-wide tree of a binary tree (module doc "Wide nodes"): returns its node count M and, with
    ``fill``, writes wide_box (M, 24) float32 and wide_child (M, 4) int64 into ``box`` and ``child``
    (without, they may be empty: the count sizes them, so nothing is allocated for the worst case). A
    wide node takes its binary node's children and opens the largest-area inner one among them until
    it has 4 (or only leaves are left)."""
    N = nlo.shape[0]
    M = max(1, N)
    queue = np.empty(M, np.int64)   # binary node of each wide node
    queue[0] = 0
    nw = 1
    w = 0
    slots = np.empty(4, np.int64)
    while w < nw:
        b = queue[w]
        ns = 0
        if left[b] < 0:          # the root is a leaf: one leaf child
            slots[0] = b
            ns = 1
        else:
            slots[0] = left[b]
            slots[1] = right[b]
            ns = 2
            while ns < 4:
                best = -1
                best_area = -1.0
                for q in range(ns):
                    c = slots[q]
                    if left[c] >= 0:
                        ar = _area(nlo[c, 0], nlo[c, 1], nlo[c, 2], nhi[c, 0], nhi[c, 1], nhi[c, 2])
                        if ar > best_area:
                            best_area = ar
                            best = q
                if best < 0:
                    break
                c = slots[best]
                slots[best] = left[c]
                slots[ns] = right[c]
                ns += 1
        for q in range(4):
            if q < ns:
                c = slots[q]
                if fill:
                    for k in range(3):
                        box[w, 4 * k + q] = round_down32(nlo[c, k])
                        box[w, 12 + 4 * k + q] = round_up32(nhi[c, k])
                if left[c] < 0:
                    if fill:
                        child[w, q] = -1 - (start[c] * LEAF_CODE + count[c])
                else:
                    if fill:
                        child[w, q] = nw
                    queue[nw] = c
                    nw += 1
            elif fill:   # empty slot: a box no ray enters
                for k in range(3):
                    box[w, 4 * k + q] = np.inf
                    box[w, 12 + 4 * k + q] = -np.inf
                child[w, q] = EMPTY
        w += 1
    return nw


def empty_fiber_bvh() -> FiberBVH:
    """The ``FiberBVH`` of no fibres, with ``build_fiber_bvh``'s array types (one compiled query for both), made
    without running a kernel: what a fibre cache that holds nothing carries."""
    f64, f32, i64, i32 = np.float64, np.float32, np.int64, np.int32
    return FiberBVH(np.empty((0, 3), f64), np.empty(0, i64), np.empty(0, f64), np.empty(0, i32),
                    np.empty((0, 3), f32), np.empty((0, 3), f32), np.empty(0, i32), np.empty(0, i32),
                    np.empty(0, i64), np.empty(0, i64), np.empty(0, i64), np.zeros(1, i64), np.empty((0, 8), f64),
                    np.empty((0, 24), f32), np.empty((0, 4), i64))


def aligned_empty(shape, dtype):
    """An uninitialised C-contiguous array whose data starts on a 64-byte boundary."""
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    buf = np.empty(nbytes + 64, np.uint8)
    off = (-buf.ctypes.data) % 64
    return buf[off:off + nbytes].view(dtype).reshape(shape)


def cache_aligned(rows):
    """A copy of a C-contiguous array whose data starts on a 64-byte boundary."""
    out = aligned_empty(rows.shape, rows.dtype)
    out[...] = rows
    return out


def build_fiber_bvh(points, fiber_offsets, point_radius, keep_binary=True):
    """FiberBVH and the per-fibre segment offsets from CSR polylines (arrays; float64 points). With
    ``keep_binary`` False the binary tree goes (empty arrays) once the wide nodes are made, before the
    capsules are packed: the queries walk only the wide nodes, and the build's peak is lower (the
    fibre cache). Temporaries go as soon as the next step no longer needs them."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    seg_a, seg_r, seg_fiber, fso = segments_from_fibers(np.asarray(fiber_offsets, np.int64),
                                                        np.asarray(point_radius, np.float64))
    lo, hi = segment_bounds32(points, seg_a, seg_r)
    nlo, nhi, left, right, start, count, prim = build_bvh_nodes(lo, hi)
    del lo, hi
    leaf_max = int(count[left < 0].max()) if len(count) else 0
    if leaf_max >= LEAF_CODE:
        raise ValueError(f"a BVH leaf holds {leaf_max} segments, more than a wide node encodes ({LEAF_CODE - 1})")
    none32, none64 = np.empty((0, 24), np.float32), np.empty((0, 4), np.int64)
    M = collapse_wide(nlo, nhi, left, right, start, count, none32, none64, False)
    wide_box, wide_child = aligned_empty((M, 24), np.float32), aligned_empty((M, 4), np.int64)
    collapse_wide(nlo, nhi, left, right, start, count, wide_box, wide_child, True)
    if not keep_binary:
        nlo, nhi, left, right, start, count = nlo[:0].copy(), nhi[:0].copy(), left[:0].copy(), right[:0].copy(), \
            start[:0].copy(), count[:0].copy()
    prims = pack_prims(prim, points, seg_a, seg_r)
    if not keep_binary:
        prim = prim[:0].copy()
    return FiberBVH(points, seg_a, seg_r, seg_fiber, nlo, nhi, left, right, start, count, prim, fso, prims,
                    wide_box, wide_child), fso


@njit(cache=True, _nrt=False)
def ignore_range(bvh, ign_fiber, ign_seg, ign_window):
    """Segment index range [lo, hi] skipped by a query (empty when ign_fiber < 0)."""
    if ign_fiber < 0:
        return 1, 0
    lo = max(bvh.fiber_seg_offsets[ign_fiber], ign_seg - ign_window)
    hi = min(bvh.fiber_seg_offsets[ign_fiber + 1] - 1, ign_seg + ign_window)
    return lo, hi


@njit(cache=True)
def _skip(bvh, s, ign_fiber, ign_seg, ign_window):
    return ign_fiber >= 0 and bvh.seg_fiber[s] == ign_fiber and abs(s - ign_seg) <= ign_window


@njit(cache=True, inline="always")
def segment_hit(bvh, s, ox, oy, oz, dx, dy, dz, tmin):
    """The capsule test of segment s of any scene tuple with ``points``, ``seg_a``, ``seg_r`` (float64)."""
    i = bvh.seg_a[s]
    P = bvh.points
    return capsule_intersect(ox, oy, oz, dx, dy, dz, P[i, 0], P[i, 1], P[i, 2],
                             P[i + 1, 0], P[i + 1, 1], P[i + 1, 2], bvh.seg_r[s], tmin)


@njit(cache=True, inline="always")
def _prim_hit(prims, j, ox, oy, oz, dx, dy, dz, tmin):
    return capsule_intersect(ox, oy, oz, dx, dy, dz, prims[j, 0], prims[j, 1], prims[j, 2],
                             prims[j, 3], prims[j, 4], prims[j, 5], prims[j, 6], tmin)


PackedLeaves = namedtuple("PackedLeaves", ["prims", "ilo", "ihi"])
PackedLeaves.__doc__ = """A ``FiberBVH``'s leaf entries for ``wide_walk``: the packed capsules ``prims`` (8 columns:
a, b, radius, segment id) and the segment range [ilo, ihi] the query skips (``ignore_range``)."""


@overload(leaf_test, inline="always")
def _packed_leaf_test(leaves, j, ray, tmin):
    if is_tuple_class(leaves, PackedLeaves):
        def impl(leaves, j, ray, tmin):
            s = int(leaves.prims[j, 7])
            if s >= leaves.ilo and s <= leaves.ihi:
                return s, np.inf
            return s, _prim_hit(leaves.prims, j, ray.ox, ray.oy, ray.oz, ray.dx, ray.dy, ray.dz, tmin)
        return impl


@njit(cache=True, _nrt=False)
def intersect(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """Nearest hit (t, segment) with tmin < t < tmax; (inf, -1) when none."""
    if bvh.prims.shape[0] == 0:
        return np.inf, -1
    ilo, ihi = ignore_range(bvh, ign_fiber, ign_seg, ign_window)
    t, s = wide_nearest(bvh.wide_box, bvh.wide_child, 0, PackedLeaves(bvh.prims, ilo, ihi), Ray(ox, oy, oz, dx, dy, dz),
                        0.0, tmin, tmax)
    if s < 0:
        return np.inf, -1
    return t, s


@njit(cache=True, _nrt=False)
def occluded(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """True when any segment is hit with tmin < t < tmax."""
    if bvh.prims.shape[0] == 0:
        return False
    ilo, ihi = ignore_range(bvh, ign_fiber, ign_seg, ign_window)
    return wide_any(bvh.wide_box, bvh.wide_child, 0, PackedLeaves(bvh.prims, ilo, ihi), Ray(ox, oy, oz, dx, dy, dz),
                    0.0, tmin, tmax) >= 0


@njit(cache=True)
def intersect_brute(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """Reference: every segment tested, nearest hit, ties to the lower index."""
    best_t = tmax
    best_s = -1
    for s in range(bvh.seg_a.shape[0]):
        if _skip(bvh, s, ign_fiber, ign_seg, ign_window):
            continue
        t = segment_hit(bvh, s, ox, oy, oz, dx, dy, dz, tmin)
        if t < best_t or (t == best_t and best_s >= 0 and s < best_s):
            best_t = t
            best_s = s
    if best_s < 0:
        return np.inf, -1
    return best_t, best_s
