"""Closest points and exact coverage tests of ONE regular fibre or hair (seed 000 §5.2; the per-fibre
steps 3-4 of Algorithm 1, whose candidate search is ``stages.core.yarn.lookup``).

A fibre is given in yarn space by the model (``stages.core.yarn.model``): regular fibre j of ply k by
``regular_xy`` with its table row (``RegularFibre``: k, j, R, theta, theta0; loops included: a
cycle's mutation is a consistent random number, §4.4.1), a hair by ``hair_point`` with its shape
(``HairShape``: start and end radius r0, r1, start azimuth th1, azimuth extent pe of
``model.hair_params``, and its z extent z1, ze). Its centre curve in fabric space is that curve
mapped by Eq. 7; p is inside the fibre when its distance to the centre curve is below the fibre
radius (the definition of ``lookup``).

``YarnVisit`` is what the tests of one yarn's fibres at p share: the yarn's sampled frames
(frame-sample arrays ``fs``, ``fr``, its samples lo..hi-1, the step ``i`` holding p's foot point),
the yarn (index ``c``, type parameters ``tp``, random key ``yseed``), p in yarn space (``x``, ``y`` at
arc length ``s``) and in fabric space (``px``, ``py``, ``pz``), the z window [za, zb] holding every
fibre point within the fibre radius ``rf`` of p, and eps_c (``eps``), the bound of the sampled
frames' error.

Under the sampled frames (allocation-free, scalar): ``regular_closest_s`` and ``hair_closest_s``
give the distance of p to the fibre over the window, the closest parameter and the unit tangent
there, by Gauss-Newton with forward differences until a step moves the fibre point by less than
tol. Cheaper hair rejects come first: ``hair_quick_reject`` (the hair's z and radius ranges) and
``hair_prefilter`` (a lower bound of the distance from the hair's yarn-space polyline).
Under the exact frames of Eq. 7, for the rare points within eps_c of a fibre surface (where the
sampled frames cannot decide): ``exact_regular`` and ``exact_hair`` build a local model of Eq. 7
from exact frames at three arc lengths (``local_frames``), run Gauss-Newton on it
(``regular_closest``, ``hair_closest``), and decide with the exact map at the model's closest point
(``regular_exact``, ``hair_exact``) when the model distance is within MODEL_SLACK fibre radii.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.curves.frames import curve_frame_at
from stages.core.dispatch import is_tuple_class
from stages.core.sampling import NO_HIT
from stages.core.yarn.frame_samples import eq7, frame_at
from stages.core.yarn.model import PLY_RADIUS, YARN_ALPHA, hair_point, hair_speed_bound, regular_xy

TWO_PI = 2.0 * math.pi
MODEL_SLACK = 0.1  # exact-frame local model: distance error allowed before the exact check, in fibre radii
HAIR_SAMPLES = 16

RegularFibre = namedtuple("RegularFibre", ["k", "j", "R", "th", "th0"])
RegularFibre.__doc__ = """Regular fibre j of ply k and its table row: radius R, azimuth th, migration phase th0."""

HairShape = namedtuple("HairShape", ["r0", "r1", "th1", "pe", "z1", "ze"])
HairShape.__doc__ = """A hair: start and end radius, start azimuth, azimuth extent, z start and z extent."""

YarnVisit = namedtuple("YarnVisit", ["fs", "fr", "lo", "hi", "i", "c", "tp", "yseed", "s", "x", "y", "za", "zb",
                                     "rf", "eps", "px", "py", "pz"])
YarnVisit.__doc__ = """What the tests of one yarn's fibres at p share (module doc)."""

LocalFrames = namedtuple("LocalFrames", ["za", "zm", "zb", "M"])
LocalFrames.__doc__ = """Exact frames at arc lengths za < zm < zb: M[i] = (position, normal, binormal) at node i."""


@njit(cache=True, inline="always")
def stored_hair(tab, hh):
    """The ``HairShape`` of stored (hybrid-mode) hair row hh of the tables."""
    return HairShape(tab.hair_r0[hh], tab.hair_r1[hh], tab.hair_th1[hh], tab.hair_pe[hh], tab.hair_z1[hh],
                     tab.hair_ze[hh])


