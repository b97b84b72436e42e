"""Yarn centre curves: C1 cubic Hermite (uniform Catmull-Rom) splines and their arc length
(seed 000 §4.2, §5.1).

A ``Curves`` namedtuple of flat arrays describes all curves (layout in docs/architecture.md):
curve c owns points ``offsets[c]:offsets[c+1]``; segment i (global, same index as its first
point) runs from point i to the next one (closed curves wrap). Positions on a curve are given by
arc length s in [0, curve_length[c]] (closed curves: s wraps).

Kernels
-------
segment_coeffs(cv, i)           power-basis coefficients a t^3 + b t^2 + c t + d of segment i
coeffs_s(cv, i)                 the same as 12 scalars (allocation-free, for hot loops)
velocity_s / acceleration_s     dP/dt and d2P/dt2 from those scalars
segment_point / segment_deriv   position / dP/dt on segment i at t in [0, 1]
segment_arclen_to(cv, i, t)     arc length from the segment start to t (Gauss-Legendre)
arclen_coeffs(a, b, c, t0, t1)  arc length of a cubic's piece from its derivative's coefficients
wrap_s(cv, c, s)                arc length wrapped into a closed curve's period (clamped when open)
locate(cv, c, s)                (segment, t) at arc length s
last_at_or_below(arr, a, b, x)  the bisection of a sorted array that ``locate`` and the frame lookups use
curve_point_at(cv, c, s)        position at arc length s
normalize3, cross3              3-vector helpers

Frames are in ``stages.core.curves.frames``, closest points and the grid of yarns near a point in
``stages.core.curves.closest``, seed 000's yarn space in ``stages.core.curves.yarn_space``.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

Curves = namedtuple("Curves", [
    "points", "tangents", "offsets", "closed", "seg_curve", "seg_length", "seg_arclen",
    "curve_length", "frame_s", "frame_offsets", "frame_normal", "frame_twist", "radius", "delta",
    "grid_lo", "grid_cell", "grid_dims", "grid_cell_start", "grid_items", "grid_pad",
])


# 8-point Gauss-Legendre on [0, 1]
_GL_X = np.array([0.019855071751231856, 0.10166676129318664, 0.2372337950418355, 0.4082826787521751,
                  0.5917173212478249, 0.7627662049581645, 0.8983332387068134, 0.9801449282487681])


_GL_W = np.array([0.05061426814518813, 0.11119051722668724, 0.15685332293894363, 0.18134189168918100,
                  0.18134189168918100, 0.15685332293894363, 0.11119051722668724, 0.05061426814518813])


@njit(cache=True)
def next_index(cv, i):
    # a plain call (LLVM inlines it): numba IR inlining (inline="always") of a function taking the
    # Curves tuple copies the tuple at every call, which made each caller ~20x slower
    c = cv.seg_curve[i]
    j = i + 1
    if j == cv.offsets[c + 1]:
        j = cv.offsets[c]
    return j


@njit(cache=True)
def coeffs_s(cv, i):
    """Segment i's power-basis coefficients as 12 scalars (ax, ay, az, bx, ..., dz): the
    allocation-free form the hot kernels use."""
    c = cv.seg_curve[i]
    j = i + 1
    if j == cv.offsets[c + 1]:
        j = cv.offsets[c]
    P = cv.points
    M = cv.tangents
    ax = 2.0 * P[i, 0] - 2.0 * P[j, 0] + M[i, 0] + M[j, 0]
    ay = 2.0 * P[i, 1] - 2.0 * P[j, 1] + M[i, 1] + M[j, 1]
    az = 2.0 * P[i, 2] - 2.0 * P[j, 2] + M[i, 2] + M[j, 2]
    bx = -3.0 * P[i, 0] + 3.0 * P[j, 0] - 2.0 * M[i, 0] - M[j, 0]
    by = -3.0 * P[i, 1] + 3.0 * P[j, 1] - 2.0 * M[i, 1] - M[j, 1]
    bz = -3.0 * P[i, 2] + 3.0 * P[j, 2] - 2.0 * M[i, 2] - M[j, 2]
    return ax, ay, az, bx, by, bz, M[i, 0], M[i, 1], M[i, 2], P[i, 0], P[i, 1], P[i, 2]


@njit(cache=True)
def point_unit_tangent_s(co, t):
    """(x, y, z, tx, ty, tz): the point and unit tangent at t of the segment whose ``coeffs_s`` are ``co``."""
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = co
    px = ((ax * t + bx) * t + cx) * t + dx
    py = ((ay * t + by) * t + cy) * t + dy
    pz = ((az * t + bz) * t + cz) * t + dz
    tx, ty, tz = velocity_s(ax, ay, az, bx, by, bz, cx, cy, cz, t)
    nt = math.sqrt(tx * tx + ty * ty + tz * tz)
    return px, py, pz, tx / nt, ty / nt, tz / nt


@njit(cache=True)
def velocity_s(ax, ay, az, bx, by, bz, cx, cy, cz, t):
    """P'(t) = (3 a t + 2 b) t + c of a segment with power-basis coefficients a, b, c (``coeffs_s``), 3 scalars."""
    return (3.0 * ax * t + 2.0 * bx) * t + cx, (3.0 * ay * t + 2.0 * by) * t + cy, (3.0 * az * t + 2.0 * bz) * t + cz


