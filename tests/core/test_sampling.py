"""``stages.core.sampling``: the power heuristic and Russian roulette every integrator shares.

References: the power heuristic's weights of two strategies sum to one (Veach 1997, Eq. 9.13), so a
multi-sample MIS estimator is unbiased — checked against an integral known in closed form; Russian
roulette divided by its survival probability is unbiased — checked against the throughput it replaces,
within the Monte Carlo error; the escape term of the fibre integrators against a brute-force sum.
"""
import math

import numpy as np
from numba import njit

from stages.core.rng import uniform
from stages.core.sampling import NO_HIT, RR_MAX_SURVIVAL, power_heuristic, roulette_survival


def test_power_heuristic_partition_of_unity():
    rng = np.random.default_rng(3)
    for a, b in rng.uniform(1e-6, 1e3, (200, 2)):
        assert abs(power_heuristic(a, b) + power_heuristic(b, a) - 1.0) < 1e-15
        assert power_heuristic(a, b) == a * a / (a * a + b * b)
    assert power_heuristic(0.0, 1.0) == 0.0
    assert power_heuristic(0.0, 0.0) == 0.0    # a strategy of density 0 gets no weight, not nan
    assert power_heuristic(2.0, 0.0) == 1.0


@njit(cache=True)
def _mis_estimate(n, seed):
    """Mean and standard error of the two-strategy MIS estimate of int_0^1 x^2 dx = 1/3: one sample from
    p1 = 1 (uniform) and one from p2 = 2x (inverse CDF sqrt(u)) per trial, each weighted by the power
    heuristic against the other strategy's density."""
    s = 0.0
    s2 = 0.0
    for i in range(n):
        x1 = uniform(seed, i, 0)
        x2 = math.sqrt(uniform(seed, i, 1))
        e = 0.0
        e += power_heuristic(1.0, 2.0 * x1) * x1 * x1 / 1.0
        if x2 > 0.0:
            e += power_heuristic(2.0 * x2, 1.0) * x2 * x2 / (2.0 * x2)
        s += e
        s2 += e * e
    m = s / n
    return m, math.sqrt(max(s2 / n - m * m, 0.0) / n)


def test_mis_with_the_power_heuristic_is_unbiased():
    mean, se = _mis_estimate(400_000, 11)
    assert abs(mean - 1.0 / 3.0) < 4.0 * se, (mean, se)
    assert se < 1e-3


def test_roulette_survival_is_the_capped_largest_channel():
    assert roulette_survival(0.2, 0.7, 0.4) == 0.7
    assert roulette_survival(3.0, 0.1, 0.1) == RR_MAX_SURVIVAL   # every path can end
    assert roulette_survival(0.0, 0.0, 0.0) == 0.0


@njit(cache=True)
def _roulette_mean(tp, n, seed):
    """Mean and standard error of the rouletted throughput: tp / q when the path survives, else 0."""
    q = roulette_survival(tp[0], tp[1], tp[2])
    s = 0.0
    s2 = 0.0
    for i in range(n):
        e = tp[0] / q if uniform(seed, i, 3) < q else 0.0
        s += e
        s2 += e * e
    m = s / n
    return m, math.sqrt(max(s2 / n - m * m, 0.0) / n)


def test_russian_roulette_is_unbiased():
    for tp in ([0.3, 0.1, 0.05], [0.9, 2.0, 0.5], [0.02, 0.02, 0.02]):
        mean, se = _roulette_mean(np.array(tp), 200_000, 5)
        assert abs(mean - tp[0]) < 4.0 * se + 1e-12, (tp, mean, se)


def test_no_hit_is_finite_and_beyond_any_scene():
    assert math.isfinite(NO_HIT) and NO_HIT * 0.0 == 0.0
    assert NO_HIT > 1e6 ** 2    # pipeline.limits bounds coordinates to 1e6: no squared distance reaches it


def test_escaped_radiance_is_the_weighted_sum_over_lights():
    """``stages.render.lights.add_escaped_radiance`` against the brute-force sum of light_eval x the power
    heuristic of light_pdf, for a constant environment plus a spherical Gaussian (a directional light adds
    nothing to an escaping ray)."""
    from stages.render.lights import (
        LightTable,
        add_escaped_radiance,
        envmap_tables,
        light_eval,
        light_pdf,
        pack_light,
    )

    lights = np.stack([pack_light("constant", (0.5, 0.6, 0.7)),
                       pack_light("sg", (2.0, 1.0, 0.5), (0.0, 0.3, 0.95), 12.0),
                       pack_light("directional", (3.0, 3.0, 3.0), (0.0, 0.0, -1.0))])
    env, marg, cond = envmap_tables()
    table = LightTable(lights, env, marg, cond)
    d = np.array([0.1, 0.25, 0.96])
    d /= np.linalg.norm(d)
    tp = (0.8, 0.5, 0.3)
    for mis, pdf_prev in ((False, 0.0), (True, 0.4)):
        want = np.array([0.01, 0.02, 0.03])
        for k in range(len(lights)):
            rgb = np.array(light_eval(lights, k, env, marg, cond, d))
            w = 1.0
            if mis:
                pl = light_pdf(lights, k, env, marg, cond, d)
                w = pdf_prev ** 2 / (pdf_prev ** 2 + pl ** 2)
            want += np.array(tp) * rgb * w
        got = add_escaped_radiance(table, d, mis, pdf_prev, *tp, 0.01, 0.02, 0.03)
        np.testing.assert_allclose(got, want, rtol=1e-14)
        assert got[0] > 0.01 + 0.8 * 0.5 * (0.5 if mis else 0.99)   # the environment reached it
