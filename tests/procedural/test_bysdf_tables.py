"""The BYSDF yarn model's 1D tables: the build (stages/procedural/bysdf_tables.py) and the render-time
lookups and fibre frame (stages/core/yarn/implicit_tables.py).

References: brute-force 2D marches written here (point-in-circles for the fibre cast, point-in-ellipse
for the ply shadowing), the closed form of the directions a touching neighbour circle blocks, a lone
fibre (nothing can block it: shadowing 1), the procedural yarn model (model.ply_to_yarn, ply_angle,
fiber_twist) for the fibre frame and the lookups' turning, and the lookups' own contract (periodic in
the angle, continuous in z, piecewise one table between blends).
"""
import math

import numpy as np
import pytest
from numba import njit

from pipeline.presets import load_preset, pack, scale_preset
from stages.core.yarn import implicit_plies as IP, implicit_tables as IT, model as M
from stages.procedural import bysdf_tables as BT

KEY = np.uint64(2024)


def _tp(name="cotton1", radius=0.02, **over):
    d = scale_preset(load_preset(name), radius)
    d.update(over)
    return pack(d)


@njit(cache=True)
def first_inside_circles(cx, cy, r, sx, sy, dx, dy, step, t_max):
    """(j, t): march s + t d in steps, the first point inside a circle, bisected to 1e-15; (-1, inf)."""
    n = int(t_max / step) + 1
    prev = 0.0
    for i in range(n + 1):
        t = i * step
        for j in range(cx.shape[0]):
            if (sx + t * dx - cx[j]) ** 2 + (sy + t * dy - cy[j]) ** 2 <= r * r:
                lo, hi = prev, t
                while hi - lo > 1e-15:
                    mid = 0.5 * (lo + hi)
                    if (sx + mid * dx - cx[j]) ** 2 + (sy + mid * dy - cy[j]) ** 2 <= r * r:
                        hi = mid
                    else:
                        lo = mid
                return j, hi
        prev = t
    return -1, np.inf


def test_fibre_cast_matches_point_in_circles():
    """For 12 angles of table 0 of cotton1 (and the same angles on a ring-free random table 3): the line
    from outside the ply tube towards the centre (unit-disc angle psi = theta + twist) meets first the
    fibre a brute-force point-in-circles march meets first, at the same distance (1e-12), and the table
    stores that fibre's phase (j + 0.5) / N and the angle from the tube's normal (the ellipse gradient
    at the line's boundary point) to the fibre's normal at the march's hit point."""
    tp = _tp()
    r = tp[M.FIBER_RADIUS]
    ar, at = IP.ply_half_axes(tp)
    for m in (0, 3):
        x, y, twist = BT.fibre_arrangement(tp, KEY, m, 4)
        table = BT.fibre_table_of(tp, x, y, twist, 12, 8, 0.5)
        for i in range(12):
            psi = 2 * math.pi * i / 12 + twist
            e = np.array([tp[M.E_SHORT] * math.cos(psi), tp[M.E_LONG] * math.sin(psi)])
            e /= np.linalg.norm(e)
            tb = 1.0 / math.hypot(e[0] / ar, e[1] / at)
            s = (tb + 2 * r) * e
            j_bf, t_bf = first_inside_circles(x, y, r, s[0], s[1], -e[0], -e[1], r / 200, 4 * tb)
            j, t = BT.cast_circles(x, y, r, s[0], s[1], -e[0], -e[1], -1)
            assert j == j_bf and t == pytest.approx(t_bf, abs=1e-12)
            h = s - t_bf * e
            fn = (h - (x[j], y[j])) / r
            g = np.array([tb * e[0] / ar ** 2, tb * e[1] / at ** 2])
            angle = math.atan2(g[0] * fn[1] - g[1] * fn[0], g @ fn)
            assert fn @ e >= -1e-9          # the visible side of the fibre faces out along the line
            assert table[i, IT.FIBRE_NORMAL_ANGLE] == pytest.approx(angle, abs=1e-6)
            assert table[i, IT.FIBRE_PHASE] == (j + 0.5) / len(x)


def test_lone_fibre_is_never_shadowed():
    """One fibre per ply: nothing can block the half circle above its surface, so every sample that meets
    the fibre stores shadowing 1 after the remap; the lines that miss it store phase -1."""
    tp = _tp(fiber_num=1)
    x, y, twist = BT.fibre_arrangement(tp, KEY, 0, 4)
    table = BT.fibre_table_of(tp, x, y, twist, 64, 256, 0.5)
    hit = table[:, IT.FIBRE_PHASE] >= 0
    assert hit.any()
    assert np.all(table[hit, IT.FIBRE_SHADOW] == 1.0)
    assert np.all(table[~hit, IT.FIBRE_PHASE] == -1.0)


