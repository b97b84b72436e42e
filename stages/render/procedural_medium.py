"""Procedural density source (``--source procedural``): seed 000's realization-minimizing lookups.

At a point p the procedural tables answer Algorithm 1 on the fly (``stages.procedural.lookup``):
inside a fibre (regular, loop or hair) or not, the covering fibre's tangent, its yarn's density and
albedo; the yarn type gives the SGGX roughness. Nothing is realized.

ProceduralMedium fields: ``cv`` (``stages.core.curves.Curves`` of the yarns artifact) and ``tab``
(``stages.procedural.tables.Tables``).

Majorants: ``yarn_capsules(cv, tab, step_frac)`` covers each yarn's tube (every fibre surface lies
within ``yarn_extent`` of the axis) with capsules between axis points spaced at most
step_frac x extent in arc length; a capsule's radius is extent + half the spacing (any curve point
between two samples lies within half the arc length of one of them), its majorant the yarn's
density bound (``lookup.yarn_bound``). Outside every tube the majorant is zero.
"""
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.curves import curve_point_at
from stages.procedural.lookup import lookup_point, yarn_bound
from stages.procedural.yarn_model import ROUGHNESS

from .medium import is_source, medium_lookup

ProceduralMedium = namedtuple("ProceduralMedium", ["cv", "tab"])


@njit(cache=True)
def procedural_lookup(med, x, y, z):
    p = np.empty(3)
    p[0] = x
    p[1] = y
    p[2] = z
    r = lookup_point(med.cv, med.tab, p)
    if not r[0]:
        return 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    rough = med.tab.tparams[med.tab.yarn_type[r[1]], ROUGHNESS]
    return r[6], r[3], r[4], r[5], r[7], r[8], r[9], rough


@overload(medium_lookup)
def _procedural_overload(med, x, y, z):
    if is_source(med, ProceduralMedium):
        return lambda med, x, y, z: procedural_lookup(med, x, y, z)


@njit(cache=True)
def _count_pieces(cv, tab, step_frac):
    n = 0
    for c in range(cv.curve_length.shape[0]):
        ext, _ = yarn_bound(tab, c)
        step = max(step_frac * ext, 1e-12)
        n += max(1, int(np.ceil(cv.curve_length[c] / step)))
    return n


@njit(cache=True)
def yarn_capsules(cv, tab, step_frac):
    """(a (K, 3), b (K, 3), radius (K,), bound (K,)) capsules covering every yarn tube."""
    n = _count_pieces(cv, tab, step_frac)
    a = np.empty((n, 3))
    b = np.empty((n, 3))
    rad = np.empty(n)
    bound = np.empty(n)
    k = 0
    for c in range(cv.curve_length.shape[0]):
        ext, den = yarn_bound(tab, c)
        L = cv.curve_length[c]
        m = max(1, int(np.ceil(L / max(step_frac * ext, 1e-12))))
        h = L / m
        prev = curve_point_at(cv, c, 0.0)
        for i in range(m):
            nxt = curve_point_at(cv, c, min((i + 1) * h, L))
            a[k] = prev
            b[k] = nxt
            rad[k] = ext + 0.5 * h
            bound[k] = den
            prev = nxt
            k += 1
    return a, b, rad, bound
