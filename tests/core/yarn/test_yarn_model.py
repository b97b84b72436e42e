"""The procedural yarn model (seed 000 §3.2): presets, scaling, cross-section sampling, loops, hair tree.

References: the published preset numbers (../shared/reference/yarn-presets.toml), Eq. 3 (chi-square of
the rejection sampler), the similarity rule of pipeline/presets.py (closed form), the product
distribution of hair extents (chi-square of Algorithm 3's tree) and brute-force filtering of all
hairs (Algorithm 3's active sets).
"""
import math
import tomllib

import numpy as np
import pytest
from scipy import integrate, stats

from pipeline import presets
from pipeline.errors import LoomError
from stages.core.yarn import hair_free, model as M
from tests.chisquare import chi2_test
from tests.helpers import shared_file

NAMES = ["cotton1", "cotton2", "polyester1", "rayon1", "rayon2", "rayon3", "rayon4", "silk1", "silk2"]


def test_nine_presets_ship_and_pass_the_schema():
    assert presets.list_presets() == NAMES
    for name in NAMES:
        d = presets.load_preset(name)
        # the derived fibre radius fills PACKING_FRACTION of the ply's elliptical cross-section
        fill = d["fiber_num"] * d["fiber_radius"] ** 2 / (d["ellipse_long"] * d["ellipse_short"])
        assert fill == pytest.approx(presets.PACKING_FRACTION, rel=1e-12)
        assert 0.0001 <= d["fiber_radius"] <= 0.004
        assert d["rho_max"] == 1.0 and d["R_max"] == 1.0


def test_preset_numbers_match_the_published_sets():
    ref = tomllib.loads(shared_file("reference/yarn-presets.toml").read_text())
    for name in NAMES:
        d = presets.load_preset(name)
        for k, v in ref[name].items():
            assert d[k] == v, (name, k)


def _tp(name="cotton1", **over):
    d = presets.load_preset(name)
    d.update(over)
    return presets.pack(d)


def test_scaling_is_a_similarity():
    """Every fibre of a preset scaled by S sits at S times the unscaled position at S times the z."""
    d = presets.load_preset("rayon2")
    S = 2.5
    a = presets.pack(d)
    b = presets.pack(presets.scale_preset(d, d["yarn_radius"] * S))
    R, th, th0 = M.sample_regular_fibers(a, np.uint64(3))
    R2, th2, th02 = M.sample_regular_fibers(b, np.uint64(3))
    assert np.array_equal(R, R2) and np.array_equal(th, th2)
    for z in (0.0, 0.137, 0.9):
        for k in range(2):
            for j in range(0, 79, 13):
                x, y, _ = M.regular_xy(a, np.uint64(5), k, j, R[k, j], th[k, j], th0[k, j], z)
                xs, ys, _ = M.regular_xy(b, np.uint64(5), k, j, R[k, j], th[k, j], th0[k, j], z * S)
                assert xs == pytest.approx(S * x, rel=1e-9, abs=1e-12)
                assert ys == pytest.approx(S * y, rel=1e-9, abs=1e-12)
    assert b[M.HAIR_DENSITY] == pytest.approx(a[M.HAIR_DENSITY] / S)
    assert b[M.FIBER_RADIUS] == pytest.approx(a[M.FIBER_RADIUS] * S)


def test_cross_section_sampling_follows_eq3():
    """Rejection sampling of Eq. 3 on the unit disc: density of (R, theta) is R p(R) / Z."""
    tp = _tp("polyester1", fiber_num=20000, ply_num=1)
    R, th, _ = M.sample_regular_fibers(tp, np.uint64(11))
    eps, beta = tp[M.EPSILON], tp[M.BETA]
    def p(r):
        return (1 - 2 * eps) * np.clip((math.e - np.exp(r)) / (math.e - 1), 0, None) ** beta + eps

    Z = integrate.quad(lambda r: r * p(r), 0, 1)[0] * 2 * math.pi
    res = chi2_test(np.stack([R[0], th[0]], axis=1), lambda x, y: x * p(x) / Z,
                    bounds=((0.0, 1.0), (0.0, 2 * math.pi)), res=(20, 8))
    assert res.passed, res.message


def test_ply_and_fibre_geometry():
    """Ply centres at yarn_radius / 2; a fibre with R = 1 at its migration maximum lies on the ellipse."""
    tp = _tp("cotton1")
    cx, cy, drx, dry = M.ply_frame(tp, 1, 0.0)
    assert math.hypot(cx, cy) == pytest.approx(0.5 * tp[M.YARN_RADIUS])
    assert math.atan2(cy, cx) == pytest.approx(2 * math.pi / 3)
    th0 = 0.3
    z = -th0 * tp[M.ALPHA] / (tp[M.S_MIG] * 2 * math.pi) + 5 * tp[M.ALPHA] / tp[M.S_MIG]  # phase = 10 pi
    tp[M.P_LOOP] = 0.0
    x, y, kind = M.regular_xy(tp, np.uint64(0), 0, 0, 1.0, 0.7, th0, z)
    cx, cy, drx, dry = M.ply_frame(tp, 0, z)
    a = (x - cx) * drx + (y - cy) * dry
    b = -(x - cx) * dry + (y - cy) * drx
    assert kind == 1
    assert (a / tp[M.E_SHORT]) ** 2 + (b / tp[M.E_LONG]) ** 2 == pytest.approx(1.0, rel=1e-9)
    psi = math.atan2(b / tp[M.E_LONG], a / tp[M.E_SHORT])
    assert math.cos(psi - (0.7 + M.fiber_twist(tp, z))) == pytest.approx(1.0)


