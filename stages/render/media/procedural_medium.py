"""Procedural density source (``--source procedural``): seed 000's realization-minimizing lookups.

At a point p the procedural tables answer Algorithm 1 on the fly (``stages.core.yarn.lookup``):
inside a fibre (regular, loop or hair) or not, the covering fibre's tangent, its yarn's density and
albedo; the yarn type gives the SGGX roughness. Nothing is realized.

ProceduralMedium fields: ``cv`` (``stages.core.curves.spline.Curves`` of the yarns artifact) and ``tab``
(``stages.core.yarn.tables.Tables``).

Majorants: ``tube_box(cv, tab, step_frac)`` gives a box holding every fibre from the yarns' extent tubes
(``yarn_extent``, hairs included) walked along their axes only (a large cloth's box: pipeline.renderers.volpath);
``capsule_box(cv, tab, step_frac)`` and ``capsule_majorants(cv, tab, step_frac, lo, hi, res)`` walk capsules
that hold every fibre surface, each carrying its yarn's density, without storing them (a 1,000-yarn fabric has
some 10^8), and give their box and the majorant grid (a cell
takes the largest bound of the capsules that reach it; zero elsewhere): the *core* tube of the
regular fibres (radius ply_radius + rho_max R_max max(e_short, e_long) + the fibre radius, far inside
the hair extent) as capsules between axis points spaced step_frac x that radius apart (radius + half
the spacing: any curve point between two samples lies within half the arc length of one), plus every
loop cycle and every stored hair (hybrid mode) as a chain of capsules along its centre curve (Eq. 7
with the sampled frames; radius: fibre radius + half a sample step times the curve's fabric-space
speed bound + 2 eps_c). In the realization-free hair mode (nothing stored per hair) the yarn's full
extent tube (``yarn_extent``, hairs included) stands in for the core tube.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.curves.spline import curve_point_at
from stages.core.threads import chunk_kernel, for_chunks
from stages.core.yarn.fibre_tests import stored_hair
from stages.core.yarn.frame_samples import eq7, frame_at
from stages.core.yarn.lookup import lookup_point
from stages.core.yarn.model import (
    DENSITY,
    E_LONG,
    E_SHORT,
    FIBER_RADIUS,
    PLY_NUM,
    PLY_RADIUS,
    R_MAX,
    RHO_MAX,
    ROUGHNESS,
    USE_MIGRATION,
    hair_point,
    hair_speed_bound,
    regular_xy,
    transverse_speed_bound,
)
from stages.core.yarn.tables import loop_fibre
from stages.render.media.medium import NO_MEDIUM, PAGED_OUT, MediumPoint, register_medium
from stages.render.media.tracking import cell_half_diagonal, raster_capsule

ProceduralMedium = namedtuple("ProceduralMedium", ["cv", "tab"])


@njit(cache=True, _nrt=False)
def procedural_lookup(med, x, y, z, skip=-1):
    missed = med.tab.fs_miss[0]
    r = lookup_point(med.cv, med.tab, x, y, z, np.int64(skip))  # a literal skip would compile it again
    if med.tab.fs_miss[0] != missed:  # a yarn's frame samples were not resident (paged tables): no answer yet
        return PAGED_OUT
    if not r.inside:
        return NO_MEDIUM
    rough = med.tab.tparams[med.tab.yarn_type[r.yarn], ROUGHNESS]
    return MediumPoint(r.density, r.dir_x, r.dir_y, r.dir_z, r.albedo_r, r.albedo_g, r.albedo_b, rough,
                       np.int64(r.yarn), np.int64(r.fibre))


register_medium(ProceduralMedium, procedural_lookup)


@njit(cache=True)
def _core_radius(tp):
    U = tp[R_MAX] * (tp[RHO_MAX] if tp[USE_MIGRATION] != 0.0 else 1.0)
    return tp[PLY_RADIUS] + U * max(tp[E_SHORT], tp[E_LONG]) + tp[FIBER_RADIUS]


BOX_SIZE = 7  # a walk's box: min x, y, z, max x, y, z of the capsules' end points, their largest radius
BOX, RASTER = 0, 1  # what a walk does with each capsule


@njit(cache=True, inline="always")
def _emit(mode, box, mu, lo, cs, half_diag, res, px, py, pz, qx, qy, qz, r, den):
    """One capsule (segment p-q, radius r, density bound den) of a walk: grow the box, or raster it.
    15 parameters: the walk's accumulator (mode, box, grid, origin, cell size, half diagonal, resolution), the
    capsule and its density bound."""
    if mode == BOX:
        box[0] = min(box[0], px, qx)
        box[1] = min(box[1], py, qy)
        box[2] = min(box[2], pz, qz)
        box[3] = max(box[3], px, qx)
        box[4] = max(box[4], py, qy)
        box[5] = max(box[5], pz, qz)
        box[6] = max(box[6], r)
    else:
        raster_capsule(mu, lo, cs, half_diag, res, px, py, pz, qx, qy, qz, r, den)


@njit(cache=True)
def _fabric_point(tab, lo, hi, i, x, y, z):
    i, f = frame_at(tab.fs_s, tab.fs_frame, lo, hi, i, z)
    X, Y, Z = eq7(f, x, y)
    return i, X, Y, Z


@njit(cache=True)
def _walk_yarn(cv, tab, c, step_frac, hair_samples, loop_step_fibers, mode, box, mu, glo, cs, half_diag, res):
    """Every capsule of yarn c (module doc: core tube, loop cycles, hybrid-mode hairs; the extent
    tube in the realization-free hair mode), each handed to _emit. Needs the derived frame samples.
    13 parameters: the fabric and yarn, the walk's sampling settings and its accumulator (``_emit``'s)."""
    t = tab.yarn_type[c]
    tp = tab.tparams[t]
    den = tp[DENSITY]
    eps = tab.yarn_eps[c]
    rf = tp[FIBER_RADIUS]
    gmax = 2.0 - tab.yarn_gmin[c]
    lo = tab.fs_at[c]
    hi = lo + tab.fs_n[c]
    L = cv.curve_length[c]
    core = _core_radius(tp)
    hair_tube = tab.hair_mode[0] != 0 and tab.hair_count[tab.yarn_ply_off[c]:tab.yarn_ply_off[c + 1]].sum() > 0
    r_tube = tab.yarn_extent[c] if hair_tube else core
    nt = max(1, int(np.ceil(L / max(step_frac * r_tube, 1e-12))))
    h = L / nt
    prev = curve_point_at(cv, c, 0.0)
    for q in range(nt):
        nxt = curve_point_at(cv, c, min((q + 1) * h, L))
        _emit(mode, box, mu, glo, cs, half_diag, res, prev[0], prev[1], prev[2], nxt[0], nxt[1], nxt[2],
              r_tube + 0.5 * h + eps, den)
        prev = nxt
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
                _emit(mode, box, mu, glo, cs, half_diag, res, px, py, pz, qx, qy, qz,
                      rf + 0.5 * vfib * dz + 2.0 * eps, den)
                px, py, pz = qx, qy, qz
        if tab.hair_mode[0] == 0:
            base = tab.hair_off[g]
            for hh in range(base, base + tab.hair_count[g]):
                hs = stored_hair(tab, hh)
                speed = hair_speed_bound(tp, hs.r0, hs.r1, hs.pe, hs.ze) * max(gmax, 1.0)
                dt = 1.0 / (hair_samples - 1)
                i = lo
                x, y, z = hair_point(tp, k, hs.r0, hs.r1, hs.th1, hs.pe, hs.z1, hs.ze, 0.0)
                i, px, py, pz = _fabric_point(tab, lo, hi, i, x, y, z)
                for q in range(hair_samples - 1):
                    tq = min((q + 1) * dt, 1.0)
                    x, y, z = hair_point(tp, k, hs.r0, hs.r1, hs.th1, hs.pe, hs.z1, hs.ze, tq)
                    i, qx, qy, qz = _fabric_point(tab, lo, hi, i, x, y, z)
                    _emit(mode, box, mu, glo, cs, half_diag, res, px, py, pz, qx, qy, qz,
                          rf + 0.5 * speed * dt + 2.0 * eps, den)
                    px, py, pz = qx, qy, qz


@njit(cache=True)
def _axis_box(cv, tab, c, step_frac, box):
    """Grow box (min x, y, z, max x, y, z) by yarn c's extent tube (``yarn_extent``, hairs included): capsules of
    radius yarn_extent + half the step + eps_c between axis points step_frac x the extent apart."""
    r = tab.yarn_extent[c]
    L = cv.curve_length[c]
    nt = max(1, int(np.ceil(L / max(step_frac * r, 1e-12))))
    h = L / nt
    rr = r + 0.5 * h + tab.yarn_eps[c]
    for q in range(nt + 1):
        p = curve_point_at(cv, c, min(q * h, L))
        for a in range(3):
            box[a] = min(box[a], p[a] - rr)
            box[3 + a] = max(box[3 + a], p[a] + rr)


def tube_box(cv, tab, step_frac):
    """(lo (3,), hi (3,)): the box of the yarns' extent tubes, which hold every fibre: looser than
    ``capsule_box``'s but from the axes alone (no loop or hair is walked), for a grid too coarse to feel the
    difference (yarns on threads)."""
    Y = cv.curve_length.shape[0]
    boxes = np.empty((Y, 6))
    boxes[:, :3] = np.inf
    boxes[:, 3:] = -np.inf
    for_chunks(_tube_boxes, Y, cv, tab, float(step_frac), boxes)
    return boxes[:, :3].min(axis=0), boxes[:, 3:].max(axis=0)


@chunk_kernel
def _tube_boxes(cv, tab, step_frac, boxes, c0, c1):
    """``tube_box``'s per-yarn boxes of yarns c0 .. c1 - 1."""
    for c in range(c0, c1):
        _axis_box(cv, tab, c, step_frac, boxes[c])


