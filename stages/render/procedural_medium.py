"""Procedural density source (``--source procedural``): seed 000's realization-minimizing lookups.

At a point p the procedural tables answer Algorithm 1 on the fly (``stages.core.yarn.lookup``):
inside a fibre (regular, loop or hair) or not, the covering fibre's tangent, its yarn's density and
albedo; the yarn type gives the SGGX roughness. Nothing is realized.

ProceduralMedium fields: ``cv`` (``stages.core.curves.spline.Curves`` of the yarns artifact) and ``tab``
(``stages.core.yarn.tables.Tables``).

Majorants: ``fiber_capsules(cv, tab, step_frac)`` gives capsules that hold every fibre surface,
each carrying its yarn's density (the majorant grid takes the largest bound of the capsules that
reach a cell; zero elsewhere): the *core* tube of the regular fibres (radius ply_radius + rho_max
R_max max(e_short, e_long) + the fibre radius, far inside the hair extent) as capsules between axis
points spaced step_frac x that radius apart (radius + half the spacing: any curve point between
two samples lies within half the arc length of one), plus every loop cycle and every stored hair
(hybrid mode) as a chain of capsules along its centre curve (Eq. 7 with the sampled frames;
radius: fibre radius + half a sample step times the curve's fabric-space speed bound + 2 eps_c).
In the realization-free hair mode (nothing stored per hair) the yarn's full extent tube
(``yarn_extent``, hairs included) stands in for the core tube.
"""
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

import math

from stages.core.curves.spline import curve_point_at
from stages.core.yarn.frame_samples import eq7, frame_at
from stages.core.yarn.lookup import lookup_point
from stages.core.yarn.tables import loop_fibre
from stages.core.yarn.model import (DENSITY, E_LONG, E_SHORT, FIBER_RADIUS, PLY_NUM, PLY_RADIUS, R_MAX, RHO_MAX, ROUGHNESS, USE_MIGRATION, hair_point, hair_speed_bound, regular_xy, transverse_speed_bound)

from stages.core.dispatch import is_tuple_class
from stages.render.medium import NO_MEDIUM, MediumPoint, medium_lookup

ProceduralMedium = namedtuple("ProceduralMedium", ["cv", "tab"])


@njit(cache=True)
def procedural_lookup(med, x, y, z):
    r = lookup_point(med.cv, med.tab, x, y, z)
    if not r.inside:
        return NO_MEDIUM
    rough = med.tab.tparams[med.tab.yarn_type[r.yarn], ROUGHNESS]
    return MediumPoint(r.density, r.dir_x, r.dir_y, r.dir_z, r.albedo_r, r.albedo_g, r.albedo_b, rough,
                       np.int64(r.yarn), np.int64(r.fibre))


@overload(medium_lookup)
def _procedural_overload(med, x, y, z):
    if is_tuple_class(med, ProceduralMedium):
        return lambda med, x, y, z: procedural_lookup(med, x, y, z)


@njit(cache=True)
def _core_radius(tp):
    U = tp[R_MAX] * (tp[RHO_MAX] if tp[USE_MIGRATION] != 0.0 else 1.0)
    return tp[PLY_RADIUS] + U * max(tp[E_SHORT], tp[E_LONG]) + tp[FIBER_RADIUS]


@njit(cache=True, inline="always")
def _put_capsule(a, b, rad, bound, m, px, py, pz, qx, qy, qz, r, den):
    """Write capsule m (segment p-q, radius r, majorant den); returns m + 1."""
    a[m, 0], a[m, 1], a[m, 2] = px, py, pz
    b[m, 0], b[m, 1], b[m, 2] = qx, qy, qz
    rad[m] = r
    bound[m] = den
    return m + 1


@njit(cache=True)
def _fabric_point(tab, lo, hi, i, x, y, z):
    i, f = frame_at(tab.fs_s, tab.fs_frame, lo, hi, i, z)
    X, Y, Z = eq7(f, x, y)
    return i, X, Y, Z


