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
capsules' exact bounds padded by a relative 1e-9 so rounding never culls a true hit.

Nodes (``FiberBVH``): ``node_lo``/``node_hi`` (N, 3) float64 bounds, ``node_left``/``node_right``
child indices (-1 at leaves), ``node_start``/``node_count`` the leaf's range in ``prim``
(segment indices). Node 0 is the root. The traversal reads cache-line packed copies (random
secondary rays in 10^5 dense segments are memory-bound): ``nodes`` (N, 8) float64 = bounds lo(3),
hi(3), then (left, right) for inner nodes or (-1 - start, count) for leaves; ``prims`` (S, 8)
float64 in leaf order = capsule end points a(3), b(3), radius, segment index.
``fiber_seg_offsets`` (F + 1) is the CSR of segments per fibre.

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

from stages.core.geometry.capsule import capsule_intersect
from stages.core.geometry.slab import safe_inverse, slab_enter

LEAF_MAX = 4
N_BINS = 16

FiberBVH = namedtuple("FiberBVH", ["points", "seg_a", "seg_r", "seg_fiber",
                                   "node_lo", "node_hi", "node_left", "node_right", "node_start", "node_count", "prim",
                                   "fiber_seg_offsets", "nodes", "prims"])


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


@njit(cache=True)
def segment_bounds(points, seg_a, seg_r):
    S = seg_a.shape[0]
    lo = np.empty((S, 3))
    hi = np.empty((S, 3))
    for s in range(S):
        i = seg_a[s]
        r = seg_r[s]
        for k in range(3):
            a = points[i, k]
            b = points[i + 1, k]
            pad = r + 1e-9 * (abs(a) + abs(b) + r)
            lo[s, k] = min(a, b) - pad
            hi[s, k] = max(a, b) + pad
    return lo, hi


@njit(cache=True)
def _area(lx, ly, lz, hx, hy, hz):
    dx = max(hx - lx, 0.0)
    dy = max(hy - ly, 0.0)
    dz = max(hz - lz, 0.0)
    return dx * dy + dy * dz + dz * dx


@njit(cache=True)
def build_bvh_nodes(lo, hi):
    """Binned-SAH BVH over boxes (S, 3): returns (node_lo, node_hi, left, right, start, count, prim)."""
    S = lo.shape[0]
    cen = 0.5 * (lo + hi)
    prim = np.arange(S).astype(np.int64)
    maxn = max(1, 2 * S - 1)
    nlo = np.empty((maxn, 3))
    nhi = np.empty((maxn, 3))
    left = np.full(maxn, -1, np.int32)
    right = np.full(maxn, -1, np.int32)
    start = np.zeros(maxn, np.int64)
    count = np.zeros(maxn, np.int64)
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
        blo = np.full(3, np.inf)
        bhi = np.full(3, -np.inf)
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for j in range(s0, s1):
            p = prim[j]
            for k in range(3):
                blo[k] = min(blo[k], lo[p, k])
                bhi[k] = max(bhi[k], hi[p, k])
                clo[k] = min(clo[k], cen[p, k])
                chi[k] = max(chi[k], cen[p, k])
        nlo[node] = blo
        nhi[node] = bhi
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
                b = int((cen[p, ax] - clo[ax]) * scale)
                if b >= N_BINS:
                    b = N_BINS - 1
                bin_cnt[b] += 1
                for k in range(3):
                    bin_lo[b, k] = min(bin_lo[b, k], lo[p, k])
                    bin_hi[b, k] = max(bin_hi[b, k], hi[p, k])
            # sweep from the right
            rl0 = np.inf; rl1 = np.inf; rl2 = np.inf
            rh0 = -np.inf; rh1 = -np.inf; rh2 = -np.inf
            rc = 0
            for b in range(N_BINS - 1, 0, -1):
                rc += bin_cnt[b]
                if bin_cnt[b] > 0:
                    rl0 = min(rl0, bin_lo[b, 0]); rl1 = min(rl1, bin_lo[b, 1]); rl2 = min(rl2, bin_lo[b, 2])
                    rh0 = max(rh0, bin_hi[b, 0]); rh1 = max(rh1, bin_hi[b, 1]); rh2 = max(rh2, bin_hi[b, 2])
                right_cnt[b] = rc
                right_area[b] = _area(rl0, rl1, rl2, rh0, rh1, rh2) if rc > 0 else 0.0
            ll0 = np.inf; ll1 = np.inf; ll2 = np.inf
            lh0 = -np.inf; lh1 = -np.inf; lh2 = -np.inf
            lc = 0
            for b in range(N_BINS - 1):
                lc += bin_cnt[b]
                if bin_cnt[b] > 0:
                    ll0 = min(ll0, bin_lo[b, 0]); ll1 = min(ll1, bin_lo[b, 1]); ll2 = min(ll2, bin_lo[b, 2])
                    lh0 = max(lh0, bin_hi[b, 0]); lh1 = max(lh1, bin_hi[b, 1]); lh2 = max(lh2, bin_hi[b, 2])
                if lc == 0 or right_cnt[b + 1] == 0:
                    continue
                cost = lc * _area(ll0, ll1, ll2, lh0, lh1, lh2) + right_cnt[b + 1] * right_area[b + 1]
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
                b = int((cen[prim[i], ax] - clo[ax]) * scale)
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
    return nlo[:nn].copy(), nhi[:nn].copy(), left[:nn].copy(), right[:nn].copy(), start[:nn].copy(), count[:nn].copy(), prim


