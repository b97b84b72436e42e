"""Point lookups without realization: seed 000 Algorithms 1-3 on the tables of tables.py.

``lookup_point(cv, tab, px, py, pz)`` answers, for a fabric-space point p,
    (inside, yarn, kind, dir_x, dir_y, dir_z, density, albedo_r, albedo_g, albedo_b)
with kind 0 none, 1 regular, 2 loop, 3 hair; direction the unit fibre tangent at the closest
point of the covering fibre (zero outside); density the yarn type's density (0 outside).
``tab`` must carry its derived fields (``tables.derive_lookup_accel``; ``load_tables`` does it).

Definition (shared with the brute-force reference and the realization): p is inside fibre F when
its fabric-space distance to F's centre curve (the yarn-space fibre mapped by Eq. 7) is below the
fibre radius. Where several fibres cover p, the first in the order (yarn, ply, regular before
hair, fibre index) answers (Algorithm 1 returns at the first hit; the order makes that choice
well defined); a regular fibre's kind (1 or 2) is the kind of its cycle at the closest point.

Steps (Algorithm 1), allocation-free:
1. Candidate yarns: the runs of coarse chords in p's cell of the chord grid (frame_samples.py),
   yarn by yarn in ascending order; the nearest chord bounds p's distance to the axis from below
   (a yarn farther than its extent bound + eps_c is skipped) and seeds Newton for the foot point
   s on the sampled (Hermite) axis (seed 000 §5.2). A closed yarn's fibres run from s = 0 to its
   length L and do not join at the seam: near the seam both end pieces are visited, each as an
   open yarn's end, and the covering fibre first in the order below answers.
2. Yarn space (Eq. 8-9) with the sampled frame at s: (x, y) and the tangential residual w. The
   derived fringe occupancy (tables.fringe_occupancy: bits per yarn z-bin, radial shell and
   azimuth sector, one set for loops and one for hairs) and the core radius type_rcore decide
   which of the regular, loop and hair tests below can find anything: a point beyond the core
   in no set cell leaves the yarn at once.
3. Per ply (all plies, not only the nearest of §4.5, so that the answer is exact): the twist-
   compensated unit-disc point and its azimuth bin give candidate fibres (Algorithm 2, footnote
   2), skipped at once where p's unit-disc radius lies outside the ply's (or the loop z-bin's)
   radius range; a candidate's cross-sectional distance d bounds its true distance D
   (D >= d / K - slack, model.reach_factor; in the bin scan with the fibre's own speed bound,
   since a fibre with a loop cycle near s is also tested by the loop scan with the type's K);
   candidates that may cover p get D by Gauss-Newton along the fibre (loops included: a cycle's
   mutation is a consistent random number, §4.4.1) under the sampled frames.
4. Hairs of the ply active at s (hybrid z-bins by binary search, or Algorithm 3), a quick z and
   radius reject, a yarn-space polyline prefilter, then Gauss-Newton along the hair.
The sampled frames differ from Eq. 7's exact frames by at most eps_c (``yarn_eps``, measured when
the tables are loaded): a distance farther than eps_c from the radius is decided at once, the rest
(rare: eps_c is about 1 % of the fibre radius) with the exact frames (a local model of Eq. 7 from
exact frames at three arc lengths, then the exact map). Inside/outside, yarn and kind are those
of the exact model.
"""
import math

import numpy as np
from numba import njit, prange

from stages.core.curves.frames import curve_frame_at

from stages.core.yarn import hair_free
from stages.core.yarn.frame_samples import chord_lower_bound, eq7, foot_point, frame_at
from stages.core.yarn.tables import fringe_bits, fringe_window, hair_node_seed_nb, yarn_space_limit, z_window
from stages.core.yarn.model import (DENSITY, E_LONG, E_SHORT, FIBER_NUM, FIBER_RADIUS, PLY_NUM, PLY_RADIUS, YARN_ALPHA, ZE_MU, ZE_SIG, fiber_twist, hair_params, hair_point, hair_speed_bound, ply_frame, reach_factor, regular_xy)

