"""Render-time fibre cache of the procedural source (``--source procedural --cache MiB``, seed 000 §6).

The procedural lookups answer any point of any yarn without storing a fibre, but their fixed cost
(candidate yarns, foot point, frame: Algorithm 1 before any fibre test) is many times a capsule BVH's
whole query. The cache realizes, at render setup, the fibres of the parts of the yarns the render
looks at, into a capsule BVH under a memory budget; every other point is answered by the exact
lookups. Both describe one fabric: the cached fibres are runs of the full realization's vertices
(same random numbers, same floats: ``stages.procedural.realize.window_pieces``).

Bricks. The majorant grid's box is cut into cubic *bricks* (``BrickGrid``: at least twice the
largest yarn extent wide, at most ``MAX_BRICKS_PER_AXIS`` along an axis). A brick is *cached* when
every fibre segment whose capsule meets it is in the cache; then the cache's answer inside it (the
covering segment of the lowest fibre: ``realized_medium.covering_segment``) is the realized
reference's answer, and a lookup there costs a BVH query. Elsewhere the procedural lookup answers.

Which segments a brick needs. Each yarn's arc length is cut into *samples* of length ds (about
half a brick). A fibre point at yarn parameter z lies within the yarn's extent of the axis at z;
a segment's ends are at most ``spacing`` apart in z. So a segment with an end in sample j lies in
the ball of radius R_j = extent + spacing + ds / 2 about the sample's axis midpoint, and a brick
needs (at most) the samples whose ball's box meets it (``sample_bricks``). Realizing a sample
realizes every segment with an end in it, and the hairs whose z range meets it.

Which bricks. A pilot (``pilot_bricks``, no lookups, no random numbers) marches camera rays through
the majorant grid until the majorant optical depth passes ``PILOT_DEPTH`` and counts its steps in
fibre material per brick. Bricks with fibre material are ordered (``brick_order``): those the pilot
marched through, most steps first (where the camera looks longest), then their neighbours (the first
bounce stays near), then every other, ties by distance to the camera. In that order a brick is
cached when the samples it needs (``brick_samples``) that are not yet taken fit what is left of the
budget, their estimated bytes (``choose_bricks``; a brick that does not fit is passed over). So the
cost grows with what the camera sees, not with the scene, and a budget of 0 caches nothing.

``FibreCacheMedium`` fields: ``proc`` (the ``ProceduralMedium`` that answers elsewhere), ``brick_lo``
(3,), ``brick_inv`` (3,) (1 / brick size), ``brick_res`` (3,) int64, ``cached`` (nz * ny * nx,) uint8,
``bvh`` (``FiberBVH`` of the cached fibres), ``fibre_yarn`` (F,) int32, ``fibre_id`` (F,) int64 (the
procedural lookup's fibre number: yarn, ply, regular or hair, index; the pieces of one fibre share
it), per yarn ``yarn_density``, ``yarn_albedo`` (Y, 3), ``yarn_roughness`` (the tables' values), and
the BVH arrays a lookup reads (``wide_box``, ``wide_child``, ``prims``, ``seg_fiber``, ``points``,
``seg_a``) again at the top level. The lookup is compiled without reference counting (as the whole
volpath estimator is, ``stages.render.integrators.volpath``), so nesting the tables' ~80 arrays in the medium costs
nothing per lookup (with reference counting, the atomic counts on them had been 80 % of a render). Its
``medium_lookup`` returns the procedural source's
``MediumPoint``: the yarn type's density and roughness, the yarn's albedo, the segment's tangent.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.curves.spline import curve_point_at
from stages.core.yarn.lookup import FIBRE_ID_STRIDE, ORDER_STRIDE
from stages.render.camera import camera_ray_into
from stages.render.media.medium import NO_MEDIUM, MediumPoint, register_medium
from stages.render.media.procedural_medium import procedural_lookup
from stages.render.media.realized_medium import covering_segment_arrays, segment_tangent
from stages.render.media.tracking import ray_box

MAX_BRICKS_PER_AXIS = 256
PILOT_DEPTH = 8.0  # majorant optical depth a pilot ray marches into the fabric (e^-8: 3e-4 of the light gets further)

FibreCacheMedium = namedtuple("FibreCacheMedium", ["proc", "brick_lo", "brick_inv", "brick_res", "cached", "bvh",
                                                   "fibre_yarn", "fibre_id", "yarn_density", "yarn_albedo",
                                                   "yarn_roughness", "wide_box", "wide_child", "prims", "seg_fiber",
                                                   "points", "seg_a"])
BrickGrid = namedtuple("BrickGrid", ["lo", "size", "res"])
BrickGrid.__doc__ = """Cubic bricks over a box: lo (3,), size (scalar edge), res (3,) int64 (nx, ny, nz)."""
YarnSamples = namedtuple("YarnSamples", ["yarn", "s0", "s1", "centre", "radius"])
YarnSamples.__doc__ = """Arc-length samples of the yarns: yarn (n,) int64, [s0, s1] (n,), the axis midpoint (n, 3)
and the radius of the ball that holds every segment with an end in the sample (n,)."""


def brick_grid(lo, hi, max_extent, centred=False) -> BrickGrid:
    """Bricks at least 2 x the largest yarn extent wide, at most MAX_BRICKS_PER_AXIS along an axis, from the
    box's corner, or ``centred`` on the box (a flat cloth two bricks thick is then split at its middle, not in a
    sliver of crowns that no brick's occupancy sees)."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    ext = np.maximum(hi - lo, 1e-12)
    size = max(2.0 * float(max_extent), float(ext.max()) / MAX_BRICKS_PER_AXIS)
    res = np.maximum(1, np.ceil(ext / size)).astype(np.int64)
    if centred:
        lo = 0.5 * (lo + hi) - 0.5 * size * res
    return BrickGrid(lo, size, res)


