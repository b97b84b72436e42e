"""Implicit plies of the BYSDF yarn model (seed 004 §3.3): stages/core/yarn/implicit_plies.py.

References: the procedural yarn model (model.ply_frame, sample_regular_fibers, regular_xy) and a
brute-force march written here: along the ray in steps of r_f / 20 (r_f the fibre radius), the exact
membership of every ply (the point's offset from ply k's centre at the point's own z, in ply k's frame,
inside the ellipse with half axes e_short + r_f, e_long + r_f), the first inside sample bisected to
1e-13. "Grazing": a ray whose penetration into a ply (or clearance from it) is below DELTA = 1e-5 in
the ply's normalised elliptic radius g = sqrt((a / A_r)^2 + (b / A_t)^2) (1 on the ply surface), i.e.
about 1e-7 cm for the 0.02 cm yarns here: a march of step r_f / 20 cannot see such a clip, and
implicit_plies counts entries shallower than GRAZE (1e-6 in g^2 - 1) as misses.
"""
import math

import numpy as np
import pytest
from numba import njit

from pipeline.presets import load_preset, pack, scale_preset
from stages.core.yarn import implicit_plies as IP, model as M

DELTA = 1e-5
TOL = 1e-4
MAX_ITER = 8


def _tp(name, radius=0.02):
    return pack(scale_preset(load_preset(name), radius))


@njit(cache=True)
def gauge(tp, k, x, y, z):
    """Normalised elliptic radius of (x, y, z) in ply k (1 on the ply surface), from model.ply_frame."""
    cx, cy, drx, dry = M.ply_frame(tp, k, z)
    a = (x - cx) * drx + (y - cy) * dry
    b = -(x - cx) * dry + (y - cy) * drx
    return math.sqrt((a / (tp[M.E_SHORT] + tp[M.FIBER_RADIUS])) ** 2 + (b / (tp[M.E_LONG] + tp[M.FIBER_RADIUS])) ** 2)


@njit(cache=True)
def gauge_on_ray(tp, k, o, d, u):
    return gauge(tp, k, o[0] + u * d[0], o[1] + u * d[1], o[2] + u * d[2])


@njit(cache=True)
def min_gauge_on(tp, k, o, d, lo, hi, n):
    """Smallest g of ply k on [lo, hi] along the ray: the best of n + 1 even samples, refined by ternary
    search between its neighbours."""
    best = np.inf
    ub = lo
    for i in range(n + 1):
        u = lo + (hi - lo) * i / n
        g = gauge_on_ray(tp, k, o, d, u)
        if g < best:
            best = g
            ub = u
    a = max(ub - (hi - lo) / n, lo)
    b = min(ub + (hi - lo) / n, hi)
    for _ in range(100):
        m1 = a + (b - a) / 3.0
        m2 = b - (b - a) / 3.0
        if gauge_on_ray(tp, k, o, d, m1) < gauge_on_ray(tp, k, o, d, m2):
            b = m2
        else:
            a = m1
    return min(best, gauge_on_ray(tp, k, o, d, 0.5 * (a + b)))


@njit(cache=True)
def brute_force(tp, o, d, u_max, step):
    """Per ply: the first entry u (-1: none), the smallest g on that first inside stretch, the smallest g
    on the whole chord (the march's samples, refined around the smallest)."""
    P = int(tp[M.PLY_NUM])
    first = np.full(P, -1.0)
    seg_min = np.full(P, np.inf)
    gmin = np.full(P, np.inf)
    gmin_u = np.zeros(P)
    left = np.zeros(P, np.bool_)
    n = int(math.ceil(u_max / step))
    for i in range(n + 1):
        u = min(i * step, u_max)
        for k in range(P):
            g = gauge_on_ray(tp, k, o, d, u)
            if g < gmin[k]:
                gmin[k] = g
                gmin_u[k] = u
            if left[k]:
                continue
            if first[k] < 0.0:
                if g <= 1.0:
                    if i == 0:
                        first[k] = 0.0
                    else:
                        lo = u - step
                        hi = u
                        while hi - lo > 1e-13:
                            mid = 0.5 * (lo + hi)
                            if gauge_on_ray(tp, k, o, d, mid) <= 1.0:
                                hi = mid
                            else:
                                lo = mid
                        first[k] = hi
                    seg_min[k] = g
            elif g > 1.0:
                left[k] = True
            else:
                seg_min[k] = min(seg_min[k], g)
    for k in range(P):
        gmin[k] = min(gmin[k], min_gauge_on(tp, k, o, d, max(gmin_u[k] - step, 0.0), min(gmin_u[k] + step, u_max), 2))
        if first[k] >= 0.0:
            seg_min[k] = min(seg_min[k], min_gauge_on(tp, k, o, d, first[k], min(first[k] + step, u_max), 2))
    return first, seg_min, gmin


