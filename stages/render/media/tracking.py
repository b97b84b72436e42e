"""Free-flight sampling and transmittance through a majorant grid: delta and ratio tracking.

Delta tracking (Woodcock et al. 1965; seed 000 §5.4) samples tentative collisions from a
homogeneous majorant mu >= sigma_t and accepts one as real with probability sigma_t / mu; ratio
tracking (Novak et al. 2014) multiplies the transmittance estimate by (1 - sigma_t / mu) at each
tentative collision instead. Both are unbiased whatever mu as long as mu bounds sigma_t.

Majorants are piecewise constant on a ``MajorantGrid`` (a coarse grid of cells over the medium's
box, walked with a 3D DDA): a cell's majorant is the largest density any source can give inside it
(per yarn: the yarn's density bound where its tube reaches the cell) and **zero where no yarn tube
reaches**, so rays skip empty space without a single lookup, and outside the box nothing happens.
A cell may be *refined*: cut into k x k x k sub-cells with majorants of their own, walked by a
second DDA inside the cell. A grid over a large cloth is capped in cells (far coarser than the
fibres), and a close camera's paths then pay a null collision for every empty corner of a coarse
cell; refining the cells the camera sees (``pipeline.fibre_cache``) takes that back where it counts.

MajorantGrid fields: lo, hi (float64[3], the box), res (int64[3]: nx, ny, nz), mu (float64[nz, ny, nx]),
fine (int32[nz, ny, nx]: a refined cell's block of sub-cells, -1 for none; empty when no cell is
refined) and fine_mu (float64[blocks, k, k, k], z, y, x order; zero blocks when none is). Where a
cell is refined its ``mu`` is still a bound of its whole volume (pilots and tests read it).

``track(med, maj, o, d, tmax, seed, index, dim, ratio, skip_fibre=-1)`` returns a ``Flight``
    (collided, t, transmittance, dim, lookups, point)
with dim the next random-number dimension, lookups the medium lookups made and point the
``MediumPoint`` at the collision (``NO_MEDIUM`` without one). Delta mode (ratio = False) stops at
the first real collision before tmax (collided = True, t there); ratio mode runs to tmax (t = tmax)
and returns the transmittance estimate.
Random numbers are ``uniform(seed, index, dim)`` with dim counting up: a pure function of the
path, so results do not depend on threads.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.capsule import point_segment_dist2
from stages.core.rng import uniform
from stages.render.media.medium import NO_MEDIUM, PAGED_OUT, PAGED_OUT_YARN, extinction, medium_lookup

MajorantGrid = namedtuple("MajorantGrid", ["lo", "hi", "res", "mu", "fine", "fine_mu"])
Flight = namedtuple("Flight", ["collided", "t", "transmittance", "dim", "lookups", "point"])
Flight.__doc__ = """track's result (module doc)."""

RATIO_RR_THRESHOLD = 0.1  # ratio tracking plays Russian roulette below this transmittance


def make_majorant_grid(lo, hi, res, mu, fine=None, fine_mu=None) -> MajorantGrid:
    """A ``MajorantGrid``; without ``fine`` / ``fine_mu`` no cell is refined."""
    if fine is None:
        fine, fine_mu = np.zeros((0, 0, 0), np.int32), np.zeros((0, 1, 1, 1))
    return MajorantGrid(np.asarray(lo, np.float64), np.asarray(hi, np.float64),
                        np.asarray(res, np.int64), np.ascontiguousarray(mu, np.float64),
                        np.ascontiguousarray(fine, np.int32), np.ascontiguousarray(fine_mu, np.float64))


@njit(cache=True)
def majorants_from_capsules(a, b, radius, bound, lo, hi, res):
    """Majorant grid from capsules (segment a[k]-b[k], radius[k]) each carrying a density bound[k]:
    a cell gets the largest bound of the capsules that may reach it (``raster_capsule``)."""
    mu = np.zeros((res[2], res[1], res[0]))
    cs = (hi - lo) / res
    half_diag = cell_half_diagonal(cs)
    for k in range(a.shape[0]):
        raster_capsule(mu, lo, cs, half_diag, res, a[k, 0], a[k, 1], a[k, 2], b[k, 0], b[k, 1], b[k, 2],
                       radius[k], bound[k])
    return mu


