"""Free-flight sampling (stages/render/media/tracking.py: delta tracking) against the closed-form exponential.

Reference: in a homogeneous box of density den, fibre tangent t and roughness sigma, the extinction along
a unit direction d is den sqrt(1 + (sigma^2 - 1)(t . d)^2) (Jakob 2010 Eq. 8 with the fibre-like SGGX
of Heitz 2015 §4, in closed form), so the first real collision lies at distance s past the box entry with
density sigma_t exp(-sigma_t s) on [0, L] and the ray escapes with probability exp(-sigma_t L). Delta
tracking samples it through tentative collisions of a piecewise-constant majorant (here different per
cell, all >= the density); the chi-square harness (tests/chisquare.py: chi2_test_1d) compares the
collision distances with that density, the escapes forming a bin of their own.
"""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.dispatch import runtime_value
from stages.render.media.medium import HomogeneousMedium
from stages.render.media.tracking import make_majorant_grid, ray_box, track
from tests.chisquare import chi2_test_1d

LO = np.array([-1.0, -1.0, -0.5])
HI = np.array([1.0, 1.0, 0.5])
O = np.array([-0.3, 0.2, 2.0])
D = np.array([0.35, -0.2, -1.0]) / np.linalg.norm([0.35, -0.2, -1.0])


@njit
def _collisions(med, maj, o, d, n, seed):
    """(collided, t) of n delta-tracking walks along o + t d."""
    hit = np.empty(n, np.bool_)
    t = np.empty(n)
    for k in range(n):
        r = track(med, maj, o[0], o[1], o[2], d[0], d[1], d[2], np.inf, seed, k, np.int64(0), runtime_value(False),
                  np.int64(-1))   # a runtime flag: test_volpath's track_many shares this compiled track
        hit[k] = r.collided
        t[k] = r.t
    return hit, t


def _majorant(den, factor):
    """A 3 x 2 x 3 majorant grid over the box, cell values den x (factor, factor + 0.1, ...)."""
    res = np.array([3, 2, 3])
    mu = den * (factor + 0.1 * np.arange(18).reshape(3, 2, 3))
    return make_majorant_grid(LO, HI, res, mu)


@pytest.mark.parametrize("rough, tangent", [(1.0, (0.0, 0.0, 1.0)), (0.3, (0.6, 0.0, 0.8))])
def test_free_flight_distances_chi2(rough, tangent):
    """Reference: closed-form exponential free flights with the escape probability exp(-sigma_t L) (module
    doc); 200k walks through a majorant 1.0-2.7 x the density (null collisions in every cell); Šidák over 2."""
    den = 2.5
    t = np.asarray(tangent) / np.linalg.norm(tangent)
    med = HomogeneousMedium(LO, HI, den, t, rough, np.array([0.5, 0.5, 0.5]))
    sigma_t = den * math.sqrt(1.0 + (rough * rough - 1.0) * float(t @ D) ** 2)
    t0, t1 = ray_box(LO, HI, *O, *D)
    hit, s = _collisions(med, _majorant(den, 1.0), O, D, 200_000, 7)
    assert np.all(s[~hit] == np.inf)
    res = chi2_test_1d(s[hit] - t0, lambda x: sigma_t * np.exp(-sigma_t * x), (0.0, t1 - t0), bins=60,
                       n_total=len(hit), n_tests=2)
    assert res.passed, res.message
    # the harness pooled the escapes against exp(-sigma_t L): also check the escape fraction on its own
    p_esc = math.exp(-sigma_t * (t1 - t0))
    assert abs((~hit).mean() - p_esc) < 5 * math.sqrt(p_esc * (1 - p_esc) / len(hit))


def test_free_flight_rejects_a_wrong_extinction():
    """The test must fail: the same walks against the exponential of 1.03 sigma_t."""
    den = 2.5
    med = HomogeneousMedium(LO, HI, den, np.array([0.0, 0.0, 1.0]), 1.0, np.array([0.5, 0.5, 0.5]))
    t0, t1 = ray_box(LO, HI, *O, *D)
    hit, s = _collisions(med, _majorant(den, 1.0), O, D, 200_000, 7)
    st = 1.03 * den
    res = chi2_test_1d(s[hit] - t0, lambda x: st * np.exp(-st * x), (0.0, t1 - t0), bins=60, n_total=len(hit))
    assert not res.passed, res.message
