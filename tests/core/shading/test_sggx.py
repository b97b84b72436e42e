"""SGGX micro-flake phase function (Heitz et al. 2015): normalisation, reciprocity, exact sampling.

References: closed forms (S = I: D = 1/pi, f = 1/(4 pi)); Heitz 2015 Eq. 5 (projected area is the
integral of <w, m>^+ D(m)) by quadrature; the shared chi-square harness (tests/chisquare.py) for
sampling against evaluation.
"""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.shading.sggx import fiber_sggx, ndf, phase_eval, projected_area, sggx_eval, sggx_pdf, sggx_sample
from tests.chisquare import bin_integrals, check_shading_model, xy_to_directions

CASES = [  # (tangent, roughness, wi)
    ((0.0, 0.0, 1.0), 1.0, (0.3, -0.4, 0.866)),
    ((0.3, 0.5, 0.8), 0.6, (0.6, -0.2, 0.3)),
    ((1.0, 0.0, 0.0), 0.3, (0.2, 0.9, -0.4)),
    ((0.0, 0.7, 0.7), 0.3, (0.0, 0.7, 0.7)),  # wi along the fibre: the cone degenerates to a ring
]


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


@njit
def _ndf_many(S, m):
    out = np.empty(m.shape[0])
    for k in range(m.shape[0]):
        out[k] = ndf(S, m[k, 0], m[k, 1], m[k, 2])
    return out


def test_isotropic_closed_form():
    """S = I (roughness 1): D = 1/pi, sigma = 1, f = 1/(4 pi) for every pair."""
    S = fiber_sggx(0.0, 0.6, 0.8, 1.0)
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b = _unit(rng.normal(size=3)), _unit(rng.normal(size=3))
        assert ndf(S, *a) == pytest.approx(1.0 / math.pi, rel=1e-12)
        assert projected_area(S, *a) == pytest.approx(1.0, rel=1e-12)
        assert phase_eval(S, *a, *b) == pytest.approx(0.25 / math.pi, rel=1e-12)


@pytest.mark.parametrize("t, rough, wi", CASES[1:3])
def test_projected_area_is_ndf_integral(t, rough, wi):
    """Heitz 2015 Eq. 5: sigma(w) = integral over the sphere of <w, m>^+ D(m), by Gauss-Legendre."""
    t = _unit(t)
    w = _unit(wi)
    S = fiber_sggx(*t, rough)

    def integrand(x, y):
        m = xy_to_directions(x, y, axis=t)
        return np.maximum(m @ w, 0.0) * _ndf_many(S, np.ascontiguousarray(m))

    val = bin_integrals(integrand, ((-1, 1), (-math.pi, math.pi)), (200, 64), sub=6).sum()
    assert val == pytest.approx(projected_area(S, *w), rel=2e-3)


@pytest.mark.parametrize("t, rough, wi", CASES)
def test_phase_reciprocity(t, rough, wi):
    """sigma(wi) f(wi, wo) = sigma(wo) f(wo, wi): the medium's scattering kernel is symmetric."""
    S = fiber_sggx(*_unit(t), rough)
    rng = np.random.default_rng(7)
    for _ in range(50):
        a, b = _unit(rng.normal(size=3)), _unit(rng.normal(size=3))
        lhs = projected_area(S, *a) * phase_eval(S, *a, *b)
        rhs = projected_area(S, *b) * phase_eval(S, *b, *a)
        assert lhs == pytest.approx(rhs, rel=1e-10, abs=1e-300)


@pytest.mark.parametrize("t, rough, wi", CASES)
def test_phase_sampling_chi_square(t, rough, wi):
    """Visible-normal sampling through the uniform interface (sggx_sample / sggx_pdf / sggx_eval, p = (sigma,))
    and the shading adapter (tests/chisquare.py: check_shading_model): at every sample weight == eval / pdf
    (= 1, so pdf == eval: exact sampling) and pdf(sample) == returned pdf; then the chi-square of 200k samples against
    the pdf; the density integrates to 1 over the sphere (checked inside the harness). Parameterised
    about the fibre axis: the specular cone of a fibre is a circle of constant cos theta."""
    t = _unit(t)
    res = check_shading_model(sggx_sample, sggx_pdf, sggx_eval, np.array([rough]), t, _unit(wi), angles="cos",
                              n=200_000, seed=11, res=(60, 40), n_tests=len(CASES), n_contract=200_000)
    assert res.passed, res.message