@njit(cache=True, inline="always")
def fibre_xy(tp, yseed, fib, z):
    """Yarn-space (x, y, kind) of regular fibre ``fib`` of the yarn with key yseed at z."""
    return regular_xy(tp, yseed, fib.k, fib.j, fib.R, fib.th, fib.th0, z)


@njit(cache=True, inline="always")
def _hair_xyz(tp, k, hs, t):
    return hair_point(tp, k, hs.r0, hs.r1, hs.th1, hs.pe, hs.z1, hs.ze, t)


@njit(cache=True)
def local_frames(cv, c, s, h, pos0, n0, b0):
    """Exact frames at three arc lengths around s (window [za, zb] of half width h, clipped to the
    curve): the local model of Eq. 7 that Gauss-Newton iterates on (``LocalFrames``)."""
    L = cv.curve_length[c]
    za = max(0.0, s - h)
    zb = min(L, s + h)
    zm = 0.5 * (za + zb)
    M = np.empty((3, 3, 3))
    zs = (za, zm, zb)
    for i in range(3):
        if zs[i] == s:
            M[i, 0] = pos0
            M[i, 1] = n0
            M[i, 2] = b0
            continue
        pos, t, n, b = curve_frame_at(cv, c, zs[i])
        M[i, 0] = pos
        M[i, 1] = n
        M[i, 2] = b
    return LocalFrames(za, zm, zb, M)


@njit(cache=True)
def _model_map(lf, x, y, z):
    """Eq. 7 with position and frame interpolated quadratically between the three nodes."""
    za, zm, zb, M = lf.za, lf.zm, lf.zb, lf.M
    wa = (z - zm) * (z - zb) / ((za - zm) * (za - zb))
    wm = (z - za) * (z - zb) / ((zm - za) * (zm - zb))
    wb = (z - za) * (z - zm) / ((zb - za) * (zb - zm))
    out = np.empty(3)
    for d in range(3):
        out[d] = (wa * (M[0, 0, d] + x * M[0, 1, d] + y * M[0, 2, d])
                  + wm * (M[1, 0, d] + x * M[1, 1, d] + y * M[1, 2, d])
                  + wb * (M[2, 0, d] + x * M[2, 1, d] + y * M[2, 2, d]))
    return out


@njit(cache=True)
def _exact_map(cv, c, x, y, z):
    pos, t, n, b = curve_frame_at(cv, c, z)
    return pos + x * n + y * b


@njit(cache=True)
def _distance(F, p):
    """|F - p| of two points (arrays)."""
    r = F - p
    return math.sqrt(np.dot(r, r))


@njit(cache=True)
def _gn_terms(Fp, Fm, F0, p, step):
    """((F0 - p) . D, D . D) with D = (Fp - Fm) / step: a Gauss-Newton step's numerator and denominator."""
    D = (Fp - Fm) / step
    return np.dot(F0 - p, D), np.dot(D, D)


@njit(cache=True)
def _reg_model(lf, tp, yseed, fib, z):
    x, y, kind = fibre_xy(tp, yseed, fib, z)
    return _model_map(lf, x, y, z)


@njit(cache=True)
def regular_closest(lf, tp, yseed, fib, p, z0):
    """(model distance, z*) of regular fibre ``fib`` to p: Gauss-Newton on the local model ``lf``
    over [za, zb] from z0."""
    za = lf.za
    zb = lf.zb
    return _model_closest(lf, tp, yseed, fib, p, za, zb, z0, 1e-3 * (zb - za), 1e-13 * (1.0 + zb), False)


@njit(cache=True)
def regular_exact(cv, c, tp, yseed, fib, p, z):
    """Exact (distance, kind) of regular fibre ``fib`` of yarn c at z."""
    x, y, kind = fibre_xy(tp, yseed, fib, z)
    return _distance(_exact_map(cv, c, x, y, z), p), kind


@njit(cache=True)
def hair_window(hs, za, zb):
    """(ta, tb): the part of hair ``hs`` (z = z1 + t ze, t in [0, 1]) whose z lies in the window [za, zb];
    empty (ta > tb) where none does."""
    z1 = hs.z1
    ze = hs.ze
    ta = 0.0
    tb = 1.0
    if ze > 0.0:
        ta = max(ta, (za - z1) / ze)
        tb = min(tb, (zb - z1) / ze)
    elif ze < 0.0:
        ta = max(ta, (zb - z1) / ze)
        tb = min(tb, (za - z1) / ze)
    elif z1 < za or z1 > zb:
        return 1.0, 0.0
    return ta, tb


