"""The BCSDF's SH table C_S (stages/core/shading/bcsdf_sh.py) against the closed-form albedo and a
brute-force world-space quadrature of Y_j times bcsdf_eval, and its omega_o-space rotation."""
import math

import numpy as np
import pytest
from numba import njit

from stages.core import sh
from stages.core.shading import bcsdf as B, bcsdf_sh as BS


def preset(name):
    from pipeline.bcsdf_presets import load_bcsdf_preset

    return load_bcsdf_preset(name)


@njit
def _brute_force(p, t, wv, L, n_theta, n_phi):
    """int Y_j(w) bcsdf_eval(p, t, wv, w) dw over world directions w, (n_coef, 3): midpoint rule in the
    BCSDF's own angles about t (bcsdf.from_angles), dw = cos(theta) dtheta dphi."""
    n = (L + 1) * (L + 1)
    out = np.zeros((n, 3))
    y = np.empty(n)
    dth = math.pi / n_theta
    dph = 2.0 * math.pi / n_phi
    for a in range(n_theta):
        th = -0.5 * math.pi + (a + 0.5) * dth
        jac = math.cos(th) * dth * dph
        for b in range(n_phi):
            w = B.from_angles(t, th, -math.pi + (b + 0.5) * dph)
            f0, f1, f2 = B.bcsdf_eval(p, t, wv, w)
            sh.sh_eval(L, w[0], w[1], w[2], y)
            for j in range(n):
                out[j, 0] += jac * f0 * y[j]
                out[j, 1] += jac * f1 * y[j]
                out[j, 2] += jac * f2 * y[j]
    return out


@pytest.mark.parametrize("name", ["silk", "gabardine", "cotton"])
def test_order_zero_is_the_albedo(name):
    """Reference: the closed-form albedo bcsdf_albedo(p, theta_v) = int S cos dw = sqrt(4 pi) C_S[theta_v, 0]
    (Y_0 = 1/sqrt(4 pi)), on the table's rows and at off-grid angles near the poles and the lobe ends."""
    p = preset(name)
    table = BS.bcsdf_sh_table(p, 5, 512)
    assert table.shape == (512, 36, 3)
    thetas = BS.bcsdf_theta_grid(512)
    assert thetas[0] == -math.pi / 2 and thetas[-1] == pytest.approx(math.pi / 2, abs=1e-15)
    for k in (0, 1, 100, 255, 256, 400, 511):
        np.testing.assert_allclose(table[k, 0] * math.sqrt(4 * math.pi), B.bcsdf_albedo(p, thetas[k]), rtol=1e-10)
    odd = np.array([-1.5707, -1.2, -0.31, 0.0, 0.77, 1.5702])
    rows = BS.bcsdf_sh_angle_rows(p, 3, odd)
    for k, th in enumerate(odd):
        np.testing.assert_allclose(rows[k, 0] * math.sqrt(4 * math.pi), B.bcsdf_albedo(p, th), rtol=1e-10)


@pytest.mark.parametrize("name,theta_v", [("silk", 0.3), ("silk", -1.2), ("fleece", 0.9), ("cotton", -0.05)])
def test_all_coefficients_match_brute_force_in_omega_o_space(name, theta_v):
    """Reference: brute-force midpoint quadrature (1200 x 144 nodes in the fibre angles, as
    tests/core/shading/test_bcsdf.py) of Y_j(w) bcsdf_eval(p, t, w_view, w) with t = +x and the view
    (sin theta_v, cos theta_v, 0), so world = omega_o-space: every coefficient of order <= 5. The brute
    force agrees with itself at 2400 x 288 nodes to 1e-9 (the TT azimuthal lobe's kink at phi_d = +-pi
    limits the midpoint rule for cotton's wide gamma_TT); the table's quadrature is exact in phi."""
    p = preset(name)
    t = np.array([1.0, 0.0, 0.0])
    wv = np.array([math.sin(theta_v), math.cos(theta_v), 0.0])
    ref = _brute_force(p, t, wv, 5, 1200, 144)
    row = BS.bcsdf_sh_angle_rows(p, 5, np.array([theta_v]))[0]
    np.testing.assert_allclose(row, ref, atol=1e-8)
    assert np.abs(ref[1:]).max() > 0.05  # the test sees non-trivial higher orders