@njit(cache=True)
def fiber_capsules(cv, tab, step_frac, hair_samples=16, loop_step_fibers=2.0):
    """(a (K, 3), b (K, 3), radius (K,), bound (K,)) capsules covering every fibre surface: core
    tubes, loop cycles and (hybrid mode) hairs; in the realization-free mode each yarn's full
    extent tube stands in for its hairs. Needs the tables' derived frame samples."""
    ncap = 0
    Y = cv.curve_length.shape[0]
    # count
    for c in range(Y):
        tp = tab.tparams[tab.yarn_type[c]]
        core = _core_radius(tp)
        ext = tab.yarn_extent[c]
        hair_tube = tab.hair_mode[0] != 0 and tab.hair_count[tab.yarn_ply_off[c]:tab.yarn_ply_off[c + 1]].sum() > 0
        r_tube = ext if hair_tube else core
        ncap += max(1, int(np.ceil(cv.curve_length[c] / max(step_frac * r_tube, 1e-12))))
        rf = tp[FIBER_RADIUS]
        for k in range(int(tp[PLY_NUM])):
            g = tab.yarn_ply_off[c] + k
            for e in range(tab.lp_off[g], tab.lp_off[g + 1]):
                ncap += 1 + _loop_steps(tab, tp, c, k, e, rf * loop_step_fibers)
            if tab.hair_mode[0] == 0:
                ncap += tab.hair_count[g] * (hair_samples - 1)
    a = np.empty((ncap, 3))
    b = np.empty((ncap, 3))
    rad = np.empty(ncap)
    bound = np.empty(ncap)
    m = 0
    for c in range(Y):
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        den = tp[DENSITY]
        eps = tab.yarn_eps[c]
        rf = tp[FIBER_RADIUS]
        gmax = 2.0 - tab.yarn_gmin[c]
        lo = tab.fs_off[c]
        hi = tab.fs_off[c + 1]
        L = cv.curve_length[c]
        core = _core_radius(tp)
        hair_tube = tab.hair_mode[0] != 0 and tab.hair_count[tab.yarn_ply_off[c]:tab.yarn_ply_off[c + 1]].sum() > 0
        r_tube = tab.yarn_extent[c] if hair_tube else core
        nt = max(1, int(np.ceil(L / max(step_frac * r_tube, 1e-12))))
        h = L / nt
        prev = curve_point_at(cv, c, 0.0)
        for q in range(nt):
            nxt = curve_point_at(cv, c, min((q + 1) * h, L))
            a[m] = prev
            b[m] = nxt
            rad[m] = r_tube + 0.5 * h + eps
            bound[m] = den
            prev = nxt
            m += 1
        yseed = np.uint64(tab.yarn_seed[c])
        # fabric-space speed of a regular/loop fibre: g_max (axial) + its yarn-space transverse speed
        vfib = gmax + transverse_speed_bound(tp)
        for k in range(int(tp[PLY_NUM])):
            g = tab.yarn_ply_off[c] + k
            for e in range(tab.lp_off[g], tab.lp_off[g + 1]):
                j, fi, z0, z1 = loop_fibre(tab, tp, c, k, e)
                ns = _loop_steps(tab, tp, c, k, e, rf * loop_step_fibers)
                dz = (z1 - z0) / ns
                x, y, kd = regular_xy(tp, yseed, k, j, tab.fib_R[fi], tab.fib_th[fi], tab.fib_th0[fi], z0)
                i = lo
                i, px, py, pz = _fabric_point(tab, lo, hi, i, x, y, z0)
                for q in range(ns):
                    z = min(z0 + (q + 1) * dz, z1)
                    x, y, kd = regular_xy(tp, yseed, k, j, tab.fib_R[fi], tab.fib_th[fi], tab.fib_th0[fi], z)
                    i, qx, qy, qz = _fabric_point(tab, lo, hi, i, x, y, z)
                    m = _put_capsule(a, b, rad, bound, m, px, py, pz, qx, qy, qz, rf + 0.5 * vfib * dz + 2.0 * eps, den)
                    px, py, pz = qx, qy, qz
            if tab.hair_mode[0] == 0:
                base = tab.hair_off[g]
                for hh in range(base, base + tab.hair_count[g]):
                    r0 = tab.hair_r0[hh]
                    r1 = tab.hair_r1[hh]
                    th1 = tab.hair_th1[hh]
                    pe = tab.hair_pe[hh]
                    z1 = tab.hair_z1[hh]
                    ze = tab.hair_ze[hh]
                    speed = hair_speed_bound(tp, r0, r1, pe, ze) * max(gmax, 1.0)
                    dt = 1.0 / (hair_samples - 1)
                    i = lo
                    x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, 0.0)
                    i, px, py, pz = _fabric_point(tab, lo, hi, i, x, y, z)
                    for q in range(hair_samples - 1):
                        tq = min((q + 1) * dt, 1.0)
                        x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, tq)
                        i, qx, qy, qz = _fabric_point(tab, lo, hi, i, x, y, z)
                        m = _put_capsule(a, b, rad, bound, m, px, py, pz, qx, qy, qz,
                                         rf + 0.5 * speed * dt + 2.0 * eps, den)
                        px, py, pz = qx, qy, qz
    return a[:m], b[:m], rad[:m], bound[:m]


@njit(cache=True)
def _loop_steps(tab, tp, c, k, e, step):
    _, _, z0, z1 = loop_fibre(tab, tp, c, k, e)
    return max(1, int(math.ceil((z1 - z0) / step)))