@njit(cache=True)
def _hair_model(lf, tp, k, hs, t):
    x, y, z = _hair_xyz(tp, k, hs, t)
    return _model_map(lf, x, y, z)


def _model_point(lf, tp, key, curve, t):
    """The local model's point (array) at parameter t of ``curve``: a ``RegularFibre`` (key: its yarn's random key)
    or a ``HairShape`` (key: its ply); numba-only (``stages.core.dispatch``)."""
    raise TypeError("_model_point is only callable from numba-compiled code")


@overload(_model_point)
def _model_point_overload(lf, tp, key, curve, t):
    if is_tuple_class(curve, RegularFibre):
        return lambda lf, tp, key, curve, t: _reg_model(lf, tp, key, curve, t)
    if is_tuple_class(curve, HairShape):
        return lambda lf, tp, key, curve, t: _hair_model(lf, tp, key, curve, t)


@njit(cache=True)
def _model_closest(lf, tp, key, curve, p, lo, hi, t0, h, tol, guarded):
    """(model distance, t*) of ``curve`` (``_model_point``) to p: Gauss-Newton with central differences of
    step h on the local model ``lf`` over [lo, hi] from t0, until a step is below tol; ``guarded``: also stop
    where the differences or the step degenerate (a hair's window may shrink to a point)."""
    t = min(max(t0, lo), hi)
    for _it in range(12):
        tp_ = min(t + h, hi)
        tm = max(t - h, lo)
        if guarded and tp_ <= tm:
            break
        Fp = _model_point(lf, tp, key, curve, tp_)
        Fm = _model_point(lf, tp, key, curve, tm)
        F0 = _model_point(lf, tp, key, curve, t)
        g, dd = _gn_terms(Fp, Fm, F0, p, tp_ - tm)
        if guarded and dd <= 0.0:
            break
        tn = min(max(t - g / dd, lo), hi)
        if abs(tn - t) < tol:
            t = tn
            break
        t = tn
    return _distance(_model_point(lf, tp, key, curve, t), p), t


@njit(cache=True)
def hair_closest(lf, tp, k, hs, p, t0):
    """(model distance, t*) of hair ``hs`` of ply k to p: Gauss-Newton in t over the part of the
    hair whose z lies in the model window [za, zb]; distance NO_HIT where no part does."""
    ta, tb = hair_window(hs, lf.za, lf.zb)
    if ta > tb:
        return NO_HIT, 0.0
    return _model_closest(lf, tp, k, hs, p, ta, tb, t0, max(1e-3 * (tb - ta), 1e-9), 1e-13, True)


@njit(cache=True)
def hair_exact(cv, c, tp, k, hs, p, t):
    """Exact distance of hair ``hs`` of ply k of yarn c to p at t."""
    x, y, z = _hair_xyz(tp, k, hs, t)
    return _distance(_exact_map(cv, c, x, y, z), p)


@njit(cache=True)
def hair_near_z(hs, z, limit):
    """(ta, tb): the part of hair ``hs`` (z = z1 + t ze, t in [0, 1]) whose z lies within ``limit`` of z, empty
    (ta > tb) where none does; all of it, (0, 1), for a hair of constant z (ze = 0)."""
    ta = 0.0
    tb = 1.0
    if hs.ze != 0.0:
        t1 = (z - limit - hs.z1) / hs.ze
        t2 = (z + limit - hs.z1) / hs.ze
        ta = max(ta, min(t1, t2))
        tb = min(tb, max(t1, t2))
    return ta, tb


@njit(cache=True)
def hair_quick_reject(tp, hs, rho_k, s, limit):
    """True when no point of the hair can lie within yarn-space distance ``limit`` of a point at
    distance rho_k from ply k's centre in the cross-section at s: the hair's z must come within
    limit of s, and its radius R(t) within limit (+ the ply centre's drift over limit in z) of rho_k."""
    r0 = hs.r0
    r1 = hs.r1
    ta, tb = hair_near_z(hs, s, limit)
    if ta > tb or (hs.ze == 0.0 and abs(hs.z1 - s) > limit):
        return True
    Ra = r0 + (r1 - r0) * ta
    Rb = r0 + (r1 - r0) * tb
    m = limit * (1.0 + TWO_PI * tp[PLY_RADIUS] / tp[YARN_ALPHA])
    return rho_k < min(Ra, Rb) - m or rho_k > max(Ra, Rb) + m