@njit(cache=True)
def majorants_from_prims(prims, seg_fiber, fiber_yarn, yarn_density, lo, hi, res):
    """``majorants_from_capsules`` of a fibre BVH's packed capsules (``prims`` rows: a, b, radius, segment;
    bound: the density of the segment's yarn), read in place instead of listed (a listing is 64 bytes a
    segment: 430 MB for a 1,000-yarn close-up's fibre cache). The same grid: a cell keeps the largest
    bound of the capsules that reach it, whatever their order."""
    mu = np.zeros((res[2], res[1], res[0]))
    cs = (hi - lo) / res
    half_diag = cell_half_diagonal(cs)
    for j in range(prims.shape[0]):
        den = yarn_density[fiber_yarn[seg_fiber[int(prims[j, 7])]]]
        raster_capsule(mu, lo, cs, half_diag, res, prims[j, 0], prims[j, 1], prims[j, 2], prims[j, 3], prims[j, 4],
                       prims[j, 5], prims[j, 6], den)
    return mu


@njit(cache=True)
def fine_majorants_from_prims(prims, seg_fiber, fiber_yarn, yarn_density, lo, hi, res, fine, blocks, k):
    """float64[blocks, k, k, k]: the sub-cell majorants of the refined cells (``fine`` >= 0) from a
    fibre BVH's packed capsules, as ``majorants_from_prims`` on the grid k times finer restricted to
    those cells; sub-cells of unrefined cells are skipped."""
    out = np.zeros((blocks, k, k, k))
    fres = np.array([res[0] * k, res[1] * k, res[2] * k], np.int64)
    cs = (hi - lo) / fres
    half_diag = cell_half_diagonal(cs)
    for j in range(prims.shape[0]):
        den = yarn_density[fiber_yarn[seg_fiber[int(prims[j, 7])]]]
        ax, ay, az, bx, by, bz, r = (prims[j, 0], prims[j, 1], prims[j, 2], prims[j, 3], prims[j, 4], prims[j, 5],
                                     prims[j, 6])
        x0, x1, y0, y1, z0, z1 = _capsule_cells(lo, cs, fres, ax, ay, az, bx, by, bz, r)
        for iz in range(z0, z1 + 1):
            for iy in range(y0, y1 + 1):
                for ix in range(x0, x1 + 1):
                    b = fine[iz // k, iy // k, ix // k]
                    if b < 0 or out[b, iz % k, iy % k, ix % k] >= den:
                        continue
                    if _cell_reached(lo, cs, half_diag, ix, iy, iz, ax, ay, az, bx, by, bz, r):
                        out[b, iz % k, iy % k, ix % k] = den
    return out


@njit(cache=True, inline="always")
def cell_half_diagonal(cs):
    return 0.5 * math.sqrt(cs[0] ** 2 + cs[1] ** 2 + cs[2] ** 2) * (1.0 + 1e-9)


@njit(cache=True, inline="always")
def _cell_reached(lo, cs, half_diag, ix, iy, iz, ax, ay, az, bx, by, bz, r):
    """The capsule a-b of radius r may reach cell (ix, iy, iz): its centre within r + half the diagonal.
    13 parameters: the grid (origin, cell size, half diagonal), the cell and the capsule, as scalars in
    ``raster_capsule``'s loop."""
    cx = lo[0] + (ix + 0.5) * cs[0]
    cy = lo[1] + (iy + 0.5) * cs[1]
    cz = lo[2] + (iz + 0.5) * cs[2]
    return point_segment_dist2(cx, cy, cz, ax, ay, az, bx, by, bz) <= (r + half_diag) ** 2


@njit(cache=True, inline="always")
def _cell_range(p, q, r, lo, cs, n):
    i0 = max(int(math.floor((min(p, q) - r - lo) / cs)), 0)
    i1 = min(int(math.floor((max(p, q) + r - lo) / cs)), n - 1)
    return i0, i1


@njit(cache=True, inline="always")
def _capsule_cells(lo, cs, res, ax, ay, az, bx, by, bz, r):
    """(x0, x1, y0, y1, z0, z1): the cells of a grid (origin lo, cell cs, res cells) the capsule's box covers."""
    x0, x1 = _cell_range(ax, bx, r, lo[0], cs[0], res[0])
    y0, y1 = _cell_range(ay, by, r, lo[1], cs[1], res[1])
    z0, z1 = _cell_range(az, bz, r, lo[2], cs[2], res[2])
    return x0, x1, y0, y1, z0, z1


@njit(cache=True, inline="always")
def _dda_axis(o, d, c, cs, tm, n):
    """One axis of a DDA through cells of size cs from c (n of them), entered at ray parameter tm:
    (cell, t of its far boundary, t per cell)."""
    i = min(max(int(math.floor((o + tm * d - c) / cs)), 0), n - 1)
    if d == 0.0:
        return i, np.inf, np.inf
    return i, (c + (i + (1 if d > 0.0 else 0)) * cs - o) / d, cs / abs(d)


@njit(cache=True, inline="always")
def _dda_step(i, j, l, ti, tj, tl, si, sj, sl, di, dj, dl, ni, nj, nl):
    """The DDA's next cell across the nearest boundary: (i, j, l, ti, tj, tl, inside the ni x nj x nl cells).
    15 parameters: the DDA's state (cell, next crossings, steps, deltas, sizes per axis), nine scalars it returns
    updated."""
    if ti <= tj and ti <= tl:
        i += si
        ti += di
        return i, j, l, ti, tj, tl, 0 <= i < ni
    if tj <= tl:
        j += sj
        tj += dj
        return i, j, l, ti, tj, tl, 0 <= j < nj
    l += sl
    tl += dl
    return i, j, l, ti, tj, tl, 0 <= l < nl


@njit(cache=True)
def raster_capsule(mu, lo, cs, half_diag, res, ax, ay, az, bx, by, bz, r, den):
    """Raise to ``den`` every cell of ``mu`` (cell size cs, origin lo) the capsule a-b of radius r may
    reach: conservative, a cell within r of the segment has its centre within r + half its diagonal
    (at most one cell looser than exact).
    13 parameters: the grid (array, origin, cell size, half diagonal, resolution), the capsule and its density."""
    x0, x1, y0, y1, z0, z1 = _capsule_cells(lo, cs, res, ax, ay, az, bx, by, bz, r)
    for iz in range(z0, z1 + 1):
        for iy in range(y0, y1 + 1):
            for ix in range(x0, x1 + 1):
                if mu[iz, iy, ix] < den and _cell_reached(lo, cs, half_diag, ix, iy, iz, ax, ay, az, bx, by, bz, r):
                    mu[iz, iy, ix] = den


@njit(cache=True)
def majorants_from_voxels(density, lo, hi, res):
    """Majorant grid for a trilinearly interpolated voxel density (Z, Y, X) with voxel centres at
    (i + 0.5)/N of [lo, hi] and border clamping: a cell takes the maximum of every voxel whose
    interpolation support (one voxel either side of its centre) meets the cell."""
    vz, vy, vx = density.shape
    nx, ny, nz = res[0], res[1], res[2]
    mu = np.zeros((nz, ny, nx))
    vres = np.array([vx, vy, vz])
    for iz in range(nz):
        for iy in range(ny):
            for ix in range(nx):
                idx = (ix, iy, iz)
                j0 = np.empty(3, np.int64)
                j1 = np.empty(3, np.int64)
                for ax in range(3):
                    n = res[ax]
                    # cell [idx/n, (idx+1)/n] in unit coordinates; voxel j centred at (j+0.5)/N
                    u0 = idx[ax] / n * vres[ax] - 0.5
                    u1 = (idx[ax] + 1) / n * vres[ax] - 0.5
                    j0[ax] = min(max(int(math.floor(u0)), 0), vres[ax] - 1)
                    j1[ax] = min(max(int(math.ceil(u1)), 0), vres[ax] - 1)
                m = 0.0
                for kz in range(j0[2], j1[2] + 1):
                    for ky in range(j0[1], j1[1] + 1):
                        for kx in range(j0[0], j1[0] + 1):
                            if density[kz, ky, kx] > m:
                                m = density[kz, ky, kx]
                mu[iz, iy, ix] = m
    return mu


@njit(cache=True)
def ray_box(lo, hi, ox, oy, oz, dx, dy, dz):
    """(t_near, t_far) of the ray with the box; t_near > t_far when it misses."""
    t0 = -np.inf
    t1 = np.inf
    o = (ox, oy, oz)
    d = (dx, dy, dz)
    for ax in range(3):
        if d[ax] != 0.0:
            inv = 1.0 / d[ax]
            ta = (lo[ax] - o[ax]) * inv
            tb = (hi[ax] - o[ax]) * inv
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
        elif o[ax] < lo[ax] or o[ax] > hi[ax]:
            return 1.0, 0.0
    return t0, t1


PAGED_OUT_T = -1.0  # delta tracking's T once a lookup answered medium.PAGED_OUT (delta tracking keeps T = 1)
_PASSED, _COLLIDED, _ENDED = 0, 1, 2  # _collide: reached t_exit; a real collision; ratio tracking's roulette ended it


@njit(cache=True, inline="always", _nrt=False)
def _collide(med, mu, t, t_exit, ox, oy, oz, dx, dy, dz, T, dim, lookups, seed, index, ratio, skip_fibre):
    """Tentative collisions at rate ``mu`` from t until t_exit (``track``'s inner loop): (state, t, T,
    dim, lookups, point) with state _PASSED (t past t_exit), _COLLIDED (delta tracking, point there)
    or _ENDED (ratio tracking's Russian roulette).
    17 parameters: ``track``'s inner loop state (majorant, t, exit, ray, transmittance, dim, lookups) and the
    random stream and mode."""
    while True:
        u = uniform(seed, index, dim)
        dim += 1
        t -= math.log(1.0 - u) / mu
        if t >= t_exit:
            return _PASSED, t, T, dim, lookups, NO_MEDIUM
        state, T, dim, m = _tentative(med, mu, t, ox, oy, oz, dx, dy, dz, T, dim, seed, index, ratio, skip_fibre)
        lookups += 1
        if state != _PASSED:
            return state, t, T, dim, lookups, m


@njit(cache=True, inline="always", _nrt=False)
def _tentative(med, mu, t, ox, oy, oz, dx, dy, dz, T, dim, seed, index, ratio, skip_fibre):
    """One tentative collision at t under majorant mu: (state, T, dim, point), state _PASSED (a null
    collision: go on), _COLLIDED (delta tracking accepted it) or _ENDED (ratio tracking's roulette).
    15 parameters: ``_collide``'s state for one collision."""
    m = medium_lookup(med, ox + t * dx, oy + t * dy, oz + t * dz, skip_fibre)
    if m.yarn == PAGED_OUT_YARN:
        # no answer yet (medium.PAGED_OUT): a null collision, so the ray's later lookups ask for their yarns too;
        # delta tracking (whose T is otherwise 1) remembers it in T, and the ray ends as a PAGED_OUT collision
        return _PASSED, T if ratio else PAGED_OUT_T, dim, NO_MEDIUM
    st = extinction(m.den, m.tx, m.ty, m.tz, m.roughness, dx, dy, dz)
    if ratio:
        T *= 1.0 - st / mu
        if T < RATIO_RR_THRESHOLD:
            q = uniform(seed, index, dim)
            dim += 1
            if q >= 0.5:
                return _ENDED, 0.0, dim, NO_MEDIUM
            T *= 2.0
    else:
        v = uniform(seed, index, dim)
        dim += 1
        if v * mu < st:
            return _COLLIDED, T, dim, m
    return _PASSED, T, dim, NO_MEDIUM


@njit(cache=True, _nrt=False)
def track(med, maj, ox, oy, oz, dx, dy, dz, tmax, seed, index, dim, ratio, skip_fibre=-1):
    """Delta tracking (ratio=False) or ratio tracking (ratio=True) along o + t d, t in [0, tmax] through
    every fibre but ``skip_fibre`` (a MediumPoint.fibre, -1 none: ``medium_lookup``'s skip): a ray
    leaving a fibre that scattered it as a whole does not meet that fibre again.
    14 parameters: the medium and majorant, the ray and its length, the random stream (seed, index, dim), the mode
    and the skipped fibre."""
    T = 1.0
    lookups = 0
    t_near, t_far = ray_box(maj.lo, maj.hi, ox, oy, oz, dx, dy, dz)
    t_near = max(t_near, 0.0)
    t_far = min(t_far, tmax)
    if not (t_near < t_far):
        return Flight(False, tmax, T, dim, lookups, NO_MEDIUM)
    lo = maj.lo
    res = maj.res
    cs0 = (maj.hi[0] - lo[0]) / res[0]
    cs1 = (maj.hi[1] - lo[1]) / res[1]
    cs2 = (maj.hi[2] - lo[2]) / res[2]
    # entry cell
    tm = t_near + 1e-9 * (t_far - t_near)
    ix, tnx, tdx = _dda_axis(ox, dx, lo[0], cs0, tm, res[0])
    iy, tny, tdy = _dda_axis(oy, dy, lo[1], cs1, tm, res[1])
    iz, tnz, tdz = _dda_axis(oz, dz, lo[2], cs2, tm, res[2])
    sx = 1 if dx > 0.0 else -1
    sy = 1 if dy > 0.0 else -1
    sz = 1 if dz > 0.0 else -1
    refined = maj.fine_mu.shape[0] > 0
    k = maj.fine_mu.shape[1]
    t = t_near
    while True:
        t_exit = min(tnx, tny, tnz, t_far)
        mu = maj.mu[iz, iy, ix]
        if mu > 0.0:
            b = maj.fine[iz, iy, ix] if refined else -1
            if b < 0:
                state, t, T, dim, lookups, m = _collide(med, mu, t, t_exit, ox, oy, oz, dx, dy, dz, T, dim, lookups,
                                                        seed, index, ratio, skip_fibre)
                if state == _COLLIDED:
                    return Flight(True, t, T, dim, lookups, m if T != PAGED_OUT_T else PAGED_OUT)
                if state == _ENDED:
                    return Flight(False, tmax, 0.0, dim, lookups, NO_MEDIUM)
            else:  # the cell's k^3 sub-cells, by their own DDA from t to t_exit
                tm = t + 1e-9 * (t_exit - t)
                jx, fnx, fdx = _dda_axis(ox, dx, lo[0] + ix * cs0, cs0 / k, tm, k)
                jy, fny, fdy = _dda_axis(oy, dy, lo[1] + iy * cs1, cs1 / k, tm, k)
                jz, fnz, fdz = _dda_axis(oz, dz, lo[2] + iz * cs2, cs2 / k, tm, k)
                # one exponential optical depth carried across sub-cells (a piecewise-constant rate:
                # the collision where the integral of fmu reaches tau), fresh after each tentative collision;
                # what is left at the cell's exit is dropped (the process is memoryless)
                tau = -math.log(1.0 - uniform(seed, index, dim))
                dim += 1
                while True:
                    s_exit = min(fnx, fny, fnz, t_exit)
                    fmu = maj.fine_mu[b, jz, jy, jx]
                    if fmu > 0.0:
                        while True:
                            span = fmu * max(s_exit - t, 0.0)
                            if tau >= span:
                                tau -= span
                                break
                            t += tau / fmu
                            state, T, dim, m = _tentative(med, fmu, t, ox, oy, oz, dx, dy, dz, T, dim, seed, index,
                                                          ratio, skip_fibre)
                            lookups += 1
                            if state == _COLLIDED:
                                return Flight(True, t, T, dim, lookups, m if T != PAGED_OUT_T else PAGED_OUT)
                            if state == _ENDED:
                                return Flight(False, tmax, 0.0, dim, lookups, NO_MEDIUM)
                            tau = -math.log(1.0 - uniform(seed, index, dim))
                            dim += 1
                    t = s_exit
                    if s_exit >= t_exit:
                        break
                    jx, jy, jz, fnx, fny, fnz, inside = _dda_step(jx, jy, jz, fnx, fny, fnz, sx, sy, sz, fdx, fdy, fdz,
                                                                   k, k, k)
                    if not inside:
                        break
        t = t_exit
        if t_exit >= t_far:
            break
        ix, iy, iz, tnx, tny, tnz, inside = _dda_step(ix, iy, iz, tnx, tny, tnz, sx, sy, sz, tdx, tdy, tdz,
                                                       res[0], res[1], res[2])
        if not inside:
            break
    if not ratio and T == PAGED_OUT_T:   # a lookup could not answer: the path ends here (medium.PAGED_OUT)
        return Flight(True, t, T, dim, lookups, PAGED_OUT)
    return Flight(False, tmax, T, dim, lookups, NO_MEDIUM)


@njit(cache=True)
def ray_meets_majorant(maj, ox, oy, oz, dx, dy, dz):
    """True when the ray passes through a cell with a non-zero majorant (it may meet fibres)."""
    t_near, t_far = ray_box(maj.lo, maj.hi, ox, oy, oz, dx, dy, dz)
    t_near = max(t_near, 0.0)
    if not (t_near < t_far):
        return False
    n = 4 * (maj.res[0] + maj.res[1] + maj.res[2])
    h = (t_far - t_near) / n
    cs0 = (maj.hi[0] - maj.lo[0]) / maj.res[0]
    cs1 = (maj.hi[1] - maj.lo[1]) / maj.res[1]
    cs2 = (maj.hi[2] - maj.lo[2]) / maj.res[2]
    for i in range(n):
        t = t_near + (i + 0.5) * h
        ix = min(max(int(math.floor((ox + t * dx - maj.lo[0]) / cs0)), 0), maj.res[0] - 1)
        iy = min(max(int(math.floor((oy + t * dy - maj.lo[1]) / cs1)), 0), maj.res[1] - 1)
        iz = min(max(int(math.floor((oz + t * dz - maj.lo[2]) / cs2)), 0), maj.res[2] - 1)
        if maj.mu[iz, iy, ix] > 0.0:
            return True
    return False
