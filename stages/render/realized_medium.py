"""Realized-fibre density source (``--source realized``): the reference of seed 000 §6.1.

All fibres are realized as polylines (a ``fibers`` artifact) and put in a SAH BVH over their
segments (``stages.core.geometry.bvh``, capsules of the segment's radius). The density rule is the
procedural one: p is inside a fibre when it lies in one of the fibre's capsules; then den(p) is the
density of the fibre's yarn and dir(p) the segment's tangent. Where several fibres cover p the one
with the lowest fibre index answers (the realization orders fibres as the lookups do: yarn, ply,
regular before hair), so both sources describe the same medium.

RealizedMedium fields: ``bvh`` (``FiberBVH``), ``fiber_yarn`` (F,) int32, ``yarn_density`` (Y,),
``yarn_albedo`` (Y, 3), ``yarn_roughness`` (Y,) float64.

``fiber_capsules(med)`` gives the capsules and density bounds for a majorant grid.
"""
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.geometry.capsule import point_segment_dist2
from stages.render.medium import NO_MEDIUM, MediumPoint, medium_lookup

RealizedMedium = namedtuple("RealizedMedium", ["bvh", "fiber_yarn", "yarn_density", "yarn_albedo", "yarn_roughness"])


@njit(cache=True)
def covering_segment(bvh, x, y, z):
    """Segment of the lowest-index fibre whose capsule contains (x, y, z), or -1. Walks the BVH's
    cache-line packed ``nodes`` / ``prims`` (see ``stages.core.geometry.bvh``)."""
    nodes = bvh.nodes
    prims = bvh.prims
    if prims.shape[0] == 0:
        return -1
    stack = np.empty(128, np.int64)
    stack[0] = 0
    sp = 1
    best = -1
    best_f = np.iinfo(np.int64).max
    while sp > 0:
        sp -= 1
        nd = stack[sp]
        if (x < nodes[nd, 0] or x > nodes[nd, 3] or y < nodes[nd, 1] or y > nodes[nd, 4]
                or z < nodes[nd, 2] or z > nodes[nd, 5]):
            continue
        a = int(nodes[nd, 6])
        if a >= 0:
            stack[sp] = a
            stack[sp + 1] = int(nodes[nd, 7])
            sp += 2
            continue
        start = -1 - a
        for q in range(start, start + int(nodes[nd, 7])):
            s = int(prims[q, 7])
            f = bvh.seg_fiber[s]
            if f >= best_f:
                continue
            r = prims[q, 6]
            if point_segment_dist2(x, y, z, prims[q, 0], prims[q, 1], prims[q, 2],
                                   prims[q, 3], prims[q, 4], prims[q, 5]) < r * r:
                best = s
                best_f = f
    return best


@njit(cache=True)
def realized_lookup(med, x, y, z):
    s = covering_segment(med.bvh, x, y, z)
    if s < 0:
        return NO_MEDIUM
    pts = med.bvh.points
    i = med.bvh.seg_a[s]
    tx = pts[i + 1, 0] - pts[i, 0]
    ty = pts[i + 1, 1] - pts[i, 1]
    tz = pts[i + 1, 2] - pts[i, 2]
    n = np.sqrt(tx * tx + ty * ty + tz * tz)
    if n > 0.0:
        tx /= n
        ty /= n
        tz /= n
    else:
        tx, ty, tz = 0.0, 0.0, 1.0
    f = med.bvh.seg_fiber[s]
    c = med.fiber_yarn[f]
    a = med.yarn_albedo
    return MediumPoint(np.float64(med.yarn_density[c]), tx, ty, tz, np.float64(a[c, 0]), np.float64(a[c, 1]),
                       np.float64(a[c, 2]), np.float64(med.yarn_roughness[c]), np.int64(c), np.int64(f))


@overload(medium_lookup)
def _realized_overload(med, x, y, z):
    if is_tuple_class(med, RealizedMedium):
        return lambda med, x, y, z: realized_lookup(med, x, y, z)


@njit(cache=True)
def fiber_capsules(med):
    """(a, b, radius, bound) of every fibre segment, bound = its yarn's density."""
    bvh = med.bvh
    n = bvh.seg_a.shape[0]
    a = np.empty((n, 3))
    b = np.empty((n, 3))
    bound = np.empty(n)
    for s in range(n):
        i = bvh.seg_a[s]
        a[s] = bvh.points[i]
        b[s] = bvh.points[i + 1]
        bound[s] = med.yarn_density[med.fiber_yarn[bvh.seg_fiber[s]]]
    return a, b, bvh.seg_r.copy(), bound
