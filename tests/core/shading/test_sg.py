"""Spherical Gaussians (stages/core/sg.py): mass, product, spherical Fibonacci axes and the SH expansion
C_G (direct and tabulated) against scipy quadrature, scipy's Bessel functions and SH projection."""
import math

import numpy as np
import pytest
from scipy import integrate
from scipy.special import eval_legendre, ive

from stages.core import sg, sh

LAMBDAS = [0.0, 0.1, 1.0, 10.0, 100.0, 1000.0, 5000.0]


def _sg_integral(lam, f):
    """int_{-1}^{1} e^{lam (u - 1)} f(u) du by scipy quad, in s = lam (1 - u) for lam > 0 (the mass sits
    within a few 1/lam of u = 1), split at s = 60 (e^-60 beyond)."""
    if lam == 0.0:
        return integrate.quad(f, -1.0, 1.0, epsabs=1e-14, epsrel=1e-12, limit=200)[0]
    top = 2.0 * lam

    def g(s):
        return math.exp(-s) * f(1.0 - s / lam) / lam

    v = integrate.quad(g, 0.0, min(top, 60.0), epsabs=1e-14, epsrel=1e-12, limit=200)[0]
    if top > 60.0:
        v += integrate.quad(g, 60.0, top, epsabs=1e-14, epsrel=1e-12, limit=200)[0]
    return v


@pytest.mark.parametrize("lam", LAMBDAS + [1e-7])
def test_mass_matches_quadrature(lam):
    """Reference: scipy quad of M = 2 pi int e^{lam (u - 1)} du (4 pi at lam = 0)."""
    ref = 2.0 * math.pi * _sg_integral(lam, lambda u: 1.0)
    assert sg.sg_mass(lam) == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize("lam", LAMBDAS)
def test_zonal_coefficients_match_quadrature(lam):
    """Reference: scipy quad of C_G[lam, l] = 2 pi int e^{lam(u-1)} Y_{l,0}(u) du / M, with M by quadrature
    too, l <= 8; and the closed form sqrt((2l+1)/(4 pi)) i_l/i_0 with scipy's scaled Bessel ive."""
    L = 8
    out = np.empty(L + 1)
    sg.sg_zonal_coefficients(lam, L, out)
    mass = 2.0 * math.pi * _sg_integral(lam, lambda u: 1.0)
    for l in range(L + 1):
        k = math.sqrt((2 * l + 1) / (4 * math.pi))
        ref = 2.0 * math.pi * _sg_integral(lam, lambda u, k=k, l=l: k * eval_legendre(l, u)) / mass
        assert out[l] == pytest.approx(ref, abs=1e-11)
        if lam > 0:
            assert out[l] == pytest.approx(k * ive(l + 0.5, lam) / ive(0.5, lam), abs=1e-13)


def test_zonal_coefficients_extreme_sharpness():
    """Reference: the limits: lam -> infinity is the delta at +z (C_G -> Y_{l,0}(z) = sqrt((2l+1)/(4 pi)))
    with r_l ~ exp(-l(l+1)/(2 lam)); scipy ive at lam = 1e6."""
    out = np.empty(9)
    sg.sg_zonal_coefficients(1e6, 8, out)
    k = np.sqrt((2 * np.arange(9) + 1) / (4 * math.pi))
    ref = k * np.array([ive(l + 0.5, 1e6) / ive(0.5, 1e6) for l in range(9)])
    np.testing.assert_allclose(out, ref, atol=1e-13)
    np.testing.assert_allclose(out / k, np.exp(-np.arange(9) * np.arange(1, 10) / 2e6), atol=1e-9)


def test_table_interpolation_within_documented_bound():
    """Reference: the direct computation (tested above). The table rows equal it at the nodes; off the
    nodes (log-midpoints, a dense log sweep, small lam, lam beyond the grid) the documented bound 2e-7."""
    L = 8
    grid, table = sg.build_sg_table(L)
    assert grid.shape == (128,) and table.shape == (128, L + 1) and grid[0] == 0.0
    d, o = np.empty(L + 1), np.empty(L + 1)
    for i, lam in enumerate(grid):
        sg.sg_zonal_coefficients(lam, L, d)
        np.testing.assert_array_equal(table[i], d)
    mids = np.sqrt(grid[1:-1] * grid[2:])
    lams = np.concatenate([mids, np.logspace(-4, 4, 3001), np.linspace(0, 1e-2, 101), [2e4, 3e5]])
    worst = 0.0
    for lam in lams:
        sg.sg_zonal_coefficients(lam, L, d)
        sg.sg_table_lookup(grid, table, lam, L, o)
        worst = max(worst, np.abs(d - o).max())
    assert worst <= 2e-7


