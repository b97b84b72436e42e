"""Yarn centre curves: C1 cubic Hermite (uniform Catmull-Rom) splines with arc length and
rotation-minimising frames, and the queries every stage asks of them (seed 000 §4.2, §5.1, §5.2).

A ``Curves`` namedtuple of flat arrays describes all curves (layout in docs/architecture.md):
curve c owns points ``offsets[c]:offsets[c+1]``; segment i (global, same index as its first
point) runs from point i to the next one (closed curves wrap). Positions on a curve are given by
arc length s in [0, curve_length[c]] (closed curves: s wraps).

Kernels
-------
segment_coeffs(cv, i)           power-basis coefficients a t^3 + b t^2 + c t + d of segment i
segment_point / segment_deriv   position / dP/dt on segment i at t in [0, 1]
segment_arclen_to(cv, i, t)     arc length from the segment start to t (Gauss-Legendre)
locate(cv, c, s)                (segment, t) at arc length s
curve_point_at(cv, c, s)        position at arc length s
curve_frame_at(cv, c, s)        (position, tangent, normal, binormal): RMF, b = t x n
frame_at_segment(cv, c, i, t)   the same frame at segment i, parameter t (no arc-length inversion:
                                the stored RMF sample before it is found from (i, t) directly)
curve_frame_at_s / frame_at_segment_s   allocation-free forms (12 scalars) for hot loops
closest_on_segment(cv, i, p)    (t, distance^2): global minimum over t in [0, 1], exact root
                                isolation of the quintic d/dt |P(t) - p|^2 (never a local minimum)
closest_point_on_curve(cv,c,p)  (s, distance^2) over all segments of curve c near p
yarns_near(cv, p, r, out)       curves passing within r of p (grid over segment boxes)
to_yarn_space(cv, c, p)         seed 000 Eq. 8-9: (x, y, s, distance^2) with x along n, y along b
from_yarn_space(cv, c, x, y, s) seed 000 Eq. 7: x n(s) + y b(s) + alpha(s)
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
def _next_index(cv, i):
    # a plain call (LLVM inlines it): numba IR inlining (inline="always") of a function taking the
    # Curves tuple copies the tuple at every call, which made each caller ~20x slower
    c = cv.seg_curve[i]
    j = i + 1
    if j == cv.offsets[c + 1]:
        j = cv.offsets[c]
    return j


@njit(cache=True)
def _coeffs_s(cv, i):
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
def _speed_s(ax, ay, az, bx, by, bz, cx, cy, cz, t):
    x = (3.0 * ax * t + 2.0 * bx) * t + cx
    y = (3.0 * ay * t + 2.0 * by) * t + cy
    z = (3.0 * az * t + 2.0 * bz) * t + cz
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def _arclen_s(ax, ay, az, bx, by, bz, cx, cy, cz, t0, t1):
    """_arclen_coeffs on scalar coefficients (same quadrature, same operations)."""
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
    j = _next_index(cv, i)
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
def _arclen_coeffs(a, b, c, t0, t1):
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
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = _coeffs_s(cv, i)
    return _arclen_s(ax, ay, az, bx, by, bz, cx, cy, cz, 0.0, t)


@njit(cache=True)
def _wrap_s(cv, c, s):
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
    s = _wrap_s(cv, c, s)
    lo = cv.offsets[c]
    nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
    hi = lo + nseg - 1
    # last segment whose start arc length <= s
    a = lo
    b = hi
    while a < b:
        m = (a + b + 1) // 2
        if cv.seg_arclen[m] <= s:
            a = m
        else:
            b = m - 1
    i = a
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = _coeffs_s(cv, i)
    t = _t_at_length_s(ax, ay, az, bx, by, bz, cx, cy, cz, cv.seg_length[i], s - cv.seg_arclen[i])
    return i, t


@njit(cache=True)
def curve_point_at(cv, c, s):
    i, t = locate(cv, c, s)
    return segment_point(cv, i, t)


@njit(cache=True)
def _normalize(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return v / n


@njit(cache=True)
def _cross(a, b):
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@njit(cache=True)
def double_reflection(x0, t0, r0, x1, t1):
    """One step of the double reflection method (Wang et al. 2008): carry the reference vector r0 at
    (x0, t0) to the point x1 with unit tangent t1; returns r1 (orthonormal to t1)."""
    v1 = x1 - x0
    c1 = np.dot(v1, v1)
    if c1 < 1e-300:
        rl = r0
        tl = t0
    else:
        rl = r0 - (2.0 / c1) * np.dot(v1, r0) * v1
        tl = t0 - (2.0 / c1) * np.dot(v1, t0) * v1
    v2 = t1 - tl
    c2 = np.dot(v2, v2)
    if c2 < 1e-300:
        r1 = rl
    else:
        r1 = rl - (2.0 / c2) * np.dot(v2, rl) * v2
    r1 = r1 - np.dot(r1, t1) * t1
    return _normalize(r1)


@njit(cache=True)
def _frame_sample_index(cv, c, i, t, s):
    """Index of the stored RMF sample at or before (segment i, t) = arc length s on curve c, and that
    sample's (segment, t). Samples sit at t = q/K of every segment (stages/ingest/spline_process.py
    rotation_minimising_frames: curve c's sample frame_offsets[c] + (i - offsets[c]) K + q is segment
    i at t = q/K), so no arc length is inverted; a frame table of another layout is searched by s."""
    lo = cv.offsets[c]
    fo = cv.frame_offsets[c]
    nf = cv.frame_offsets[c + 1] - fo
    nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
    K = (nf - 1) // nseg if nseg > 0 else 0
    if K >= 1 and K * nseg == nf - 1:
        q = int(math.floor(t * K))
        if q < 0:
            q = 0
        elif q > K:
            q = K
        return fo + (i - lo) * K + q, i, q / K
    a = fo
    b = fo + nf - 1
    while a < b:
        m = (a + b + 1) // 2
        if cv.frame_s[m] <= s:
            a = m
        else:
            b = m - 1
    j, t0 = locate(cv, c, cv.frame_s[a])
    return a, j, t0


@njit(cache=True)
def _frame_s(cv, c, i, t, s):
    """The RMF at (segment i, t) = arc length s (s already wrapped) as 12 scalars: position, unit
    tangent, normal, binormal (double reflection from the stored sample at or before it, closed
    curves' holonomy spread along the length). Allocation free."""
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = _coeffs_s(cv, i)
    px = ((ax * t + bx) * t + cx) * t + dx
    py = ((ay * t + by) * t + cy) * t + dy
    pz = ((az * t + bz) * t + cz) * t + dz
    tx = (3.0 * ax * t + 2.0 * bx) * t + cx
    ty = (3.0 * ay * t + 2.0 * by) * t + cy
    tz = (3.0 * az * t + 2.0 * bz) * t + cz
    nt = math.sqrt(tx * tx + ty * ty + tz * tz)
    tx /= nt
    ty /= nt
    tz /= nt
    a, j, t0 = _frame_sample_index(cv, c, i, t, s)
    if j != i:
        ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = _coeffs_s(cv, j)
    x0 = ((ax * t0 + bx) * t0 + cx) * t0 + dx
    y0 = ((ay * t0 + by) * t0 + cy) * t0 + dy
    z0 = ((az * t0 + bz) * t0 + cz) * t0 + dz
    ux = (3.0 * ax * t0 + 2.0 * bx) * t0 + cx
    uy = (3.0 * ay * t0 + 2.0 * by) * t0 + cy
    uz = (3.0 * az * t0 + 2.0 * bz) * t0 + cz
    nu = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux /= nu
    uy /= nu
    uz /= nu
    # double reflection (Wang et al. 2008) of the stored normal r0 from (x0, u) to (p, t)
    rx = cv.frame_normal[a, 0]
    ry = cv.frame_normal[a, 1]
    rz = cv.frame_normal[a, 2]
    vx = px - x0
    vy = py - y0
    vz = pz - z0
    c1 = vx * vx + vy * vy + vz * vz
    # at the sample itself (up to rounding: p and x0 come from t and q/K, which may differ in the
    # last bits) the chord direction is noise and the two reflections could compose to a half turn
    # about t: take the stored normal, as the reflections would at the exact same point
    if c1 > 1e-24 * (1.0 + px * px + py * py + pz * pz):
        f = (2.0 / c1) * (vx * rx + vy * ry + vz * rz)
        rx -= f * vx
        ry -= f * vy
        rz -= f * vz
        f = (2.0 / c1) * (vx * ux + vy * uy + vz * uz)
        ux -= f * vx
        uy -= f * vy
        uz -= f * vz
        vx = tx - ux
        vy = ty - uy
        vz = tz - uz
        c2 = vx * vx + vy * vy + vz * vz
        if c2 >= 1e-300:
            f = (2.0 / c2) * (vx * rx + vy * ry + vz * rz)
            rx -= f * vx
            ry -= f * vy
            rz -= f * vz
    f = rx * tx + ry * ty + rz * tz
    rx -= f * tx
    ry -= f * ty
    rz -= f * tz
    nr = math.sqrt(rx * rx + ry * ry + rz * rz)
    rx /= nr
    ry /= nr
    rz /= nr
    tw = cv.frame_twist[c]
    if tw != 0.0:  # Rodrigues rotation about t by -tw s / L
        ang = -tw * s / cv.curve_length[c]
        ca = math.cos(ang)
        sa = math.sin(ang)
        kx = ty * rz - tz * ry
        ky = tz * rx - tx * rz
        kz = tx * ry - ty * rx
        f = (tx * rx + ty * ry + tz * rz) * (1.0 - ca)
        rx = rx * ca + kx * sa + tx * f
        ry = ry * ca + ky * sa + ty * f
        rz = rz * ca + kz * sa + tz * f
    f = rx * tx + ry * ty + rz * tz
    rx -= f * tx
    ry -= f * ty
    rz -= f * tz
    nr = math.sqrt(rx * rx + ry * ry + rz * rz)
    rx /= nr
    ry /= nr
    rz /= nr
    return (px, py, pz, tx, ty, tz, rx, ry, rz,
            ty * rz - tz * ry, tz * rx - tx * rz, tx * ry - ty * rx)


@njit(cache=True)
def _frame_arrays(f):
    pos = np.empty(3)
    tan = np.empty(3)
    n = np.empty(3)
    bn = np.empty(3)
    for k in range(3):
        pos[k] = f[k]
        tan[k] = f[3 + k]
        n[k] = f[6 + k]
        bn[k] = f[9 + k]
    return pos, tan, n, bn


@njit(cache=True)
def curve_frame_at_s(cv, c, s):
    """curve_frame_at as 12 scalars (px, py, pz, tx, ty, tz, nx, ny, nz, bx, by, bz)."""
    s = _wrap_s(cv, c, s)
    i, t = locate(cv, c, s)
    return _frame_s(cv, c, i, t, s)


@njit(cache=True)
def frame_at_segment_s(cv, c, i, t):
    """The frame at segment i, parameter t (no arc-length inversion) as 12 scalars, and its arc
    length s: (frame tuple, s)."""
    s = cv.seg_arclen[i] + segment_arclen_to(cv, i, t)
    return _frame_s(cv, c, i, t, s), s


@njit(cache=True)
def frame_at_segment(cv, c, i, t):
    """(position, unit tangent, normal, binormal) at segment i of curve c, parameter t: the same
    frame as curve_frame_at at that point's arc length, without inverting the arc length."""
    f, s = frame_at_segment_s(cv, c, i, t)
    return _frame_arrays(f)


@njit(cache=True)
def curve_frame_at(cv, c, s):
    """(position, unit tangent, normal, binormal) at arc length s: the rotation-minimising frame
    (double reflection from the nearest stored sample), closed curves with their holonomy
    spread evenly along the length so the frame closes up."""
    return _frame_arrays(curve_frame_at_s(cv, c, s))


# ------------------------------------------------------------------------------------------------
# closest point: exact root isolation of the quintic derivative of the squared distance
@njit(cache=True, inline="always")
def _peval(cf, deg, t):
    r = cf[deg]
    for k in range(deg - 1, -1, -1):
        r = r * t + cf[k]
    return r


@njit(cache=True)
def _roots01(q, out):
    """Sorted roots in (0, 1) of the quintic q[0] + q[1] t + ... + q[5] t^5 (returns count).

    Each derivative's roots split [0, 1] into intervals where the next lower derivative is monotone,
    so each interval holds at most one root, found by safeguarded Newton: no root is missed."""
    D = np.zeros((5, 6))
    for k in range(6):
        D[0, k] = q[k]
    for lev in range(1, 5):
        for k in range(0, 6 - lev):
            D[lev, k] = D[lev - 1, k + 1] * (k + 1)
    roots = np.empty(8)
    nr = 0
    if D[4, 1] != 0.0:
        r = -D[4, 0] / D[4, 1]
        if 0.0 < r < 1.0:
            roots[0] = r
            nr = 1
    br = np.empty(8)
    for lev in range(3, -1, -1):
        deg = 5 - lev
        br[0] = 0.0
        for k in range(nr):
            br[k + 1] = roots[k]
        br[nr + 1] = 1.0
        nb = nr + 2
        nnew = 0
        for k in range(nb - 1):
            lo = br[k]
            hi = br[k + 1]
            flo = _peval(D[lev], deg, lo)
            fhi = _peval(D[lev], deg, hi)
            if flo == 0.0:
                if lo > 0.0 and (nnew == 0 or roots[nnew - 1] != lo):
                    out[nnew] = lo
                    nnew += 1
                continue
            if flo * fhi > 0.0 or fhi == 0.0:
                continue
            a = lo
            b = hi
            t = 0.5 * (a + b)
            for _ in range(60):
                f = _peval(D[lev], deg, t)
                if f == 0.0:
                    break
                if (f < 0.0) == (flo < 0.0):
                    a = t
                else:
                    b = t
                df = _peval(D[lev + 1], deg - 1, t) if lev < 4 else 0.0
                tn = t - f / df if df != 0.0 else 0.5 * (a + b)
                if not (a < tn < b):
                    tn = 0.5 * (a + b)
                if abs(tn - t) < 1e-15:
                    t = tn
                    break
                t = tn
            out[nnew] = t
            nnew += 1
        for k in range(nnew):
            roots[k] = out[k]
        nr = nnew
    for k in range(nr):
        out[k] = roots[k]
    return nr


@njit(cache=True)
def closest_on_segment(cv, i, p):
    """(t, squared distance) of the closest point of segment i to p; the global minimum over [0, 1]."""
    a, b, c, d = segment_coeffs(cv, i)
    e = d - p
    q = np.empty(6)  # (1/2) d/dt |P(t) - p|^2
    q[5] = 3.0 * np.dot(a, a)
    q[4] = 5.0 * np.dot(a, b)
    q[3] = 4.0 * np.dot(a, c) + 2.0 * np.dot(b, b)
    q[2] = 3.0 * np.dot(b, c) + 3.0 * np.dot(a, e)
    q[1] = np.dot(c, c) + 2.0 * np.dot(b, e)
    q[0] = np.dot(c, e)
    roots = np.empty(8)
    nr = _roots01(q, roots)
    best_t = 0.0
    best = np.dot(e, e)
    g1 = a + b + c + e
    d1 = np.dot(g1, g1)
    if d1 < best:
        best = d1
        best_t = 1.0
    for k in range(nr):
        t = roots[k]
        g = ((a * t + b) * t + c) * t + e
        dd = np.dot(g, g)
        if dd < best:
            best = dd
            best_t = t
    return best_t, best


@njit(cache=True, inline="always")
def _segment_box_dist2(cv, i, p):
    """Squared distance from p to the box of segment i's Bezier control points (a lower bound).
    Inlined into its callers (it runs over every segment of a grid cell): as a separate call taking
    the Curves tuple it cost ~20x its arithmetic."""
    c = cv.seg_curve[i]
    j = i + 1
    if j == cv.offsets[c + 1]:
        j = cv.offsets[c]
    d2 = 0.0
    for k in range(3):
        b0 = cv.points[i, k]
        b3 = cv.points[j, k]
        b1 = b0 + cv.tangents[i, k] / 3.0
        b2 = b3 - cv.tangents[j, k] / 3.0
        lo = min(min(b0, b1), min(b2, b3))
        hi = max(max(b0, b1), max(b2, b3))
        if p[k] < lo:
            d2 += (lo - p[k]) ** 2
        elif p[k] > hi:
            d2 += (p[k] - hi) ** 2
    return d2


@njit(cache=True)
def _grid_cell_of(cv, p):
    cell = cv.grid_cell[0]
    idx = 0
    stride = 1
    for k in range(3):
        g = int(math.floor((p[k] - cv.grid_lo[k]) / cell))
        if g < 0 or g >= cv.grid_dims[k]:
            return -1
        idx += g * stride
        stride *= cv.grid_dims[k]
    return idx


@njit(cache=True)
def nearest_segments_in_cell(cv, p):
    """(start, end) into grid_items of the segments whose padded boxes overlap p's cell."""
    cell = _grid_cell_of(cv, p)
    if cell < 0:
        return 0, 0
    return cv.grid_cell_start[cell], cv.grid_cell_start[cell + 1]


@njit(cache=True)
def closest_point_on_curve(cv, c, p):
    """(s, squared distance) of the closest point of curve c to p: the global minimum.

    The grid's candidate segments in p's cell cover every point within the curve's pad (yarn radius
    + δ); when the best candidate is farther than that pad, all segments of the curve are searched
    (with box pruning), so the answer is exact everywhere."""
    best = 1e300
    best_i = -1
    best_t = 0.0
    start, end = nearest_segments_in_cell(cv, p)
    for k in range(start, end):
        i = cv.grid_items[k]
        if cv.seg_curve[i] != c:
            continue
        if _segment_box_dist2(cv, i, p) >= best:
            continue
        t, d2 = closest_on_segment(cv, i, p)
        if d2 < best:
            best = d2
            best_i = i
            best_t = t
    if best > cv.grid_pad[c] * cv.grid_pad[c]:
        lo = cv.offsets[c]
        nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
        for i in range(lo, lo + nseg):
            if _segment_box_dist2(cv, i, p) >= best:
                continue
            t, d2 = closest_on_segment(cv, i, p)
            if d2 < best:
                best = d2
                best_i = i
                best_t = t
    s = cv.seg_arclen[best_i] + segment_arclen_to(cv, best_i, best_t)
    return s, best


@njit(cache=True)
def yarns_near(cv, p, r, out):
    """Write into ``out`` the distinct curves that pass within r of p; exact for r up to each
    curve's grid pad (yarn radius + δ by default); returns how many."""
    start, end = nearest_segments_in_cell(cv, p)
    n = 0
    r2 = r * r
    for k in range(start, end):
        i = cv.grid_items[k]
        c = cv.seg_curve[i]
        dup = False
        for m in range(n):
            if out[m] == c:
                dup = True
                break
        if dup:
            continue
        if _segment_box_dist2(cv, i, p) > r2:
            continue
        t, d2 = closest_on_segment(cv, i, p)
        if d2 <= r2 and n < out.shape[0]:
            out[n] = c
            n += 1
    return n


@njit(cache=True)
def to_yarn_space(cv, c, p):
    """seed 000 Eq. 8-9: yarn-space (x, y, z = s) of fabric-space p for curve c, and distance^2."""
    s, d2 = closest_point_on_curve(cv, c, p)
    pos, tan, n, bn = curve_frame_at(cv, c, s)
    r = p - pos
    return np.dot(r, n), np.dot(r, bn), s, d2


@njit(cache=True)
def from_yarn_space(cv, c, x, y, s):
    """seed 000 Eq. 7: f([x, y, s]) = x n(s) + y b(s) + alpha(s)."""
    pos, tan, n, bn = curve_frame_at(cv, c, s)
    return pos + x * n + y * bn
