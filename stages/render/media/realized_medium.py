"""Realized-fibre density source (``--source realized``): the reference of seed 000 §6.1.

All fibres are realized as polylines (a ``fibers`` artifact) and put in a SAH BVH over their
segments (``stages.core.geometry.bvh``, capsules of the segment's radius). The density rule is the
procedural one: p is inside a fibre when it lies in one of the fibre's capsules; then den(p) is the
density of the fibre's yarn and dir(p) the segment's tangent. Where several fibres cover p the one
with the lowest fibre index answers (the realization orders fibres as the lookups do: yarn, ply,
regular before hair), so both sources describe the same medium.

RealizedMedium fields: ``bvh`` (``FiberBVH``), ``fiber_yarn`` (F,) int32, ``yarn_density`` (Y,),
``yarn_albedo`` (Y, 3), ``yarn_roughness`` (Y,) float64, ``fibre_id`` (F,) int64 or empty: the number
a ``MediumPoint`` gives the covering fibre and ``medium_lookup``'s skip names. The procedural
realization cuts one fibre into pieces (runs of regular cycles, each loop cycle) that meet end to
end; with the procedural lookup's numbers (``fibre_cache.fibre_ids``) a ray leaving a fibre skips all
its pieces, as the procedural source and its cache do. Empty: each polyline is its own fibre (its
index).

``fiber_capsules(med)`` gives the capsules and density bounds for a majorant grid.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.box4 import box4_contains
from stages.core.geometry.capsule import point_segment_dist2
from stages.core.geometry.stack import STACK_SIZE, stack_array
from stages.core.geometry.wide_walk import leaf_range
from stages.render.media.medium import NO_MEDIUM, MediumPoint, register_medium

RealizedMedium = namedtuple("RealizedMedium", ["bvh", "fiber_yarn", "yarn_density", "yarn_albedo", "yarn_roughness",
                                               "fibre_id"])


@njit(cache=True, _nrt=False)
def covering_segment(bvh, x, y, z, skip=-1, fibre_id=None):
    """Segment of the lowest-index fibre whose capsule contains (x, y, z) (of its segments that do, the
    lowest: the answer does not depend on the tree), or -1; fibre ``skip`` (-1: none; numbered by
    ``fibre_id``, else by index) counts as empty. Walks the BVH's 4-wide nodes and leaf-ordered
    ``prims`` (see ``stages.core.geometry.bvh``)."""
    if fibre_id is None:
        return covering_segment_arrays(bvh.wide_box, bvh.wide_child, bvh.prims, bvh.seg_fiber, x, y, z, skip,
                                       bvh.seg_fiber[:0])
    return covering_segment_arrays(bvh.wide_box, bvh.wide_child, bvh.prims, bvh.seg_fiber, x, y, z, skip, fibre_id)


@njit(cache=True, _nrt=False)
def covering_segment_arrays(box, child, prims, seg_fiber, x, y, z, skip, fibre_id):
    """``covering_segment`` on the BVH arrays it reads (for callers that hold them apart); ``skip``
    names a fibre by ``fibre_id[f]`` (the fibre cache's numbers, whose pieces share one) or, with
    ``fibre_id`` empty, by its index f."""
    if prims.shape[0] == 0:
        return -1
    stack = stack_array(STACK_SIZE, np.int64)
    stack[0] = 0
    sp = 1
    best = -1
    best_f = np.iinfo(np.int64).max
    while sp > 0:
        sp -= 1
        ref = stack[sp]
        if ref >= 0:
            holds = box4_contains(box, ref, x, y, z)
            for q in range(4):
                if holds & (1 << q):
                    stack[sp] = child[ref, q]
                    sp += 1
            continue
        start, n = leaf_range(ref)
        for q in range(start, start + n):
            s = int(prims[q, 7])
            f = seg_fiber[s]
            if f > best_f or (f == best_f and s > best):
                continue
            if skip >= 0 and (fibre_id[f] if fibre_id.shape[0] > 0 else f) == skip:
                continue
            r = prims[q, 6]
            if point_segment_dist2(x, y, z, prims[q, 0], prims[q, 1], prims[q, 2],
                                   prims[q, 3], prims[q, 4], prims[q, 5]) < r * r:
                best = s
                best_f = f
    return best


@njit(cache=True, inline="always")
def segment_tangent(points, seg_a, s):
    """Unit tangent of segment s (from its first vertex to the next; +z for a degenerate segment)."""
    i = seg_a[s]
    tx = points[i + 1, 0] - points[i, 0]
    ty = points[i + 1, 1] - points[i, 1]
    tz = points[i + 1, 2] - points[i, 2]
    n = np.sqrt(tx * tx + ty * ty + tz * tz)
    if n > 0.0:
        return tx / n, ty / n, tz / n
    return 0.0, 0.0, 1.0


@njit(cache=True)
def realized_lookup(med, x, y, z, skip=-1):
    s = covering_segment(med.bvh, x, y, z, skip, med.fibre_id)
    if s < 0:
        return NO_MEDIUM
    tx, ty, tz = segment_tangent(med.bvh.points, med.bvh.seg_a, s)
    f = med.bvh.seg_fiber[s]
    c = med.fiber_yarn[f]
    a = med.yarn_albedo
    fid = med.fibre_id[f] if med.fibre_id.shape[0] > 0 else np.int64(f)
    return MediumPoint(np.float64(med.yarn_density[c]), tx, ty, tz, np.float64(a[c, 0]), np.float64(a[c, 1]),
                       np.float64(a[c, 2]), np.float64(med.yarn_roughness[c]), np.int64(c), fid)


register_medium(RealizedMedium, realized_lookup)


@njit(cache=True)
def fiber_capsules(med):
    """(a, b, radius, bound) of every fibre segment, bound = its yarn's density."""
    return segment_capsules(med.bvh, med.yarn_density, med.fiber_yarn)


@njit(cache=True)
def segment_capsules(bvh, yarn_density, fiber_yarn):
    """(a, b, radius, bound) of every segment of ``bvh``, bound = yarn_density[fiber_yarn[its fibre]]."""
    n = bvh.seg_a.shape[0]
    a = np.empty((n, 3))
    b = np.empty((n, 3))
    bound = np.empty(n)
    for s in range(n):
        i = bvh.seg_a[s]
        a[s] = bvh.points[i]
        b[s] = bvh.points[i + 1]
        bound[s] = yarn_density[fiber_yarn[bvh.seg_fiber[s]]]
    return a, b, bvh.seg_r.copy(), bound