@pytest.mark.parametrize("name", ["silk", "polyester"])
def test_rotated_world_expansion_equals_table_row(name):
    """Reference: brute-force world-space expansion b_j = int Y_j(w) bcsdf_eval(p, t, w_view, w) dw at a
    random tangent and a view on a table row; the shading rule of §5.3.1 needs c_S . (D(R) c_T) = b . c_T
    for every world expansion c_T, i.e. D(R)^T c_S = b, with R = omega_o_frame(t, w_view)."""
    L = 4
    n = sh.sh_count(L)
    p = preset(name)
    rng = np.random.default_rng(21)
    table = BS.bcsdf_sh_table(p, L, 512)
    thetas = BS.bcsdf_theta_grid(512)
    for k in (130, 301):
        t = rng.normal(size=3)
        t /= np.linalg.norm(t)
        wv = B.from_angles(t, thetas[k], rng.uniform(-math.pi, math.pi))
        R, D = np.empty((3, 3)), np.empty((n, n))
        theta_v = BS.omega_o_frame(t, wv, R)
        assert theta_v == pytest.approx(thetas[k], abs=1e-12)
        np.testing.assert_allclose(R @ wv, [math.sin(theta_v), math.cos(theta_v), 0.0], atol=1e-12)
        sh.sh_rotation(L, R, D)
        b = _brute_force(p, t, wv, L, 1200, 144)
        np.testing.assert_allclose(D.T @ table[k], b, atol=1e-8)
        c_T = rng.normal(size=n)
        c_loc = np.empty(n)
        sh.sh_rotate(L, D, c_T, c_loc)
        np.testing.assert_allclose(c_loc @ table[k], c_T @ b, atol=1e-7)


def test_omega_o_frame_is_a_rotation_also_along_the_fibre():
    """Reference: definitions: rows orthonormal, det +1, x = t, view in the xy-plane with y >= 0; a view
    along the fibre still gives a rotation and theta_v = +-pi/2."""
    R = np.empty((3, 3))
    rng = np.random.default_rng(4)
    for _ in range(20):
        t, w = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
        for view, th in ((w, math.asin(w @ t)), (t, math.pi / 2), (-t, -math.pi / 2)):
            theta_v = BS.omega_o_frame(t, view, R)
            assert theta_v == pytest.approx(th, abs=1e-7)
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
            np.testing.assert_allclose(R[0], t, atol=1e-15)
            loc = R @ view
            assert abs(loc[2]) < 1e-12 and loc[1] >= -1e-12


def test_lookup_interpolates_rows_linearly():
    """Reference: the table rows at the nodes, the mean of two rows midway, clamping beyond +-pi/2, and the
    direct quadrature at random angles within the linear-interpolation error (h^2/8 max |C_S''|, h = pi/511;
    measured 4e-5 on the five presets at L = 5)."""
    p = preset("silk")
    L = 5
    table = BS.bcsdf_sh_table(p, L, 512)
    th = BS.bcsdf_theta_grid(512)
    out = np.empty((36, 3))
    BS.bcsdf_sh_lookup(table, th[200], L, out)
    np.testing.assert_allclose(out, table[200], atol=1e-15)
    BS.bcsdf_sh_lookup(table, 0.5 * (th[10] + th[11]), L, out)
    np.testing.assert_allclose(out, 0.5 * (table[10] + table[11]), atol=1e-15)
    BS.bcsdf_sh_lookup(table, 2.0, L, out)
    np.testing.assert_allclose(out, table[-1], atol=1e-15)
    small = np.empty((4, 3))
    BS.bcsdf_sh_lookup(table, -0.4, 1, small)
    np.testing.assert_allclose(small, BS.bcsdf_sh_angle_rows(p, 1, np.array([-0.4]))[0], atol=1e-4)
    rnd = np.random.default_rng(1).uniform(-1.5, 1.5, 40)
    direct = BS.bcsdf_sh_angle_rows(p, L, rnd)
    for k, x in enumerate(rnd):
        BS.bcsdf_sh_lookup(table, x, L, out)
        np.testing.assert_allclose(out, direct[k], atol=1e-4)