@njit(cache=True, inline="always")
def _brick_index(lo, inv, res, x, y, z):
    """Flat index (z, y, x order) of the brick holding (x, y, z), or -1 outside the grid."""
    fx = (x - lo[0]) * inv[0]
    fy = (y - lo[1]) * inv[1]
    fz = (z - lo[2]) * inv[2]
    if not (fx >= 0.0 and fy >= 0.0 and fz >= 0.0):
        return -1
    ix = int(fx)
    iy = int(fy)
    iz = int(fz)
    if ix >= res[0] or iy >= res[1] or iz >= res[2]:
        return -1
    return (iz * res[1] + iy) * res[0] + ix


@njit(cache=True, _nrt=False)
def fibre_cache_lookup(med, x, y, z, skip=-1):
    """The cache's answer in a cached brick (the covering segment of the lowest fibre but ``skip``, its
    tangent), else the procedural lookup's."""
    b = _brick_index(med.brick_lo, med.brick_inv, med.brick_res, x, y, z)
    if b < 0 or med.cached[b] == 0:
        return procedural_lookup(med.proc, x, y, z, skip)
    s = covering_segment_arrays(med.wide_box, med.wide_child, med.prims, med.seg_fiber, x, y, z, skip,
                                med.fibre_id)
    if s < 0:
        return NO_MEDIUM
    tx, ty, tz = segment_tangent(med.points, med.seg_a, s)
    f = med.seg_fiber[s]
    c = med.fibre_yarn[f]
    return MediumPoint(med.yarn_density[c], tx, ty, tz, med.yarn_albedo[c, 0], med.yarn_albedo[c, 1],
                       med.yarn_albedo[c, 2], med.yarn_roughness[c], np.int64(c), med.fibre_id[f])


register_medium(FibreCacheMedium, fibre_cache_lookup)


# ------------------------------------------------------------------------------------------------
# which bricks
@njit(cache=True)
def occupied_bricks(maj, lo, size, res):
    """uint8 (nz * ny * nx): 1 where a majorant cell with a non-zero bound overlaps the brick."""
    occ = np.zeros(res[0] * res[1] * res[2], np.uint8)
    nx, ny, nz = maj.res[0], maj.res[1], maj.res[2]
    cs = (maj.hi - maj.lo) / maj.res
    for iz in range(nz):
        for iy in range(ny):
            for ix in range(nx):
                if maj.mu[iz, iy, ix] <= 0.0:
                    continue
                a0 = (maj.lo[0] + ix * cs[0] - lo[0]) / size
                a1 = (maj.lo[1] + iy * cs[1] - lo[1]) / size
                a2 = (maj.lo[2] + iz * cs[2] - lo[2]) / size
                for bz in range(max(0, int(math.floor(a2))), min(res[2], int(math.floor(a2 + cs[2] / size)) + 1)):
                    for by in range(max(0, int(math.floor(a1))), min(res[1], int(math.floor(a1 + cs[1] / size)) + 1)):
                        for bx in range(max(0, int(math.floor(a0))),
                                        min(res[0], int(math.floor(a0 + cs[0] / size)) + 1)):
                            occ[(bz * res[1] + by) * res[0] + bx] = 1
    return occ