@pytest.mark.parametrize("alpha_deg", [10.0, 30.0, 60.0, 85.0])
def test_open_fraction_against_the_closed_form_of_a_touching_neighbour(alpha_deg):
    """Circle A at the origin and a touching neighbour B at (2 r, 0): from the point of A at alpha from
    A's top towards B, B blocks the directions within asin(r / |HB|) of the direction to its centre;
    the open fraction of the half circle about A's normal is 1 - (that cone within the half circle) / pi."""
    r = 1.0
    cx, cy = np.array([0.0, 2.0 * r]), np.array([0.0, 0.0])
    a = math.radians(alpha_deg)
    n = np.array([math.sin(a), math.cos(a)])
    h = r * n
    v = np.array([cx[1], cy[1]]) - h
    phi = math.atan2(n[0] * v[1] - n[1] * v[0], n @ v)      # signed angle from n to the centre of B
    w = math.asin(r / np.linalg.norm(v))
    lo, hi = max(phi - w, -math.pi / 2), min(phi + w, math.pi / 2)
    exact = 1.0 - max(hi - lo, 0.0) / math.pi
    n_rays = 20000
    got = BT.open_fraction_circles(cx, cy, r, h[0], h[1], n[0], n[1], 0, n_rays)
    assert got == pytest.approx(exact, abs=2.0 / n_rays)
    assert exact < 1.0 or alpha_deg < 20


def test_packed_ring_is_partly_shadowed():
    """A ring of touching fibres inside the ply: every line meets it, the remapped shadowing lies in
    (thr, 1], is 1 on the fibres' tops (the ring is convex: nothing above a top) and below 1 in the
    notches between fibres."""
    tp = _tp()
    r = tp[M.FIBER_RADIUS]
    n = 24
    rho = r / math.sin(math.pi / n)          # neighbours touch
    assert rho + r < min(tp[M.E_SHORT], tp[M.E_LONG])
    ang = 2 * math.pi * np.arange(n) / n
    x, y = rho * np.cos(ang), rho * np.sin(ang)
    thr = 0.5
    table = BT.fibre_table_of(tp, x, y, 0.0, 720, 512, thr)
    s = table[:, IT.FIBRE_SHADOW]
    assert np.all(table[:, IT.FIBRE_PHASE] >= 0)
    assert np.all(s > thr) and np.all(s <= 1.0)
    assert s.max() == 1.0 and s.min() < 0.9


@njit(cache=True)
def ellipse_gauge(cx, cy, ca, sa, ar, at, k, px, py):
    a = (px - cx[k]) * ca[k] + (py - cy[k]) * sa[k]
    b = -(px - cx[k]) * sa[k] + (py - cy[k]) * ca[k]
    return (a / ar) ** 2 + (b / at) ** 2


@njit(cache=True)
def ply_shadow_brute_force(cx, cy, ca, sa, ar, at, R, phi, n_rays, step):
    """Open fraction at the outermost ply point on the radius at angle phi: point-in-ellipse marches."""
    P = cx.shape[0]
    ex, ey = math.cos(phi), math.sin(phi)
    hk = -1
    prev = 1.01 * R
    rr = prev
    while rr > -R and hk < 0:
        for k in range(P):
            if ellipse_gauge(cx, cy, ca, sa, ar, at, k, rr * ex, rr * ey) <= 1.0:
                hk = k
                break
        if hk < 0:
            prev = rr
            rr -= step
    lo, hi = rr, prev
    while hi - lo > 1e-15:
        mid = 0.5 * (lo + hi)
        if ellipse_gauge(cx, cy, ca, sa, ar, at, hk, mid * ex, mid * ey) <= 1.0:
            lo = mid
        else:
            hi = mid
    hx, hy = hi * ex, hi * ey
    qa = ((hx - cx[hk]) * ca[hk] + (hy - cy[hk]) * sa[hk]) / (ar * ar)
    qb = (-(hx - cx[hk]) * sa[hk] + (hy - cy[hk]) * ca[hk]) / (at * at)
    nx, ny = qa * ca[hk] - qb * sa[hk], qa * sa[hk] + qb * ca[hk]
    nn = math.sqrt(nx * nx + ny * ny)
    nx, ny = nx / nn, ny / nn
    free = 0
    for q in range(n_rays):
        beta = -0.5 * math.pi + math.pi * (q + 0.5) / n_rays
        dx = math.cos(beta) * nx - math.sin(beta) * ny
        dy = math.sin(beta) * nx + math.cos(beta) * ny
        blocked = False
        t = step
        while t < 3.0 * R and not blocked:
            for k in range(P):
                if k != hk and ellipse_gauge(cx, cy, ca, sa, ar, at, k, hx + t * dx, hy + t * dy) <= 1.0:
                    blocked = True
            t += step
        if not blocked:
            free += 1
    return free / n_rays


