"""The slab test: where a ray enters an axis-aligned box.

``slab_enter(lx, ly, lz, hx, hy, hz, ox, oy, oz, ix, iy, iz, tmin, tmax)`` -> the entry distance
max over axes of the near plane distance, for the box [l, h], the ray origin o and the reciprocal
direction i = 1 / d (``inverse_direction``, ``safe_inverse`` of each component: a zero component becomes
``INVERSE_OF_ZERO``, so the slab of a parallel axis is all or nothing); inf when the ray misses the box, leaves
it before ``tmin`` or enters it beyond ``tmax``. The BVH traversals (``stages.core.geometry.bvh``,
``stages.core.shell.traversal``) call it for every node they visit.
"""
import numpy as np
from numba import njit

INVERSE_OF_ZERO = 1e300   # safe_inverse(0): finite, so 0 x it stays 0 where an axis' slab holds the origin


@njit(cache=True)
def safe_inverse(d):
    if d == 0.0:
        return INVERSE_OF_ZERO
    return 1.0 / d


@njit(cache=True)
def inverse_direction(dx, dy, dz):
    """(ix, iy, iz): the ray's reciprocal direction, ``safe_inverse`` of each component."""
    return safe_inverse(dx), safe_inverse(dy), safe_inverse(dz)


@njit(cache=True)
def slab_enter(lx, ly, lz, hx, hy, hz, ox, oy, oz, ix, iy, iz, tmin, tmax):
    """Entry distance of the ray (origin o, reciprocal direction i) into the box [l, h] within [tmin, tmax];
    inf when it misses. 14 parameters: a box (lo, hi), the ray's origin and reciprocal direction and the
    window, as scalars the walks already hold."""
    t0 = (lx - ox) * ix
    t1 = (hx - ox) * ix
    tn = min(t0, t1)
    tf = max(t0, t1)
    t0 = (ly - oy) * iy
    t1 = (hy - oy) * iy
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    t0 = (lz - oz) * iz
    t1 = (hz - oz) * iz
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    if tf < tn or tf < tmin or tn > tmax:
        return np.inf
    return tn