TWO_PI = 2.0 * math.pi
MODEL_SLACK = 0.1  # exact-frame local model: distance error allowed before the exact check, in fibre radii
HAIR_SAMPLES = 16
FOOT_TOL = 1e-4  # foot-point Newton stops at steps below this x the fibre radius (w absorbs the rest)
GN_TOL = 1e-5  # Gauss-Newton stops when a step moves the fibre point by less than this x the fibre radius
OUTSIDE = (False, -1, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
NO_FIBRE = 1 << 62  # yarn_lookup's order key when nothing covers p
OUTSIDE_KEYED = OUTSIDE + (NO_FIBRE,)
ORDER_STRIDE = 1 << 32  # order key of a hit: (2 ply + is_hair) * ORDER_STRIDE + fibre index


@njit(cache=True)
def local_frames(cv, c, s, h, pos0, n0, b0):
    """Exact frames at three arc lengths around s (window [za, zb] of half width h, clipped to the
    curve): the local model of Eq. 7 that Gauss-Newton iterates on. Returns (za, zm, zb, M) with
    M[i] = (position, normal, binormal) at node i."""
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
    return za, zm, zb, M


@njit(cache=True)
def _model_map(za, zm, zb, M, x, y, z):
    """Eq. 7 with position and frame interpolated quadratically between the three nodes."""
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
def _reg_model(za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, z):
    x, y, kind = regular_xy(tp, yseed, k, j, Rj, th, th0, z)
    return _model_map(za, zm, zb, M, x, y, z)


@njit(cache=True)
def regular_closest(cv, c, za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, p, z0):
    """(model distance, z*) of regular fibre (k, j) to p: Gauss-Newton on the local model over
    [za, zb] from z0."""
    h = 1e-3 * (zb - za)
    z = min(max(z0, za), zb)
    for it in range(12):
        zp = min(z + h, zb)
        zn = max(z - h, za)
        Fp = _reg_model(za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, zp)
        Fm = _reg_model(za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, zn)
        F0 = _reg_model(za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, z)
        D = (Fp - Fm) / (zp - zn)
        znew = min(max(z - np.dot(F0 - p, D) / np.dot(D, D), za), zb)
        if abs(znew - z) < 1e-13 * (1.0 + zb):
            z = znew
            break
        z = znew
    F = _reg_model(za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, z)
    r = F - p
    return math.sqrt(np.dot(r, r)), z


@njit(cache=True)
def regular_exact(cv, c, tp, yseed, k, j, Rj, th, th0, p, z):
    """Exact (distance, kind) of regular fibre (k, j) at z."""
    x, y, kind = regular_xy(tp, yseed, k, j, Rj, th, th0, z)
    F = _exact_map(cv, c, x, y, z)
    r = F - p
    return math.sqrt(np.dot(r, r)), kind


@njit(cache=True)
def _hair_model(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, t):
    x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, t)
    return _model_map(za, zm, zb, M, x, y, z)


@njit(cache=True)
def hair_closest(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, p, t0):
    """(model distance, t*) of a hair to p: Gauss-Newton in t over the part of the hair whose z
    lies in the model window [za, zb]; distance 1e300 where no part does."""
    ta = 0.0
    tb = 1.0
    if ze > 0.0:
        ta = max(ta, (za - z1) / ze)
        tb = min(tb, (zb - z1) / ze)
    elif ze < 0.0:
        ta = max(ta, (zb - z1) / ze)
        tb = min(tb, (za - z1) / ze)
    elif z1 < za or z1 > zb:
        return 1e300, 0.0
    if ta > tb:
        return 1e300, 0.0
    t = min(max(t0, ta), tb)
    h = max(1e-3 * (tb - ta), 1e-9)
    for it in range(12):
        tp_ = min(t + h, tb)
        tm = max(t - h, ta)
        if tp_ <= tm:
            break
        Fp = _hair_model(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, tp_)
        Fm = _hair_model(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, tm)
        F0 = _hair_model(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, t)
        D = (Fp - Fm) / (tp_ - tm)
        dd = np.dot(D, D)
        if dd <= 0.0:
            break
        tn = min(max(t - np.dot(F0 - p, D) / dd, ta), tb)
        if abs(tn - t) < 1e-13:
            t = tn
            break
        t = tn
    F = _hair_model(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, t)
    r = F - p
    return math.sqrt(np.dot(r, r)), t


@njit(cache=True)
def hair_exact(cv, c, tp, k, r0, r1, th1, pe, z1, ze, p, t):
    x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, t)
    r = _exact_map(cv, c, x, y, z) - p
    return math.sqrt(np.dot(r, r))


@njit(cache=True)
def _hair_quick_reject(tp, r0, r1, z1, ze, rho_k, s, limit):
    """True when no point of the hair can lie within yarn-space distance ``limit`` of a point at
    distance rho_k from ply k's centre in the cross-section at s: the hair's z must come within
    limit of s, and its radius R(t) within limit (+ the ply centre's drift over limit in z) of rho_k."""
    ta = 0.0
    tb = 1.0
    if ze != 0.0:
        t1 = (s - limit - z1) / ze
        t2 = (s + limit - z1) / ze
        ta = max(ta, min(t1, t2))
        tb = min(tb, max(t1, t2))
        if ta > tb:
            return True
    elif abs(z1 - s) > limit:
        return True
    Ra = r0 + (r1 - r0) * ta
    Rb = r0 + (r1 - r0) * tb
    m = limit * (1.0 + TWO_PI * tp[PLY_RADIUS] / tp[YARN_ALPHA])
    return rho_k < min(Ra, Rb) - m or rho_k > max(Ra, Rb) + m


