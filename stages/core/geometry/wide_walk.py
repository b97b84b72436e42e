"""The walk of a 4-wide BVH (``stages.core.geometry.bvh``, *Wide nodes*), written once for every tree of
fibre capsules loomlight casts rays through.

A ray is a ``Ray`` (origin and unit direction, six scalars passed by value). Its walk pops a node, tests
the four child boxes (``push_children_sorted``: entry distances within [node_tmin, the best hit so
far], pushed farthest first so the nearest is visited next) and, at a leaf, tests its primitives:

- ``wide_nearest(box, child, root, leaves, ray, node_tmin, tmin, tmax)`` -> (t, primitive id): the nearest
  hit with tmin < t < tmax, ties to the lower id; (tmax, -1) when there is none. A popped node that
  starts beyond the best hit is skipped.
- ``wide_any(box, child, root, leaves, ray, node_tmin, tmin, tmax)`` -> a primitive id hit with
  tmin < t < tmax, or -1: shadow rays stop at the first one found.

What a leaf entry is differs per tree, and only that: ``leaf_test(leaves, j, ray, tmin)`` -> (id, t) of
leaf entry j (t = inf where the query skips it, so neither walk records it), answered per leaves class
through ``numba.extending.overload`` (``stages.core.dispatch``), inlined into the walk:

- ``bvh.PackedLeaves``: a ``FiberBVH``'s packed capsules, one fibre's neighbouring segments skipped
  (``bvh.intersect`` / ``bvh.occluded``: realized fibres, ``fiberpath``);
- ``shell.traversal.ShellLeaves``: an exemplar's wrapped pieces in a shell-mapped tiling
  (``fiber_nearest`` / ``fiber_any``);
- ``precompute.svf.visibility.PeriodLeaves``: one period of the flat periodic fabric, a capsule that
  contains the ray's origin let through (the SVF's visibility images).

The walks are ``inline="always"``: each query compiles its own copy with its own leaf test, in the frame
of a function compiled without reference counting, so the node stacks live on the machine stack
(``stages.core.geometry.stack``) and no array's reference count is touched per ray.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.box4 import box4_enter
from stages.core.geometry.slab import safe_inverse
from stages.core.geometry.stack import STACK_SIZE, stack_array

LEAF_CODE = 32   # a leaf child reference is -1 - (first prim * LEAF_CODE + count), count < LEAF_CODE

Ray = namedtuple("Ray", ["ox", "oy", "oz", "dx", "dy", "dz"])
Ray.__doc__ = """A ray o + t d: its origin (ox, oy, oz) and unit direction (dx, dy, dz), scalars (numba passes the
tuple by value)."""


def leaf_test(leaves, j, ray, tmin):
    """(primitive id, t) of leaf entry ``j`` for ``ray`` beyond ``tmin`` (t = inf: missed or skipped).
    numba-only: each leaves class overloads it (module doc)."""
    raise TypeError("leaf_test is only callable from numba-compiled code")


@njit(cache=True, inline="always")
def direction_signs(ix, iy, iz):
    """The near-plane column offsets (0 or 12) of ``box4.box4_enter`` for a ray's reciprocal direction."""
    return 0 if ix >= 0.0 else 12, 0 if iy >= 0.0 else 12, 0 if iz >= 0.0 else 12