@njit(cache=True)
def hair_prefilter(tp, k, hs, x, y, z, limit):
    """Yarn-space distance from (x, y, z) to the hair's polyline sampled over the part of the hair
    whose z lies within ``limit`` of z (the only part that can come within limit), less the chord
    slack; returns (lower bound of that distance, best t)."""
    ta, tb = hair_near_z(hs, z, limit)
    if ta > tb:
        return NO_HIT, 0.0
    n = min(HAIR_SAMPLES, max(1, int(math.ceil((tb - ta) * HAIR_SAMPLES))))
    best = NO_HIT
    bt = ta
    for i in range(n + 1):
        t = ta + (tb - ta) * i / n
        qx, qy, qz = _hair_xyz(tp, k, hs, t)
        dx = x - qx
        dy = y - qy
        dz = z - qz
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < best:
            best = d2
            bt = t
    # speed bound of the hair in yarn space -> arc length per sample interval
    return math.sqrt(best) - 0.5 * hair_speed_bound(tp, hs.r0, hs.r1, hs.pe, hs.ze) * (tb - ta) / n, bt


# ------------------------------------------------------------------------------------------------
# distances under the sampled frames (scalar, allocation-free)
@njit(cache=True, inline="always")
def _gn_terms_s(fx, fy, fz, ax, ay, az, inv, px, py, pz):
    """(D, D . D, (f - p) . D) with D = (a - f) inv: the forward-difference tangent at f (the point a one step
    on, inv = 1 / step) and a Gauss-Newton step's denominator and numerator towards p, scalars."""
    Dx = (ax - fx) * inv
    Dy = (ay - fy) * inv
    Dz = (az - fz) * inv
    return Dx, Dy, Dz, Dx * Dx + Dy * Dy + Dz * Dz, (fx - px) * Dx + (fy - py) * Dy + (fz - pz) * Dz


@njit(cache=True, inline="always")
def _closest_s(fx, fy, fz, px, py, pz, Dx, Dy, Dz):
    """(|f - p|, D / |D|): the distance of p to the closest point f and the unit tangent there (D where it
    is 0)."""
    rx, ry, rz = fx - px, fy - py, fz - pz
    n = math.sqrt(Dx * Dx + Dy * Dy + Dz * Dz)
    if n > 0.0:
        Dx /= n
        Dy /= n
        Dz /= n
    return math.sqrt(rx * rx + ry * ry + rz * rz), Dx, Dy, Dz


@njit(cache=True, inline="always")
def _reg_at(vis, fib, i, z):
    """(step, F(z), kind) of regular fibre ``fib`` under the visit's sampled frames."""
    x, y, kind = fibre_xy(vis.tp, vis.yseed, fib, z)
    i, f = frame_at(vis.fs, vis.fr, vis.lo, vis.hi, i, z)
    X, Y, Z = eq7(f, x, y)
    return i, X, Y, Z, kind


@njit(cache=True)
def regular_closest_s(vis, fib, z0, tol):
    """(distance, z*, unit tangent (3 scalars), kind) of regular fibre ``fib`` to the visit's point p
    under the sampled frames: Gauss-Newton over the visit's window [za, zb] from z0 (forward
    differences), until a step moves the fibre point by less than tol (the distance then errs by
    O(tol^2 / distance))."""
    za = vis.za
    zb = vis.zb
    px = vis.px
    py = vis.py
    pz = vis.pz
    i = vis.i
    h = 1e-5 * (zb - za)
    z = min(max(z0, za), zb)
    Dx = Dy = Dz = 0.0
    fx = fy = fz = 0.0
    kind = 1
    for _it in range(16):
        i, fx, fy, fz, kind = _reg_at(vis, fib, i, z)
        zh = z + h if z + h <= zb else z - h
        i, ax, ay, az, kd = _reg_at(vis, fib, i, zh)
        Dx, Dy, Dz, dd, g = _gn_terms_s(fx, fy, fz, ax, ay, az, 1.0 / (zh - z), px, py, pz)
        znew = min(max(z - g / dd, za), zb)
        if abs(znew - z) * math.sqrt(dd) < tol:
            break
        z = znew
    d, Dx, Dy, Dz = _closest_s(fx, fy, fz, px, py, pz, Dx, Dy, Dz)
    return d, z, Dx, Dy, Dz, kind