@njit(cache=True)
def _hair_prefilter(tp, k, r0, r1, th1, pe, z1, ze, x, y, z, limit):
    """Yarn-space distance from (x, y, z) to the hair's polyline sampled over the part of the hair
    whose z lies within ``limit`` of z (the only part that can come within limit), less the chord
    slack; returns (lower bound of that distance, best t)."""
    ta = 0.0
    tb = 1.0
    if ze != 0.0:
        t1 = (z - limit - z1) / ze
        t2 = (z + limit - z1) / ze
        ta = max(ta, min(t1, t2))
        tb = min(tb, max(t1, t2))
        if ta > tb:
            return 1e300, 0.0
    n = min(HAIR_SAMPLES, max(1, int(math.ceil((tb - ta) * HAIR_SAMPLES))))
    best = 1e300
    bt = ta
    for i in range(n + 1):
        t = ta + (tb - ta) * i / n
        qx, qy, qz = hair_point(tp, k, r0, r1, th1, pe, z1, ze, t)
        dx = x - qx
        dy = y - qy
        dz = z - qz
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < best:
            best = d2
            bt = t
    # speed bound of the hair in yarn space -> arc length per sample interval
    return math.sqrt(best) - 0.5 * hair_speed_bound(tp, r0, r1, pe, ze) * (tb - ta) / n, bt


# ------------------------------------------------------------------------------------------------
# distances under the sampled frames (scalar, allocation-free)
@njit(cache=True, inline="always")
def _reg_at(fs, fr, lo, hi, i, tp, yseed, k, j, Rj, th, th0, z):
    """(step, F(z), kind) of regular fibre (k, j) under the sampled frames (fs, fr)."""
    x, y, kind = regular_xy(tp, yseed, k, j, Rj, th, th0, z)
    i, f = frame_at(fs, fr, lo, hi, i, z)
    X, Y, Z = eq7(f, x, y)
    return i, X, Y, Z, kind


@njit(cache=True)
def regular_closest_s(fs, fr, lo, hi, i, za, zb, tp, yseed, k, j, Rj, th, th0, px, py, pz, z0, tol):
    """(distance, z*, unit tangent (3 scalars), kind) of regular fibre (k, j) to p under the
    sampled frames: Gauss-Newton over [za, zb] from z0 (forward differences), until a step moves
    the fibre point by less than tol (the distance then errs by O(tol^2 / distance))."""
    h = 1e-5 * (zb - za)
    z = min(max(z0, za), zb)
    Dx = Dy = Dz = 0.0
    fx = fy = fz = 0.0
    kind = 1
    for it in range(16):
        i, fx, fy, fz, kind = _reg_at(fs, fr, lo, hi, i, tp, yseed, k, j, Rj, th, th0, z)
        zh = z + h if z + h <= zb else z - h
        i, ax, ay, az, kd = _reg_at(fs, fr, lo, hi, i, tp, yseed, k, j, Rj, th, th0, zh)
        inv = 1.0 / (zh - z)
        Dx = (ax - fx) * inv
        Dy = (ay - fy) * inv
        Dz = (az - fz) * inv
        dd = Dx * Dx + Dy * Dy + Dz * Dz
        znew = min(max(z - ((fx - px) * Dx + (fy - py) * Dy + (fz - pz) * Dz) / dd, za), zb)
        if abs(znew - z) * math.sqrt(dd) < tol:
            break
        z = znew
    rx, ry, rz = fx - px, fy - py, fz - pz
    n = math.sqrt(Dx * Dx + Dy * Dy + Dz * Dz)
    return math.sqrt(rx * rx + ry * ry + rz * rz), z, Dx / n, Dy / n, Dz / n, kind


@njit(cache=True, inline="always")
def _hair_at(fs, fr, lo, hi, i, tp, k, r0, r1, th1, pe, z1, ze, t):
    x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, t)
    i, f = frame_at(fs, fr, lo, hi, i, z)
    X, Y, Z = eq7(f, x, y)
    return i, X, Y, Z


