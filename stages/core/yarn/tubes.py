"""Yarn tubes: rays against the yarn curves themselves (seed 004 §3.2), for ``--method bysdf``.

The BYSDF renders cloth from the ``yarns`` artifact alone. Each yarn is a tube of radius
``R_env`` (the farthest reach of its plies, ``stages.core.yarn.implicit_plies.ply_reach_radius``,
plus a margin; ``pipeline.renderers.bysdf``) around the ingest stage's C1 cubic Hermite spline. The
tube is traced as a chain of capsules around a polyline that follows the spline closely enough:

    Subdivision bound. On a piece [t0, t0 + h] of a cubic segment P(t) = a t^3 + b t^2 + c t + d,
    the chord's distance from the curve is at most h^2 / 8 max |P''| (linear interpolation error),
    and P''(t) = 6 a t + 2 b is linear, so max |P''| = max(|2 b|, |6 a + 2 b|). A segment is cut into
    n = ceil(sqrt(max|P''| / (8 eps))) equal pieces in t with eps = ``rel_err`` R_env (default 1 %),
    so every point of the polyline lies within eps of the spline and vice versa; the capsule tube and
    the spline's tube differ by at most eps (``tests/core/yarn/test_tubes.py`` measures it).

The capsules go into the SAH BVH of the explicit-fibre renderer (``stages.core.geometry.bvh``),
one "fibre" per yarn, so the traversal is the one every fibre tracer uses. A hit on piece j at axis
fraction lam maps back to the spline's (segment, t) = (piece_seg[j], piece_t0[j] + lam (piece_t1[j]
- piece_t0[j])); the rotation-minimising frame stored by ingest (``stages.core.curves.frames``) then
gives the arc length s and the frame (tangent T, normal N, binormal B) there, so the azimuth of a hit
is measured from the same reference direction along the yarn in every frame of an animation.

Yarn space (seed 000 Eq. 7, the coordinates of the procedural yarn model): x along N, y along B,
z = arc length. ``yarn_hit_frame`` returns a ``YarnFrame``; ``to_yarn`` / ``from_yarn`` map points
and directions between world and yarn space with the frame at the hit (the yarn treated as straight
over the few radii a ray spends inside it).

Kernels: ``tube_pieces`` (subdivision), ``yarn_hit_frame``, ``to_yarn`` (``to_yarn_into`` writes into
the caller's vectors), ``dir_from_yarn``, ``point_from_yarn``, ``cylinder_span`` (entry and exit of a
ray through the straight envelope in yarn space). The per-ray kernels allocate nothing but ``to_yarn``'s
result, and ``yarn_hit_frame`` is compiled without reference counting, for ``stages.render.integrators.bysdf``.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.curves.frames import frame_at_segment_s
from stages.core.curves.spline import acceleration_s, coeffs_s, velocity_s

# One yarn's polyline: points of curve c at offsets[c]:offsets[c + 1]; piece j (first point j) covers the
# spline segment piece_seg[j] from piece_t0[j] to piece_t1[j].
TubePieces = namedtuple("TubePieces", ["points", "offsets", "piece_seg", "piece_t0", "piece_t1", "piece_curve",
                                       "radius", "max_deviation"])

# Frame of a yarn hit: origin (the axis point at arc length s), tangent, normal, binormal, s, curve
YarnFrame = namedtuple("YarnFrame", ["px", "py", "pz", "tx", "ty", "tz", "nx", "ny", "nz", "bx", "by", "bz",
                                     "s", "curve"])


@njit(cache=True)
def pieces_per_segment(cv, i, eps):
    """Number of equal-t pieces of spline segment i whose chords stay within eps of the curve."""
    ax, ay, az, bx, by, bz, _, _, _, _, _, _ = coeffs_s(cv, i)
    m0 = 2.0 * math.sqrt(bx * bx + by * by + bz * bz)
    ex = 6.0 * ax + 2.0 * bx
    ey = 6.0 * ay + 2.0 * by
    ez = 6.0 * az + 2.0 * bz
    m1 = math.sqrt(ex * ex + ey * ey + ez * ez)
    m = max(m0, m1)
    return max(1, int(math.ceil(math.sqrt(m / (8.0 * eps)))))


@njit(cache=True)
def _count(cv, eps):
    C = cv.offsets.shape[0] - 1
    npts = np.zeros(C, np.int64)
    for c in range(C):
        lo = cv.offsets[c]
        nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
        total = 0
        for i in range(lo, lo + nseg):
            total += pieces_per_segment(cv, i, eps[c])
        npts[c] = total + 1
    return npts


@njit(cache=True)
def _fill(cv, eps, offsets, points, seg, t0, t1, pc):
    C = cv.offsets.shape[0] - 1
    for c in range(C):
        lo = cv.offsets[c]
        nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
        k = offsets[c]
        for i in range(lo, lo + nseg):
            n = pieces_per_segment(cv, i, eps[c])
            ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = coeffs_s(cv, i)
            for q in range(n):
                t = q / n
                points[k, 0] = ((ax * t + bx) * t + cx) * t + dx
                points[k, 1] = ((ay * t + by) * t + cy) * t + dy
                points[k, 2] = ((az * t + bz) * t + cz) * t + dz
                seg[k] = i
                t0[k] = t
                t1[k] = (q + 1) / n
                pc[k] = c
                k += 1
        # the last point: the end of the last segment (a closed curve's start again)
        i = lo + nseg - 1
        ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = coeffs_s(cv, i)
        points[k, 0] = ax + bx + cx + dx
        points[k, 1] = ay + by + cy + dy
        points[k, 2] = az + bz + cz + dz
        seg[k] = i
        t0[k] = 1.0
        t1[k] = 1.0
        pc[k] = c


def tube_pieces(cv, radius, rel_err=0.01) -> TubePieces:
    """The polylines of every yarn (``TubePieces``) for tube radii ``radius`` (per curve) and the
    relative chord bound ``rel_err`` (see the module doc)."""
    radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, np.float64), (len(cv.offsets) - 1,)))
    eps = rel_err * radius
    npts = _count(cv, eps)
    offsets = np.zeros(len(npts) + 1, np.int64)
    np.cumsum(npts, out=offsets[1:])
    N = int(offsets[-1])
    points = np.empty((N, 3))
    seg = np.empty(N, np.int64)
    t0 = np.empty(N)
    t1 = np.empty(N)
    pc = np.empty(N, np.int32)
    _fill(cv, eps, offsets, points, seg, t0, t1, pc)
    return TubePieces(points, offsets, seg, t0, t1, pc, radius[pc].copy(), eps)


@njit(cache=True, _nrt=False)
def yarn_hit_frame(cv, pieces, j, px, py, pz):
    """``YarnFrame`` at the hit point p on piece j: the spline parameter of p's closest point (from its
    projection on the piece's chord, then three Newton steps on the spline segment), then the stored
    rotation-minimising frame there."""
    P = pieces.points
    ax = P[j, 0]
    ay = P[j, 1]
    az = P[j, 2]
    ex = P[j + 1, 0] - ax
    ey = P[j + 1, 1] - ay
    ez = P[j + 1, 2] - az
    L2 = ex * ex + ey * ey + ez * ez
    lam = 0.0
    if L2 > 0.0:
        lam = ((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / L2
        lam = min(1.0, max(0.0, lam))
    t0 = pieces.piece_t0[j]
    t1 = pieces.piece_t1[j]
    t = t0 + lam * (t1 - t0)
    # Newton steps to the spline's closest point: g(t) = (P(t) - p) . P'(t) = 0
    i = pieces.piece_seg[j]
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = coeffs_s(cv, i)
    lo = max(0.0, t0 - (t1 - t0))
    hi = min(1.0, t1 + (t1 - t0))
    for _ in range(3):
        qx = ((ax * t + bx) * t + cx) * t + dx - px
        qy = ((ay * t + by) * t + cy) * t + dy - py
        qz = ((az * t + bz) * t + cz) * t + dz - pz
        ux, uy, uz = velocity_s(ax, ay, az, bx, by, bz, cx, cy, cz, t)
        vx, vy, vz = acceleration_s(ax, ay, az, bx, by, bz, t)
        g = qx * ux + qy * uy + qz * uz
        gp = ux * ux + uy * uy + uz * uz + qx * vx + qy * vy + qz * vz
        if gp <= 0.0:
            break
        t = min(hi, max(lo, t - g / gp))
    c = pieces.piece_curve[j]
    f, s = frame_at_segment_s(cv, c, i, t)
    return YarnFrame(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9], f[10], f[11], s, c)


@njit(cache=True)
def to_yarn(fr, px, py, pz, dx, dy, dz):
    """Yarn-space (point (3), direction (3)) of the world point p and direction d."""
    o = np.empty(3)
    d = np.empty(3)
    to_yarn_into(fr, px, py, pz, dx, dy, dz, o, d)
    return o, d


@njit(cache=True)
def to_yarn_into(fr, px, py, pz, dx, dy, dz, o, d):
    """``to_yarn`` writing the yarn-space point into o and the direction into d."""
    rx = px - fr.px
    ry = py - fr.py
    rz = pz - fr.pz
    o[0] = rx * fr.nx + ry * fr.ny + rz * fr.nz
    o[1] = rx * fr.bx + ry * fr.by + rz * fr.bz
    o[2] = fr.s + rx * fr.tx + ry * fr.ty + rz * fr.tz
    d[0] = dx * fr.nx + dy * fr.ny + dz * fr.nz
    d[1] = dx * fr.bx + dy * fr.by + dz * fr.bz
    d[2] = dx * fr.tx + dy * fr.ty + dz * fr.tz


@njit(cache=True)
def dir_from_yarn(fr, v, out):
    """World direction of the yarn-space direction v, written into out."""
    out[0] = v[0] * fr.nx + v[1] * fr.bx + v[2] * fr.tx
    out[1] = v[0] * fr.ny + v[1] * fr.by + v[2] * fr.ty
    out[2] = v[0] * fr.nz + v[1] * fr.bz + v[2] * fr.tz


@njit(cache=True)
def point_from_yarn(fr, q):
    """World point (x, y, z) of the yarn-space point q (x, y, z = arc length)."""
    dz = q[2] - fr.s
    return (fr.px + q[0] * fr.nx + q[1] * fr.bx + dz * fr.tx,
            fr.py + q[0] * fr.ny + q[1] * fr.by + dz * fr.ty,
            fr.pz + q[0] * fr.nz + q[1] * fr.bz + dz * fr.tz)


@njit(cache=True)
def cylinder_span(o, d, R):
    """(u_in, u_out) of the yarn-space ray o + u d through the straight cylinder x^2 + y^2 <= R^2
    (u_in > u_out: it misses; a ray along the axis inside it spans (-inf, inf))."""
    a = d[0] * d[0] + d[1] * d[1]
    b = o[0] * d[0] + o[1] * d[1]
    c = o[0] * o[0] + o[1] * o[1] - R * R
    if a < 1e-300:
        if c <= 0.0:
            return -np.inf, np.inf
        return 1.0, 0.0
    disc = b * b - a * c
    if disc < 0.0:
        return 1.0, 0.0
    sq = math.sqrt(disc)
    # numerically stable roots
    q = -(b + sq) if b >= 0.0 else -(b - sq)
    r0 = q / a
    r1 = c / q if q != 0.0 else r0
    return min(r0, r1), max(r0, r1)
