"""Counter-based random numbers (stages/core/rng.py) and the yarn model's clamped normals
(stages/core/yarn/model.py: clamped_normal), through the chi-square harness (tests/chisquare.py).

References: pairs (uniform(s, i, 0), uniform(s, i, 1)) are uniform on the unit square, and pairs of
normal variates from disjoint dimensions (normal(s, i, 0), normal(s, i, 2)) mapped by the standard normal
CDF Phi are too (Box-Muller exact, dimensions independent) -- chi-square against the constant density;
clamped_normal is normal clamped to +-3 (closed form).
"""
import numpy as np
from numba import njit
from scipy import stats

from stages.core.rng import normal, uniform
from stages.core.yarn.model import CLAMP, clamped_normal
from tests.chisquare import chi2_test

UNIT = ((0.0, 1.0), (0.0, 1.0))


@njit
def _draw(n, seed):
    u = np.empty((n, 2))
    z = np.empty((n, 2))
    c = np.empty(n)
    for i in range(n):
        u[i, 0] = uniform(seed, i, 0)
        u[i, 1] = uniform(seed, i, 1)
        z[i, 0] = normal(seed, i, 0)
        z[i, 1] = normal(seed, i, 2)
        c[i] = clamped_normal(seed, i, 0)
    return u, z, c


def test_uniform_and_normal_pairs_chi2():
    """Reference: the constant density on the unit square for (u0, u1) and (Phi(z0), Phi(z2)); 200k pairs,
    40 x 40 bins, Šidák over 2."""
    u, z, c = _draw(200_000, 31)
    def ones(x, y):
        return np.ones_like(x)

    res = chi2_test(u, ones, UNIT, res=(40, 40), n_tests=2)
    assert res.passed, "uniform: " + res.message
    res = chi2_test(stats.norm.cdf(z), ones, UNIT, res=(40, 40), n_tests=2)
    assert res.passed, "normal: " + res.message
    np.testing.assert_array_equal(c, np.clip(z[:, 0], -CLAMP, CLAMP))


def test_harness_rejects_a_scaled_normal():
    """The test must fail: normal variates scaled by 1.02 are not standard normal."""
    _, z, _ = _draw(200_000, 31)
    res = chi2_test(stats.norm.cdf(1.02 * z), lambda x, y: np.ones_like(x), UNIT, res=(40, 40))
    assert not res.passed, res.message