@njit(cache=True)
def hair_closest_s(fs, fr, lo, hi, za, zb, tp, k, r0, r1, th1, pe, z1, ze, px, py, pz, t0, tol):
    """(distance, t*, unit tangent (3 scalars)) of a hair to p under the sampled frames, over the
    part of the hair whose z lies in [za, zb] (distance 1e300 where no part does): Gauss-Newton in
    t with forward differences, until a step moves the hair point by less than tol."""
    ta = 0.0
    tb = 1.0
    if ze > 0.0:
        ta = max(ta, (za - z1) / ze)
        tb = min(tb, (zb - z1) / ze)
    elif ze < 0.0:
        ta = max(ta, (zb - z1) / ze)
        tb = min(tb, (za - z1) / ze)
    elif z1 < za or z1 > zb:
        return 1e300, 0.0, 0.0, 0.0, 0.0
    if ta > tb:
        return 1e300, 0.0, 0.0, 0.0, 0.0
    t = min(max(t0, ta), tb)
    h = max(1e-5 * (tb - ta), 1e-10)
    Dx = Dy = Dz = 0.0
    fx = fy = fz = 0.0
    i = lo
    for it in range(16):
        i, fx, fy, fz = _hair_at(fs, fr, lo, hi, i, tp, k, r0, r1, th1, pe, z1, ze, t)
        th_ = t + h if t + h <= 1.0 else t - h
        i, ax, ay, az = _hair_at(fs, fr, lo, hi, i, tp, k, r0, r1, th1, pe, z1, ze, th_)
        inv = 1.0 / (th_ - t)
        Dx = (ax - fx) * inv
        Dy = (ay - fy) * inv
        Dz = (az - fz) * inv
        dd = Dx * Dx + Dy * Dy + Dz * Dz
        if dd <= 0.0:
            break
        tn = min(max(t - ((fx - px) * Dx + (fy - py) * Dy + (fz - pz) * Dz) / dd, ta), tb)
        if abs(tn - t) * math.sqrt(dd) < tol:
            break
        t = tn
    rx, ry, rz = fx - px, fy - py, fz - pz
    n = math.sqrt(Dx * Dx + Dy * Dy + Dz * Dz)
    if n > 0.0:
        Dx /= n
        Dy /= n
        Dz /= n
    return math.sqrt(rx * rx + ry * ry + rz * rz), t, Dx, Dy, Dz


# ------------------------------------------------------------------------------------------------
# exact-frame decisions (within eps_c of a fibre surface)
@njit(cache=True)
def _exact_regular(cv, c, tp, yseed, k, j, Rj, th, th0, rf, eps, px, py, pz, zs):
    """(covered, kind) of regular fibre (k, j) under the exact frames, near z*."""
    p = np.array([px, py, pz])
    pe_, te_, ne_, be_ = curve_frame_at(cv, c, zs)
    Za, Zm, Zb, M = local_frames(cv, c, zs, max(4.0 * (rf + eps), 1e-6), pe_, ne_, be_)
    De, ze_ = regular_closest(cv, c, Za, Zm, Zb, M, tp, yseed, k, j, Rj, th, th0, p, zs)
    if De >= rf * (1.0 + MODEL_SLACK):
        return False, 0
    D, kind = regular_exact(cv, c, tp, yseed, k, j, Rj, th, th0, p, ze_)
    return D < rf, kind


@njit(cache=True)
def _exact_hair(cv, c, tp, k, r0, r1, th1, pe, z1, ze, rf, eps, px, py, pz, ts):
    p = np.array([px, py, pz])
    hx, hy, hz = hair_point(tp, k, r0, r1, th1, pe, z1, ze, ts)
    pe_, te_, ne_, be_ = curve_frame_at(cv, c, hz)
    Za, Zm, Zb, M = local_frames(cv, c, hz, max(4.0 * (rf + eps), 1e-6), pe_, ne_, be_)
    De, te = hair_closest(Za, Zm, Zb, M, tp, k, r0, r1, th1, pe, z1, ze, p, ts)
    if De >= rf * (1.0 + MODEL_SLACK):
        return False
    return hair_exact(cv, c, tp, k, r0, r1, th1, pe, z1, ze, p, te) < rf


# ------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _answer(c, kind, tx, ty, tz, tp, tab, key):
    return (True, c, kind, tx, ty, tz, tp[DENSITY], tab.yarn_albedo[c, 0], tab.yarn_albedo[c, 1],
            tab.yarn_albedo[c, 2], key)


@njit(cache=True, inline="always")
def _order_key(k, is_hair, j):
    """Where a hit stands in the covering order (ply, regular before hair, fibre index) of one yarn."""
    return (2 * k + (1 if is_hair else 0)) * ORDER_STRIDE + j


