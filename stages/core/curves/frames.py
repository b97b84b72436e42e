"""Rotation-minimising frames along yarn curves (double reflection, Wang et al. 2008).

The ingest stage stores RMF samples (``frame_s``, ``frame_offsets``, ``frame_normal``,
``frame_twist`` of ``Curves``); these kernels carry the nearest stored sample to any point by one
double reflection, with a closed curve's holonomy spread evenly along its length so the frame
closes up. The binormal is b = t x n.

curve_frame_at(cv, c, s)        (position, tangent, normal, binormal) at arc length s
frame_at_segment(cv, c, i, t)   the same frame at segment i, parameter t (no arc-length inversion:
                                the stored RMF sample before it is found from (i, t) directly)
curve_frame_at_s / frame_at_segment_s   allocation-free forms (12 scalars) for hot loops, compiled
                                without reference counting (``_nrt=False``: reading the curves' arrays
                                costs no atomic reference-count updates per call)
double_reflection(x0, t0, r0, x1, t1)   one step of the method (used by the ingest stage too)
"""
import math

import numpy as np
from numba import njit

from .spline import coeffs_s, last_at_or_below, locate, normalize3, point_unit_tangent_s, segment_arclen_to, wrap_s


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
    return normalize3(r1)


@njit(cache=True, _nrt=False)
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
    a = last_at_or_below(cv.frame_s, fo, fo + nf - 1, s)
    j, t0 = locate(cv, c, cv.frame_s[a])
    return a, j, t0


@njit(cache=True, _nrt=False)
def frame_s(cv, c, i, t, s):
    """The RMF at (segment i, t) = arc length s (s already wrapped) as 12 scalars: position, unit
    tangent, normal, binormal (double reflection from the stored sample at or before it, closed
    curves' holonomy spread along the length). Allocation free."""
    co = coeffs_s(cv, i)
    px, py, pz, tx, ty, tz = point_unit_tangent_s(co, t)
    a, j, t0 = _frame_sample_index(cv, c, i, t, s)
    if j != i:
        co = coeffs_s(cv, j)
    x0, y0, z0, ux, uy, uz = point_unit_tangent_s(co, t0)
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
        rx, ry, rz = _reflect(rx, ry, rz, vx, vy, vz, c1)
        ux, uy, uz = _reflect(ux, uy, uz, vx, vy, vz, c1)
        vx = tx - ux
        vy = ty - uy
        vz = tz - uz
        c2 = vx * vx + vy * vy + vz * vz
        if c2 >= 1e-300:
            rx, ry, rz = _reflect(rx, ry, rz, vx, vy, vz, c2)
    rx, ry, rz = _unit_normal_part(rx, ry, rz, tx, ty, tz)
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
    rx, ry, rz = _unit_normal_part(rx, ry, rz, tx, ty, tz)
    return (px, py, pz, tx, ty, tz, rx, ry, rz,
            ty * rz - tz * ry, tz * rx - tx * rz, tx * ry - ty * rx)


@njit(cache=True)
def _reflect(rx, ry, rz, vx, vy, vz, c):
    """r reflected in the plane normal to v, c = |v|^2: r - (2 / c) (v . r) v (a step of the double reflection)."""
    f = (2.0 / c) * (vx * rx + vy * ry + vz * rz)
    return rx - f * vx, ry - f * vy, rz - f * vz


@njit(cache=True)
def _unit_normal_part(rx, ry, rz, tx, ty, tz):
    """r's part normal to the unit vector t, normalised: (r - (r . t) t) / |r - (r . t) t|."""
    f = rx * tx + ry * ty + rz * tz
    rx -= f * tx
    ry -= f * ty
    rz -= f * tz
    nr = math.sqrt(rx * rx + ry * ry + rz * rz)
    return rx / nr, ry / nr, rz / nr


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


@njit(cache=True, _nrt=False)
def curve_frame_at_s(cv, c, s):
    """curve_frame_at as 12 scalars (px, py, pz, tx, ty, tz, nx, ny, nz, bx, by, bz)."""
    s = wrap_s(cv, c, s)
    i, t = locate(cv, c, s)
    return frame_s(cv, c, i, t, s)


@njit(cache=True, _nrt=False)
def frame_at_segment_s(cv, c, i, t):
    """The frame at segment i, parameter t (no arc-length inversion) as 12 scalars, and its arc
    length s: (frame tuple, s)."""
    s = cv.seg_arclen[i] + segment_arclen_to(cv, i, t)
    return frame_s(cv, c, i, t, s), s


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
