"""Ray queries of an explicit-fibre scene, whatever holds the fibres.

Integrators that shade fibre surfaces (``stages.render.integrators.fiberpath``, and the precomputes after it)
ask a *surface scene* two things, each a generic kernel answered per scene class (dispatch:
``stages.core.dispatch``):

    surface_hit(scene, cell, ray, tmin, tmax, skip)
        -> SurfaceHit, the nearest fibre hit along the ray (a ``Ray``, unit d) in (tmin, tmax)
    surface_occluded(scene, cell, ray, tmin, tmax, skip)
        -> True when any fibre lies along the ray in (tmin, tmax)

``SurfaceHit`` fields: ``t`` (inf on a miss), ``prim`` (the hit capsule segment, -1 on a miss),
``fiber`` (its fibre: the material index), ``cell`` (where a continuation ray starts: the shell
tetrahedron, -1 for flat scenes), ``tx, ty, tz`` the unit fibre tangent, ``nx, ny, nz`` the capsule's
outward normal at the hit, ``radius`` the capsule radius. ``skip``, a ``Skip`` (fields ``fiber``, ``prim``,
``window``): segments of fibre ``fiber`` within ``window`` segments of segment ``prim`` are skipped (a ray leaving
a fibre through its BCSDF; fiber -1 skips nothing); ``cell`` is the ray's starting cell (-1: outside / unknown).
``Ray`` (``stages.core.geometry.wide_walk``) and ``Skip`` are tuples of scalars, passed by value; the scene
classes' own kernels take the scalars.

Scene classes: ``FiberBVH`` (``stages.core.geometry.bvh``: realized fibres in one SAH BVH; below),
``EmbreeFibers`` (``stages.core.geometry.embree``: the same fibres traced by Embree 4) and
``ShellScene`` (``stages.core.shell.traversal``: tiled exemplars under a shell map); each answers both queries
through ``answer_surface_queries(scene_class, hit, any_hit)``.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.geometry.bvh import FiberBVH, intersect, occluded
from stages.core.geometry.capsule import capsule_normal

SurfaceHit = namedtuple("SurfaceHit", ["t", "prim", "fiber", "cell", "tx", "ty", "tz", "nx", "ny", "nz", "radius"])
Skip = namedtuple("Skip", ["fiber", "prim", "window"])
Skip.__doc__ = """The segments a surface query passes over: those of fibre ``fiber`` within ``window`` segments of
segment ``prim`` (the fibre a ray leaves; fiber -1: none)."""


def surface_hit(scene, cell, ray, tmin, tmax, skip):
    """The nearest fibre hit (``SurfaceHit``); numba-only (overloaded per scene class)."""
    raise TypeError("surface_hit is only callable from numba-compiled code")


def surface_occluded(scene, cell, ray, tmin, tmax, skip):
    """Any fibre along the ray; numba-only (overloaded per scene class)."""
    raise TypeError("surface_occluded is only callable from numba-compiled code")


def answer_surface_queries(scene_class, hit, any_hit, with_cell=False):
    """Answers ``surface_hit`` / ``surface_occluded`` for ``scene_class`` (overloads) by the kernels ``hit`` /
    ``any_hit``, which take the scene, with ``with_cell`` the ray's starting cell, then the ray, window and skips."""
    _answer_by(surface_hit, scene_class, hit, with_cell)
    _answer_by(surface_occluded, scene_class, any_hit, with_cell)


def _answer_by(generic, scene_class, kernel, with_cell):
    """Overloads ``generic`` for ``scene_class`` by a call of ``kernel`` (``answer_surface_queries``)."""
    if with_cell:
        def impl(scene, cell, ray, tmin, tmax, skip):
            return kernel(scene, cell, ray.ox, ray.oy, ray.oz, ray.dx, ray.dy, ray.dz, tmin, tmax, skip.fiber,
                          skip.prim, skip.window)
    else:
        def impl(scene, cell, ray, tmin, tmax, skip):
            return kernel(scene, ray.ox, ray.oy, ray.oz, ray.dx, ray.dy, ray.dz, tmin, tmax, skip.fiber, skip.prim,
                          skip.window)

    @overload(generic)
    def _of_class(scene, cell, ray, tmin, tmax, skip):
        if is_tuple_class(scene, scene_class):
            return impl


# ------------------------------------------------------------------------------------------------
# realized fibres in one BVH
@njit(cache=True, _nrt=False)
def segment_surface_hit(fibres, t, s, ox, oy, oz, dx, dy, dz):
    """The ``SurfaceHit`` of a ray (o, d) meeting segment s at t (a miss when s < 0); ``fibres`` is any
    scene tuple with the segment arrays of ``stages.core.geometry.bvh`` (points, seg_a, seg_r, seg_fiber)."""
    if s < 0:
        return SurfaceHit(t, -1, -1, -1, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    ia = fibres.seg_a[s]
    P = fibres.points
    return capsule_surface_hit(t, s, np.int64(fibres.seg_fiber[s]), np.float64(fibres.seg_r[s]),
                               P[ia, 0], P[ia, 1], P[ia, 2], P[ia + 1, 0], P[ia + 1, 1], P[ia + 1, 2],
                               ox, oy, oz, dx, dy, dz)


@njit(cache=True, inline="always")
def capsule_surface_hit(t, s, fiber, r, ax, ay, az, bx, by, bz, ox, oy, oz, dx, dy, dz):
    """The ``SurfaceHit`` of a ray (o, d) meeting capsule s (a -> b, radius r, of fibre ``fiber``) at t.
    16 parameters: the hit (t, segment, fibre, radius), the capsule's end points and the ray as scalars: every
    scene class (BVH, Embree, shell) builds its ``SurfaceHit`` here from numbers it holds in a layout of its own."""
    tl = math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2)
    if tl > 0.0:
        tx = (bx - ax) / tl
        ty = (by - ay) / tl
        tz = (bz - az) / tl
    else:
        tx = 1.0
        ty = 0.0
        tz = 0.0
    nx, ny, nz, _ = capsule_normal(ox + t * dx, oy + t * dy, oz + t * dz, ax, ay, az, bx, by, bz)
    return SurfaceHit(t, s, fiber, -1, tx, ty, tz, nx, ny, nz, r)


@njit(cache=True, _nrt=False)
def bvh_surface_hit(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window):
    t, s = intersect(bvh, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window)
    return segment_surface_hit(bvh, t, s, ox, oy, oz, dx, dy, dz)


answer_surface_queries(FiberBVH, bvh_surface_hit, occluded)

