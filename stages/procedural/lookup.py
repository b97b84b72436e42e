"""Point lookups without realization: seed 000 Algorithms 1-3 on the tables of tables.py.

``lookup_point(cv, tab, p)`` answers, for a fabric-space point p,
    (inside, yarn, kind, dir_x, dir_y, dir_z, density, albedo_r, albedo_g, albedo_b)
with kind 0 none, 1 regular, 2 loop, 3 hair; direction the unit fibre tangent at the closest
point of the covering fibre (zero outside); density the yarn type's density (0 outside).

Definition (shared with the brute-force reference and the realization): p is inside fibre F when
its fabric-space distance to F's centre curve (the yarn-space fibre mapped by Eq. 7) is below the
fibre radius. Where several fibres cover p, the first in the order (yarn, ply, regular before
hair, fibre index) answers (Algorithm 1 returns at the first hit; the order makes that choice
well defined); a regular fibre's kind (1 or 2) is the kind of its cycle at the closest point.

Steps (Algorithm 1):
1. Candidate yarns: the spline segments of p's cell in the tables' curve grid (padded by each
   yarn's extent bound), nearest box first; p's foot point on the yarn (seed 000 §5.2): exact
   (root isolation, stages/core/curves.py), or, when the tables carry sampled frames
   (``loomlight tables --frame-samples``), on the chords of the samples by local descent.
2. Yarn space (Eq. 8-9) with the frame at the foot point s: (x, y) and the tangential residual w.
3. Per ply (all plies, not only the nearest of §4.5, so that the answer is exact): the twist-
   compensated unit-disc point and its azimuth bin give candidate fibres (Algorithm 2, footnote
   2); a candidate's cross-sectional distance d bounds its true distance D (D >= d / K - slack);
   candidates that may cover p get D by Gauss-Newton along the fibre (loops included: a cycle's
   mutation is a consistent random number, §4.4.1) under the sampled frames.
4. Hairs of the ply active at s' (hybrid z-bins by binary search, or Algorithm 3), a quick z and
   radius reject, a yarn-space polyline prefilter, then Gauss-Newton along the hair.
Without sampled frames the distances come from a local model of Eq. 7 (exact frames at three arc
lengths around s, quadratic interpolation), and every fibre the model puts within 10 % of the
radius is re-measured with the exact frames. With sampled frames (which differ from Eq. 7 by at
most eps_c, ``yarn_eps``, measured when the tables are built) a distance farther than eps_c from
the radius is decided at once and the rest with the exact frames. Either way inside/outside, yarn
and kind are those of the exact model.
"""
import math

import numpy as np
from numba import njit, prange

from stages.core.curves import (_segment_box_dist2, closest_on_segment, curve_frame_at, nearest_segments_in_cell,
                                segment_arclen_to)

from . import hair_free
from .frame_samples import project_local, sampled_frame
from .tables import hair_node_seed_nb
from .yarn_model import (DENSITY, E_LONG, E_SHORT, FIBER_NUM, FIBER_RADIUS, PLY_NUM, PLY_RADIUS, YARN_ALPHA,
                         ZE_MU, ZE_SIG, fiber_twist, hair_params, hair_point, ply_frame, regular_xy)

TWO_PI = 2.0 * math.pi
MODEL_SLACK = 0.1  # exact-frame local model: distance error allowed before the exact check, in fibre radii
MAX_YARNS = 64
HAIR_SAMPLES = 16


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
def _hair_prefilter(tp, k, r0, r1, th1, pe, z1, ze, x, y, z):
    """Yarn-space distance from (x, y, z) to the hair's sampled polyline, less the chord slack;
    returns (lower bound of the yarn-space distance, best t)."""
    best = 1e300
    bt = 0.0
    px, py, pz = hair_point(tp, k, r0, r1, th1, pe, z1, ze, 0.0)
    for i in range(HAIR_SAMPLES + 1):
        t = i / HAIR_SAMPLES
        qx, qy, qz = hair_point(tp, k, r0, r1, th1, pe, z1, ze, t)
        dx = x - qx
        dy = y - qy
        dz = z - qz
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < best:
            best = d2
            bt = t
    # speed bound of the hair in yarn space -> arc length per sample interval
    rm = max(r0, r1) + tp[PLY_RADIUS]
    speed = abs(ze) * (1.0 + rm * TWO_PI / tp[YARN_ALPHA]) + abs(r1 - r0) + max(r0, r1) * abs(pe)
    return math.sqrt(best) - 0.5 * speed / HAIR_SAMPLES, bt