@njit(cache=True)
def pilot_bricks(maj, cam, width, height, stride, lo, size, res, depth):
    """Pilot of the camera's view: per brick, the number of march steps (half a majorant cell) of the
    pilot camera rays (every ``stride``-th pixel centre) in fibre material (majorant > 0) before
    their majorant optical depth exceeds ``depth`` (int64), and uint8 1 for those bricks and their
    26 neighbours (the first bounce stays near)."""
    nb = res[0] * res[1] * res[2]
    steps = np.zeros(nb, np.int64)
    o = np.empty(3)
    d = np.empty(3)
    cs0 = (maj.hi[0] - maj.lo[0]) / maj.res[0]
    cs1 = (maj.hi[1] - maj.lo[1]) / maj.res[1]
    cs2 = (maj.hi[2] - maj.lo[2]) / maj.res[2]
    h = 0.5 * min(cs0, min(cs1, cs2))
    for row in range(0, height, stride):
        for col in range(0, width, stride):
            camera_ray_into(cam, row, col, 0.5, 0.5, o, d)
            t0, t1 = ray_box(maj.lo, maj.hi, o[0], o[1], o[2], d[0], d[1], d[2])
            t = max(t0, 0.0)
            tau = 0.0
            while t < t1 and tau < depth:
                x = o[0] + t * d[0]
                y = o[1] + t * d[1]
                z = o[2] + t * d[2]
                ix = min(max(int(math.floor((x - maj.lo[0]) / cs0)), 0), maj.res[0] - 1)
                iy = min(max(int(math.floor((y - maj.lo[1]) / cs1)), 0), maj.res[1] - 1)
                iz = min(max(int(math.floor((z - maj.lo[2]) / cs2)), 0), maj.res[2] - 1)
                mu = maj.mu[iz, iy, ix]
                if mu > 0.0:
                    tau += mu * h
                    bx = min(max(int(math.floor((x - lo[0]) / size)), 0), res[0] - 1)
                    by = min(max(int(math.floor((y - lo[1]) / size)), 0), res[1] - 1)
                    bz = min(max(int(math.floor((z - lo[2]) / size)), 0), res[2] - 1)
                    steps[(bz * res[1] + by) * res[0] + bx] += 1
                t += h
    seen = np.zeros(nb, np.uint8)
    for bz in range(res[2]):
        for by in range(res[1]):
            for bx in range(res[0]):
                if steps[(bz * res[1] + by) * res[0] + bx] == 0:
                    continue
                for qz in range(max(0, bz - 1), min(res[2], bz + 2)):
                    for qy in range(max(0, by - 1), min(res[1], by + 2)):
                        for qx in range(max(0, bx - 1), min(res[0], bx + 2)):
                            seen[(qz * res[1] + qy) * res[0] + qx] = 1
    return steps, seen


def brick_order(occupied, steps, seen, lo, size, res, eye) -> np.ndarray:
    """The bricks with fibre material (no lookup happens elsewhere) in caching order (int64): those
    the pilot rays marched through, most steps first; then their neighbours; then the others; ties
    by distance of the brick's centre to ``eye``. A stable sort: the same scene, the same order."""
    nx, ny, nz = (int(v) for v in res)
    iz, iy, ix = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    centre = np.stack([ix.ravel(), iy.ravel(), iz.ravel()], 1) * size + lo + 0.5 * size
    dist = np.linalg.norm(centre - np.asarray(eye, np.float64), axis=1)
    cls = np.where(steps > 0, 0, np.where(seen.astype(bool), 1, 2))
    order = np.lexsort((dist, -steps, cls))
    order = order[occupied.astype(bool)[order]]
    return order


# ------------------------------------------------------------------------------------------------
# which samples
@njit(cache=True)
def yarn_samples(cv, tab, ds, spacing):
    """``YarnSamples`` of every yarn: ceil(L / ds) equal samples per yarn."""
    Y = cv.curve_length.shape[0]
    n = 0
    for c in range(Y):
        n += max(1, int(math.ceil(cv.curve_length[c] / ds)))
    yarn = np.empty(n, np.int64)
    s0 = np.empty(n)
    s1 = np.empty(n)
    centre = np.empty((n, 3))
    radius = np.empty(n)
    m = 0
    for c in range(Y):
        L = cv.curve_length[c]
        k = max(1, int(math.ceil(L / ds)))
        h = L / k
        for j in range(k):
            yarn[m] = c
            s0[m] = j * h
            s1[m] = (j + 1) * h if j + 1 < k else L
            p = curve_point_at(cv, c, (j + 0.5) * h)
            centre[m, 0] = p[0]
            centre[m, 1] = p[1]
            centre[m, 2] = p[2]
            radius[m] = tab.yarn_extent[c] + spacing + 0.5 * h + 1e-9 * (1.0 + L)
            m += 1
    return YarnSamples(yarn, s0, s1, centre, radius)


@njit(cache=True)
def _sample_brick_range(samples, m, lo, size, res):
    """The brick index box (b0, b1 inclusive, per axis) that sample m's ball's box meets; empty: b1 < b0."""
    r = samples.radius[m]
    b0 = np.empty(3, np.int64)
    b1 = np.empty(3, np.int64)
    for d in range(3):
        b0[d] = max(0, int(math.floor((samples.centre[m, d] - r - lo[d]) / size)))
        b1[d] = min(res[d] - 1, int(math.floor((samples.centre[m, d] + r - lo[d]) / size)))
    return b0, b1


