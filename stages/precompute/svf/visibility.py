"""1. Visibility images (the package doc): the segments of an exemplar and one binary image per segment,
rays from the segment's capsule surface through the flat periodic fabric (any-hit walks with image
coherence)."""

import math
from collections import namedtuple

import numba
import numpy as np
from numba import njit, prange
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.geometry.capsule import INSIDE, capsule_intersect, point_segment_dist2
from stages.core.geometry.dda import dda_axis, dda_next
from stages.core.geometry.wide_walk import Ray, leaf_test, wide_any
from stages.core.svf import pixel_direction
from stages.precompute.periodic import ray_start, slab_length
from stages.precompute.svf.pixels import packed_bytes

MAX_DIST_PERIODS = 32.0     # default max_dist = 32 max(W, H)

ExemplarSegments = namedtuple("ExemplarSegments", ["ids", "fibre", "mids", "capsules", "z_lo", "z_hi", "period"])
ExemplarSegments.__doc__ = """Segments of one exemplar: global ids (S,) int64, fibre (S,) int64 (global fibre id),
midpoints (S, 3) float64, capsules (S, 7) float64 (end points a, b and radius: the mean of the two
point radii, as the BVH's), the slab z_lo, z_hi and the period (W, H)."""


def exemplar_segments(ex_points, ex_radius, ex_offsets, ex_fibers, ex_period, k: int) -> ExemplarSegments:
    """Segments of exemplar k of a tiling (arrays as in the tiling artifact): fibre f's segment i has
    global id ex_offsets[f] - f + i and joins points ex_offsets[f] + i, + i + 1."""
    O = np.asarray(ex_offsets, np.int64)
    P = np.asarray(ex_points, np.float64)
    R = np.asarray(ex_radius, np.float64)
    f0, f1 = int(ex_fibers[k]), int(ex_fibers[k + 1])
    n = np.diff(O[f0:f1 + 1])
    nseg = np.maximum(n - 1, 0)
    fibre = np.repeat(np.arange(f0, f1, dtype=np.int64), nseg)
    first = np.repeat(O[f0:f1] - np.arange(f0, f1), nseg)          # global id of each fibre's segment 0
    ids = np.arange(int(O[f0]) - f0, int(O[f1]) - f1, dtype=np.int64)
    a = ids - first + O[fibre]                                     # first point of each segment
    mids = 0.5 * (P[a] + P[a + 1])
    capsules = np.concatenate([P[a], P[a + 1], (0.5 * (R[a] + R[a + 1]))[:, None]], axis=1)
    zs, rs = P[O[f0]:O[f1], 2], R[O[f0]:O[f1]]
    W, H = (float(v) for v in ex_period[k])
    return ExemplarSegments(ids, fibre, mids, capsules, float((zs - rs).min()), float((zs + rs).max()), (W, H))