@njit(cache=True)
def _hair_active(tab, c, g, tp, z, margin, out_idx, out_z1, out_ze):
    """Active hairs of slot g at z into the out arrays (ascending hair index); returns how many."""
    if tab.hair_mode[0] == 0:
        lo = tab.hb_zoff[g]
        hi = tab.hb_zoff[g + 1]
        nbp = hi - lo
        if nbp < 2 or z < tab.hb_z[lo] or z >= tab.hb_z[hi - 1]:
            return 0
        a = lo
        b = hi - 2
        while a < b:  # last breakpoint <= z
            m = (a + b + 1) // 2
            if tab.hb_z[m] <= z:
                a = m
            else:
                b = m - 1
        gb = lo - g + (a - lo)
        n = 0
        base = tab.hair_off[g]
        for q in range(tab.hb_start[gb], tab.hb_start[gb + 1]):
            h = tab.hb_items[q]
            out_idx[n] = h
            out_z1[n] = tab.hair_z1[base + h]
            out_ze[n] = tab.hair_ze[base + h]
            n += 1
        return n
    nh = tab.hair_count[g]
    k = g - tab.yarn_ply_off[c]
    seed = hair_node_seed_nb(np.uint64(tab.yarn_seed[c]), k)
    return hair_free.active_hairs(tab.yarn_length[c], nh, tp[ZE_MU], tp[ZE_SIG], seed, z, margin,
                                  out_idx, out_z1, out_ze)


@njit(cache=True)
def _project(cv, tab, i, p, fast):
    """(arc length, squared distance) of p's foot point on spline segment i: on the chords of the
    frame samples (fast) or exactly (root isolation of stages/core/curves.py)."""
    if fast:
        return project_local(tab.fs_s, tab.fs_frame, tab.seg_fs[i], tab.seg_fs_end[i], p)
    t, d2 = closest_on_segment(cv, i, p)
    return cv.seg_arclen[i] + segment_arclen_to(cv, i, t), d2


@njit(cache=True)
def candidate_yarns(cv, tab, p, out_c, out_s, out_d2, fast):
    """Yarns whose axis passes within their extent bound (+ sampling error) of p, with p's foot
    point (arc length s, squared distance; see _project), in one pass over the spline segments of
    p's grid cell (the tables' copy of the curves pads the grid by each yarn's extent, so the cell
    holds every such segment). Returns how many, by yarn index."""
    start, end = nearest_segments_in_cell(cv, p)
    n = 0
    found = np.empty(out_c.shape[0], np.bool_)
    first = np.empty(out_c.shape[0], np.int64)
    firstd = np.empty(out_c.shape[0])
    slot = np.empty(end - start, np.int64)
    bd = np.empty(end - start)
    # pass 1: box distances; per yarn the segment with the nearest box (projected first, so that
    # the boxes of the others are pruned against a good distance)
    for q in range(start, end):
        i = cv.grid_items[q]
        c = cv.seg_curve[i]
        m = 0
        while m < n and out_c[m] != c:
            m += 1
        if m == n:
            if n == out_c.shape[0]:
                slot[q - start] = -1
                continue
            e = tab.yarn_extent[c] + (2.0 * tab.yarn_eps[c] if fast else 0.0)
            out_c[m] = c
            out_d2[m] = e * e
            found[m] = False
            first[m] = -1
            firstd[m] = 1e300
            n += 1
        slot[q - start] = m
        d = _segment_box_dist2(cv, i, p)
        bd[q - start] = d
        if d < out_d2[m] and d < firstd[m]:
            firstd[m] = d
            first[m] = q
    for m in range(n):
        q = first[m]
        if q >= 0:
            sp, d2 = _project(cv, tab, cv.grid_items[q], p, fast)
            if d2 < out_d2[m]:
                out_d2[m] = d2
                out_s[m] = sp
                found[m] = True
    for q in range(start, end):
        m = slot[q - start]
        if m < 0 or q == first[m] or bd[q - start] >= out_d2[m]:
            continue
        sp, d2 = _project(cv, tab, cv.grid_items[q], p, fast)
        if d2 < out_d2[m]:
            out_d2[m] = d2
            out_s[m] = sp
            found[m] = True
    k = 0
    for m in range(n):
        if found[m]:
            out_c[k] = out_c[m]
            out_d2[k] = out_d2[m]
            out_s[k] = out_s[m]
            k += 1
    for i in range(1, k):  # ascending yarn index
        c = out_c[i]
        sv = out_s[i]
        dv = out_d2[i]
        j = i - 1
        while j >= 0 and out_c[j] > c:
            out_c[j + 1] = out_c[j]
            out_s[j + 1] = out_s[j]
            out_d2[j + 1] = out_d2[j]
            j -= 1
        out_c[j + 1] = c
        out_s[j + 1] = sv
        out_d2[j + 1] = dv
    return k