def test_loop_cycles_are_continuous_and_reach_r1():
    """A mutated cycle starts and ends at rho_min R_j (continuity) and reaches U_loop at its maximum."""
    tp = _tp("rayon4")
    tp[M.P_LOOP] = 1.0
    Rj, th, th0 = 0.8, 1.1, 0.4
    found = 0
    for c in range(1, 30):
        U = M.loop_unit_radius(tp, np.uint64(9), 0, 3, Rj, th, th0, c)
        if U < 0:
            continue
        found += 1
        zc = (2 * math.pi * c - th0) * tp[M.ALPHA] / (tp[M.S_MIG] * 2 * math.pi)
        half = 0.5 * tp[M.ALPHA] / tp[M.S_MIG]
        for z in (zc - half + 1e-12, zc + half - 1e-12):
            u, _ = M.fiber_unit_radius(tp, np.uint64(9), 0, 3, Rj, th, th0, z)
            assert u == pytest.approx(tp[M.RHO_MIN] * Rj, rel=1e-6)
        u, kind = M.fiber_unit_radius(tp, np.uint64(9), 0, 3, Rj, th, th0, zc)
        assert kind == 2 and u == pytest.approx(U)
        assert U <= tp[M.U_MAX] + 1e-12
    assert found > 5


def test_loop_frequency_matches_density():
    """Mutated cycles per unit length per ply = loop density, less the rejected (r1 <= 1.05 r) ones."""
    tp = _tp("cotton1", use_flyaways=1)
    R, th, th0 = M.sample_regular_fibers(tp, np.uint64(2))
    L = 40.0
    n_cyc = 0
    n_mut = 0
    for j in range(R.shape[1]):
        c0 = M.cycle_of(M.migration_phase(tp, th0[0, j], 0.0))
        c1 = M.cycle_of(M.migration_phase(tp, th0[0, j], L))
        for c in range(c0 + 1, c1):
            n_cyc += 1
            n_mut += M.loop_unit_radius(tp, np.uint64(4), 0, j, R[0, j], th[0, j], th0[0, j], c) > 0
    expected = tp[M.P_LOOP] * n_cyc
    assert n_mut <= expected + 4 * math.sqrt(expected)
    assert n_mut > 0.2 * expected


def test_hair_tree_draws_the_product_distribution():
    """Algorithm 3's tree: (z1, ze) uniform x N(mu, sigma) truncated at 3 sigma (chi-square)."""
    L, n, mu, sig = 2.0, 20000, 0.01, 0.04
    z1, ze = hair_free.all_hairs(L, n, mu, sig, np.uint64(77))
    raw_ze = ze
    inside = (z1 + ze > 0) & (z1 + ze < L)  # clamping at the yarn ends changes ze only there
    z = 3.0
    norm = stats.norm.cdf(z) - stats.norm.cdf(-z)
    def pdf(x, y):
        return (1.0 / L) * stats.norm.pdf((y - mu) / sig) / (sig * norm)

    xy = np.stack([z1[inside], raw_ze[inside]], axis=1)
    # condition on the un-clamped region {0 < z1 + ze < L}: its mass under the product density
    def F(v):
        return (stats.norm.cdf(np.clip((v - mu) / sig, -z, z)) - stats.norm.cdf(-z)) / norm

    p_in = integrate.quad(lambda x: (F(L - x) - F(-x)) / L, 0.0, L, limit=200)[0]
    res = chi2_test(xy, lambda x, y: pdf(x, y) * ((x + y > 0) & (x + y < L)) / p_in,
                    bounds=((0.0, L), (mu - z * sig, mu + z * sig)), res=(10, 12))
    assert res.passed, res.message


def test_hair_tree_active_sets_equal_brute_force():
    """ACTIVEFIBERS(z) = {j : z in [min(z1, z2) - m, max(z1, z2) + m]} over all hairs (hybrid pre-generation)."""
    L, n, mu, sig, m = 1.5, 300, 0.002, 0.05, 0.001
    seed = np.uint64(123)
    z1, ze = hair_free.all_hairs(L, n, mu, sig, seed)
    lo = np.minimum(z1, z1 + ze) - m
    hi = np.maximum(z1, z1 + ze) + m
    idx = np.empty(n, np.int64)
    a1 = np.empty(n)
    ae = np.empty(n)
    for z in np.linspace(-0.01, L + 0.01, 157):
        k = hair_free.active_hairs(L, n, mu, sig, seed, z, m, idx, a1, ae)
        want = np.nonzero((lo <= z) & (z <= hi))[0]
        assert np.array_equal(idx[:k], want)
        assert np.array_equal(a1[:k], z1[want]) and np.array_equal(ae[:k], ze[want])


@pytest.mark.parametrize("key,value,place", [
    ("ply_num", 0, "ply_num"), ("fiber_num", 0, "fiber_num"), ("rho_min", 1.5, "rho_min"),
    ("flyaway_hair_density", -1.0, "flyaway_hair_density"), ("flyaway_loop_density", -2.0, "flyaway_loop_density"),
    ("density", -1.0, "density"), ("yarn_radius", 0.0, "yarn_radius"),
])
def test_bad_preset_values_name_the_parameter(key, value, place):
    d = presets.load_preset("cotton1")
    d[key] = value
    with pytest.raises(LoomError) as e:
        presets.check_preset(d, "x.toml")
    assert place in e.value.one_line()


def test_unknown_preset_and_bad_radius():
    with pytest.raises(LoomError, match="unknown preset 'wool9'"):
        presets.load_preset("wool9")
    with pytest.raises(LoomError, match="radius"):
        presets.scale_preset(presets.load_preset("silk1"), -0.1)
    with pytest.raises(LoomError, match="--radius"):
        presets.resolve_yarn_types([{}], [0.03], radius=0.0)
