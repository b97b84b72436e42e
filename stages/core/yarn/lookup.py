"""Point lookups without realization: seed 000 Algorithms 1-3 on the tables of tables.py.

``lookup_point(cv, tab, px, py, pz)`` answers, for a fabric-space point p, a ``FibreLookup``
    (inside, yarn, kind, dir_x, dir_y, dir_z, density, albedo_r, albedo_g, albedo_b, fibre)
with kind 0 none, 1 regular, 2 loop, 3 hair; dir the unit fibre tangent at the closest point of the
covering fibre (zero outside); density the yarn type's density (0 outside); ``OUTSIDE`` where no
fibre covers p; fibre a number that tells the covering fibres apart (-1 outside).
``lookup_point(..., skip)`` answers for every fibre but the one numbered ``skip`` (volpath's rays
leaving a fibre that scattered them).
``lookup_points(cv, tab, pts)`` does it for (N, 3) points on threads and returns
the same fields as arrays (``FibreLookups``: inside, yarn, kind, direction (N, 3), density,
albedo (N, 3)).
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
   open yarn's end, and the covering fibre first in the order below answers (``yarn_lookup``
   returns a ``KeyedLookup``: the answer and its place in that order). A candidate whose frame
   samples are not resident (paged tables, frame_pool.py) is asked for (``fs_want``) and counted
   (``fs_miss``) and left out: the caller must not use an answer given while ``fs_miss`` rose.
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
The per-fibre tests of steps 3-4 are ``stages.core.yarn.fibre_tests`` (one ``YarnVisit`` per
yarn visit carries what they share). The sampled frames differ from Eq. 7's exact frames by at
most eps_c (``yarn_eps``, measured when the tables are loaded): a distance farther than eps_c from
the radius is decided at once, the rest (rare: eps_c is about 1 % of the fibre radius) with the
exact frames (fibre_tests.exact_regular / exact_hair). Inside/outside, yarn and kind are those of
the exact model.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.sampling import NO_HIT
from stages.core.threads import chunk_kernel, for_chunks
from stages.core.yarn import hair_free
from stages.core.yarn.fibre_tests import (
    TWO_PI,
    HairShape,
    RegularFibre,
    YarnVisit,
    exact_hair,
    exact_regular,
    fibre_xy,
    hair_closest_s,
    hair_prefilter,
    hair_quick_reject,
    regular_closest_s,
    stored_hair,
)
from stages.core.yarn.frame_samples import chord_lower_bound, foot_point, frame_at
from stages.core.yarn.model import (
    DENSITY,
    E_LONG,
    E_SHORT,
    FIBER_RADIUS,
    PLY_RADIUS,
    YARN_ALPHA,
    ZE_MU,
    ZE_SIG,
    fiber_twist,
    fibre_counts,
    hair_params,
    ply_frame,
    reach_factor,
)
from stages.core.yarn.tables import fringe_bits, fringe_window, hair_node_seed_nb, yarn_space_limit, z_window

FOOT_TOL = 1e-4  # foot-point Newton stops at steps below this x the fibre radius (w absorbs the rest)
GN_TOL = 1e-5  # Gauss-Newton stops when a step moves the fibre point by less than this x the fibre radius

_ANSWER = ("inside", "yarn", "kind", "dir_x", "dir_y", "dir_z", "density", "albedo_r", "albedo_g", "albedo_b")
FibreLookup = namedtuple("FibreLookup", _ANSWER + ("fibre",))
FibreLookup.__doc__ = """lookup_point's answer at p (module doc); ``fibre`` identifies the covering fibre
within the fabric (yarn * FIBRE_ID_STRIDE + its order key; -1 outside)."""
KeyedLookup = namedtuple("KeyedLookup", _ANSWER + ("key",))
KeyedLookup.__doc__ = """yarn_lookup's answer: FibreLookup's fields and the covering fibre's order key
(_order_key; NO_FIBRE outside)."""
FibreLookups = namedtuple("FibreLookups", ["inside", "yarn", "kind", "direction", "density", "albedo"])
FibreLookups.__doc__ = """lookup_points' answers: inside (N,) bool, yarn (N,) int32, kind (N,) int8,
direction (N, 3), density (N,), albedo (N, 3)."""

OUTSIDE = FibreLookup(False, -1, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1)
NO_FIBRE = 1 << 62  # yarn_lookup's order key when nothing covers p
OUTSIDE_KEYED = KeyedLookup(False, -1, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, NO_FIBRE)
ORDER_STRIDE = 1 << 32  # order key of a hit: (2 ply + is_hair) * ORDER_STRIDE + fibre index
FIBRE_ID_STRIDE = 1 << 40  # FibreLookup.fibre = yarn * FIBRE_ID_STRIDE + order key (keys stay below it)


@njit(cache=True, inline="always")
def _answer(c, kind, tx, ty, tz, tp, tab, key):
    return KeyedLookup(True, np.int64(c), kind, tx, ty, tz, tp[DENSITY], tab.yarn_albedo[c, 0],
                       tab.yarn_albedo[c, 1], tab.yarn_albedo[c, 2], key)


@njit(cache=True, inline="always")
def _unkeyed(r):
    fibre = r.yarn * FIBRE_ID_STRIDE + r.key if r.inside else np.int64(-1)
    return FibreLookup(r.inside, r.yarn, r.kind, r.dir_x, r.dir_y, r.dir_z, r.density, r.albedo_r, r.albedo_g,
                       r.albedo_b, fibre)


@njit(cache=True, inline="always")
def _order_key(k, is_hair, j):
    """Where a hit stands in the covering order (ply, regular before hair, fibre index) of one yarn."""
    return (2 * k + (1 if is_hair else 0)) * ORDER_STRIDE + j


@njit(cache=True, _nrt=False)
def yarn_lookup(cv, tab, c, s, i, px, py, pz, skip_key):
    """Steps 2-4 of Algorithm 1 in yarn c, p's foot point at arc length s (frame-sample step i):
    a ``KeyedLookup`` (lookup_point's answer and the order key of the covering fibre), the fibre of
    order key ``skip_key`` (-1: none) counting as empty."""
    t = tab.yarn_type[c]
    tp = tab.tparams[t]
    lo = tab.fs_at[c]
    hi = lo + tab.fs_n[c]
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
    P, N = fibre_counts(tp)
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
    vis = YarnVisit(tab.fs_s, tab.fs_frame, lo, hi, i, c, tp, yseed, s, x, y, za, zb, rf, eps, px, py, pz)
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
                hit, kind, tx, ty, tz = _regular_test(cv, tab, vis, k, j, fi, reach_j)
                if hit and _order_key(k, False, j) != skip_key:
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
                    hit, kind, tx, ty, tz = _regular_test(cv, tab, vis, k, j, fi, reach)
                    if hit and _order_key(k, False, j) != skip_key:
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
                # the hair's z and radius ranges (one row): a looser fibre_tests.hair_quick_reject
                if (s < tab.hair_box[hh, 0] - limit or s > tab.hair_box[hh, 1] + limit
                        or rho_k < tab.hair_box[hh, 2] - mr or rho_k > tab.hair_box[hh, 3] + mr):
                    continue
                hs = stored_hair(tab, hh)
                hit, tx, ty, tz = _hair_test(cv, vis, k, hs, rho_k, limit)
                if hit and _order_key(k, True, tab.hb_items[qq]) != skip_key:
                    return _answer(c, 3, tx, ty, tz, tp, tab, _order_key(k, True, tab.hb_items[qq]))
        else:
            seed = hair_node_seed_nb(np.uint64(tab.yarn_seed[c]), k)
            margin = tab.type_mz[t] + (w + 2.0 * eps) / gmin
            hit, tx, ty, tz, h = _free_mode_hairs(cv, vis, k, nh, seed, L, margin, rho_k, limit, skip_key)
            if hit:
                return _answer(c, 3, tx, ty, tz, tp, tab, _order_key(k, True, h))
    return OUTSIDE_KEYED


@njit(cache=True, inline="always")
def _regular_test(cv, tab, vis, k, j, fi, reach):
    """(covered, kind, tangent) of regular fibre j of ply k (fi its global index) at the visit's point:
    cross-section reach test at s, Gauss-Newton under the sampled frames, exact frames within eps_c
    of the surface."""
    fib = RegularFibre(k, np.int64(j), tab.fib_R[fi], tab.fib_th[fi], tab.fib_th0[fi])  # one typing for both callers
    X, Y, kind = fibre_xy(vis.tp, vis.yseed, fib, vis.s)
    dx = vis.x - X
    dy = vis.y - Y
    if dx * dx + dy * dy >= reach * reach:
        return False, 0, 0.0, 0.0, 0.0
    Dm, zs, tx, ty, tz, kind = regular_closest_s(vis, fib, vis.s, GN_TOL * vis.rf)
    if Dm >= vis.rf + vis.eps:
        return False, 0, 0.0, 0.0, 0.0
    if Dm > vis.rf - vis.eps:  # too close to the surface to decide with the sampled frames
        inside, kind = exact_regular(cv, vis, fib, zs)
        if not inside:
            return False, 0, 0.0, 0.0, 0.0
    return True, kind, tx, ty, tz


@njit(cache=True, inline="always")
def _hair_test(cv, vis, k, hs, rho_k, limit):
    """(covered, tangent) of hair ``hs`` of ply k at the visit's point (rho_k: p's distance from the
    ply centre, limit: the yarn-space reach of the visit)."""
    if hair_quick_reject(vis.tp, hs, rho_k, vis.s, limit):
        return False, 0.0, 0.0, 0.0
    lb, bt = hair_prefilter(vis.tp, k, hs, vis.x, vis.y, vis.s, limit)
    if lb > limit:
        return False, 0.0, 0.0, 0.0
    Dm, ts, tx, ty, tz = hair_closest_s(vis, k, hs, bt, GN_TOL * vis.rf)
    if Dm >= vis.rf + vis.eps:
        return False, 0.0, 0.0, 0.0
    if Dm > vis.rf - vis.eps and not exact_hair(cv, vis, k, hs, ts):
        return False, 0.0, 0.0, 0.0
    return True, tx, ty, tz


@njit(cache=True, _nrt=True)  # allocates: keeps reference counting under a caller without it
def _free_mode_hairs(cv, vis, k, nh, seed, L, margin, rho_k, limit, skip_key):
    """Realization-free hair mode (Algorithm 3): the active hairs of ply k at s from the implicit
    quad-tree (scratch arrays of the ply's hair count), then the same tests as the hybrid mode:
    (covered, tangent, hair index), the hair of order key ``skip_key`` passed over.
    A function of its own so that yarn_lookup allocates nothing."""
    tp = vis.tp
    hidx = np.empty(nh, np.int64)
    hz1 = np.empty(nh)
    hze = np.empty(nh)
    na = hair_free.active_hairs(L, nh, tp[ZE_MU], tp[ZE_SIG], seed, vis.s, margin, hidx, hz1, hze)
    for qq in range(na):
        r0, r1, th1, pe = hair_params(tp, vis.yseed, k, hidx[qq])
        hit, tx, ty, tz = _hair_test(cv, vis, k, HairShape(r0, r1, th1, pe, hz1[qq], hze[qq]), rho_k, limit)
        if hit and _order_key(k, True, hidx[qq]) != skip_key:
            return True, tx, ty, tz, hidx[qq]
    return False, 0.0, 0.0, 0.0, 0


@njit(cache=True, _nrt=False)
def lookup_point(cv, tab, px, py, pz, skip=-1):
    """seed 000 Algorithm 1 at fabric-space point p: a ``FibreLookup`` (module doc); the fibre numbered
    ``skip`` (a FibreLookup.fibre, -1: none) counts as empty, so the first of the others answers."""
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
    while q < qe:
        c = tab.fg_yarn[q]
        best = NO_HIT
        bq = np.int64(-1)  # not a literal: _seam_visits gets one typing
        bt = 0.0
        while q < qe and tab.fg_yarn[q] == c:  # every run of yarn c in the cell
            for ch in range(tab.fg_a[q], tab.fg_b[q]):
                lb, t = chord_lower_bound(tab.kn_pos, tab.kn_sag, ch, px, py, pz)
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
        skip_key = skip - c * FIBRE_ID_STRIDE if skip >= 0 and skip // FIBRE_ID_STRIDE == c else -1
        seam = cv.closed[c] and _near_seam(tab, c, bound, rf, eps, px, py, pz)
        if gated and not seam:
            continue
        base = tab.fs_at[c]
        if base < 0:  # yarn c's frame samples are not resident: ask for them, this answer does not count
            tab.fs_want[c] = 1
            tab.fs_miss[0] += 1
            continue
        if seam:
            res = _seam_visits(cv, tab, c, gated, bq, bt, bound, rf, px, py, pz, skip_key)
            if res.inside:
                return _unkeyed(res)
            continue
        # foot point: Newton from the nearest chord, bracketed by its neighbours
        k0 = tab.kn_off[c]
        k1 = tab.kn_off[c + 1] - 1
        ia = base + tab.kn_idx[bq]
        s0 = tab.kn_s[bq] + bt * (tab.kn_s[bq + 1] - tab.kn_s[bq])
        fa = base + tab.kn_idx[max(bq - 1, k0)]
        fb = base + tab.kn_idx[min(bq + 2, k1)]
        s, i, d2 = foot_point(tab.fs_s, tab.fs_frame, fa, fb + 1, ia, s0, tab.fs_s[fa], tab.fs_s[fb], px, py, pz,
                              FOOT_TOL * rf)
        if d2 >= bound * bound:
            continue
        res = yarn_lookup(cv, tab, c, s, i, px, py, pz, skip_key)
        if res.inside:
            return _unkeyed(res)
    return OUTSIDE


@njit(cache=True, inline="always")
def _visit(cv, tab, c, ka, kb, ia, s0, bound, rf, px, py, pz, skip_key):
    """yarn_lookup at p's foot point on yarn c between coarse knots ka and kb (frame-sample hint ia,
    Newton from s0); OUTSIDE_KEYED when the foot point is farther than bound. (lookup_point's main
    visit spells this out: returning the constant from an inlined call costs it ~20 %.)
    13 parameters: ``yarn_lookup``'s context (curves, tables, yarn, knot range, frame hint, Newton start, distance
    bound, radius factor), the point and the skip key, as the lookup holds them."""
    base = tab.fs_at[c]
    fa = base + tab.kn_idx[ka]
    fb = base + tab.kn_idx[kb]
    s, i, d2 = foot_point(tab.fs_s, tab.fs_frame, fa, fb + 1, ia, s0, tab.fs_s[fa], tab.fs_s[fb], px, py, pz,
                          FOOT_TOL * rf)
    if d2 >= bound * bound:
        return OUTSIDE_KEYED
    return yarn_lookup(cv, tab, c, s, i, px, py, pz, skip_key)


@njit(cache=True, _nrt=False)
def _seam_visits(cv, tab, c, gated, bq, bt, bound, rf, px, py, pz, skip_key):
    """Closed yarn c near its seam (a closed yarn's fibres run from s = 0 to L and meet at the seam
    without joining): the main visit at the nearest chord bq unless gated, and each end piece it
    does not cover, visited as an open yarn's end; the first answer in the covering order."""
    k0 = tab.kn_off[c]
    k1 = tab.kn_off[c + 1] - 1
    ka = max(bq - 1, k0)
    kb = min(bq + 2, k1)
    res = OUTSIDE_KEYED
    base = tab.fs_at[c]
    if not gated:
        ia = base + tab.kn_idx[bq]
        s0 = tab.kn_s[bq] + bt * (tab.kn_s[bq + 1] - tab.kn_s[bq])
        res = _visit(cv, tab, c, ka, kb, ia, s0, bound, rf, px, py, pz, skip_key)
    if ka > k0:  # the start of the yarn
        r2 = _visit(cv, tab, c, k0, min(k0 + 2, k1), base + tab.kn_idx[k0], 0.0, bound, rf, px, py, pz, skip_key)
        if r2.key < res.key:
            res = r2
    if kb < k1:  # its end
        r2 = _visit(cv, tab, c, max(k1 - 2, k0), k1, base + tab.kn_idx[k1 - 1], tab.yarn_length[c], bound, rf, px,
                    py, pz, skip_key)
        if r2.key < res.key:
            res = r2
    return res