@njit(cache=True)
def fibre_circles_in_plies(tp, reg, R, th, th0, n_z, n_ang):
    """(largest g - 1 over the fibre circles' points, largest g of a circle point) over n_z heights of
    one ply turn: fibre (k, j) at model.regular_xy, its circle of radius r_f, g of its own ply k."""
    P, N = R.shape
    rf = tp[M.FIBER_RADIUS]
    worst = -np.inf
    outer = 0.0
    for iz in range(n_z):
        z = tp[M.YARN_ALPHA] * iz / n_z
        for k in range(P):
            for j in range(N):
                x, y, _ = M.regular_xy(reg, 0, k, j, R[k, j], th[k, j], th0[k, j], z)
                for ia in range(n_ang):
                    ang = 2.0 * math.pi * ia / n_ang
                    g = gauge(tp, k, x + rf * math.cos(ang), y + rf * math.sin(ang), z)
                    worst = max(worst, g - 1.0)
                    outer = max(outer, g)
    return worst, outer


def _surface_normal(tp, k, p, h=1e-9):
    """Gradient of ply k's g at p (central differences)."""
    return np.array([(gauge(tp, k, *(p + h * e)) - gauge(tp, k, *(p - h * e))) / (2 * h) for e in np.eye(3)])


def random_rays(tp, n, rng, min_axial_deg=1.0):
    """(o, d, u_max, kind) of rays through the envelope: kind 0 uniform directions through uniform points
    of the envelope, 1 within min_axial_deg..10 degrees of the axis, 2 nearly tangent to the envelope,
    3 constructed to graze a ply (tangent to its surface, 1e-9..1e-5 ply radii off it), 4 along the axis
    (o inside, u_max up to 1.2 ply turns)."""
    R = IP.ply_envelope_radius(tp)
    ya = tp[M.YARN_ALPHA]
    P = int(tp[M.PLY_NUM])
    ar, at = IP.ply_half_axes(tp)
    out = []
    while len(out) < n:
        kind = int(rng.choice(5, p=[0.5, 0.2, 0.1, 0.15, 0.05]))
        if kind == 4:
            r = R * math.sqrt(rng.random())
            ph = 2 * math.pi * rng.random()
            o = np.array([r * math.cos(ph), r * math.sin(ph), ya * rng.random()])
            out.append((o, np.array([0.0, 0.0, rng.choice([-1.0, 1.0])]), ya * (0.2 + rng.random()), kind))
            continue
        if kind == 3:
            k = int(rng.integers(P))
            z = ya * rng.random()
            psi = 2 * math.pi * rng.random()
            cx, cy, drx, dry = M.ply_frame(tp, k, z)
            a, b = ar * math.cos(psi), at * math.sin(psi)
            S = np.array([cx + a * drx - b * dry, cy + a * dry + b * drx, z])
            N = _surface_normal(tp, k, S)
            N /= np.linalg.norm(N)
            d = rng.normal(size=3)
            d -= d.dot(N) * N
            d /= np.linalg.norm(d)
            X = S + N * 10 ** rng.uniform(-9, -5) * ar * rng.choice([-1.0, 1.0])
            if math.hypot(X[0], X[1]) >= R:
                continue
        else:
            r = R * math.sqrt(rng.random())
            ph = 2 * math.pi * rng.random()
            X = np.array([r * math.cos(ph), r * math.sin(ph), ya * rng.random()])
            if kind == 2:
                X[:2] *= R * (1 - 10 ** rng.uniform(-6, -2)) / r
            if kind == 1:
                th = math.radians(10 ** rng.uniform(math.log10(min_axial_deg), 1))
                az = 2 * math.pi * rng.random()
                d = np.array([math.sin(th) * math.cos(az), math.sin(th) * math.sin(az),
                              math.cos(th) * rng.choice([-1.0, 1.0])])
            else:
                d = rng.normal(size=3)
                d /= np.linalg.norm(d)
        A = d[0] ** 2 + d[1] ** 2
        B = X[0] * d[0] + X[1] * d[1]
        C = X[0] ** 2 + X[1] ** 2 - R * R
        sq = math.sqrt(B * B - A * C)
        t1, t2 = (-B - sq) / A, (-B + sq) / A
        scale = 10 ** rng.uniform(-0.5, 0.5)   # d need not be unit
        out.append((X + t1 * d, d * scale, (t2 - t1) / scale, kind))
    return out