@pytest.mark.parametrize("name", ["cotton1", "polyester1"])
def test_ply_shadow_matches_point_in_ellipse_marches(name):
    """16 angles of the ply shadowing over one period 2 pi / P: the plies as the model's ellipses at z = 0
    (ply k at model.ply_frame(tp, k, 0)), a brute-force inward march to the first ply, then a march per
    direction over the outward half circle (64 rays) with a point-in-ellipse test of the other plies:
    the same remapped fraction (one grazing direction may differ); 1 on ply 0's outermost point, less
    in the crevice between two plies."""
    tp = _tp(name)
    P = int(tp[M.PLY_NUM])
    thr = 0.6
    table = BT.ply_shadow_table(tp, 16, 64, thr)
    ar, at = IP.ply_half_axes(tp)
    fr = [M.ply_frame(tp, k, 0.0) for k in range(P)]
    cx, cy, ca, sa = (np.array([f[i] for f in fr]) for i in range(4))
    R = IP.ply_envelope_radius(tp)
    for i in range(16):
        s = ply_shadow_brute_force(cx, cy, ca, sa, ar, at, R, 2 * math.pi * i / (16 * P), 64, min(ar, at) / 2000)
        assert table[i] == pytest.approx(s * (1 - thr) + thr, abs=1.01 * (1 - thr) / 64)
    assert table[0] == 1.0 and table[8] < 1.0


def test_single_ply_is_never_ply_shadowed():
    """One ply: no other ply can block, the ply shadowing is 1 everywhere."""
    assert np.all(BT.ply_shadow_table(_tp(ply_num=1), 32, 64, 0.6) == 1.0)


def test_tables_are_deterministic():
    """The same type and key give the same bytes; another key another fibre sample (same ply shadowing);
    cotton1's packed plies leave no line without a fibre; the values lie in their ranges."""
    tp = _tp()
    a = BT.build_implicit_tables(tp, KEY, n_angles=64, n_rays=64)
    b = BT.build_implicit_tables(tp, KEY, n_angles=64, n_rays=64)
    c = BT.build_implicit_tables(tp, KEY + np.uint64(1), n_angles=64, n_rays=64)
    assert a.fibre_table.tobytes() == b.fibre_table.tobytes() and a.ply_shadow.tobytes() == b.ply_shadow.tobytes()
    assert not np.array_equal(a.fibre_table, c.fibre_table) and np.array_equal(a.ply_shadow, c.ply_shadow)
    F = a.fibre_table
    assert F.shape == (4, 64, IT.FIBRE_FIELDS)
    assert np.all(F[..., IT.FIBRE_PHASE] > 0) and np.all(F[..., IT.FIBRE_PHASE] < 1)
    assert np.all(np.abs(F[..., IT.FIBRE_NORMAL_ANGLE]) < math.pi)
    assert np.all((F[..., IT.FIBRE_SHADOW] >= 0.5) & (F[..., IT.FIBRE_SHADOW] <= 1.0))
    assert not np.array_equal(F[0], F[1])   # distinct arrangements
    assert a.switch_length == pytest.approx(tp[M.ALPHA] / (tp[M.S_MIG] * 4))


def test_lookups_are_periodic_in_the_angle():
    """fibre_lookup(psi) = fibre_lookup(psi + 2 pi) and ply_shadow_lookup(phi) = ply_shadow_lookup(phi + 2 pi
    / P) at random z; the ply shadowing turns with ply 0: at z, angle + model.ply_angle(tp, 0, z) reads what
    angle reads at z = 0."""
    tp = _tp()
    tab = BT.build_implicit_tables(tp, KEY, n_angles=64, n_rays=32)
    rng = np.random.default_rng(5)
    P = tp[M.PLY_NUM]
    for _ in range(200):
        psi, z, k = rng.uniform(-10, 10), rng.uniform(0, 5), int(rng.integers(3))
        a = IT.fibre_lookup(tab, tp, 77, k, psi, z)
        b = IT.fibre_lookup(tab, tp, 77, k, psi + 2 * math.pi, z)
        assert np.allclose(a, b, atol=1e-12, rtol=0)
        assert IT.ply_shadow_lookup(tab, tp, psi + 2 * math.pi / P, z) == pytest.approx(
            IT.ply_shadow_lookup(tab, tp, psi, z), abs=1e-12)
        assert IT.ply_shadow_lookup(tab, tp, psi + M.ply_angle(tp, 0, z), z) == pytest.approx(
            IT.ply_shadow_lookup(tab, tp, psi, 0.0), abs=1e-12)