# The hot helpers take arrays, never the ShellScene: passing the namedtuple of ~30 arrays to a call
# costs ~0.5 us (reference counts of every array), twenty times a capsule test.
@njit(cache=True, inline="always")
def _piece_hit(P, seg_a, seg_r, s, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Does the ray from the midpoint (origin already shifted into the capsule's period) enter wrapped
    capsule s beyond tmin before tmax? A capsule that contains the origin lets it through
    (``stages.precompute.periodic``: rays from a midpoint)."""
    return _piece_t(P, seg_a, seg_r, s, ox, oy, oz, dx, dy, dz, tmin) < tmax


@njit(cache=True, inline="always")
def _piece_t(P, seg_a, seg_r, s, ox, oy, oz, dx, dy, dz, tmin):
    """Where the ray enters wrapped capsule s beyond tmin (inf: never, or the capsule contains the origin)."""
    a = seg_a[s]
    r = seg_r[s]
    if point_segment_dist2(ox, oy, oz, P[a, 0], P[a, 1], P[a, 2],
                           P[a + 1, 0], P[a + 1, 1], P[a + 1, 2]) < INSIDE * r * r:
        return np.inf
    return capsule_intersect(ox, oy, oz, dx, dy, dz, P[a, 0], P[a, 1], P[a, 2],
                             P[a + 1, 0], P[a + 1, 1], P[a + 1, 2], seg_r[s], tmin)


PeriodLeaves = namedtuple("PeriodLeaves", ["points", "seg_a", "seg_r", "seg_fibre", "prim", "ign_fiber"])
PeriodLeaves.__doc__ = """An exemplar's wrapped pieces for ``wide_walk`` in one period of the flat fabric (arrays of the
``ShellScene``: points, seg_a, seg_r, seg_srcfiber, fprim), the pieces of fibre ``ign_fiber`` skipped and a
capsule that contains the ray's origin let through (``_piece_t``)."""


@overload(leaf_test, inline="always")
def _period_leaf_test(leaves, j, ray, tmin):
    if is_tuple_class(leaves, PeriodLeaves):
        def impl(leaves, j, ray, tmin):
            s = leaves.prim[j]
            if leaves.seg_fibre[s] == leaves.ign_fiber:
                return s, np.inf
            return s, _piece_t(leaves.points, leaves.seg_a, leaves.seg_r, s, ray.ox, ray.oy, ray.oz, ray.dx, ray.dy,
                               ray.dz, tmin)
        return impl


@njit(cache=True, inline="always")
def _periodic_any_hit(box, child, root, leaves, bw, bh, nx, ny, ray, L):
    """``periodic_any_hit`` of ``ray`` (a ``Ray``) on the exemplar's wide nodes (``box``, ``child``, ``root``) and
    ``PeriodLeaves``: a DDA over whole periods (bw nx by bh ny), each period's pieces walked by
    ``wide_walk.wide_any`` with the origin shifted into it."""
    ox, oy, oz, dx, dy, dz = ray
    ci = int(math.floor(ox / bw)) // nx
    cj = int(math.floor(oy / bh)) // ny
    stx, tmx, tdx = dda_axis(ci * nx * bw, (ci + 1) * nx * bw, nx * bw, ox, dx)
    sty, tmy, tdy = dda_axis(cj * ny * bh, (cj + 1) * ny * bh, ny * bh, oy, dy)
    s = 0.0
    while s < L:
        s1 = min(tmx, tmy, L)
        if s1 > s:
            shx = (ci * nx) * bw
            shy = (cj * ny) * bh
            p = wide_any(box, child, root, leaves, Ray(ox - shx, oy - shy, oz, dx, dy, dz), s, s, s1)
            if p >= 0:
                return p, ci, cj
            s = s1
        ci, cj, tmx, tmy = dda_next(ci, cj, tmx, tmy, stx, sty, tdx, tdy)
        if tmx == np.inf and tmy == np.inf:
            break
    return -1, 0, 0


@njit(cache=True)
def periodic_any_hit(sc, k, ox, oy, oz, dx, dy, dz, L, ign_fiber):
    """(piece, ci, cj): a wrapped capsule of exemplar k (not of fibre ign_fiber) that the ray o + t d,
    0 < t < L, hits in the exemplar repeated without end, found in period (ci, cj) (shift
    (ci nx bw, cj ny bh)); piece = -1 when none. Hit or not agrees with ``periodic_hit_outside`` (a walk over
    whole periods instead of blocks: the same capsules, the same roots)."""
    leaves = PeriodLeaves(sc.points, sc.seg_a, sc.seg_r, sc.seg_srcfiber, sc.fprim, ign_fiber)
    return _periodic_any_hit(sc.fw_box, sc.fw_child, sc.ex_wide_root[k], leaves, sc.block_size[0], sc.block_size[1],
                             sc.ex_nblocks[k, 0], sc.ex_nblocks[k, 1], Ray(ox, oy, oz, dx, dy, dz), L)


@njit(cache=True)
def direction_table(res_theta, res_phi):
    dirs = np.empty((res_theta, res_phi, 3))
    for r in range(res_theta):
        for c in range(res_phi):
            x, y, z = pixel_direction(r, c, res_theta, res_phi)
            dirs[r, c, 0] = x
            dirs[r, c, 1] = y
            dirs[r, c, 2] = z
    return dirs


@njit(cache=True)
def segment_image(sc, k, z_lo, z_hi, mx, my, mz, capsule, fibre, dirs, max_dist, out, col_cache):
    """Bit-packed visibility image of segment midpoint m (skipping fibre ``fibre``; rays start on the
    surface of ``capsule``, see ``ray_start``) into ``out`` (bytes); ``dirs`` from direction_table;
    scratch: ``col_cache`` (res_phi, 3) int64.
    13 parameters: the scene and exemplar, the segment (midpoint, capsule, fibre), the direction table and
    max_dist, the output row and a scratch."""
    P, seg_a, seg_r = sc.points, sc.seg_a, sc.seg_r
    box, child = sc.fw_box, sc.fw_child
    leaves = PeriodLeaves(P, seg_a, seg_r, sc.seg_srcfiber, sc.fprim, fibre)
    root = sc.ex_wide_root[k]
    bw = sc.block_size[0]
    bh = sc.block_size[1]
    nx = sc.ex_nblocks[k, 0]
    ny = sc.ex_nblocks[k, 1]
    R = dirs.shape[0]
    C = dirs.shape[1]
    out[:] = 0
    col_cache[:, 0] = -1
    pp, pi, pj = -1, 0, 0
    for r in range(R):
        for cc in range(C):
            c = cc if r % 2 == 0 else C - 1 - cc
            dx = dirs[r, c, 0]
            dy = dirs[r, c, 1]
            dz = dirs[r, c, 2]
            ox, oy, oz, t_start = ray_start(mx, my, mz, capsule, dx, dy, dz)
            L = slab_length(oz, dz, z_lo, z_hi, max_dist - t_start)
            visible = True
            if L > 0.0:
                blocked = False
                # the capsule that blocked the previous pixel, then the one that blocked the pixel above
                if pp >= 0 and _piece_hit(P, seg_a, seg_r, pp, ox - (pi * nx) * bw, oy - (pj * ny) * bh, oz,
                                          dx, dy, dz, 0.0, L):
                    blocked = True
                else:
                    q = col_cache[c, 0]
                    qi = col_cache[c, 1]
                    qj = col_cache[c, 2]
                    if q >= 0 and not (q == pp and qi == pi and qj == pj) and \
                            _piece_hit(P, seg_a, seg_r, q, ox - (qi * nx) * bw, oy - (qj * ny) * bh, oz,
                                       dx, dy, dz, 0.0, L):
                        blocked = True
                        pp, pi, pj = q, qi, qj
                    else:
                        q, qi, qj = _periodic_any_hit(box, child, root, leaves, bw, bh, nx, ny,
                                                      Ray(ox, oy, oz, dx, dy, dz), L)
                        if q >= 0:
                            blocked = True
                            pp, pi, pj = q, qi, qj
                if blocked:
                    visible = False
                    col_cache[c, 0] = pp
                    col_cache[c, 1] = pi
                    col_cache[c, 2] = pj
            if visible:
                i = r * C + c
                out[i >> 3] |= np.uint8(1 << (7 - (i & 7)))


@njit(cache=True, parallel=True)
def _visibility_kernel(sc, k, z_lo, z_hi, mids, capsules, fibres, dirs, max_dist, out):
    C = dirs.shape[1]
    for s in prange(mids.shape[0]):
        col_cache = np.empty((C, 3), np.int64)
        segment_image(sc, k, z_lo, z_hi, mids[s, 0], mids[s, 1], mids[s, 2], capsules[s], fibres[s], dirs,
                      max_dist, out[s], col_cache)


def default_max_dist(psc, k: int) -> float:
    """32 max(W, H) of exemplar k."""
    W = float(psc.ex_nblocks[k, 0] * psc.block_size[0])
    H = float(psc.ex_nblocks[k, 1] * psc.block_size[1])
    return MAX_DIST_PERIODS * max(W, H)


def visibility_images(psc, k: int, z_lo: float, z_hi: float, mids, fibres, res_theta: int = 128,
                      res_phi: int = 128, max_dist: float | None = None, capsules=None):
    """Chunk level. Bit-packed visibility images (S, ceil(D/8)) uint8 of the points ``mids`` (S, 3)
    (segment midpoints, exemplar space), each skipping its fibre ``fibres`` (S,) (global fibre ids; -1
    skips nothing), in exemplar k repeated without end; ``psc`` is the tiling's ``ShellScene`` or its
    ``periodic_scene(sc, k)`` (only exemplar k's fibres are read). With ``capsules`` (S, 7: the
    segments' ``ExemplarSegments.capsules``) each ray starts where it leaves its segment's capsule
    (module doc, 1.), without them at the point itself. ``max_dist`` counts from the point. S * D
    rays; segments are taken one at a time by the threads."""
    mids = np.ascontiguousarray(mids, np.float64).reshape(-1, 3)
    fibres = np.ascontiguousarray(fibres, np.int64).reshape(-1)
    if capsules is None:
        capsules = np.zeros((mids.shape[0], 7))
    capsules = np.ascontiguousarray(capsules, np.float64).reshape(-1, 7)
    if max_dist is None:
        max_dist = default_max_dist(psc, k)
    out = np.zeros((mids.shape[0], packed_bytes(res_theta, res_phi)), np.uint8)
    if mids.shape[0]:
        dirs = direction_table(res_theta, res_phi)
        with numba.parallel_chunksize(1):
            _visibility_kernel(psc, int(k), float(z_lo), float(z_hi), mids, capsules, fibres, dirs, float(max_dist),
                               out)
    return out