def compare_with_brute_force(tp, rays, search=IP.SEARCH_ITERATION):
    """Per ray: (ok, grazing, |du| |d| / A_min (nan unless both hit the same ply), iterations, converged,
    kind, q) with q = |d_z| / |d_xy| ply_radius 2 pi / yarn_alpha (the helix crosses the ray's ellipse
    plane once where q < 1). ok: same hit / no hit, same ply, same plies_crossed and u within 1e-6 ply radii (unless the
    entry itself grazes: its stretch inside is less than DELTA deep). grazing: where not ok, the clip
    that one side saw and the other skipped (or the ply counted by one side only) is within DELTA."""
    ar, at = IP.ply_half_axes(tp)
    amin = min(ar, at)
    rows = []
    for o, d, um, kind in rays:
        h = IP.ply_hit(tp, o, d, um, TOL, MAX_ITER, True, search)
        dn = float(np.linalg.norm(d))
        step = tp[M.FIBER_RADIUS] / 20 / dn
        first, seg_min, gmin = brute_force(tp, o, d, um, step)
        entered = [k for k in range(len(first)) if first[k] >= 0]
        bk = min(entered, key=lambda k: first[k]) if entered else -1
        same = h.hit == (bk >= 0) and (bk < 0 or bk == h.ply) and h.plies_crossed == len(entered)
        err = abs(first[bk] - h.u) * dn / amin if (same and bk >= 0) else math.nan
        ok = same and (bk < 0 or err <= 1e-6 or
                       1.0 - min_gauge_on(tp, bk, o, d, min(first[bk], h.u), max(first[bk], h.u), 4000) < DELTA)
        grazing = False
        if not ok:
            if bk >= 0 and (not h.hit or first[bk] < h.u):
                grazing = 1.0 - seg_min[bk] < DELTA              # the march saw a clip ply_hit skipped
            elif h.hit:
                w = 4 * step
                g = min_gauge_on(tp, h.ply, o, d, max(h.u - w, 0.0), min(h.u + w, um), 8)
                grazing = 1.0 - g < DELTA                         # ply_hit saw a clip the march stepped over
            if h.plies_crossed != len(entered):
                grazing = grazing or any(abs(1.0 - g) < DELTA for g in gmin)
        dxy = math.hypot(d[0], d[1])
        q = abs(d[2]) / dxy * tp[M.PLY_RADIUS] * 2 * math.pi / tp[M.YARN_ALPHA] if dxy > 0 else math.inf
        rows.append((ok, grazing, err, h.iterations, h.converged, kind, q))
    return rows


@pytest.mark.parametrize("name", ["cotton1", "polyester1"])
def test_ply_hit_agrees_with_brute_force_march(name):
    """1200 random rays per preset (cotton1: 3 plies; polyester1: 2 plies), uniform, near-axial (1-10
    degrees), tangent to the envelope, constructed to graze a ply, along the axis; |d| varies. Against the
    brute-force march: same hit / no hit, same ply, u within 1e-6 ply radii, same plies_crossed, on every
    ray but grazing ones (module doc); at most 0.2 % of the rays not built to graze disagree. The
    ellipse-plane iteration's median step count lies in 3..10 and it converges on every ray whose ellipse
    plane the ply helix crosses once (q < 1, compare_with_brute_force); rays nearer the axis may not
    converge (the certification still finds their entries)."""
    tp = _tp(name)
    rows = compare_with_brute_force(tp, random_rays(tp, 1200, np.random.default_rng(4)))
    agree = np.array([r[0] for r in rows])
    grazing = np.array([r[1] for r in rows])
    its = np.array([r[3] for r in rows])
    conv = np.array([r[4] for r in rows])
    kind = np.array([r[5] for r in rows])
    q = np.array([r[6] for r in rows])
    assert np.all(agree | grazing), np.nonzero(~(agree | grazing))
    assert np.mean(~agree[kind != 3]) <= 0.002
    assert 3 <= np.median(its) <= 10
    assert np.all(conv[q < 1.0])