def test_fibre_lookup_switches_tables_continuously():
    """Along z at a fixed fibre-pattern angle (psi = theta + model.fiber_twist(z), so the pattern turns
    with the fibres): between blends the lookup reads one table exactly (linear interpolation of the
    stored samples at u = theta / 2 pi); across a switch it changes by at most the two tables'
    difference times dz / blend_length per step (continuous); over 40 switch lengths it switches and
    uses every table; a different yarn key switches differently."""
    tp = _tp()
    tab = BT.build_implicit_tables(tp, KEY, n_angles=64, n_rays=32)
    F = tab.fibre_table
    theta = 1.234
    x = theta / (2 * math.pi) * 64
    i0, f = int(x), x - int(x)
    interp = (1 - f) * F[:, i0] + f * F[:, (i0 + 1) % 64]           # (M, fields) per table
    L, B = tab.switch_length, tab.blend_length
    zs = np.linspace(0.0, 40 * L, 40001)
    dz = zs[1] - zs[0]
    vals = np.array([IT.fibre_lookup(tab, tp, 77, 1, theta + M.fiber_twist(tp, z), z) for z in zs])
    spread = np.ptp(interp[:, [IT.FIBRE_NORMAL_ANGLE, IT.FIBRE_SHADOW]], axis=0)
    jumps = np.abs(np.diff(vals[:, [0, 2]], axis=0)).max(axis=0)
    assert np.all(jumps <= spread * dz / B * 1.001 + 1e-12)
    used = set()
    for z, v in zip(zs, vals, strict=True):
        m0, _, w = IT.table_blend(tab, 77, 1, z)
        if w == 0.0:
            assert v[0] == pytest.approx(interp[m0, IT.FIBRE_NORMAL_ANGLE], abs=1e-12)
            assert v[2] == pytest.approx(interp[m0, IT.FIBRE_SHADOW], abs=1e-12)
            used.add(m0)
    assert used == set(range(tab.n_tables))
    other = np.array([IT.fibre_lookup(tab, tp, 78, 1, theta + M.fiber_twist(tp, z), z) for z in zs[::100]])
    assert not np.array_equal(other, vals[::100])


def model_fibre(tp, k, z, psi, U, zz):
    """Yarn-space point at height zz of the model fibre at unit-disc radius U that passes angle psi at z."""
    p = psi + M.fiber_twist(tp, zz - z)
    xy = M.ply_to_yarn(tp, k, zz, U * tp[M.E_SHORT] * math.cos(p), U * tp[M.E_LONG] * math.sin(p))
    return np.array([xy[0], xy[1], zz])


def test_fibre_frame_is_orthonormal_and_follows_the_model_fibres():
    """At ply hits of random rays (cotton1 and rayon1, whose plies turn the other way): the fibre frame is
    orthonormal; the normal is the ply normal turned about the ply tangent by the normal angle (exactly
    the ply normal at angle 0); the tangent at angle 0 is the direction of the model's outer fibre
    through the hit, the central difference along z of model.ply_to_yarn(U e_short cos psi(z),
    U e_long sin psi(z)) with psi(z) turning by the fibre twist, made orthogonal to the normal."""
    for name in ("cotton1", "rayon1"):
        tp = _tp(name)
        R = IP.ply_envelope_radius(tp)
        rng = np.random.default_rng(8)
        U = tp[M.RHO_MAX] * tp[M.R_MAX]
        n = 0
        while n < 50:
            ph = rng.uniform(0, 2 * math.pi)
            o = np.array([R * math.cos(ph), R * math.sin(ph), rng.uniform(0, 1)])
            d = -o * np.array([1, 1, 0]) + rng.normal(size=3) * 0.01
            h = IP.ply_hit(tp, o, d, 2.0, 1e-4, 8)
            if not h.hit:
                continue
            n += 1
            k, z, psi = h.ply, h.point[2], h.ply_angle
            beta = rng.uniform(-1.5, 1.5)
            t, nn = (np.array(v) for v in IT.fibre_frame(tp, k, z, psi, h.tangent, h.normal, beta))
            assert np.linalg.norm(t) == pytest.approx(1, abs=1e-12)
            assert np.linalg.norm(nn) == pytest.approx(1, abs=1e-12)
            assert abs(t @ nn) < 1e-12
            pt, pn = np.array(h.tangent), np.array(h.normal)
            assert nn @ pn == pytest.approx(math.cos(beta), abs=1e-12)
            assert np.cross(pn, nn) @ pt == pytest.approx(math.sin(beta), abs=1e-12)
            t0, n0 = (np.array(v) for v in IT.fibre_frame(tp, k, z, psi, h.tangent, h.normal, 0.0))
            assert np.allclose(n0, pn, atol=1e-12)
            e = 1e-6
            v = model_fibre(tp, k, z, psi, U, z + e) - model_fibre(tp, k, z, psi, U, z - e)
            v -= (v @ n0) * n0
            assert np.allclose(t0, v / np.linalg.norm(v), atol=1e-7)