def capsule_box(cv, tab, step_frac, hair_samples=16, loop_step_fibers=2.0, yarns=None, grown=True):
    """(lo (3,), hi (3,)): the box of every fibre-holding capsule (module doc) of ``yarns`` (default all;
    their frame samples resident), grown by the largest capsule radius; ``grown`` False: (lo, hi, that
    radius), the box of the capsules' end points and the radius apart (boxes of several walks meet so).
    Walks the capsules without storing them (yarns on threads: ``stages.core.threads``)."""
    yarns = _yarn_list(cv, yarns)
    boxes = np.empty((len(yarns), BOX_SIZE))
    boxes[:, :3] = np.inf
    boxes[:, 3:] = -np.inf
    for_chunks(_box_yarns, len(yarns), cv, tab, float(step_frac), int(hair_samples), float(loop_step_fibers), yarns,
               boxes)
    rmax = boxes[:, 6].max()
    if not grown:
        return boxes[:, :3].min(axis=0), boxes[:, 3:6].max(axis=0), rmax
    return boxes[:, :3].min(axis=0) - rmax, boxes[:, 3:6].max(axis=0) + rmax


def _yarn_list(cv, yarns):
    return np.arange(cv.curve_length.shape[0], dtype=np.int64) if yarns is None else np.asarray(yarns, np.int64)


