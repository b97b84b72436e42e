"""Lambertian surface (stages/core/shading/lambert.py): the closed form rho / pi max(0, n . wo) and its
cosine-weighted sampler through the shading adapter (tests/chisquare.py: check_shading_model), which
must also reject a sampler that breaks its distribution or its weight."""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.shading.lambert import lambert_eval, lambert_pdf, lambert_sample
from tests.chisquare import check_shading_model

NRM = np.array([0.6, 0.0, -0.8])
ALB = np.array([0.2, 0.5, 0.9])
WI = np.array([0.0, 0.6, -0.8])


def test_lambert_closed_form():
    """Reference: f cos = rho / pi max(0, n . wo) and pdf = max(0, n . wo) / pi (closed form)."""
    rng = np.random.default_rng(4)
    for _ in range(200):
        wo = rng.normal(size=3)
        wo /= np.linalg.norm(wo)
        c = max(0.0, float(NRM @ wo))
        np.testing.assert_allclose(lambert_eval(ALB, NRM, WI, wo), ALB * c / math.pi, rtol=1e-14, atol=1e-300)
        assert lambert_pdf(ALB, NRM, WI, wo) == pytest.approx(c / math.pi, rel=1e-14, abs=0.0)


def test_lambert_fibre_sampling_chi2():
    """Reference: the shading adapter: chi-square of 200k cosine-weighted samples about the surface
    normal against lambert_pdf (= cos / pi, closed form above); weight == eval / pdf (= albedo exactly)
    and pdf(sample) == returned pdf at every sample."""
    res = check_shading_model(lambert_sample, lambert_pdf, lambert_eval, ALB, NRM, WI, angles="cos",
                              n=200_000, seed=3, res=(40, 40), n_contract=200_000, rtol=1e-12)
    assert res.passed, res.message


@njit
def _skewed_sample(p, n, wi, u0, u1, u2):
    """A wrong sampler with a consistent contract: u1 -> u1^1.1 bends the distribution towards the
    normal, while the returned pdf and weight are lambert's at the sampled direction."""
    return lambert_sample(p, n, wi, u0, u1 ** 1.1, u2)


@njit
def _heavy_sample(p, n, wi, u0, u1, u2):
    """A right distribution with a wrong weight (1 % too bright)."""
    wo, r, g, b, pdf = lambert_sample(p, n, wi, u0, u1, u2)
    return wo, 1.01 * r, g, b, pdf


def test_adapter_rejects_wrong_samplers():
    """The adapter must fail: a distribution 10 % off in one uniform (chi-square), and a weight that is not
    eval / pdf (contract)."""
    res = check_shading_model(_skewed_sample, lambert_pdf, lambert_eval, ALB, NRM, WI, n=200_000, seed=3,
                              res=(40, 40))
    assert not res.passed and res.message.startswith("chi2"), res.message
    res = check_shading_model(_heavy_sample, lambert_pdf, lambert_eval, ALB, NRM, WI, n=2_000, seed=3,
                              res=(10, 10))
    assert not res.passed and "weight" in res.message, res.message