@njit(cache=True, inline="always")
def _hair_at(vis, k, hs, i, t):
    x, y, z = _hair_xyz(vis.tp, k, hs, t)
    i, f = frame_at(vis.fs, vis.fr, vis.lo, vis.hi, i, z)
    X, Y, Z = eq7(f, x, y)
    return i, X, Y, Z


@njit(cache=True)
def hair_closest_s(vis, k, hs, t0, tol):
    """(distance, t*, unit tangent (3 scalars)) of hair ``hs`` of ply k to the visit's point p under
    the sampled frames, over the part of the hair whose z lies in the visit's window [za, zb]
    (distance NO_HIT where no part does): Gauss-Newton in t with forward differences, until a step
    moves the hair point by less than tol."""
    px = vis.px
    py = vis.py
    pz = vis.pz
    ta, tb = hair_window(hs, vis.za, vis.zb)
    if ta > tb:
        return NO_HIT, 0.0, 0.0, 0.0, 0.0
    t = min(max(t0, ta), tb)
    h = max(1e-5 * (tb - ta), 1e-10)
    Dx = Dy = Dz = 0.0
    fx = fy = fz = 0.0
    i = vis.lo
    for _it in range(16):
        i, fx, fy, fz = _hair_at(vis, k, hs, i, t)
        th_ = t + h if t + h <= 1.0 else t - h
        i, ax, ay, az = _hair_at(vis, k, hs, i, th_)
        Dx, Dy, Dz, dd, g = _gn_terms_s(fx, fy, fz, ax, ay, az, 1.0 / (th_ - t), px, py, pz)
        if dd <= 0.0:
            break
        tn = min(max(t - g / dd, ta), tb)
        if abs(tn - t) * math.sqrt(dd) < tol:
            break
        t = tn
    d, Dx, Dy, Dz = _closest_s(fx, fy, fz, px, py, pz, Dx, Dy, Dz)
    return d, t, Dx, Dy, Dz


# ------------------------------------------------------------------------------------------------
# exact-frame decisions (within eps_c of a fibre surface)
@njit(cache=True, _nrt=True)  # allocates: keeps reference counting under a caller without it
def exact_regular(cv, vis, fib, zs):
    """(covered, kind) of regular fibre ``fib`` under the exact frames, near z*."""
    p = np.array([vis.px, vis.py, vis.pz])
    pe_, te_, ne_, be_ = curve_frame_at(cv, vis.c, zs)
    lf = local_frames(cv, vis.c, zs, max(4.0 * (vis.rf + vis.eps), 1e-6), pe_, ne_, be_)
    De, ze_ = regular_closest(lf, vis.tp, vis.yseed, fib, p, zs)
    if De >= vis.rf * (1.0 + MODEL_SLACK):
        return False, 0
    D, kind = regular_exact(cv, vis.c, vis.tp, vis.yseed, fib, p, ze_)
    return D < vis.rf, kind


@njit(cache=True, _nrt=True)  # allocates: keeps reference counting under a caller without it
def exact_hair(cv, vis, k, hs, ts):
    """Whether hair ``hs`` of ply k covers p under the exact frames, near t*."""
    p = np.array([vis.px, vis.py, vis.pz])
    hx, hy, hz = _hair_xyz(vis.tp, k, hs, ts)
    pe_, te_, ne_, be_ = curve_frame_at(cv, vis.c, hz)
    lf = local_frames(cv, vis.c, hz, max(4.0 * (vis.rf + vis.eps), 1e-6), pe_, ne_, be_)
    De, te = hair_closest(lf, vis.tp, k, hs, p, ts)
    if De >= vis.rf * (1.0 + MODEL_SLACK):
        return False
    return hair_exact(cv, vis.c, vis.tp, k, hs, p, te) < vis.rf