@chunk_kernel
def _box_yarns(cv, tab, step_frac, hair_samples, loop_step_fibers, yarns, boxes, k0, k1):
    """``capsule_box``'s boxes of the listed yarns k0 .. k1 - 1."""
    dummy_mu = np.zeros((1, 1, 1))
    dummy3 = np.zeros(3)
    dummy_res = np.ones(3, np.int64)
    for k in range(k0, k1):
        # mode typed as _raster_workers passes it, so _walk_yarn compiles once
        _walk_yarn(cv, tab, yarns[k], step_frac, hair_samples, loop_step_fibers, np.int64(BOX), boxes[k], dummy_mu,
                   dummy3, dummy3, 0.0, dummy_res)


def capsule_majorants(cv, tab, step_frac, lo, hi, res, workers, hair_samples=16, loop_step_fibers=2.0, yarns=None,
                      into=None):
    """Majorant densities (nz, ny, nx) over the box lo-hi at resolution res: a cell takes the largest
    density of the fibre-holding capsules that may reach it (tracking.raster_capsule), of ``yarns``
    (default all; their frame samples resident), and of ``into`` (a grid of earlier yarns, raised in
    place). The capsules are walked, never stored: memory is one grid per worker (pass numba's thread
    count), whatever the fabric's size. Workers take yarns round robin and their grids meet by maximum,
    so the result does not depend on their number."""
    yarns = _yarn_list(cv, yarns)
    T = min(max(int(workers), 1), max(len(yarns), 1))
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    res = np.asarray(res, np.int64)
    grids = np.zeros((T, res[2], res[1], res[0]))
    cs = (hi - lo) / res
    half_diag = cell_half_diagonal(cs)
    for_chunks(_raster_workers, T, cv, tab, float(step_frac), int(hair_samples), float(loop_step_fibers), yarns, lo,
               cs, half_diag, res, grids, threads=T)
    mu = grids.max(axis=0) if T > 1 else grids[0]
    if into is None:
        return mu
    np.maximum(into, mu, out=into)
    return into


@chunk_kernel
def _raster_workers(cv, tab, step_frac, hair_samples, loop_step_fibers, yarns, lo, cs, half_diag, res, grids, w0,
                    w1):
    """``capsule_majorants``' workers w0 .. w1 - 1: worker w rasters the listed yarns w, w + T, ... into
    grids[w].
    13 parameters: the fabric, the walk's sampling settings, the yarns listed, the grid's geometry and the
    per-worker grids, and the chunk of workers."""
    T = grids.shape[0]
    box = np.empty(BOX_SIZE)
    for w in range(w0, w1):
        for k in range(w, yarns.shape[0], T):
            _walk_yarn(cv, tab, yarns[k], step_frac, hair_samples, loop_step_fibers, np.int64(RASTER), box, grids[w],
                       lo, cs, half_diag, res)


@njit(cache=True)
def _loop_steps(tab, tp, c, k, e, step):
    _, _, z0, z1 = loop_fibre(tab, tp, c, k, e)
    return max(1, int(math.ceil((z1 - z0) / step)))