@njit(cache=True)
def yarn_lookup(cv, tab, c, s, i, px, py, pz):
    """Steps 2-4 of Algorithm 1 in yarn c, p's foot point at arc length s (frame-sample step i):
    lookup_point's result followed by the order key of the covering fibre (_order_key; NO_FIBRE
    outside)."""
    t = tab.yarn_type[c]
    tp = tab.tparams[t]
    lo = tab.fs_off[c]
    hi = tab.fs_off[c + 1]
    i, f = frame_at(tab.fs_s, tab.fs_frame, lo, hi, i, s)
    eps = tab.yarn_eps[c]
    rx, ry, rz = px - f[0], py - f[1], pz - f[2]
    x = rx * f[6] + ry * f[7] + rz * f[8]
    y = rx * f[9] + ry * f[10] + rz * f[11]
    w = abs(rx * f[3] + ry * f[4] + rz * f[5])
    rf = tp[FIBER_RADIUS]
    if w >= rf + 2.0 * eps:
        return OUTSIDE_KEYED  # beyond an end of the yarn by more than any fibre's cap reaches
    K = tab.type_K[t]
    yseed = np.uint64(tab.yarn_seed[c])
    P = int(tp[PLY_NUM])
    N = int(tp[FIBER_NUM])
    B = tab.type_nbins[t]
    es = tp[E_SHORT]
    el = tp[E_LONG]
    twist = fiber_twist(tp, s)
    gmin = tab.yarn_gmin[c]
    # window holding every fibre point within rf of p (|z - s| <= yarn-space distance / g_min)
    L = tab.yarn_length[c]
    hwin = z_window(K, tab.type_mz[t], rf, w, eps, gmin)
    za = max(0.0, s - hwin)
    zb = min(L, s + hwin)
    reach = K * (rf + w + eps)
    binned = w + eps <= tab.type_pad[t]  # else (beyond a yarn end) every fibre of the ply
    munit = K * (rf + tab.type_pad[t]) / min(es, el)  # the bins' margin in unit-disc units
    # the fringe occupancy and the core radius gate whole parts of the visit (tables.fringe_occupancy)
    # (the bits hold for any w a visit goes on with; the core radius only for binned visits, an
    # unbinned one widens each ply's radius range by the margin its larger w needs)
    hybrid = tab.hair_mode[0] == 0
    rho = math.sqrt(x * x + y * y)
    loops, hairs = fringe_bits(tab, c, s, x, y, rho)
    hairs = hairs or not hybrid  # the realization-free mode stores no hairs to mark
    core = rho <= tab.type_rcore[t]
    wide = 0.0 if binned else K * (w + eps - tab.type_pad[t]) / min(es, el)
    if binned and not (core or loops or hairs):
        return OUTSIDE_KEYED
    # ply centres: ply 0's frame, then turns by 2 pi / P (ply_frame without a sine per ply)
    _, _, drx, dry = ply_frame(tp, 0, s)
    rot_c = math.cos(TWO_PI / P)
    rot_s = math.sin(TWO_PI / P)
    for k in range(P):
        # ---- regular and loop fibres of ply k (Algorithm 2)
        if k > 0:
            drx, dry = drx * rot_c - dry * rot_s, dry * rot_c + drx * rot_s
        cx = tp[PLY_RADIUS] * drx
        cy = tp[PLY_RADIUS] * dry
        ax = x - cx
        ay = y - cy
        u = (ax * drx + ay * dry) / es
        v = (-ax * dry + ay * drx) / el
        rr = math.sqrt(u * u + v * v)
        g = tab.yarn_ply_off[c] + k
        # the ply's fibres, and the loops of s's z-bin, cover unit-disc radii in ply_rr / lz_rr only
        if binned:
            scan_reg = core and tab.ply_rr[t, k, 0] <= rr <= tab.ply_rr[t, k, 1]
        else:  # every fibre of the ply, loops included, where a regular stretch or a loop may reach
            scan_reg = rr <= tab.ply_rr[t, k, 1] + wide or loops
        zbin = -1
        if binned and loops and tab.lp_off[g + 1] > tab.lp_off[g]:
            nzb = tab.lz_off[g + 1] - tab.lz_off[g]
            zbin = tab.lz_off[g] + min(max(int(s / tab.lz_h[g]), 0), nzb - 1)
            if not (tab.lz_rr[zbin, 0] <= rr <= tab.lz_rr[zbin, 1] + munit):
                zbin = -1
        jbest = N  # first covering regular or loop fibre of the ply (lowest index)
        kbest = 0
        tbx = tby = tbz = 0.0
        if scan_reg or zbin >= 0:
            ang = math.atan2(v, u) - twist
            ang = ang - TWO_PI * math.floor(ang / TWO_PI)
            b = min(int(ang / TWO_PI * B), B - 1)
            gb = tab.type_bin_off[t] + k * B + b
            fo = tab.type_fib_off[t] + k * N
            q0 = tab.bin_start[gb] if binned else 0
            q1 = tab.bin_start[gb + 1] if binned else N
            if not scan_reg:
                q1 = q0
            for q in range(q0, q1):
                j = tab.bin_items[q] if binned else q
                fi = fo + j
                reach_j = reach
                if binned:
                    if rr < tab.fib_rlo[fi] or rr > tab.fib_rhi[fi]:
                        continue
                    # the fibre's own reach factor: a fibre whose cycles near s include a loop is
                    # also in the loop scan below, with the yarn type's factor K
                    reach_j = reach_factor(tab.fib_v[fi], gmin) * (rf + w + eps)
                hit, kind, tx, ty, tz = _regular_test(cv, tab, c, tp, yseed, k, j, fi, x, y, s, reach_j, i, lo, hi,
                                                      za, zb, rf, eps, px, py, pz)
                if hit:
                    jbest, kbest, tbx, tby, tbz = j, kind, tx, ty, tz
                    break
            if zbin >= 0:
                # loops: mutated cycles active in s's z-bin whose fibre is in the azimuth bin
                bit = np.uint64(1) << np.uint64(b % 64)
                lbase = tab.lp_off[g]
                for qq in range(tab.lz_start[zbin], tab.lz_start[zbin + 1]):
                    le = lbase + tab.lz_items[qq]
                    j = tab.lp_fib[le]
                    if j >= jbest:
                        break
                    fi = fo + j
                    if (tab.fib_mask[fi] & bit) == 0 or rr < tab.fib_rlo[fi] or rr > tab.lp_U[le] + munit:
                        continue
                    hit, kind, tx, ty, tz = _regular_test(cv, tab, c, tp, yseed, k, j, fi, x, y, s, reach, i, lo, hi,
                                                          za, zb, rf, eps, px, py, pz)
                    if hit:
                        jbest, kbest, tbx, tby, tbz = j, kind, tx, ty, tz
                        break
        if jbest < N:
            return _answer(c, kbest, tbx, tby, tbz, tp, tab, _order_key(k, False, jbest))
        # ---- hair fibres of ply k (hybrid z-bins or Algorithm 3)
        nh = tab.hair_count[g]
        if nh == 0 or not hairs:
            continue
        limit = yarn_space_limit(rf, w, eps, gmin)
        rho_k = math.sqrt(ax * ax + ay * ay)
        if hybrid:
            # hybrid: the z-bin holding s by binary search, its active list in place
            hlo = tab.hb_zoff[g]
            hhi = tab.hb_zoff[g + 1]
            if hhi - hlo < 2 or s < tab.hb_z[hlo] or s >= tab.hb_z[hhi - 1]:
                continue
            a_ = hlo
            b_ = hhi - 2
            while a_ < b_:  # last breakpoint <= s
                m = (a_ + b_ + 1) // 2
                if tab.hb_z[m] <= s:
                    a_ = m
                else:
                    b_ = m - 1
            zbin = a_ - g
            base = tab.hair_off[g]
            mr = limit * (1.0 + TWO_PI * tp[PLY_RADIUS] / tp[YARN_ALPHA])
            for qq in range(tab.hb_start[zbin], tab.hb_start[zbin + 1]):
                hh = base + tab.hb_items[qq]
                # the hair's z and radius ranges (one row): a looser _hair_quick_reject
                if (s < tab.hair_box[hh, 0] - limit or s > tab.hair_box[hh, 1] + limit
                        or rho_k < tab.hair_box[hh, 2] - mr or rho_k > tab.hair_box[hh, 3] + mr):
                    continue
                res = _hair_test(cv, tab.fs_s, tab.fs_frame, c, tp, k, tab.hair_r0[hh], tab.hair_r1[hh], tab.hair_th1[hh],
                                 tab.hair_pe[hh], tab.hair_z1[hh], tab.hair_ze[hh], x, y, s, rho_k, limit, lo, hi, za,
                                 zb, rf, eps, px, py, pz)
                if res[0]:
                    return _answer(c, 3, res[1], res[2], res[3], tp, tab, _order_key(k, True, tab.hb_items[qq]))
        else:
            seed = hair_node_seed_nb(np.uint64(tab.yarn_seed[c]), k)
            margin = tab.type_mz[t] + (w + 2.0 * eps) / gmin
            res = _free_mode_hairs(cv, tab.fs_s, tab.fs_frame, c, tp, k, nh, yseed, seed, L, margin, x, y, s, rho_k,
                                   limit, lo, hi, za, zb, rf, eps, px, py, pz)
            if res[0]:
                return _answer(c, 3, res[1], res[2], res[3], tp, tab, _order_key(k, True, res[4]))
    return OUTSIDE_KEYED