@njit(cache=True)
def _smap(tab, lo, hi, x, y, z):
    """Eq. 7 with the sampled frames."""
    pos, t, n, b = sampled_frame(tab.fs_s, tab.fs_frame, lo, hi, z)
    return pos + x * n + y * b


@njit(cache=True)
def regular_closest_s(tab, lo, hi, za, zb, tp, yseed, k, j, Rj, th, th0, p, z0):
    """(distance, z*, tangent, kind) of regular fibre (k, j) to p under the sampled frames:
    Gauss-Newton over [za, zb] from z0."""
    h = 1e-4 * (zb - za)
    z = min(max(z0, za), zb)
    D = np.zeros(3)
    for it in range(12):
        zp = min(z + h, zb)
        zn = max(z - h, za)
        x, y, kd = regular_xy(tp, yseed, k, j, Rj, th, th0, zp)
        Fp = _smap(tab, lo, hi, x, y, zp)
        x, y, kd = regular_xy(tp, yseed, k, j, Rj, th, th0, zn)
        Fm = _smap(tab, lo, hi, x, y, zn)
        x, y, kd = regular_xy(tp, yseed, k, j, Rj, th, th0, z)
        F0 = _smap(tab, lo, hi, x, y, z)
        D = (Fp - Fm) / (zp - zn)
        znew = min(max(z - np.dot(F0 - p, D) / np.dot(D, D), za), zb)
        if abs(znew - z) < 1e-13 * (1.0 + zb):
            z = znew
            break
        z = znew
    x, y, kind = regular_xy(tp, yseed, k, j, Rj, th, th0, z)
    r = _smap(tab, lo, hi, x, y, z) - p
    return math.sqrt(np.dot(r, r)), z, D / math.sqrt(np.dot(D, D)), kind


@njit(cache=True)
def hair_closest_s(tab, lo, hi, za, zb, tp, k, r0, r1, th1, pe, z1, ze, p, t0):
    """(distance, t*, tangent) of a hair to p under the sampled frames, over the part of the hair
    whose z lies in [za, zb]; distance 1e300 where no part does."""
    ta = 0.0
    tb = 1.0
    if ze > 0.0:
        ta = max(ta, (za - z1) / ze)
        tb = min(tb, (zb - z1) / ze)
    elif ze < 0.0:
        ta = max(ta, (zb - z1) / ze)
        tb = min(tb, (za - z1) / ze)
    elif z1 < za or z1 > zb:
        return 1e300, 0.0, np.zeros(3)
    if ta > tb:
        return 1e300, 0.0, np.zeros(3)
    t = min(max(t0, ta), tb)
    h = max(1e-4 * (tb - ta), 1e-9)
    D = np.zeros(3)
    for it in range(12):
        tp_ = min(t + h, 1.0)
        tm = max(t - h, 0.0)
        x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, tp_)
        Fp = _smap(tab, lo, hi, x, y, z)
        x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, tm)
        Fm = _smap(tab, lo, hi, x, y, z)
        x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, t)
        F0 = _smap(tab, lo, hi, x, y, z)
        D = (Fp - Fm) / (tp_ - tm)
        dd = np.dot(D, D)
        if dd <= 0.0:
            break
        tn = min(max(t - np.dot(F0 - p, D) / dd, ta), tb)
        if abs(tn - t) < 1e-13:
            t = tn
            break
        t = tn
    x, y, z = hair_point(tp, k, r0, r1, th1, pe, z1, ze, t)
    r = _smap(tab, lo, hi, x, y, z) - p
    nd = math.sqrt(np.dot(D, D))
    return math.sqrt(np.dot(r, r)), t, (D / nd if nd > 0.0 else D)