@pytest.mark.slow
@pytest.mark.parametrize("search", [IP.SEARCH_ITERATION, IP.SEARCH_MARCH])
@pytest.mark.parametrize("name", ["cotton1", "silk1", "polyester1", "rayon1"])
def test_ply_hit_agrees_with_brute_force_march_many_rays(name, search):
    """As the fast test with 5000 rays per preset and near-axial rays down to 0.1 degree; four presets
    (silk1 and cotton1: 3 plies; polyester1, rayon1: 2 plies; rayon1's plies turn clockwise); both
    searches (the paper's iteration and the march alone)."""
    tp = _tp(name)
    rows = compare_with_brute_force(tp, random_rays(tp, 5000, np.random.default_rng(11), min_axial_deg=0.1), search)
    agree = np.array([r[0] for r in rows])
    grazing = np.array([r[1] for r in rows])
    kind = np.array([r[5] for r in rows])
    assert np.all(agree | grazing)
    assert np.mean(~agree[kind != 3]) <= 0.002


def test_hit_frame_matches_the_model():
    """At the hit: the point is on ply k's surface (g = 1), the tangent is the normalised central
    difference of model.ply_frame's centre along z, the normal is unit, orthogonal to the tangent and
    outward (p + eps n outside ply k, p - eps n inside), and the ply angle psi places the hit on the
    line from the centre along (e_short cos psi, e_long sin psi) (the unit-disc angle of the model)."""
    tp = _tp("cotton1")
    rng = np.random.default_rng(2)
    n_hits = 0
    for o, d, um, _ in random_rays(tp, 300, rng):
        h = IP.ply_hit(tp, o, d, um, TOL, MAX_ITER)
        if not h.hit or h.u == 0.0:   # (u = 0: an axial ray starting inside a ply)
            continue
        n_hits += 1
        p = np.array(h.point)
        k = h.ply
        assert gauge(tp, k, *p) == pytest.approx(1.0, abs=1e-8)
        e = 1e-7
        c1 = np.array(M.ply_frame(tp, k, p[2] + e)[:2] + (p[2] + e,))
        c0 = np.array(M.ply_frame(tp, k, p[2] - e)[:2] + (p[2] - e,))
        t = (c1 - c0) / np.linalg.norm(c1 - c0)
        assert np.allclose(h.tangent, t, atol=1e-7)
        nrm = np.array(h.normal)
        assert np.linalg.norm(nrm) == pytest.approx(1.0, abs=1e-12)
        assert abs(nrm.dot(h.tangent)) < 1e-12
        eps = 1e-6 * tp[M.E_SHORT]
        assert gauge(tp, k, *(p + eps * nrm)) > 1.0 > gauge(tp, k, *(p - eps * nrm))
        cx, cy, drx, dry = M.ply_frame(tp, k, p[2])
        a = (p[0] - cx) * drx + (p[1] - cy) * dry
        b = -(p[0] - cx) * dry + (p[1] - cy) * drx
        ux, uy = a / tp[M.E_SHORT], b / tp[M.E_LONG]
        assert math.atan2(uy, ux) == pytest.approx(h.ply_angle, abs=1e-12)
    assert n_hits > 150


@pytest.mark.parametrize("name", ["cotton1", "polyester1", "rayon1"])
def test_ply_tube_is_the_hull_of_the_model_fibres(name):
    """The regular fibres of the model (sample_regular_fibers + regular_xy, loops off) at 40 heights: each
    fibre circle lies inside its ply's tube up to the ellipse offset slack (2 % of r_f), the outermost
    fibres reach the tube (within 3 % of the ply radius); every tube point lies within ply_reach_radius
    (which it attains) and ply_envelope_radius."""
    tp = _tp(name)
    reg = tp.copy()
    reg[M.USE_FLYAWAYS] = 0.0
    R, th, th0 = M.sample_regular_fibers(reg, np.uint64(99))
    rf = tp[M.FIBER_RADIUS]
    ar, at = IP.ply_half_axes(tp)
    worst_out, outermost = fibre_circles_in_plies(tp, reg, R, th, th0, 40, 24)
    assert worst_out * max(ar, at) <= 0.02 * rf   # (g - 1) A_max bounds the distance outside
    assert outermost >= 0.97
    t = np.linspace(0, 2 * np.pi, 200001)
    r = np.hypot(tp[M.PLY_RADIUS] + ar * np.cos(t), at * np.sin(t))
    assert r.max() <= IP.ply_reach_radius(tp) + 1e-15
    assert r.max() >= IP.ply_reach_radius(tp) - 1e-9
    assert IP.ply_reach_radius(tp) <= IP.ply_envelope_radius(tp)