@njit(cache=True)
def acceleration_s(ax, ay, az, bx, by, bz, t):
    """P''(t) = 6 a t + 2 b of a segment with power-basis coefficients a, b (``coeffs_s``), 3 scalars."""
    return 6.0 * ax * t + 2.0 * bx, 6.0 * ay * t + 2.0 * by, 6.0 * az * t + 2.0 * bz


@njit(cache=True)
def _speed_s(ax, ay, az, bx, by, bz, cx, cy, cz, t):
    x, y, z = velocity_s(ax, ay, az, bx, by, bz, cx, cy, cz, t)
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def _arclen_s(ax, ay, az, bx, by, bz, cx, cy, cz, t0, t1):
    """arclen_coeffs on scalar coefficients (same quadrature, same operations)."""
    total = 0.0
    h = 0.5 * (t1 - t0)
    for panel in range(2):
        lo = t0 + panel * h
        for k in range(8):
            total += _GL_W[k] * _speed_s(ax, ay, az, bx, by, bz, cx, cy, cz, lo + h * _GL_X[k])
    return total * h


@njit(cache=True)
def _t_at_length_s(ax, ay, az, bx, by, bz, cx, cy, cz, seglen, target):
    """Invert arc length within a segment: safeguarded Newton on L(t) - target."""
    if target <= 0.0:
        return 0.0
    if target >= seglen:
        return 1.0
    lo = 0.0
    hi = 1.0
    t = target / seglen
    for _ in range(30):
        f = _arclen_s(ax, ay, az, bx, by, bz, cx, cy, cz, 0.0, t) - target
        if abs(f) < 1e-13 * max(seglen, 1e-30):
            break
        if f > 0.0:
            hi = t
        else:
            lo = t
        sp = _speed_s(ax, ay, az, bx, by, bz, cx, cy, cz, t)
        tn = t - f / sp if sp > 0.0 else 0.5 * (lo + hi)
        if not (lo < tn < hi):
            tn = 0.5 * (lo + hi)
        t = tn
    return t


@njit(cache=True)
def segment_coeffs(cv, i):
    """(a, b, c, d) with P(t) = a t^3 + b t^2 + c t + d on segment i (cubic Hermite)."""
    j = next_index(cv, i)
    p0 = cv.points[i]
    p1 = cv.points[j]
    m0 = cv.tangents[i]
    m1 = cv.tangents[j]
    a = 2.0 * p0 - 2.0 * p1 + m0 + m1
    b = -3.0 * p0 + 3.0 * p1 - 2.0 * m0 - m1
    return a, b, m0.copy(), p0.copy()


@njit(cache=True)
def segment_point(cv, i, t):
    a, b, c, d = segment_coeffs(cv, i)
    return ((a * t + b) * t + c) * t + d


@njit(cache=True)
def segment_deriv(cv, i, t):
    a, b, c, d = segment_coeffs(cv, i)
    return (3.0 * a * t + 2.0 * b) * t + c


@njit(cache=True)
def _speed(a, b, c, t):
    x = (3.0 * a[0] * t + 2.0 * b[0]) * t + c[0]
    y = (3.0 * a[1] * t + 2.0 * b[1]) * t + c[1]
    z = (3.0 * a[2] * t + 2.0 * b[2]) * t + c[2]
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def arclen_coeffs(a, b, c, t0, t1):
    """Arc length between t0 and t1 (two 8-point Gauss-Legendre panels)."""
    total = 0.0
    h = 0.5 * (t1 - t0)
    for panel in range(2):
        lo = t0 + panel * h
        for k in range(8):
            total += _GL_W[k] * _speed(a, b, c, lo + h * _GL_X[k])
    return total * h


@njit(cache=True)
def segment_arclen_to(cv, i, t):
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = coeffs_s(cv, i)
    return _arclen_s(ax, ay, az, bx, by, bz, cx, cy, cz, 0.0, t)


@njit(cache=True)
def wrap_s(cv, c, s):
    L = cv.curve_length[c]
    if cv.closed[c]:
        s = s - math.floor(s / L) * L
    else:
        if s < 0.0:
            s = 0.0
        elif s > L:
            s = L
    return s


@njit(cache=True)
def locate(cv, c, s):
    """(segment index, t) at arc length s on curve c (clamped; wrapped on closed curves)."""
    s = wrap_s(cv, c, s)
    lo = cv.offsets[c]
    nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
    hi = lo + nseg - 1
    # last segment whose start arc length <= s
    a = last_at_or_below(cv.seg_arclen, lo, hi, s)
    return a, segment_t_at(cv, a, s - cv.seg_arclen[a])


@njit(cache=True)
def last_at_or_below(arr, a, b, x):
    """The last index m in [a, b] with arr[m] <= x (a where there is none), by bisection of the sorted arr[a..b]."""
    while a < b:
        m = (a + b + 1) // 2
        if arr[m] <= x:
            a = m
        else:
            b = m - 1
    return a


@njit(cache=True)
def segment_t_at(cv, i, length):
    """Parameter t of segment i at arc length ``length`` from its start (clamped to the segment)."""
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = coeffs_s(cv, i)
    return _t_at_length_s(ax, ay, az, bx, by, bz, cx, cy, cz, cv.seg_length[i], length)


@njit(cache=True)
def curve_point_at(cv, c, s):
    i, t = locate(cv, c, s)
    return segment_point(cv, i, t)


@njit(cache=True)
def normalize3(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return v / n


@njit(cache=True)
def cross3(a, b):
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out
