"""Real spherical harmonics (stages/core/sh.py): evaluation against scipy, orthonormality on an exact
quadrature, and Ivanic-Ruedenberg rotation matrices against the projection of the rotated function."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import sph_harm_y

from stages.core import sh


def _scipy_real_sh(L, d):
    """Real SH of the module's convention from scipy's complex Y_l^m (Condon-Shortley phase included)."""
    theta = math.acos(max(-1.0, min(1.0, d[2])))
    phi = math.atan2(d[1], d[0])
    out = np.empty(sh.sh_count(L))
    for l in range(L + 1):
        for m in range(-l, l + 1):
            Y = sph_harm_y(l, abs(m), theta, phi)
            j = l * (l + 1) + m
            if m == 0:
                out[j] = Y.real
            elif m > 0:
                out[j] = math.sqrt(2.0) * (-1) ** m * Y.real
            else:
                out[j] = math.sqrt(2.0) * (-1) ** m * Y.imag
    return out


def _random_dirs(n, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    return np.vstack([v, [[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0], [0, -1.0, 0]]])


@pytest.mark.parametrize("L", [8, 16])
def test_sh_eval_matches_scipy(L):
    """Reference: scipy.special.sph_harm_y converted to real SH (Y_{l,+-m} = sqrt2 (-1)^m Re/Im Y_l^m),
    at random directions and the poles and equator."""
    y = np.empty(sh.sh_count(L))
    for d in _random_dirs(40, 5):
        sh.sh_eval(L, d[0], d[1], d[2], y)
        np.testing.assert_allclose(y, _scipy_real_sh(L, d), rtol=0, atol=1e-12)


def test_order_one_is_y_z_x():
    """Convention (closed form): order 1 = sqrt(3/(4 pi)) (y, z, x); Y_0 = 1/sqrt(4 pi)."""
    d = np.array([0.48, -0.6, 0.64])
    y = np.empty(4)
    sh.sh_eval(1, d[0], d[1], d[2], y)
    k = math.sqrt(3.0 / (4.0 * math.pi))
    np.testing.assert_allclose(y, [1 / math.sqrt(4 * math.pi), k * d[1], k * d[2], k * d[0]], atol=1e-15)


@pytest.mark.parametrize("L", [0, 1, 4, 8])
def test_orthonormality_on_exact_quadrature(L):
    """Reference: the identity; the Gauss-Legendre x uniform rule with (L+1) x (2L+1) nodes integrates
    every product Y_j Y_k of order <= L exactly, so the Gram matrix must be I to rounding."""
    d, w = sh.sh_quadrature(L, 0, 0)
    assert d.shape == ((L + 1) * (2 * L + 1), 3) and w.shape == (d.shape[0],)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-15)
    G = sh.sh_project(_eval_many(L, d), d, w, L)
    np.testing.assert_allclose(G, np.eye(sh.sh_count(L)), atol=1e-10)


def test_gauss_legendre_matches_numpy():
    """Reference: numpy.polynomial.legendre.leggauss."""
    for n in (1, 2, 7, 16, 64, 301):
        x, w = sh.gauss_legendre(n)
        xr, wr = np.polynomial.legendre.leggauss(n)
        np.testing.assert_allclose(x, xr, atol=1e-14)
        np.testing.assert_allclose(w, wr, atol=1e-14)


def _eval_many(L, dirs):
    out = np.empty((dirs.shape[0], sh.sh_count(L)))
    for k in range(dirs.shape[0]):
        sh.sh_eval(L, dirs[k, 0], dirs[k, 1], dirs[k, 2], out[k])
    return out


def _rotations(n, seed):
    return Rotation.random(n, random_state=seed).as_matrix()


@pytest.mark.parametrize("L", [4, 5, 8])
def test_rotation_matches_projection_of_rotated_function(L):
    """Reference: projection by exact quadrature of g(w) = f(R^T w) for f a random expansion of order L
    (g is of order L too, so the rule with (L+1) x (2L+1) nodes projects it exactly): D(R) c = coeffs of g."""
    n = sh.sh_count(L)
    rng = np.random.default_rng(L)
    d, w = sh.sh_quadrature(L, 0, 0)
    D = np.empty((n, n))
    for R in _rotations(4, 10 + L):
        c = rng.normal(size=n)
        g = _eval_many(L, d @ R) @ c            # rows d_k R = (R^T d_k)^T
        ref = sh.sh_project(g[:, None], d, w, L)[:, 0]
        sh.sh_rotation(L, R, D)
        assert np.abs(D @ c - ref).max() <= 1e-10


def test_rotation_is_an_orthogonal_representation():
    """Reference: group properties: D(R1 R2) = D(R1) D(R2), D(R) D(R)^T = I, D(R^T) = D(R)^T, D(I) = I,
    and D is block diagonal by order."""
    L = 8
    n = sh.sh_count(L)
    R1, R2 = _rotations(2, 77)
    D1, D2, D12, Dt, Di = (np.empty((n, n)) for _ in range(5))
    sh.sh_rotation(L, R1, D1)
    sh.sh_rotation(L, R2, D2)
    sh.sh_rotation(L, R1 @ R2, D12)
    sh.sh_rotation(L, np.ascontiguousarray(R1.T), Dt)
    sh.sh_rotation(L, np.eye(3), Di)
    np.testing.assert_allclose(D12, D1 @ D2, atol=1e-12)
    np.testing.assert_allclose(D1 @ D1.T, np.eye(n), atol=1e-12)
    np.testing.assert_allclose(Dt, D1.T, atol=1e-12)
    np.testing.assert_allclose(Di, np.eye(n), atol=1e-15)
    order = np.repeat(np.arange(L + 1), 2 * np.arange(L + 1) + 1)
    assert np.all(D1[order[:, None] != order[None, :]] == 0.0)


def test_rotation_of_a_direction_kernel():
    """Reference: the expansion of a delta at v is (Y_j(v)); rotated by R it must become (Y_j(R v))."""
    L = 6
    n = sh.sh_count(L)
    v = np.array([0.2, -0.4, 0.8])
    v /= np.linalg.norm(v)
    D = np.empty((n, n))
    for R in _rotations(3, 5):
        sh.sh_rotation(L, R, D)
        yv, yr = np.empty(n), np.empty(n)
        sh.sh_eval(L, *v, yv)
        sh.sh_eval(L, *(R @ v), yr)
        np.testing.assert_allclose(D @ yv, yr, atol=1e-12)


@pytest.mark.parametrize("L", [0, 1, 4, 8, 16])
def test_rotate_rows_equals_the_rotation_matrix(L):
    """Reference: D(R) @ c of ``sh_rotation`` (itself checked against projection above) for random
    rotations (1e-12) and for rotations at and near the Euler angles' poles, b = 0 and pi (1e-7, the
    documented 1e-8 per entry); a table of a higher order serves a lower one."""
    n = sh.sh_count(L)
    X = sh.quarter_turn_x(L)
    X16 = sh.quarter_turn_x(16)
    rng = np.random.default_rng(L)
    D = np.empty((n, n))

    def rz(t):
        return Rotation.from_euler("z", t).as_matrix()

    poles = [rz(0.3) @ Rotation.from_euler("y", b).as_matrix() @ rz(1.1)
             for b in (0.0, math.pi, 1e-9, math.pi - 1e-9, 3e-8, 1e-6)]
    for R, tol in [(R, 1e-12) for R in _rotations(8, 40 + L)] + [(R, 1e-7) for R in poles]:
        R = np.ascontiguousarray(R)
        sh.sh_rotation(L, R, D)
        C = rng.normal(size=(3, n))
        for table in (X, X16):
            out = np.empty((3, n))
            sh.sh_rotate_rows(L, R, table, C, out)
            assert np.abs(out - C @ D.T).max() <= tol * max(1.0, np.abs(C).max())


def test_blockwise_rotate_equals_matrix_product():
    """Reference: numpy's D @ c (sh_rotate applies only the diagonal blocks, also of a larger D)."""
    D = np.empty((sh.sh_count(8), sh.sh_count(8)))
    sh.sh_rotation(8, _rotations(1, 3)[0], D)
    c = np.random.default_rng(2).normal(size=sh.sh_count(8))
    out = np.empty(sh.sh_count(8))
    sh.sh_rotate(8, D, c, out)
    np.testing.assert_allclose(out, D @ c, atol=1e-13)
    out5 = np.empty(sh.sh_count(5))
    sh.sh_rotate(5, D, c, out5)
    np.testing.assert_allclose(out5, (D @ c)[:36], atol=1e-13)


def test_frame_rotations():
    """Reference: definitions: rotation_z_to(a) e_z = a with det +1; rotation_to_frame maps each axis to e_k."""
    R = np.empty((3, 3))
    for a in _random_dirs(20, 9):
        sh.rotation_z_to(a, R)
        np.testing.assert_allclose(R @ [0, 0, 1.0], a, atol=1e-14)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
        F = np.empty((3, 3))
        sh.rotation_to_frame(R[:, 0].copy(), R[:, 1].copy(), R[:, 2].copy(), F)
        np.testing.assert_allclose(F @ R, np.eye(3), atol=1e-14)


def test_order_above_limit_is_refused():
    """Contract: orders above SH_LMAX raise instead of reading past the coefficient tables."""
    with pytest.raises(ValueError):
        sh.sh_eval(sh.SH_LMAX + 1, 0.0, 0.0, 1.0, np.empty(sh.sh_count(sh.SH_LMAX + 1)))