@njit(cache=True)
def pack_nodes(nlo, nhi, left, right, start, count, prim, points, seg_a, seg_r):
    N = nlo.shape[0]
    nodes = np.empty((N, 8))
    for n in range(N):
        for k in range(3):
            nodes[n, k] = nlo[n, k]
            nodes[n, 3 + k] = nhi[n, k]
        if left[n] < 0:
            nodes[n, 6] = -1.0 - start[n]
            nodes[n, 7] = count[n]
        else:
            nodes[n, 6] = left[n]
            nodes[n, 7] = right[n]
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
    return nodes, prims


def build_fiber_bvh(points, fiber_offsets, point_radius):
    """FiberBVH and the per-fibre segment offsets from CSR polylines (arrays; float64 points)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    seg_a, seg_r, seg_fiber, fso = segments_from_fibers(np.asarray(fiber_offsets, np.int64),
                                                        np.asarray(point_radius, np.float64))
    lo, hi = segment_bounds(points, seg_a, seg_r)
    nlo, nhi, left, right, start, count, prim = build_bvh_nodes(lo, hi)
    nodes, prims = pack_nodes(nlo, nhi, left, right, start, count, prim, points, seg_a, seg_r)
    return FiberBVH(points, seg_a, seg_r, seg_fiber, nlo, nhi, left, right, start, count, prim, fso, nodes, prims), fso


# ------------------------------------------------------------------------------------------------
@njit(cache=True)
def _node_enter(nodes, node, ox, oy, oz, ix, iy, iz, tmax):
    """Entry distance of a ray into box ``node`` of the packed node array (``slab_enter``, tmin 0)."""
    return slab_enter(nodes[node, 0], nodes[node, 1], nodes[node, 2], nodes[node, 3], nodes[node, 4], nodes[node, 5],
                      ox, oy, oz, ix, iy, iz, 0.0, tmax)


@njit(cache=True)
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


@njit(cache=True)
def _seg_hit(bvh, s, ox, oy, oz, dx, dy, dz, tmin):
    i = bvh.seg_a[s]
    P = bvh.points
    return capsule_intersect(ox, oy, oz, dx, dy, dz, P[i, 0], P[i, 1], P[i, 2],
                             P[i + 1, 0], P[i + 1, 1], P[i + 1, 2], bvh.seg_r[s], tmin)


@njit(cache=True)
def _prim_hit(prims, j, ox, oy, oz, dx, dy, dz, tmin):
    return capsule_intersect(ox, oy, oz, dx, dy, dz, prims[j, 0], prims[j, 1], prims[j, 2],
                             prims[j, 3], prims[j, 4], prims[j, 5], prims[j, 6], tmin)


@njit(cache=True)
def intersect(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """Nearest hit (t, segment) with tmin < t < tmax; (inf, -1) when none."""
    nodes = bvh.nodes
    prims = bvh.prims
    if prims.shape[0] == 0:
        return np.inf, -1
    ilo, ihi = ignore_range(bvh, ign_fiber, ign_seg, ign_window)
    ix = safe_inverse(dx)
    iy = safe_inverse(dy)
    iz = safe_inverse(dz)
    stack = np.empty(256, np.int64)
    stack_t = np.empty(256)  # entry distance of each pushed node: skipped if a nearer hit was found since
    best_t = tmax
    best_s = -1
    t_root = _node_enter(nodes, 0, ox, oy, oz, ix, iy, iz, best_t)
    if t_root == np.inf:
        return np.inf, -1
    stack[0] = 0
    stack_t[0] = t_root
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if stack_t[sp] > best_t:
            continue
        a = int(nodes[node, 6])
        b = int(nodes[node, 7])
        if a < 0:
            j0 = -1 - a
            for j in range(j0, j0 + b):
                s = int(prims[j, 7])
                if s >= ilo and s <= ihi:
                    continue
                t = _prim_hit(prims, j, ox, oy, oz, dx, dy, dz, tmin)
                if t < best_t or (t == best_t and best_s >= 0 and s < best_s):
                    best_t = t
                    best_s = s
            continue
        tl = _node_enter(nodes, a, ox, oy, oz, ix, iy, iz, best_t)
        tr = _node_enter(nodes, b, ox, oy, oz, ix, iy, iz, best_t)
        # push the far child first so the near one is visited first
        if tl <= tr:
            if tr != np.inf:
                stack[sp] = b
                stack_t[sp] = tr
                sp += 1
            if tl != np.inf:
                stack[sp] = a
                stack_t[sp] = tl
                sp += 1
        else:
            if tl != np.inf:
                stack[sp] = a
                stack_t[sp] = tl
                sp += 1
            if tr != np.inf:
                stack[sp] = b
                stack_t[sp] = tr
                sp += 1
    if best_s < 0:
        return np.inf, -1
    return best_t, best_s


@njit(cache=True)
def occluded(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """True when any segment is hit with tmin < t < tmax."""
    nodes = bvh.nodes
    prims = bvh.prims
    if prims.shape[0] == 0:
        return False
    ilo, ihi = ignore_range(bvh, ign_fiber, ign_seg, ign_window)
    ix = safe_inverse(dx)
    iy = safe_inverse(dy)
    iz = safe_inverse(dz)
    if _node_enter(nodes, 0, ox, oy, oz, ix, iy, iz, tmax) == np.inf:
        return False
    stack = np.empty(256, np.int64)
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        a = int(nodes[node, 6])
        b = int(nodes[node, 7])
        if a < 0:
            j0 = -1 - a
            for j in range(j0, j0 + b):
                s = int(prims[j, 7])
                if s >= ilo and s <= ihi:
                    continue
                if _prim_hit(prims, j, ox, oy, oz, dx, dy, dz, tmin) < tmax:
                    return True
            continue
        if _node_enter(nodes, a, ox, oy, oz, ix, iy, iz, tmax) != np.inf:
            stack[sp] = a
            sp += 1
        if _node_enter(nodes, b, ox, oy, oz, ix, iy, iz, tmax) != np.inf:
            stack[sp] = b
            sp += 1
    return False


@njit(cache=True)
def intersect_brute(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """Reference: every segment tested, nearest hit, ties to the lower index."""
    best_t = tmax
    best_s = -1
    for s in range(bvh.seg_a.shape[0]):
        if _skip(bvh, s, ign_fiber, ign_seg, ign_window):
            continue
        t = _seg_hit(bvh, s, ox, oy, oz, dx, dy, dz, tmin)
        if t < best_t or (t == best_t and best_s >= 0 and s < best_s):
            best_t = t
            best_s = s
    if best_s < 0:
        return np.inf, -1
    return best_t, best_s