@njit(cache=True, inline="always")
def _regular_test(cv, tab, c, tp, yseed, k, j, fi, x, y, s, reach, i, lo, hi, za, zb, rf, eps, px, py, pz):
    """(covered, kind, tangent) of regular fibre (k, j) (fi its global index): cross-section reach
    test at s, Gauss-Newton under the sampled frames, exact frames within eps_c of the surface."""
    Rj = tab.fib_R[fi]
    th = tab.fib_th[fi]
    th0 = tab.fib_th0[fi]
    X, Y, kind = regular_xy(tp, yseed, k, j, Rj, th, th0, s)
    dx = x - X
    dy = y - Y
    if dx * dx + dy * dy >= reach * reach:
        return False, 0, 0.0, 0.0, 0.0
    Dm, zs, tx, ty, tz, kind = regular_closest_s(tab.fs_s, tab.fs_frame, lo, hi, i, za, zb, tp, yseed, k, j, Rj, th, th0, px, py, pz, s,
                                                 GN_TOL * rf)
    if Dm >= rf + eps:
        return False, 0, 0.0, 0.0, 0.0
    if Dm > rf - eps:  # too close to the surface to decide with the sampled frames
        inside, kind = _exact_regular(cv, c, tp, yseed, k, j, Rj, th, th0, rf, eps, px, py, pz, zs)
        if not inside:
            return False, 0, 0.0, 0.0, 0.0
    return True, kind, tx, ty, tz