def test_degenerate_rays_are_finite():
    """Rays along the axis (inside a ply: hit at u = 0; in a gap: compared with the brute-force march),
    a zero-length chord, a ray tangent to the envelope and a ray through the axis: finite fields, unit
    frames where there is a hit."""
    tp = _tp("cotton1")
    R = IP.ply_envelope_radius(tp)
    cases = [
        (np.array([tp[M.PLY_RADIUS], 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), 0.3),    # on ply 0's centre line
        (np.array([0.99 * R, 0.0, 0.05]), np.array([0.0, 0.0, -2.0]), 0.2),           # outside the plies' reach
        (np.array([R, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0]), 0.0),                   # zero-length chord
        (np.array([R, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.0),                    # tangent to the envelope
        (np.array([R, 0.0, 0.0]), np.array([-1.0, 0.0, 1e-12]), 2 * R),               # through the axis
    ]
    for o, d, um in cases:
        h = IP.ply_hit(tp, o, d, um, TOL, MAX_ITER)
        vals = np.array([h.u, h.ply_angle, *h.point, *h.tangent, *h.normal], float)
        assert np.all(np.isfinite(vals))
        first, _, _ = brute_force(tp, o, d, um, tp[M.FIBER_RADIUS] / 20 / np.linalg.norm(d))
        assert h.hit == bool((first >= 0).any())
        if h.hit:
            assert h.u == pytest.approx(first[first >= 0].min(), abs=1e-9)
            assert np.linalg.norm(h.tangent) == pytest.approx(1.0) and np.linalg.norm(h.normal) == pytest.approx(1.0)
    assert IP.ply_hit(tp, *cases[0][:2], 0.3, TOL, MAX_ITER).u == 0.0


@pytest.mark.parametrize("name", ["cotton1", "polyester1"])
def test_render_queries_agree_with_ply_hit(name):
    """The renderer's queries against ``ply_hit`` (iteration, full count) on the fast test's rays (module
    doc, "Queries"): ``ply_hit(count=False)`` gives the same first hit bit for bit, ``plies_crossed`` the same
    count, ``ply_blocks`` the same hit / no hit. With SEARCH_MARCH (the march alone) the same hit, ply and
    count, u within 1e-9 ply radii, on every ray not built to graze a ply, and no iterations reported."""
    tp = _tp(name)
    ar, at = IP.ply_half_axes(tp)
    amin = min(ar, at)
    n_hits = 0
    for o, d, um, kind in random_rays(tp, 1200, np.random.default_rng(4)):
        full = IP.ply_hit(tp, o, d, um, TOL, MAX_ITER)
        first = IP.ply_hit(tp, o, d, um, TOL, MAX_ITER, False)
        assert (first.hit, first.ply, first.u, first.point, first.normal, first.plies_crossed) == \
               (full.hit, full.ply, full.u, full.point, full.normal, -1)
        assert IP.plies_crossed(tp, o, d, um, TOL, MAX_ITER) == full.plies_crossed
        assert IP.ply_blocks(tp, o, d, um, TOL, MAX_ITER) == full.hit
        n_hits += full.hit
        if kind == 3:
            continue
        dn = float(np.linalg.norm(d))
        for count in (True, False):
            m = IP.ply_hit(tp, o, d, um, TOL, MAX_ITER, count, IP.SEARCH_MARCH)
            assert m.hit == full.hit and m.ply == full.ply
            assert abs(m.u - full.u) * dn <= 1e-9 * amin
            assert m.iterations == 0 and m.converged
            assert m.plies_crossed == (full.plies_crossed if count else -1)
        assert IP.plies_crossed(tp, o, d, um, TOL, MAX_ITER, IP.SEARCH_MARCH) == full.plies_crossed
        assert IP.ply_blocks(tp, o, d, um, TOL, MAX_ITER, IP.SEARCH_MARCH) == full.hit
    assert n_hits > 400


@pytest.mark.parametrize("name", ["cotton1", "polyester1"])
def test_march_search_agrees_with_brute_force_march(name):
    """SEARCH_MARCH against the brute-force march on the fast test's rays, with its criteria (same hit,
    ply, count, u within 1e-6 ply radii unless grazing)."""
    tp = _tp(name)
    rows = compare_with_brute_force(tp, random_rays(tp, 1200, np.random.default_rng(4)), IP.SEARCH_MARCH)
    agree = np.array([r[0] for r in rows])
    grazing = np.array([r[1] for r in rows])
    kind = np.array([r[5] for r in rows])
    assert np.all(agree | grazing), np.nonzero(~(agree | grazing))
    assert np.mean(~agree[kind != 3]) <= 0.002