@njit(cache=True)
def _model_tangent_regular(za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, z):
    h = 1e-4 * (zb - za)
    a = max(z - h, za)
    b = min(z + h, zb)
    D = _reg_model(za, zm, zb, M, tp, yseed, k, j, Rj, th, th0, b) - _reg_model(za, zm, zb, M, tp, yseed, k, j,
                                                                                 Rj, th, th0, a)
    return D / math.sqrt(np.dot(D, D))


@njit(cache=True)
def _model_tangent_hair(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, t):
    a = max(t - 1e-4, 0.0)
    b = min(t + 1e-4, 1.0)
    D = _hair_model(za, zm, zb, M, tp, k, r0, r1, th1, pe, z1, ze, b) - _hair_model(za, zm, zb, M, tp, k, r0, r1,
                                                                                     th1, pe, z1, ze, a)
    n = math.sqrt(np.dot(D, D))
    return D / n if n > 0.0 else D


@njit(cache=True)
def _answer(c, kind, T, tp, tab):
    return (True, c, kind, T[0], T[1], T[2], tp[DENSITY], tab.yarn_albedo[c, 0], tab.yarn_albedo[c, 1],
            tab.yarn_albedo[c, 2])


@njit(cache=True)
def lookup_point(cv, tab, p):
    """seed 000 Algorithm 1 at fabric-space point p (float64[3]); see the module doc for the result."""
    cand = np.empty(MAX_YARNS, np.int64)
    cs = np.empty(MAX_YARNS)
    cd2 = np.empty(MAX_YARNS)
    fast = tab.fs_s.shape[0] > 0  # sampled frames present: pre-classify with them
    n = candidate_yarns(cv, tab, p, cand, cs, cd2, fast)
    for ci in range(n):
        c = cand[ci]
        s = cs[ci]
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        lo = tab.fs_off[c]
        hi = tab.fs_off[c + 1]
        if fast:
            pos, tan, nn, bn = sampled_frame(tab.fs_s, tab.fs_frame, lo, hi, s)
            eps = tab.yarn_eps[c]
        else:
            pos, tan, nn, bn = curve_frame_at(cv, c, s)
            eps = 0.0
        r = p - pos
        x = np.dot(r, nn)
        y = np.dot(r, bn)
        w = abs(np.dot(r, tan))
        rf = tp[FIBER_RADIUS]
        if w >= rf + 2.0 * eps:
            continue  # beyond an end of the yarn by more than any fibre's cap reaches
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
        hwin = (max((1.0 + K) * (rf + w + eps), tab.type_mz[t]) + w + 2.0 * eps) / gmin
        za = max(0.0, s - hwin)
        zb = min(L, s + hwin)
        reach = K * (rf + w + eps)
        have_model = False  # exact mode: one local model of Eq. 7 around s for the whole yarn
        Za = Zm = Zb = 0.0
        M = np.empty((3, 3, 3))
        for k in range(P):
            # ---- regular and loop fibres of ply k (Algorithm 2)
            cx, cy, drx, dry = ply_frame(tp, k, s)
            ax = x - cx
            ay = y - cy
            u = (ax * drx + ay * dry) / es
            v = (-ax * dry + ay * drx) / el
            rr = math.sqrt(u * u + v * v)
            ang = math.atan2(v, u) - twist
            ang = ang - TWO_PI * math.floor(ang / TWO_PI)
            b = min(int(ang / TWO_PI * B), B - 1)
            gb = tab.type_bin_off[t] + k * B + b
            fo = tab.type_fib_off[t] + k * N
            binned = w + eps <= tab.type_pad[t]  # else (beyond a yarn end) every fibre of the ply
            q0 = tab.bin_start[gb] if binned else 0
            q1 = tab.bin_start[gb + 1] if binned else N
            for q in range(q0, q1):
                j = tab.bin_items[q] if binned else q
                f = fo + j
                if binned and (rr < tab.fib_rlo[f] or rr > tab.fib_rhi[f]):
                    continue
                Rj = tab.fib_R[f]
                th = tab.fib_th[f]
                th0 = tab.fib_th0[f]
                X, Y, kind = regular_xy(tp, yseed, k, j, Rj, th, th0, s)
                dx = x - X
                dy = y - Y
                if dx * dx + dy * dy >= reach * reach:
                    continue
                if fast:
                    Dm, zs, T, kind = regular_closest_s(tab, lo, hi, za, zb, tp, yseed, k, j, Rj, th, th0, p, s)
                    if Dm >= rf + eps:
                        continue
                    if Dm <= rf - eps:
                        return _answer(c, kind, T, tp, tab)
                    # too close to the surface to decide with the sampled frames: exact frames
                    pe_, te_, ne_, be_ = curve_frame_at(cv, c, zs)
                    Za, Zm, Zb, M = local_frames(cv, c, zs, max(4.0 * (rf + eps), 1e-6), pe_, ne_, be_)
                else:
                    zs = s
                    if not have_model:
                        Za, Zm, Zb, M = local_frames(cv, c, s, hwin, pos, nn, bn)
                        have_model = True
                De, ze_ = regular_closest(cv, c, Za, Zm, Zb, M, tp, yseed, k, j, Rj, th, th0, p, zs)
                if De >= rf * (1.0 + MODEL_SLACK):
                    continue
                D, kind = regular_exact(cv, c, tp, yseed, k, j, Rj, th, th0, p, ze_)
                if D >= rf:
                    continue
                if not fast:
                    T = _model_tangent_regular(Za, Zm, Zb, M, tp, yseed, k, j, Rj, th, th0, ze_)
                return _answer(c, kind, T, tp, tab)
            # ---- hair fibres of ply k (hybrid z-bins or Algorithm 3)
            g = tab.yarn_ply_off[c] + k
            nh = tab.hair_count[g]
            if nh == 0:
                continue
            margin = tab.type_mz[t] + (w + 2.0 * eps) / gmin
            hidx = np.empty(nh, np.int64)
            hz1 = np.empty(nh)
            hze = np.empty(nh)
            na = _hair_active(tab, c, g, tp, s, margin, hidx, hz1, hze)
            limit = 1.1 * (rf + w + 2.0 * eps) / gmin
            rho_k = math.sqrt(ax * ax + ay * ay)
            for q in range(na):
                h = hidx[q]
                r0, r1, th1, pe = hair_params(tp, yseed, k, h)
                if _hair_quick_reject(tp, r0, r1, hz1[q], hze[q], rho_k, s, limit):
                    continue
                lb, bt = _hair_prefilter(tp, k, r0, r1, th1, pe, hz1[q], hze[q], x, y, s)
                if lb > limit:
                    continue
                if fast:
                    Dm, ts, T = hair_closest_s(tab, lo, hi, za, zb, tp, k, r0, r1, th1, pe, hz1[q], hze[q], p, bt)
                    if Dm >= rf + eps:
                        continue
                    if Dm <= rf - eps:
                        return _answer(c, 3, T, tp, tab)
                    hx, hy, hz = hair_point(tp, k, r0, r1, th1, pe, hz1[q], hze[q], ts)
                    pe_, te_, ne_, be_ = curve_frame_at(cv, c, hz)
                    Za, Zm, Zb, M = local_frames(cv, c, hz, max(4.0 * (rf + eps), 1e-6), pe_, ne_, be_)
                    have_model = False  # the model now sits around this hair, not around s
                else:
                    ts = bt
                    if not have_model:
                        Za, Zm, Zb, M = local_frames(cv, c, s, hwin, pos, nn, bn)
                        have_model = True
                De, te = hair_closest(Za, Zm, Zb, M, tp, k, r0, r1, th1, pe, hz1[q], hze[q], p, ts)
                if De >= rf * (1.0 + MODEL_SLACK):
                    continue
                D = hair_exact(cv, c, tp, k, r0, r1, th1, pe, hz1[q], hze[q], p, te)
                if D >= rf:
                    continue
                if not fast:
                    T = _model_tangent_hair(Za, Zm, Zb, M, tp, k, r0, r1, th1, pe, hz1[q], hze[q], te)
                return _answer(c, 3, T, tp, tab)
    return (False, -1, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@njit(cache=True)
def yarn_bound(tab, c):
    """(radius bound around the yarn axis, density bound) of yarn c: for tight delta tracking."""
    return tab.yarn_extent[c], tab.tparams[tab.yarn_type[c], DENSITY]


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
        p = np.empty(3)
        p[0] = pts[i, 0]
        p[1] = pts[i, 1]
        p[2] = pts[i, 2]
        res = lookup_point(cv, tab, p)
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