@njit(cache=True, inline="always")
def _hair_test(cv, fs, fr, c, tp, k, r0, r1, th1, pe, z1, ze, x, y, s, rho_k, limit, lo, hi, za, zb, rf, eps, px, py,
               pz):
    """(covered, tangent) of a hair of ply k with shape (r0, r1, th1, pe) and z extent (z1, ze)."""
    if _hair_quick_reject(tp, r0, r1, z1, ze, rho_k, s, limit):
        return False, 0.0, 0.0, 0.0
    lb, bt = _hair_prefilter(tp, k, r0, r1, th1, pe, z1, ze, x, y, s, limit)
    if lb > limit:
        return False, 0.0, 0.0, 0.0
    Dm, ts, tx, ty, tz = hair_closest_s(fs, fr, lo, hi, za, zb, tp, k, r0, r1, th1, pe, z1, ze, px, py, pz, bt,
                                     GN_TOL * rf)
    if Dm >= rf + eps:
        return False, 0.0, 0.0, 0.0
    if Dm > rf - eps and not _exact_hair(cv, c, tp, k, r0, r1, th1, pe, z1, ze, rf, eps, px, py, pz, ts):
        return False, 0.0, 0.0, 0.0
    return True, tx, ty, tz


@njit(cache=True)
def _free_mode_hairs(cv, fs, fr, c, tp, k, nh, yseed, seed, L, margin, x, y, s, rho_k, limit, lo, hi, za, zb, rf, eps,
                     px, py, pz):
    """Realization-free hair mode (Algorithm 3): the active hairs of ply k at s from the implicit
    quad-tree (scratch arrays of the ply's hair count), then the same tests as the hybrid mode:
    (covered, tangent, hair index).
    A function of its own so that yarn_lookup allocates nothing."""
    hidx = np.empty(nh, np.int64)
    hz1 = np.empty(nh)
    hze = np.empty(nh)
    na = hair_free.active_hairs(L, nh, tp[ZE_MU], tp[ZE_SIG], seed, s, margin, hidx, hz1, hze)
    for qq in range(na):
        r0, r1, th1, pe = hair_params(tp, yseed, k, hidx[qq])
        res = _hair_test(cv, fs, fr, c, tp, k, r0, r1, th1, pe, hz1[qq], hze[qq], x, y, s, rho_k, limit, lo, hi, za, zb,
                         rf, eps, px, py, pz)
        if res[0]:
            return True, res[1], res[2], res[3], hidx[qq]
    return False, 0.0, 0.0, 0.0, 0


@njit(cache=True)
def lookup_point(cv, tab, px, py, pz):
    """seed 000 Algorithm 1 at fabric-space point p; see the module doc for the result."""
    lo3 = tab.fg_lo
    cell = tab.fg_cell[0]
    dims = tab.fg_dims
    fx = (px - lo3[0]) / cell
    fy = (py - lo3[1]) / cell
    fz = (pz - lo3[2]) / cell
    if not (0.0 <= fx < dims[0] and 0.0 <= fy < dims[1] and 0.0 <= fz < dims[2]):
        return OUTSIDE  # the grid covers every yarn's extent
    g = (int(fz) * dims[1] + int(fy)) * dims[0] + int(fx)
    q = tab.fg_start[g]
    qe = tab.fg_start[g + 1]
    fr = tab.fs_frame
    while q < qe:
        c = tab.fg_yarn[q]
        best = 1e300
        bq = -1
        bt = 0.0
        while q < qe and tab.fg_yarn[q] == c:  # every run of yarn c in the cell
            for ch in range(tab.fg_a[q], tab.fg_b[q]):
                lb, t = chord_lower_bound(fr, tab.kn_idx, tab.kn_sag, ch, px, py, pz)
                if lb < best:
                    best = lb
                    bq = ch
                    bt = t
            q += 1
        eps = tab.yarn_eps[c]
        bound = tab.yarn_extent[c] + 2.0 * eps
        if best >= bound:
            continue
        # beyond the chord's gate (tables.chord_gates) nothing of the yarn near that chord can cover p;
        # p's axis distance is at least sqrt(best^2 - w^2) with w < r_f + 2 eps_c for a visit that goes on
        gate = tab.kn_rgate[bq]
        rf = tab.tparams[tab.yarn_type[c], FIBER_RADIUS]
        m = rf + 2.0 * eps
        gated = best > 0.0 and best * best >= gate * gate + m * m
        if cv.closed[c] and _near_seam(tab, c, bound, rf, eps, px, py, pz):
            res = _seam_visits(cv, tab, c, gated, bq, bt, bound, rf, px, py, pz)
            if res[0]:
                return res[:10]
            continue
        if gated:
            continue
        # foot point: Newton from the nearest chord, bracketed by its neighbours
        k0 = tab.kn_off[c]
        k1 = tab.kn_off[c + 1] - 1
        ia = tab.kn_idx[bq]
        s0 = tab.fs_s[ia] + bt * (tab.fs_s[tab.kn_idx[bq + 1]] - tab.fs_s[ia])
        fa = tab.kn_idx[max(bq - 1, k0)]
        fb = tab.kn_idx[min(bq + 2, k1)]
        s, i, d2 = foot_point(tab.fs_s, fr, fa, fb + 1, ia, s0, tab.fs_s[fa], tab.fs_s[fb], px, py, pz, FOOT_TOL * rf)
        if d2 >= bound * bound:
            continue
        res = yarn_lookup(cv, tab, c, s, i, px, py, pz)
        if res[0]:
            return res[:10]
    return OUTSIDE


