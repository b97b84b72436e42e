"""Spherical Gaussians (SGs) and their spherical-harmonics expansion (seed 001 §2, §4.1, §4.3, §5.2.2).

The lobe
--------
    G(w; xi, lam) = exp(lam (w . xi - 1))                         axis xi (unit), sharpness lam >= 0
    M(lam) = int G dw = 2 pi (1 - exp(-2 lam)) / lam              (4 pi at lam = 0)       ``sg_mass``
A normalised SG is G / M (unit integral): a light of power P has radiance P G / M (stages.render.lights).

Product (§5.2.2): G(w; xi1, lam1) G(w; xi2, lam2) = s G(w; xi, lam) with
    xi_sum = lam1 xi1 + lam2 xi2,  lam = |xi_sum|,  xi = xi_sum / lam,  s = exp(lam - lam1 - lam2)
(``sg_product``; when xi_sum = 0 the product is the constant s and xi is +z).

Axes of the sum-of-SGs visibility (§4.1): ``spherical_fibonacci_axes(Q, angle)`` returns, q = 1..Q,
    xi'_q = (r_q cos phi_q, r_q sin phi_q, z_q),  r_q = sqrt(1 - z_q^2),
    phi_q = 4 pi q / (1 + sqrt5),  z_q = 1 - (q - 1)/Q,
turned by ``angle`` about +z (counter-clockwise seen from +z: x -> (cos a, sin a, 0)). As printed, the
formula covers the upper hemisphere only (z from 1 down to 1/Q): the paper assumes light from above
the fabric. It is kept exactly as printed.

SH expansion (§4.3)
-------------------
A normalised SG about +z is zonal; its only coefficients are (j = l (l + 1))

    C_G[lam, l] = int G(w; z, lam)/M(lam) Y_{l,0}(w) dw = sqrt((2l + 1)/(4 pi)) i_l(lam) / i_0(lam)

with i_l the modified spherical Bessel functions (int_{-1}^{1} e^{lam u} P_l(u) du = 2 i_l(lam) and
M = 4 pi e^{-lam} i_0(lam)). ``sg_zonal_coefficients`` computes the ratios r_l = i_l / i_0 directly,
never the (overflowing) functions: rho_l = i_l / i_{l-1} = lam / (2l + 1 + lam rho_{l+1}) by the
backward recurrence (a continued fraction) started at l = L + 30 + 8 sqrt(lam) with rho = 0 -- the
start error is damped by ~exp(-(start^2 - L^2)/lam) < e^-64 -- and r_l = rho_1 ... rho_l. Exact
to rounding for every lam >= 0 (r_l = 0 for l > 0 at lam = 0; r_l -> 1 as lam -> infinity, the delta).
With the zonal rotation formula the expansion of an SG of any axis is
    c_{l,m} = C_G[lam, l] sqrt(4 pi / (2l + 1)) Y_{l,m}(xi) = r_l(lam) Y_{l,m}(xi)   ``sg_sh_coefficients``.

Table (the paper's supplement, which chose its lam values and interpolation, is lost; this is ours):
``SG_LAMBDA_GRID`` = lam = 0 followed by 127 values log-spaced from 1e-2 to 1e4 (ratio 10^(6/126),
step h = 0.1097 in ln lam); ``build_sg_table(L)`` -> (grid, table (128, L + 1)).
``sg_table_lookup(grid, table, lam, L, out)`` interpolates
  - lam in [1e-2, 1e4]: quintic Lagrange through the six nearest nodes in ln lam (error ~ h^6 f^(6)),
  - lam in [0, 1e-2): quadratic in lam through lam = 0, grid[1], grid[2] (C_G[lam, l] ~ lam^l there),
  - lam > 1e4: no table, the direct computation (cost ~ 8 sqrt(lam) divisions).
Measured maximum error against the direct computation, l <= 8, over 20000 lam log-spaced in
[1e-4, 1e4] and 2000 uniform in [0, 1e-2]: 1.05e-7 absolute (1.2e-7 relative to the coefficient's
limit sqrt((2l+1)/(4 pi))), at l = 8 near lam = 13; below 1e-2 it is 2e-9 (cubic Lagrange in ln lam
instead would give 4.5e-6). tests/core/shading/test_sg.py holds it under 2e-7.
"""
import math