@njit(cache=True, inline="always")
def _near_seam(tab, c, bound, rf, eps, px, py, pz):
    """Whether fibres of closed yarn c within its largest z window of the seam may reach p (p within
    bound + that window of the seam point: a fibre point at arc length z lies within the extent of
    the axis at z, and the axis within |z - seam| of the seam point)."""
    t = tab.yarn_type[c]
    zw = fringe_window(tab.type_K[t], tab.type_mz[t], rf, eps, tab.yarn_gmin[c])
    a = tab.kn_off[c]
    dx = px - tab.kn_pos[a, 0]
    dy = py - tab.kn_pos[a, 1]
    dz = pz - tab.kn_pos[a, 2]
    r = bound + zw
    return dx * dx + dy * dy + dz * dz < r * r


@njit(cache=True)
def point_answer_arrays(N):
    """(inside (N,) bool, yarn (N,) int32, kind (N,) int8, direction (N, 3)) for N points' answers, all outside
    (yarn -1): the arrays ``lookup_points`` and the realized reference (``stages.procedural.realized_reference``)
    fill."""
    return np.zeros(N, np.bool_), np.full(N, -1, np.int32), np.zeros(N, np.int8), np.zeros((N, 3))


@njit(cache=True)
def store_point_answer(r, i, inside, yarn, kind, direction):
    """Writes answer r's inside, yarn, kind and direction (dir_x, dir_y, dir_z) into row i of those arrays."""
    inside[i] = r.inside
    yarn[i] = r.yarn
    kind[i] = r.kind
    direction[i, 0] = r.dir_x
    direction[i, 1] = r.dir_y
    direction[i, 2] = r.dir_z


def lookup_points(cv, tab, pts):
    """Vectorised lookup_point over (N, 3) points, on threads (``stages.core.threads``): ``FibreLookups``
    (inside, yarn, kind, direction (N, 3), density, albedo (N, 3))."""
    N = pts.shape[0]
    inside, yarn, kind, direction = point_answer_arrays(N)
    density = np.zeros(N)
    albedo = np.zeros((N, 3))
    for_chunks(_lookup_range, N, cv, tab, pts, inside, yarn, kind, direction, density, albedo)
    return FibreLookups(inside, yarn, kind, direction, density, albedo)


@chunk_kernel
def _lookup_range(cv, tab, pts, inside, yarn, kind, direction, density, albedo, i0, i1):
    """``lookup_points`` of points i0 .. i1 - 1."""
    for i in range(i0, i1):
        # skip typed as volpath passes it (not a literal): lookup_point compiles once for both
        r = lookup_point(cv, tab, pts[i, 0], pts[i, 1], pts[i, 2], np.int64(-1))
        store_point_answer(r, i, inside, yarn, kind, direction)
        density[i] = r.density
        albedo[i, 0] = r.albedo_r
        albedo[i, 1] = r.albedo_g
        albedo[i, 2] = r.albedo_b