@njit(cache=True)
def brick_samples(samples, lo, size, res):
    """CSR (offsets per brick, sample indices) of the samples whose ball's box meets each brick."""
    n = samples.yarn.shape[0]
    nb = res[0] * res[1] * res[2]
    count = np.zeros(nb + 1, np.int64)
    for m in range(n):
        b0, b1 = _sample_brick_range(samples, m, lo, size, res)
        for bz in range(b0[2], b1[2] + 1):
            for by in range(b0[1], b1[1] + 1):
                for bx in range(b0[0], b1[0] + 1):
                    count[(bz * res[1] + by) * res[0] + bx + 1] += 1
    off = np.cumsum(count)
    fill = off[:-1].copy()
    items = np.empty(off[-1], np.int64)
    for m in range(n):
        b0, b1 = _sample_brick_range(samples, m, lo, size, res)
        for bz in range(b0[2], b1[2] + 1):
            for by in range(b0[1], b1[1] + 1):
                for bx in range(b0[0], b1[0] + 1):
                    b = (bz * res[1] + by) * res[0] + bx
                    items[fill[b]] = m
                    fill[b] += 1
    return off, items


@njit(cache=True)
def choose_bricks(order, off, items, sample_bytes, budget):
    """Greedy in ranking order: a brick is cached when the samples it needs that are not yet taken
    fit what is left of ``budget`` (bytes); one that does not fit is passed over. Returns (cached
    uint8 per brick, needed uint8 per sample, bytes used)."""
    nb = off.shape[0] - 1
    cached = np.zeros(nb, np.uint8)
    need = np.zeros(sample_bytes.shape[0], np.uint8)
    used = 0.0
    for b in order:
        add = 0.0
        for q in range(off[b], off[b + 1]):
            if need[items[q]] == 0:
                add += sample_bytes[items[q]]
        if used + add > budget:
            continue
        for q in range(off[b], off[b + 1]):
            need[items[q]] = 1
        cached[b] = 1
        used += add
    return cached, need, used


def windows(samples: YarnSamples, need: np.ndarray, n_yarns: int) -> list:
    """Per yarn the merged arc-length windows (w0, w1) of its needed samples (sorted, disjoint)."""
    out = []
    idx = np.flatnonzero(need)
    yarn = samples.yarn[idx]
    for c in range(n_yarns):
        sel = idx[yarn == c]
        if not len(sel):
            out.append((np.zeros(0), np.zeros(0)))
            continue
        brk = np.flatnonzero(np.diff(sel) > 1)
        starts = np.concatenate([[0], brk + 1])
        ends = np.concatenate([brk, [len(sel) - 1]])
        out.append((samples.s0[sel[starts]].copy(), samples.s1[sel[ends]].copy()))
    return out


def fibre_ids(yarn, ply, kind, index) -> np.ndarray:
    """The procedural lookup's fibre number of realized pieces (``stages.core.yarn.lookup``)."""
    key = (2 * ply.astype(np.int64) + (kind == 3)) * ORDER_STRIDE + index.astype(np.int64)
    return yarn.astype(np.int64) * FIBRE_ID_STRIDE + key


# ------------------------------------------------------------------------------------------------
# majorants
@njit(cache=True)
def cells_in_cached_bricks(maj, lo, size, res, cached):
    """bool (nz, ny, nx): majorant cells that lie inside cached bricks only (there the cached
    capsules bound the density: every segment meeting such a cell is cached)."""
    nx, ny, nz = maj.res[0], maj.res[1], maj.res[2]
    out = np.zeros((nz, ny, nx), np.bool_)
    cs = (maj.hi - maj.lo) / maj.res
    for iz in range(nz):
        for iy in range(ny):
            for ix in range(nx):
                lo3 = np.array([maj.lo[0] + ix * cs[0], maj.lo[1] + iy * cs[1], maj.lo[2] + iz * cs[2]])
                b0 = np.empty(3, np.int64)
                b1 = np.empty(3, np.int64)
                ok = True
                for d in range(3):
                    b0[d] = int(math.floor((lo3[d] - lo[d]) / size))
                    b1[d] = int(math.floor((lo3[d] + cs[d] - lo[d]) / size))
                    if b0[d] < 0 or b1[d] >= res[d]:
                        ok = False
                if not ok:
                    continue
                for bz in range(b0[2], b1[2] + 1):
                    for by in range(b0[1], b1[1] + 1):
                        for bx in range(b0[0], b1[0] + 1):
                            if cached[(bz * res[1] + by) * res[0] + bx] == 0:
                                ok = False
                out[iz, iy, ix] = ok
    return out