@njit(cache=True, inline="always")
def _visit(cv, tab, c, ka, kb, ia, s0, bound, rf, px, py, pz):
    """yarn_lookup at p's foot point on yarn c between coarse knots ka and kb (frame-sample hint ia,
    Newton from s0); OUTSIDE_KEYED when the foot point is farther than bound. (lookup_point's main
    visit spells this out: returning the constant from an inlined call costs it ~20 %.)"""
    fa = tab.kn_idx[ka]
    fb = tab.kn_idx[kb]
    s, i, d2 = foot_point(tab.fs_s, tab.fs_frame, fa, fb + 1, ia, s0, tab.fs_s[fa], tab.fs_s[fb], px, py, pz,
                          FOOT_TOL * rf)
    if d2 >= bound * bound:
        return OUTSIDE_KEYED
    return yarn_lookup(cv, tab, c, s, i, px, py, pz)


@njit(cache=True)
def _seam_visits(cv, tab, c, gated, bq, bt, bound, rf, px, py, pz):
    """Closed yarn c near its seam (a closed yarn's fibres run from s = 0 to L and meet at the seam
    without joining): the main visit at the nearest chord bq unless gated, and each end piece it
    does not cover, visited as an open yarn's end; the first answer in the covering order."""
    k0 = tab.kn_off[c]
    k1 = tab.kn_off[c + 1] - 1
    ka = max(bq - 1, k0)
    kb = min(bq + 2, k1)
    res = OUTSIDE_KEYED
    if not gated:
        ia = tab.kn_idx[bq]
        s0 = tab.fs_s[ia] + bt * (tab.fs_s[tab.kn_idx[bq + 1]] - tab.fs_s[ia])
        res = _visit(cv, tab, c, ka, kb, ia, s0, bound, rf, px, py, pz)
    if ka > k0:  # the start of the yarn
        r2 = _visit(cv, tab, c, k0, min(k0 + 2, k1), tab.kn_idx[k0], 0.0, bound, rf, px, py, pz)
        if r2[10] < res[10]:
            res = r2
    if kb < k1:  # its end
        r2 = _visit(cv, tab, c, max(k1 - 2, k0), k1, tab.kn_idx[k1 - 1], tab.yarn_length[c], bound, rf, px, py, pz)
        if r2[10] < res[10]:
            res = r2
    return res


@njit(cache=True, inline="always")
def _near_seam(tab, c, bound, rf, eps, px, py, pz):
    """Whether fibres of closed yarn c within its largest z window of the seam may reach p (p within
    bound + that window of the seam point: a fibre point at arc length z lies within the extent of
    the axis at z, and the axis within |z - seam| of the seam point)."""
    t = tab.yarn_type[c]
    zw = fringe_window(tab.type_K[t], tab.type_mz[t], rf, eps, tab.yarn_gmin[c])
    a = tab.kn_idx[tab.kn_off[c]]
    dx = px - tab.fs_frame[a, 0]
    dy = py - tab.fs_frame[a, 1]
    dz = pz - tab.fs_frame[a, 2]
    r = bound + zw
    return dx * dx + dy * dy + dz * dz < r * r


@njit(cache=True, parallel=True)
def lookup_points(cv, tab, pts):
    """Vectorised lookup_point over (N, 3) points: inside, yarn, kind, direction (N, 3), density, albedo (N, 3)."""
    N = pts.shape[0]
    inside = np.zeros(N, np.bool_)
    yarn = np.full(N, -1, np.int32)
    kind = np.zeros(N, np.int8)
    direction = np.zeros((N, 3))
    density = np.zeros(N)
    albedo = np.zeros((N, 3))
    for i in prange(N):
        res = lookup_point(cv, tab, pts[i, 0], pts[i, 1], pts[i, 2])
        inside[i] = res[0]
        yarn[i] = res[1]
        kind[i] = res[2]
        direction[i, 0] = res[3]
        direction[i, 1] = res[4]
        direction[i, 2] = res[5]
        density[i] = res[6]
        albedo[i, 0] = res[7]
        albedo[i, 1] = res[8]
        albedo[i, 2] = res[9]
    return inside, yarn, kind, direction, density, albedo