@njit(cache=True, inline="always")
def push_children_sorted(box, child, ref, ox, oy, oz, ix, iy, iz, sx, sy, sz, tmin, tmax, stack, stack_t, sp):
    """Push the children of wide node ``ref`` that the ray meets within [tmin, tmax], farthest first (so the
    nearest is visited next), with their entry distances; returns the new stack size. The four entry
    distances are sorted by a 5-comparator network (misses are inf and sort last), written out: through a
    comparator helper returning tuples (even inlined) fiberpath on a tiling rendered 4 % slower.
    17 parameters: the node arrays, the ray's origin, reciprocal direction and near-plane offsets, the window and
    the stack, computed once per ray by the walk and handed down unchanged; inlined, so nothing is passed at run
    time."""
    ct0, ct1, ct2, ct3 = box4_enter(box, ref, sx, sy, sz, ox, oy, oz, ix, iy, iz, tmin, tmax)
    cr0 = child[ref, 0]
    cr1 = child[ref, 1]
    cr2 = child[ref, 2]
    cr3 = child[ref, 3]
    if ct1 < ct0:
        ct0, ct1 = ct1, ct0
        cr0, cr1 = cr1, cr0
    if ct3 < ct2:
        ct2, ct3 = ct3, ct2
        cr2, cr3 = cr3, cr2
    if ct2 < ct0:
        ct0, ct2 = ct2, ct0
        cr0, cr2 = cr2, cr0
    if ct3 < ct1:
        ct1, ct3 = ct3, ct1
        cr1, cr3 = cr3, cr1
    if ct2 < ct1:
        ct1, ct2 = ct2, ct1
        cr1, cr2 = cr2, cr1
    if ct3 != np.inf:
        stack[sp] = cr3
        stack_t[sp] = ct3
        sp += 1
    if ct2 != np.inf:
        stack[sp] = cr2
        stack_t[sp] = ct2
        sp += 1
    if ct1 != np.inf:
        stack[sp] = cr1
        stack_t[sp] = ct1
        sp += 1
    if ct0 != np.inf:
        stack[sp] = cr0
        stack_t[sp] = ct0
        sp += 1
    return sp


@njit(cache=True, inline="always")
def leaf_range(ref):
    """(first prim, count) of a leaf child reference (< 0)."""
    code = -1 - ref
    return code // LEAF_CODE, code % LEAF_CODE


@njit(cache=True, inline="always")
def wide_nearest(box, child, root, leaves, ray, node_tmin, tmin, tmax):
    """The nearest leaf entry the ray hits with tmin < t < tmax, (t, id), ties to the lower id; (tmax, -1)
    when none (module doc). ``box``/``child``: the wide nodes, ``root`` the node to start from."""
    ix = safe_inverse(ray.dx)
    iy = safe_inverse(ray.dy)
    iz = safe_inverse(ray.dz)
    sx, sy, sz = direction_signs(ix, iy, iz)
    # node stack and entry distances (a popped node that starts beyond the best hit is skipped), on the machine stack
    stack = stack_array(STACK_SIZE, np.int64)
    stack_t = stack_array(STACK_SIZE, np.float64)
    best_t = tmax
    best_s = -1
    stack[0] = root
    stack_t[0] = -np.inf
    sp = 1
    while sp > 0:
        sp -= 1
        ref = stack[sp]
        if stack_t[sp] > best_t:
            continue
        if ref < 0:
            j0, n = leaf_range(ref)
            for j in range(j0, j0 + n):
                s, t = leaf_test(leaves, j, ray, tmin)
                if t < best_t or (t == best_t and best_s >= 0 and s < best_s):
                    best_t = t
                    best_s = s
            continue
        sp = push_children_sorted(box, child, ref, ray.ox, ray.oy, ray.oz, ix, iy, iz, sx, sy, sz, node_tmin, best_t,
                                  stack, stack_t, sp)
    return best_t, best_s


@njit(cache=True, inline="always")
def wide_any(box, child, root, leaves, ray, node_tmin, tmin, tmax):
    """A leaf entry the ray hits with tmin < t < tmax, the first one found; -1 when none (module doc)."""
    ix = safe_inverse(ray.dx)
    iy = safe_inverse(ray.dy)
    iz = safe_inverse(ray.dz)
    sx, sy, sz = direction_signs(ix, iy, iz)
    stack = stack_array(STACK_SIZE, np.int64)
    stack_t = stack_array(STACK_SIZE, np.float64)
    stack[0] = root
    sp = 1
    while sp > 0:
        sp -= 1
        ref = stack[sp]
        if ref < 0:
            j0, n = leaf_range(ref)
            for j in range(j0, j0 + n):
                s, t = leaf_test(leaves, j, ray, tmin)
                if t < tmax:
                    return s
            continue
        sp = push_children_sorted(box, child, ref, ray.ox, ray.oy, ray.oz, ix, iy, iz, sx, sy, sz, node_tmin, tmax,
                                  stack, stack_t, sp)
    return -1
