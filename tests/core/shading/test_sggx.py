"""SGGX micro-flake phase function (Heitz et al. 2015): normalisation, reciprocity, exact sampling.

References: closed forms (S = I: D = 1/pi, f = 1/(4 pi)); Heitz 2015 Eq. 5 (projected area is the
integral of <w, m>^+ D(m)) by quadrature; the shared chi-square harness (tests/chisquare.py) for
sampling against evaluation.
"""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.shading.sggx import fiber_sggx, ndf, phase_eval, phase_sample, projected_area
from tests.chisquare import bin_integrals, chi2_test, directions_to_xy, xy_to_directions

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
def _sample_many(S, wi, u):
    out = np.empty((u.shape[0], 4))
    for k in range(u.shape[0]):
        x, y, z, p = phase_sample(S, wi[0], wi[1], wi[2], u[k, 0], u[k, 1])
        out[k, 0] = x
        out[k, 1] = y
        out[k, 2] = z
        out[k, 3] = p
    return out


@njit
def _eval_many(S, wi, wo):
    out = np.empty(wo.shape[0])
    for k in range(wo.shape[0]):
        out[k] = phase_eval(S, wi[0], wi[1], wi[2], wo[k, 0], wo[k, 1], wo[k, 2])
    return out


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
    """Visible-normal sampling draws directions with density phase_eval (chi-square, shared harness);
    the density integrates to 1 over the sphere (checked inside the harness); pdf == eval."""
    t = _unit(t)
    wi = _unit(wi)
    S = fiber_sggx(*t, rough)
    n = 200_000
    u = np.random.default_rng(11).random((n, 2))
    s = _sample_many(S, wi, u)
    wo = s[:, :3]
    assert np.allclose(np.linalg.norm(wo, axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(s[:, 3], _eval_many(S, wi, np.ascontiguousarray(wo)), rtol=1e-9)
    # parameterise about the fibre axis: the specular cone of a fibre is a circle of constant cos theta
    xy = directions_to_xy(wo, axis=t)

    def pdf_xy(x, y):
        return _eval_many(S, wi, np.ascontiguousarray(xy_to_directions(x, y, axis=t)))

    res = chi2_test(xy, pdf_xy, bounds=((-1, 1), (-math.pi, math.pi)), res=(60, 40), n_tests=len(CASES))
    assert res.passed, res.message
