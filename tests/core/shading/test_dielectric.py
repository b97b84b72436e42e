"""The rough dielectric surface of ``stages.core.shading.microfacet`` (``rough_dielectric_eval`` and
``rough_dielectric_sample``; the meshes' ``dielectric`` material). References: the shared chi-square harness
(tests/chisquare.py: check_shading_model, which also checks weight == eval / pdf and pdf(sample) == pdf) from
either side of the interface (eta 1.5: entering glass, 1 / 1.5: leaving it, with total internal reflection);
the smooth limit against Fresnel's equations (reflectance 0.04 at normal incidence, nothing lost); and the
radiance form's 1 / eta^2 on refraction."""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.rng import uniform
from stages.core.shading.microfacet import rough_dielectric_eval, rough_dielectric_sample
from tests.chisquare import check_shading_model


# the shading interface of tests/chisquare.py: p = (alpha, eta), frame = the surface normal (the local z)
@njit
def _sample(p, frame, wi, u0, u1, u2):
    ok, x, y, z, w, pdf = rough_dielectric_sample(wi[0], wi[1], wi[2], p[0], p[1], u0, u1, u2)
    wo = np.array([x, y, z])
    if not ok:
        return wo, 0.0, 0.0, 0.0, 0.0
    return wo, w, w, w, pdf


@njit
def _pdf(p, frame, wi, wo):
    return rough_dielectric_eval(wi[0], wi[1], wi[2], wo[0], wo[1], wo[2], p[0], p[1])[1]


@njit
def _eval(p, frame, wi, wo):
    v = rough_dielectric_eval(wi[0], wi[1], wi[2], wo[0], wo[1], wo[2], p[0], p[1])[0]
    return v, v, v


CASES = [(eta, alpha, theta) for eta in (1.5, 1.0 / 1.5) for alpha in (0.1, 0.4) for theta in (0.3, 1.1)]


@pytest.mark.parametrize("eta,alpha,theta", CASES)
def test_sampling_matches_its_density_chi2(eta, alpha, theta):
    """200k samples against the density over the whole sphere (reflection above, refraction below), Šidák over
    the 8 cases; the contract of every sample (weight = value / pdf, pdf(sample) = its pdf)."""
    wi = np.array([math.sin(theta), 0.0, math.cos(theta)])
    res = check_shading_model(_sample, _pdf, _eval, np.array([alpha, eta]), np.array([0.0, 0.0, 1.0]), wi,
                              n=200_000, seed=5, res=(60, 60), alpha=0.01, n_tests=len(CASES), rtol=1e-9)
    assert res.passed, f"eta {eta:.3f} alpha {alpha} theta {theta}: {res.message}"


@njit
def _albedo(theta, alpha, eta, n):
    """(reflected, refracted in flux form (weight eta^2), refracted in radiance form) means of n samples."""
    ix, iz = math.sin(theta), math.cos(theta)
    r = t = tr = 0.0
    for k in range(n):
        ok, _, _, z, w, _ = rough_dielectric_sample(ix, 0.0, iz, alpha, eta, uniform(3, k, 0), uniform(3, k, 1),
                                                    uniform(3, k, 2))
        if ok and z > 0.0:
            r += w
        elif ok:
            t += w * eta * eta
            tr += w
    return r / n, t / n, tr / n


def test_nearly_smooth_glass_keeps_fresnels_split_and_loses_nothing():
    """alpha 0.01 at normal incidence: reflectance ((1.5 - 1) / (1.5 + 1))^2 = 0.04, reflected + refracted flux
    = 1 within 0.2 %; refraction's radiance is the flux over eta^2 (1 / 2.25 entering glass, 2.25 leaving it)."""
    for eta in (1.5, 1.0 / 1.5):
        r, t, tr = _albedo(0.0, 0.01, eta, 200_000)
        assert abs(r - 0.04) < 2e-3 and abs(r + t - 1.0) < 2e-3, (eta, r, t)
        assert abs(tr - t / (eta * eta)) < 1e-9


def test_total_internal_reflection_inside_glass():
    """Leaving glass (eta 1 / 1.5) past the critical angle (41.8 degrees), a nearly smooth interface reflects
    all but GGX's tail: at 60 degrees under 0.1 % refracts (micro-normals tilted by 18 degrees or more), the
    rest is reflected within 0.5 %."""
    r, t, _ = _albedo(math.radians(60.0), 0.01, 1.0 / 1.5, 100_000)
    assert t < 1e-3 and abs(r + t - 1.0) < 5e-3, (r, t)