import numpy as np
from numba import njit

from stages.core.geometry.stack import stack_array
from stages.core.sh import SH_LMAX, sh_eval

SH_LMAX1 = SH_LMAX + 1

TWO_PI = 2.0 * math.pi
FOUR_PI = 4.0 * math.pi
INV_SQRT_4PI = 1.0 / math.sqrt(FOUR_PI)


@njit(cache=True)
def sg_eval(w, axis, lam):
    """G(w; axis, lam) = exp(lam (w . axis - 1))."""
    return math.exp(lam * (w[0] * axis[0] + w[1] * axis[1] + w[2] * axis[2] - 1.0))


@njit(cache=True)
def sg_mass(lam):
    """M(lam) = int G dw = 2 pi (1 - exp(-2 lam)) / lam; 4 pi (1 - lam) to rounding below 1e-12."""
    if lam < 1e-12:
        return FOUR_PI * (1.0 - lam)
    return TWO_PI * (-math.expm1(-2.0 * lam)) / lam


@njit(cache=True)
def sg_product(axis1, lam1, axis2, lam2):
    """(xi_x, xi_y, xi_z, lam, scale) with G(.; axis1, lam1) G(.; axis2, lam2) = scale G(.; xi, lam)."""
    sx = lam1 * axis1[0] + lam2 * axis2[0]
    sy = lam1 * axis1[1] + lam2 * axis2[1]
    sz = lam1 * axis1[2] + lam2 * axis2[2]
    lam = math.sqrt(sx * sx + sy * sy + sz * sz)
    scale = math.exp(lam - lam1 - lam2)
    if lam <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, scale
    return sx / lam, sy / lam, sz / lam, lam, scale


@njit(cache=True)
def spherical_fibonacci_axes(Q, angle):
    """(Q, 3) unit axes xi'_q of §4.1 (q = 1..Q) turned by ``angle`` about +z."""
    out = np.empty((Q, 3))
    golden = 1.0 + math.sqrt(5.0)
    ca = math.cos(angle)
    sa = math.sin(angle)
    for i in range(Q):
        q = i + 1
        z = 1.0 - (q - 1.0) / Q
        r = math.sqrt(max(0.0, 1.0 - z * z))
        phi = 4.0 * math.pi * q / golden
        x = r * math.cos(phi)
        y = r * math.sin(phi)
        out[i, 0] = ca * x - sa * y
        out[i, 1] = sa * x + ca * y
        out[i, 2] = z
    return out


# ------------------------------------------------------------------------------------------------
# SH expansion
@njit(cache=True)
def sg_bessel_ratios(lam, L, out):
    """out[l] = r_l = i_l(lam) / i_0(lam), l = 0..L (backward recurrence, see the module doc)."""
    start = L + 30 + int(8.0 * math.sqrt(lam))
    rho = 0.0
    for l in range(start, L, -1):
        rho = lam / (2.0 * l + 1.0 + lam * rho)
    # rho = rho_{L+1}; continue down to rho_1, storing rho_l in out[l]
    for l in range(L, 0, -1):
        rho = lam / (2.0 * l + 1.0 + lam * rho)
        out[l] = rho
    out[0] = 1.0
    for l in range(1, L + 1):
        out[l] *= out[l - 1]


@njit(cache=True)
def sg_zonal_coefficients(lam, L, out):
    """out[l] = C_G[lam, l] = int G(w; z, lam)/M(lam) Y_{l,0}(w) dw, l = 0..L (direct, exact)."""
    sg_bessel_ratios(lam, L, out)
    for l in range(L + 1):
        out[l] *= math.sqrt((2.0 * l + 1.0) / FOUR_PI)


def _lambda_grid():
    g = np.empty(128)
    g[0] = 0.0
    g[1:] = np.logspace(-2.0, 4.0, 127)
    return g


SG_LAMBDA_GRID = _lambda_grid()


