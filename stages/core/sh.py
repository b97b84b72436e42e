"""Real spherical harmonics: evaluation, projection by quadrature, exact rotation matrices.

Seed 001 (Khungurn et al. 2017) represents the indirect radiance transfer (IIRTF), the fibre BCSDF and
spherical Gaussian lights in one real SH basis (§2 "Notation", §4.3, §5.3): this module is that basis.

Basis and index
---------------
One index j = l (l + 1) + m, l = 0..L, m = -l..l: an expansion of order L has (L + 1)^2 coefficients
(``sh_count``). With (theta, phi) the polar and azimuthal angles of a unit direction about +z,
K_l^m = sqrt((2l + 1)/(4 pi) (l - m)!/(l + m)!) and P_l^m the associated Legendre function *without*
the Condon-Shortley phase (-1)^m,

    Y_{l,0}  = K_l^0 P_l(cos theta)
    Y_{l,m}  = sqrt2 K_l^m P_l^m(cos theta) cos(m phi)      m > 0
    Y_{l,-m} = sqrt2 K_l^m P_l^m(cos theta) sin(m phi)      m > 0

This is the usual graphics/chemistry real basis (the one of Ivanic-Ruedenberg and of Wikipedia's
"real spherical harmonics"), orthonormal: int Y_j Y_k dw = delta_jk. Without the Condon-Shortley phase
order 1 is sqrt(3/(4 pi)) (y, z, x) for m = -1, 0, 1, with no signs. From scipy's
complex Y_l^m (which carries the Condon-Shortley phase): Y_{l,m} = sqrt2 (-1)^m Re Y_l^m and
Y_{l,-m} = sqrt2 (-1)^m Im Y_l^m for m > 0.

``sh_eval`` works on the Cartesian direction, never on angles: (x + i y)^m = sin^m(theta) e^{i m phi},
times the fully normalised Legendre function divided by sin^m(theta), which obeys the usual stable
three-term recurrence in l (no poles, no factorials). Orders up to ``SH_LMAX`` = 16.

Projection
----------
``sh_quadrature(L, n_theta, n_phi)`` is the product rule Gauss-Legendre in cos(theta) x uniform in phi:
it integrates exactly every spherical polynomial of degree <= min(2 n_theta - 1, n_phi - 1); the Gram
matrix of order L needs n_theta >= L + 1 and n_phi >= 2L + 1 (the defaults when 0 is passed).
``sh_project(values (N, C), dirs, weights, L)`` -> (n_coef, C) = sum_k w_k Y_j(d_k) values[k].

Rotation
--------
``sh_rotation(L, R, out)`` fills the block-diagonal ((L+1)^2, (L+1)^2) matrix D(R) such that

    f(w) = sum_j c_j Y_j(w)  =>  f(R^T w) = sum_j (D(R) c)_j Y_j(w)

i.e. D(R) c are the coefficients of f rotated by R (what was at direction v is now at R v). D is
orthogonal and a representation: D(R1 R2) = D(R1) D(R2). Order 1 is R itself with rows and columns
permuted to (y, z, x); higher orders follow from the recurrence of Ivanic and Ruedenberg (J. Phys.
Chem. 100, 6342 (1996), with the corrections of the 1998 erratum, J. Phys. Chem. A 102, 9099), from
the order-1 block and the order l - 1 block, with the coefficients u, v, w tabulated at import. The
paper (§5.3.1) cites Pinchon and Hoggan 2007 for the same matrices; both give D(R) exactly.
Cost: one pass over sum_l (2l + 1)^2 entries (969 at L = 8), no allocation; ``sh_rotate`` applies it
block by block ((2l + 1)^2 products per order instead of (L + 1)^4). Measured, matrix plus its
application to one vector, one core: 1.4 us at L = 4, 2.4 us at L = 5, 9 us at L = 8.

A renderer that rotates a few vectors per shading point need not build D at all:
``sh_rotate_rows(L, R, X, C, out)`` writes D(R) C[i] into out[i] for each row of C through the z-y-z
Euler angles of R = R_z(a) R_y(b) R_z(g): D(R) = Z(a) X^T Z(b) X Z(g), where Z(t) = D(R_z(t)) turns
each order's (m, -m) pair by m t (the cosines and sines of m t by angle addition, once per angle) and
X = D(R_x(90 deg)) is a constant block-diagonal matrix (``quarter_turn_x(L)``, passed in, in CSR form:
45 of its 165 block entries at L = 4 are non-zero), since R_y(b) = R_x(-90 deg) R_z(b) R_x(90 deg).
Measured, one core, L = 4, on a day when D alone took 2.4 us: 0.23 us for the angles and tables
plus 0.33 us per vector (three vectors 1.2 us). Near b = 0 or pi (|sin b| < 1e-8) the angles are taken as (a, 0 or
pi, 0): every coefficient stays within 1e-8 of D(R) c (``tests/core/shading/test_sh.py``).

Frames
------
``rotation_to_frame(x, y, z, R)`` writes the rows x, y, z (a right-handed orthonormal frame given in
world coordinates) into R: R maps world coordinates to frame coordinates, so D(R) carries world SH
coefficients to the frame's (the "omega_o-space" rotation of §5.3.1). ``rotation_z_to(axis, R)`` is a
rotation with R e_z = axis: D(R) turns a zonal expansion about +z into one about ``axis``.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.frames import orthonormal_basis
from stages.core.geometry.stack import stack_array

SH_LMAX = 16
FOUR_PI = 4.0 * math.pi
SQRT2 = math.sqrt(2.0)


def _legendre_tables(lmax):
    """a_lm, b_lm of the normalised recurrence and the diagonal seeds q_m^m (all for l, m <= lmax)."""
    a = np.zeros((lmax + 1, lmax + 1))
    b = np.zeros((lmax + 1, lmax + 1))
    diag = np.zeros(lmax + 1)
    diag[0] = 1.0 / math.sqrt(FOUR_PI)
    for m in range(1, lmax + 1):
        diag[m] = diag[m - 1] * math.sqrt((2.0 * m + 1.0) / (2.0 * m))
    for m in range(lmax + 1):
        for l in range(m + 1, lmax + 1):
            a[l, m] = math.sqrt((4.0 * l * l - 1.0) / (l * l - m * m))
            if l >= m + 2:
                b[l, m] = math.sqrt(((l - 1.0) ** 2 - m * m) / (4.0 * (l - 1.0) ** 2 - 1.0))
    return a, b, diag


_LEG_A, _LEG_B, _LEG_DIAG = _legendre_tables(SH_LMAX)


def _rotation_tables(lmax):
    """Ivanic-Ruedenberg u, v, w for every (l, m, n), l >= 2, stored flat at offset(l) + (m+l)(2l+1) + (n+l)."""
    off = np.zeros(lmax + 2, np.int64)
    for l in range(lmax + 1):
        off[l + 1] = off[l] + (2 * l + 1) ** 2
    uvw = np.zeros((off[-1], 3))
    for l in range(2, lmax + 1):
        for m in range(-l, l + 1):
            am = abs(m)
            d = 1.0 if m == 0 else 0.0
            for n in range(-l, l + 1):
                denom = (2.0 * l) * (2.0 * l - 1.0) if abs(n) == l else (l + n) * (l - n)
                k = off[l] + (m + l) * (2 * l + 1) + (n + l)
                uvw[k, 0] = math.sqrt((l + m) * (l - m) / denom)
                uvw[k, 1] = 0.5 * math.sqrt((1.0 + d) * (l + am - 1.0) * (l + am) / denom) * (1.0 - 2.0 * d)
                uvw[k, 2] = -0.5 * math.sqrt(max(0.0, (l - am - 1.0) * (l - am)) / denom) * (1.0 - d)
    return off, uvw


_ROT_OFF, _ROT_UVW = _rotation_tables(SH_LMAX)
SH_COUNT_MAX = (SH_LMAX + 1) * (SH_LMAX + 1)
TURN_TABLE = 2 * (SH_LMAX + 1)          # cos and sin of m t, m = 0..SH_LMAX (sh_rotate_rows)
TURN_TABLES = 3 * TURN_TABLE


@njit(cache=True)
def sh_count(L):
    """Number of coefficients of an expansion of order L: (L + 1)^2."""
    return (L + 1) * (L + 1)


@njit(cache=True)
def sh_index(l, m):
    """Single index j = l (l + 1) + m."""
    return l * (l + 1) + m


@njit(cache=True)
def _check_order(L):
    if L < 0 or L > SH_LMAX:
        raise ValueError("spherical harmonics order out of range 0..SH_LMAX")


@njit(cache=True)
def sh_eval(L, x, y, z, out):
    """Fill out[:(L+1)^2] with Y_j(x, y, z) for a unit direction (x, y, z)."""
    _check_order(L)
    cm = 1.0   # Re (x + i y)^m
    sm = 0.0   # Im (x + i y)^m
    for m in range(L + 1):
        q2 = _LEG_DIAG[m]          # q_{l-2}, then q_{l-1}, q_l: normalised P_l^m / sin^m
        _sh_store(out, m, m, q2, cm, sm)
        if m < L:
            q1 = _LEG_A[m + 1, m] * z * q2
            _sh_store(out, m + 1, m, q1, cm, sm)
            for l in range(m + 2, L + 1):
                q = _LEG_A[l, m] * (z * q1 - _LEG_B[l, m] * q2)
                _sh_store(out, l, m, q, cm, sm)
                q2 = q1
                q1 = q
        c = cm * x - sm * y
        sm = sm * x + cm * y
        cm = c


@njit(cache=True, inline="always")
def _sh_store(out, l, m, q, cm, sm):
    j = l * (l + 1)
    if m == 0:
        out[j] = q
    else:
        out[j + m] = SQRT2 * q * cm
        out[j - m] = SQRT2 * q * sm


# ------------------------------------------------------------------------------------------------
# quadrature and projection
@njit(cache=True)
def legendre_and_derivative(n, z):
    """(P_n(z), P_n'(z)) for n >= 1 by Bonnet's recurrence k P_k = (2k - 1) z P_{k-1} - (k - 1) P_{k-2}."""
    p1 = 1.0
    p = z
    for k in range(2, n + 1):
        p0 = p1
        p1 = p
        p = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k
    return p, n * (z * p - p1) / (z * z - 1.0)


@njit(cache=True)
def gauss_legendre(n):
    """(nodes, weights) of the n-point Gauss-Legendre rule on [-1, 1], nodes ascending (Newton on P_n)."""
    x = np.empty(n)
    w = np.empty(n)
    for i in range((n + 1) // 2):
        z = math.cos(math.pi * (i + 0.75) / (n + 0.5))
        for _it in range(100):
            p, dp = legendre_and_derivative(n, z)
            dz = p / dp
            z -= dz
            if abs(dz) < 1e-16:
                break
        # derivative at the converged node
        _, dp = legendre_and_derivative(n, z)
        wk = 2.0 / ((1.0 - z * z) * dp * dp)
        x[i] = -z
        x[n - 1 - i] = z
        w[i] = wk
        w[n - 1 - i] = wk
    if n % 2 == 1:
        x[n // 2] = 0.0
    return x, w


@njit(cache=True)
def sh_quadrature(L, n_theta, n_phi):
    """(dirs (N, 3), weights (N,)), N = n_theta n_phi: Gauss-Legendre in cos(theta) x uniform phi.

    Exact for spherical polynomials of degree <= min(2 n_theta - 1, n_phi - 1); n_theta <= 0 or
    n_phi <= 0 pick L + 1 and 2L + 1, exact for products of two expansions of order L."""
    if n_theta <= 0:
        n_theta = L + 1
    if n_phi <= 0:
        n_phi = 2 * L + 1
    u, wu = gauss_legendre(n_theta)
    dirs = np.empty((n_theta * n_phi, 3))
    weights = np.empty(n_theta * n_phi)
    dphi = 2.0 * math.pi / n_phi
    k = 0
    for a in range(n_theta):
        s = math.sqrt(max(0.0, 1.0 - u[a] * u[a]))
        for b in range(n_phi):
            phi = (b + 0.5) * dphi
            dirs[k, 0] = s * math.cos(phi)
            dirs[k, 1] = s * math.sin(phi)
            dirs[k, 2] = u[a]
            weights[k] = wu[a] * dphi
            k += 1
    return dirs, weights


@njit(cache=True)
def sh_project(values, dirs, weights, L):
    """(n_coef, C) coefficients sum_k weights[k] Y_j(dirs[k]) values[k, c] of a function sampled on a rule."""
    n = sh_count(L)
    C = values.shape[1]
    out = np.zeros((n, C))
    y = np.empty(n)
    for k in range(dirs.shape[0]):
        sh_eval(L, dirs[k, 0], dirs[k, 1], dirs[k, 2], y)
        for j in range(n):
            f = weights[k] * y[j]
            for c in range(C):
                out[j, c] += f * values[k, c]
    return out


# ------------------------------------------------------------------------------------------------
# rotation (Ivanic-Ruedenberg 1996/1998)
@njit(cache=True, inline="always")
def _ir_P(out, i, l, a, b):
    """P^l_{i,a,b}: order-1 entry R1[i, .] times order l-1 entry R^{l-1}[a, .] (IR Table 2)."""
    j1 = 2                     # order-1 block centre (l = 1: j = 2 + m)
    jp = (l - 1) * l           # order l-1 block centre
    if b == l:
        return out[j1 + i, j1 + 1] * out[jp + a, jp + l - 1] - out[j1 + i, j1 - 1] * out[jp + a, jp - l + 1]
    if b == -l:
        return out[j1 + i, j1 + 1] * out[jp + a, jp - l + 1] + out[j1 + i, j1 - 1] * out[jp + a, jp + l - 1]
    return out[j1 + i, j1] * out[jp + a, jp + b]


@njit(cache=True)
def sh_rotation(L, R, out):
    """Fill out ((L+1)^2, (L+1)^2) with D(R): coefficients of f(R^T w) = D(R) @ coefficients of f."""
    _check_order(L)
    n = (L + 1) * (L + 1)
    out[:n, :n] = 0.0
    out[0, 0] = 1.0
    if L == 0:
        return
    # order 1: R in the (y, z, x) order of m = -1, 0, 1
    for i in range(3):
        ri = (i + 1) % 3       # m = i - 1 -> axis y, z, x
        for k in range(3):
            out[1 + i, 1 + k] = R[ri, (k + 1) % 3]
    for l in range(2, L + 1):
        jc = l * (l + 1)
        base = _ROT_OFF[l]
        w2 = 2 * l + 1
        for m in range(-l, l + 1):
            am = abs(m)
            for nn in range(-l, l + 1):
                k = base + (m + l) * w2 + (nn + l)
                u = _ROT_UVW[k, 0]
                v = _ROT_UVW[k, 1]
                w = _ROT_UVW[k, 2]
                r = 0.0
                if u != 0.0:
                    r += u * _ir_P(out, 0, l, m, nn)
                if v != 0.0:
                    if m == 0:
                        V = _ir_P(out, 1, l, 1, nn) + _ir_P(out, -1, l, -1, nn)
                    elif m > 0:
                        if m == 1:
                            V = SQRT2 * _ir_P(out, 1, l, 0, nn)
                        else:
                            V = _ir_P(out, 1, l, m - 1, nn) - _ir_P(out, -1, l, -m + 1, nn)
                    else:
                        if m == -1:
                            V = SQRT2 * _ir_P(out, -1, l, 0, nn)
                        else:
                            V = _ir_P(out, 1, l, m + 1, nn) + _ir_P(out, -1, l, -m - 1, nn)
                    r += v * V
                if w != 0.0 and am < l - 1:
                    if m > 0:
                        W = _ir_P(out, 1, l, m + 1, nn) + _ir_P(out, -1, l, -m - 1, nn)
                    else:
                        W = _ir_P(out, 1, l, m - 1, nn) - _ir_P(out, -1, l, -m + 1, nn)
                    r += w * W
                out[jc + m, jc + nn] = r


@njit(cache=True)
def sh_rotate(L, D, c, out):
    """out[:(L+1)^2] = D @ c block by block (D from ``sh_rotation``, of order >= L)."""
    out[0] = D[0, 0] * c[0]
    for l in range(1, L + 1):
        lo = l * l
        hi = (l + 1) * (l + 1)
        for a in range(lo, hi):
            s = 0.0
            for b in range(lo, hi):
                s += D[a, b] * c[b]
            out[a] = s


@njit(cache=True)
def rotation_to_frame(x, y, z, R):
    """R (3, 3) with rows x, y, z: world -> frame coordinates for a right-handed orthonormal frame."""
    for k in range(3):
        R[0, k] = x[k]
        R[1, k] = y[k]
        R[2, k] = z[k]


@njit(cache=True)
def rotation_z_to(axis, R):
    """A rotation R (3, 3) with R e_z = axis (unit): columns (t, b, axis), the right-handed frame of
    ``stages.core.geometry.frames.orthonormal_basis``."""
    t, b = orthonormal_basis(axis[0], axis[1], axis[2])
    for k in range(3):
        R[k, 0] = t[k]
        R[k, 1] = b[k]
        R[k, 2] = axis[k]


QuarterTurn = namedtuple("QuarterTurn", ["start", "cols", "vals", "t_start", "t_cols", "t_vals"])
QuarterTurn.__doc__ = """X = D(R_x(90 deg)) of some order, sparse (``quarter_turn_x``): rows of X in CSR form (start
(n + 1,), cols, vals), and rows of X^T the same way (t_*). About a quarter of the block entries are
non-zero (45 of 165 at order 4)."""


def quarter_turn_x(L) -> QuarterTurn:
    """The constant of ``sh_rotate_rows`` for orders up to L (module doc, Rotation)."""
    n = (L + 1) * (L + 1)
    X = np.zeros((n, n))
    sh_rotation(L, np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]), X)
    X[np.abs(X) < 1e-14] = 0.0     # the recurrence leaves rounding where the exact matrix has zeros

    def csr(M):
        nz = M != 0.0
        start = np.zeros(n + 1, np.int64)
        start[1:] = np.cumsum(nz.sum(axis=1))
        rows, cols = np.nonzero(nz)
        return start, cols.astype(np.int64), np.ascontiguousarray(M[rows, cols])

    return QuarterTurn(*csr(X), *csr(np.ascontiguousarray(X.T)))


@njit(cache=True, inline="always")
def _turn_table(L, ct, st, cs, k):
    """cs[k, m] = cos(m t), cs[k, L + 1 + m] = sin(m t) for m = 0..L, by angle addition from cos t, sin t."""
    c = 1.0
    s = 0.0
    for m in range(L + 1):
        cs[k, m] = c
        cs[k, L + 1 + m] = s
        c, s = c * ct - s * st, s * ct + c * st


@njit(cache=True, inline="always")
def _rotate_z(L, cs, k, c):
    """c <- Z(t) c in place (module doc, Rotation) with cs[k] = ``_turn_table`` of t: each order's
    (m, -m) pair turned by m t."""
    for l in range(1, L + 1):
        jc = l * (l + 1)
        for m in range(1, l + 1):
            cm = cs[k, m]
            sm = cs[k, L + 1 + m]
            p = c[jc + m]
            q = c[jc - m]
            c[jc + m] = cm * p - sm * q
            c[jc - m] = sm * p + cm * q


@njit(cache=True, inline="always")
def _sparse_apply(n, start, cols, vals, c, out):
    """out[:n] = M c for M in CSR form (rows < n only reference columns < n: M is block diagonal)."""
    for a in range(n):
        s = 0.0
        for k in range(start[a], start[a + 1]):
            s += vals[k] * c[cols[k]]
        out[a] = s


@njit(cache=True)
def sh_rotate_rows(L, R, X, C, out):
    """out[i, :(L+1)^2] = D(R) C[i, :(L+1)^2] for every row i of C, without building D (module doc,
    Rotation): z-y-z Euler angles of R; X a ``quarter_turn_x`` of order >= L; L <= SH_LMAX."""
    _check_order(L)
    n1 = math.sqrt(R[0, 2] * R[0, 2] + R[1, 2] * R[1, 2])
    n2 = math.sqrt(R[2, 0] * R[2, 0] + R[2, 1] * R[2, 1])
    cb = R[2, 2]
    if n1 > 1e-8 and n2 > 1e-8:
        sb = n1
        ca = R[0, 2] / n1
        sa = R[1, 2] / n1
        cg = -R[2, 0] / n2
        sg = R[2, 1] / n2
    else:   # b = 0 or pi: R = R_z(a) R_y(b)
        sb = 0.0
        cb = 1.0 if cb > 0.0 else -1.0
        h = math.sqrt(R[0, 1] * R[0, 1] + R[1, 1] * R[1, 1])
        ca = R[1, 1] / h
        sa = -R[0, 1] / h
        cg = 1.0
        sg = 0.0
    cs = stack_array(TURN_TABLES, np.float64).reshape((3, TURN_TABLE))
    _turn_table(L, cg, sg, cs, 0)
    _turn_table(L, cb, sb, cs, 1)
    _turn_table(L, ca, sa, cs, 2)
    v = stack_array(SH_COUNT_MAX, np.float64)
    w = stack_array(SH_COUNT_MAX, np.float64)
    n = (L + 1) * (L + 1)
    for i in range(C.shape[0]):
        for j in range(n):
            v[j] = C[i, j]
        _rotate_z(L, cs, 0, v)
        _sparse_apply(n, X.start, X.cols, X.vals, v, w)
        _rotate_z(L, cs, 1, w)
        _sparse_apply(n, X.t_start, X.t_cols, X.t_vals, w, v)
        _rotate_z(L, cs, 2, v)
        for j in range(n):
            out[i, j] = v[j]