def test_product_is_an_sg_pointwise():
    """Reference: the product of the two exponentials evaluated directly (§5.2.2 formula)."""
    rng = np.random.default_rng(8)
    for _ in range(50):
        a1, a2 = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
        l1, l2 = rng.uniform(0, 200, size=2)
        x, y, z, lam, scale = sg.sg_product(a1, l1, a2, l2)
        xi = np.array([x, y, z])
        assert np.linalg.norm(xi) == pytest.approx(1.0, abs=1e-14)
        assert lam == pytest.approx(np.linalg.norm(l1 * a1 + l2 * a2), rel=1e-14)
        for w in rng.normal(size=(5, 3)):
            w /= np.linalg.norm(w)
            ref = math.exp(l1 * (w @ a1 - 1)) * math.exp(l2 * (w @ a2 - 1))
            assert scale * sg.sg_eval(w, xi, lam) == pytest.approx(ref, rel=1e-9, abs=1e-300)
    # opposite axes of equal sharpness: a constant
    a = np.array([0.0, 0.6, 0.8])
    x, y, z, lam, scale = sg.sg_product(a, 3.0, -a, 3.0)
    assert lam == 0.0 and scale == pytest.approx(math.exp(-6.0))


def test_spherical_fibonacci_axes():
    """Reference: the §4.1 formula written out in numpy, and a rotation about z by the angle."""
    Q = 48
    q = np.arange(1, Q + 1)
    z = 1.0 - (q - 1) / Q
    r = np.sqrt(1 - z * z)
    phi = 4 * math.pi * q / (1 + math.sqrt(5))
    ref = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    a0 = sg.spherical_fibonacci_axes(Q, 0.0)
    np.testing.assert_allclose(a0, ref, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(a0, axis=1), 1.0, atol=1e-14)
    ang = 0.7
    Rz = np.array([[math.cos(ang), -math.sin(ang), 0], [math.sin(ang), math.cos(ang), 0], [0, 0, 1.0]])
    np.testing.assert_allclose(sg.spherical_fibonacci_axes(Q, ang), ref @ Rz.T, atol=1e-14)


@pytest.mark.parametrize("lam", [0.5, 3.0, 30.0])
def test_sh_coefficients_of_an_sg(lam):
    """Reference: projection of G/M by a dense Gauss-Legendre x uniform rule (sh_quadrature, exact for
    the SH part; 160 x 320 nodes resolve lam <= 30 to rounding), and the zonal expansion rotated with
    sh_rotation(rotation_z_to(axis)); the table version within the documented table bound."""
    L = 8
    n = sh.sh_count(L)
    axis = np.array([0.3, -0.5, 0.7])
    axis /= np.linalg.norm(axis)
    c = np.empty(n)
    sg.sg_sh_coefficients(axis, lam, L, c)
    d, w = sh.sh_quadrature(L, 160, 320)
    vals = np.exp(lam * (d @ axis - 1.0)) / sg.sg_mass(lam)
    ref = sh.sh_project(vals[:, None], d, w, L)[:, 0]
    np.testing.assert_allclose(c, ref, atol=1e-11)
    zonal = np.zeros(n)
    cz = np.empty(L + 1)
    sg.sg_zonal_coefficients(lam, L, cz)
    zonal[[l * (l + 1) for l in range(L + 1)]] = cz
    R, D = np.empty((3, 3)), np.empty((n, n))
    sh.rotation_z_to(axis, R)
    sh.sh_rotation(L, R, D)
    np.testing.assert_allclose(D @ zonal, c, atol=1e-13)
    grid, table = sg.build_sg_table(L)
    ct = np.empty(n)
    sg.sg_sh_coefficients_lookup(grid, table, axis, lam, L, ct)
    np.testing.assert_allclose(ct, c, atol=2e-7 * math.sqrt(4 * math.pi))