@njit(cache=True)
def _build_table(grid, L):
    table = np.empty((grid.shape[0], L + 1))
    row = np.empty(L + 1)
    for i in range(grid.shape[0]):
        sg_zonal_coefficients(grid[i], L, row)
        for l in range(L + 1):
            table[i, l] = row[l]
    return table


def build_sg_table(L):
    """(SG_LAMBDA_GRID (128,), table (128, L + 1)): C_G[lam, l] at every grid value."""
    if not 0 <= L <= SH_LMAX:
        raise ValueError(f"SG table order {L} outside 0..{SH_LMAX}")
    grid = SG_LAMBDA_GRID.copy()
    return grid, _build_table(grid, L)


@njit(cache=True)
def sg_table_lookup(grid, table, lam, L, out):
    """out[l] ~ C_G[lam, l], l = 0..L, interpolated in ``table`` (grid laid out as SG_LAMBDA_GRID)."""
    n_log = grid.shape[0] - 1            # log-spaced nodes grid[1:]
    g1 = grid[1]
    if lam > grid[n_log]:
        sg_zonal_coefficients(lam, L, out)
        return
    if lam < g1:
        # quadratic in lam through lam = 0, grid[1], grid[2] (C_G ~ lam^l near 0)
        x = max(lam, 0.0)
        g2 = grid[2]
        w0 = (x - g1) * (x - g2) / (g1 * g2)
        w1 = x * (x - g2) / (g1 * (g1 - g2))
        w2 = x * (x - g1) / (g2 * (g2 - g1))
        for l in range(L + 1):
            out[l] = w0 * table[0, l] + w1 * table[1, l] + w2 * table[2, l]
        return
    h = math.log(grid[2] / g1)
    u = math.log(lam / g1) / h           # position in units of the log step, 0 at grid[1]
    s = int(math.floor(u)) - 2           # stencil s..s+5 (log-node index), clamped inside the grid
    s = min(max(s, 0), n_log - 6)
    x = u - s                            # position inside the stencil, nodes at 0..5
    # quintic Lagrange weights
    d0 = x
    d1 = x - 1.0
    d2 = x - 2.0
    d3 = x - 3.0
    d4 = x - 4.0
    d5 = x - 5.0
    w0 = -d1 * d2 * d3 * d4 * d5 / 120.0
    w1 = d0 * d2 * d3 * d4 * d5 / 24.0
    w2 = -d0 * d1 * d3 * d4 * d5 / 12.0
    w3 = d0 * d1 * d2 * d4 * d5 / 12.0
    w4 = -d0 * d1 * d2 * d3 * d5 / 24.0
    w5 = d0 * d1 * d2 * d3 * d4 / 120.0
    for l in range(L + 1):
        out[l] = (w0 * table[s + 1, l] + w1 * table[s + 2, l] + w2 * table[s + 3, l]
                  + w3 * table[s + 4, l] + w4 * table[s + 5, l] + w5 * table[s + 6, l])


@njit(cache=True)
def sg_sh_coefficients(axis, lam, L, out):
    """out[:(L+1)^2]: SH coefficients of the normalised SG G(w; axis, lam)/M(lam) (direct, exact)."""
    sh_eval(L, axis[0], axis[1], axis[2], out)
    r = stack_array(SH_LMAX1, np.float64)   # (on the machine stack: callable without reference counting)
    sg_bessel_ratios(lam, L, r)
    for l in range(1, L + 1):
        for j in range(l * l, (l + 1) * (l + 1)):
            out[j] *= r[l]


@njit(cache=True)
def sg_sh_coefficients_lookup(grid, table, axis, lam, L, out):
    """``sg_sh_coefficients`` with C_G interpolated in a table of ``build_sg_table`` (render time)."""
    sh_eval(L, axis[0], axis[1], axis[2], out)
    c = np.empty(L + 1)
    sg_table_lookup(grid, table, lam, L, c)
    for l in range(L + 1):
        f = c[l] * math.sqrt(FOUR_PI / (2.0 * l + 1.0))
        for j in range(l * l, (l + 1) * (l + 1)):
            out[j] *= f
