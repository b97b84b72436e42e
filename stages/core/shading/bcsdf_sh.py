"""The fibre BCSDF expanded in spherical harmonics: the table C_S of seed 001 §4.3, used in §5.3.1.

omega_o-space
-------------
The frame of the expansion: x = the fibre tangent t, y chosen so that the view direction lies in the
xy-plane with y . view >= 0, z = x cross y. A view direction at longitudinal angle theta_v
(= asin(view . t), in [-pi/2, pi/2]) is then (sin theta_v, cos theta_v, 0). ``omega_o_frame(t, w, R)``
builds the world -> omega_o-space rotation R (rows x, y, z; when w is parallel to t, any y) and returns
theta_v; ``stages.core.sh.sh_rotation(L, R, D)`` turns it into the SH rotation, so that the shading of
a world-space SH radiance c_T is (§5.3.1)

    L_multi = sum_j C_S[theta_v, j] (D(R) c_T)_j          per RGB channel.

Table
-----
    C_S[theta_v, j, c] = int_{S^2} Y_j(w_l) S(w_v, w_l) cos(theta_l) d w_l                  (§4.3)

with S the two-lobe BCSDF of ``stages.core.shading.bcsdf`` in loomlight's measure: the first argument
is the direction towards the viewer, the second towards the light, and S cos(theta_l) is what
``bcsdf_eval(p, t, w_view, w_light)`` returns. Hence sqrt(4 pi) C_S[theta_v, 0, c] is the albedo
``bcsdf_albedo(p, theta_v)`` = F_R + (1 - F_R) C_TT. Rows: ``n_theta`` (default 512, the paper's count)
equally spaced theta_v from -pi/2 to pi/2 inclusive, theta_k = -pi/2 + k pi/(n_theta - 1).
``bcsdf_sh_table(p, L, n_theta)`` -> float64 (n_theta, (L+1)^2, 3); ``bcsdf_sh_lookup(table, theta_v,
L, out)`` fills out ((L+1)^2, 3) by linear interpolation in theta_v (L may be below the table's order).

Quadrature (how it stays exact for 1-degree lobes)
--------------------------------------------------
In the BCSDF's own angles, w_l = (sin theta, cos theta cos phi, cos theta sin phi), d w = cos theta
d theta d phi, the view at phi = 0 and phi_d = phi - pi. Each lobe is a channel weight times
g(theta; -theta_v, beta) N(phi):
    R:  F_R(theta_v) / G(-theta_v, beta_R) x g(theta; -theta_v, beta_R) x 1/(2 pi)
    TT: (1 - F_R(theta_v)) C_TT / G(-theta_v, beta_TT) x g(theta; -theta_v, beta_TT) x N_TT(phi - pi)
- phi: on a circle of fixed theta, Y_j is a trigonometric polynomial of degree <= l in phi (a polynomial
  of degree l in the Cartesian components), so n = 2L + 2 uniform nodes phi_b = 2 pi b / n carry it exactly
  and the phi integral against N is the sum over the nodes with weights
  W_b = (m_0 + 2 sum_{k=1}^{L} m_k cos(k phi_b)) / n, m_k the
  Fourier moments of N (N_R: m_k = delta_k0; N_TT: (-1)^k int N_TT(psi) cos(k psi) d psi, computed once by
  Gauss-Legendre to rounding). No discretisation error in phi whatever gamma_TT.
- theta: Gauss-Legendre, 16 nodes per piece, over the window -theta_v +- 10 beta clipped to
  [-pi/2, pi/2] (the Gaussian outside is below e^-50 of its peak), pieces at most 2 beta and pi/8 wide.
Agreement with a brute-force 1200 x 144 midpoint quadrature of Y_j bcsdf_eval: 1e-12 (silk, fleece),
6e-10 (cotton, limited by the brute force). Linear interpolation between rows (``bcsdf_sh_lookup``)
adds up to 4e-5 at L = 5 on the five presets. Cost after compilation, one core, 512 rows: 0.15 s at
L = 5, 0.35 s at L = 8.
``bcsdf_sh_angle_rows(p, L, thetas)`` gives rows at arbitrary theta_v with the same quadrature.
"""
import math

import numpy as np
from numba import njit

from stages.core.geometry.frames import unit_rejection
from stages.core.sh import SH_LMAX, gauss_legendre, sh_count, sh_eval
from stages.core.shading.bcsdf import BETA_R, BETA_TT, C_R, C_TT, GAMMA_TT, TT_NORM, G_norm, fresnel_R, gauss

HALF_PI = 0.5 * math.pi
TWO_PI = 2.0 * math.pi
GL_PIECE_NODES = 16
WINDOW_DEVIATIONS = 10.0
VIEW_ALONG_TANGENT = 1e-12   # omega_o_frame: a view whose part normal to t is shorter is replaced


@njit(cache=True)
def bcsdf_theta_grid(n_theta):
    """The table's theta_v values: n_theta equally spaced over [-pi/2, pi/2], ends included."""
    out = np.empty(n_theta)
    for k in range(n_theta):
        out[k] = -HALF_PI + k * math.pi / (n_theta - 1)
    return out


@njit(cache=True)
def _tt_fourier_moments(gamma, I, L, out):
    """out[k] = int_{-pi}^{pi} N_TT(psi) cos(k psi) d psi, k = 0..L (Gauss-Legendre on [0, pi], 32 nodes
    per piece, pieces at most pi/8 and 2 gamma wide)."""
    x, w = gauss_legendre(32)
    for k in range(L + 1):
        out[k] = 0.0
    pieces = max(8, int(math.ceil(0.5 * math.pi / gamma)))
    half = 0.5 * math.pi / pieces
    for p in range(pieces):
        mid = (p + 0.5) * math.pi / pieces
        for a in range(x.shape[0]):
            psi = mid + half * x[a]
            g = 2.0 * half * w[a] * gauss(psi, 0.0, gamma)   # both halves of the even integrand
            for k in range(L + 1):
                out[k] += g * math.cos(k * psi)
    out[0] += 1.0 - I                                        # the uniform floor (1 - I)/(2 pi)


@njit(cache=True)
def _lobe_moments(theta_v, beta, L, cphi, sphi, wphi, gl_x, gl_w, y, acc):
    """acc[j] = int Y_j(theta, phi) g(theta; -theta_v, beta) cos^2(theta) W(phi) d theta, phi by nodes."""
    n = sh_count(L)
    for j in range(n):
        acc[j] = 0.0
    mu = -theta_v
    lo = max(-HALF_PI, mu - WINDOW_DEVIATIONS * beta)
    hi = min(HALF_PI, mu + WINDOW_DEVIATIONS * beta)
    if hi <= lo:
        return
    width = min(2.0 * beta, math.pi / 8.0)
    pieces = max(1, int(math.ceil((hi - lo) / width)))
    half = 0.5 * (hi - lo) / pieces
    for p in range(pieces):
        mid = lo + (2 * p + 1) * half
        for a in range(gl_x.shape[0]):
            th = mid + half * gl_x[a]
            st = math.sin(th)
            ct = math.cos(th)
            g = half * gl_w[a] * gauss(th, mu, beta) * ct * ct
            for b in range(cphi.shape[0]):
                sh_eval(L, st, ct * cphi[b], ct * sphi[b], y)
                f = g * wphi[b]
                for j in range(n):
                    acc[j] += f * y[j]


@njit(cache=True)
def _bcsdf_sh_rows(p, L, thetas):
    n = sh_count(L)
    out = np.empty((thetas.shape[0], n, 3))
    gl_x, gl_w = gauss_legendre(GL_PIECE_NODES)
    nphi = 2 * L + 2
    cphi = np.empty(nphi)
    sphi = np.empty(nphi)
    for b in range(nphi):
        cphi[b] = math.cos(TWO_PI * b / nphi)
        sphi[b] = math.sin(TWO_PI * b / nphi)
    # phi weights: R lobe (N_R = 1/(2 pi), moments delta_k0), TT lobe (moments of N_TT(phi - pi))
    w_r = np.full(nphi, 1.0 / nphi)
    mom = np.empty(L + 1)
    _tt_fourier_moments(p[GAMMA_TT], p[TT_NORM], L, mom)
    w_tt = np.empty(nphi)
    for b in range(nphi):
        s = mom[0]
        for k in range(1, L + 1):
            sign = -1.0 if k % 2 == 1 else 1.0
            s += 2.0 * sign * mom[k] * math.cos(k * TWO_PI * b / nphi)
        w_tt[b] = s / nphi
    y = np.empty(n)
    a_r = np.empty(n)
    a_tt = np.empty(n)
    for i in range(thetas.shape[0]):
        tv = thetas[i]
        _lobe_moments(tv, p[BETA_R], L, cphi, sphi, w_r, gl_x, gl_w, y, a_r)
        _lobe_moments(tv, p[BETA_TT], L, cphi, sphi, w_tt, gl_x, gl_w, y, a_tt)
        g_r = G_norm(-tv, p[BETA_R])
        g_tt = G_norm(-tv, p[BETA_TT])
        for c in range(3):
            f = fresnel_R(tv, p[C_R + c])
            k_r = f / g_r if g_r > 0.0 else 0.0
            k_tt = (1.0 - f) * p[C_TT + c] / g_tt if g_tt > 0.0 else 0.0
            for j in range(n):
                out[i, j, c] = k_r * a_r[j] + k_tt * a_tt[j]
    return out


def bcsdf_sh_table(p, L, n_theta=512):
    """C_S (n_theta, (L+1)^2, 3) of the packed BCSDF ``p`` (stages.core.shading.bcsdf.pack_bcsdf)."""
    if not 0 <= L <= SH_LMAX:
        raise ValueError(f"BCSDF SH order {L} outside 0..{SH_LMAX}")
    if n_theta < 2:
        raise ValueError(f"BCSDF SH table needs at least 2 theta_v rows, got {n_theta}")
    p = np.ascontiguousarray(p, dtype=np.float64)
    return _bcsdf_sh_rows(p, L, bcsdf_theta_grid(n_theta))


@njit(cache=True)
def bcsdf_sh_angle_rows(p, L, thetas):
    """C_S rows at arbitrary theta_v values (n, (L+1)^2, 3): the same quadrature as the table."""
    return _bcsdf_sh_rows(p, L, thetas)


@njit(cache=True)
def bcsdf_sh_lookup(table, theta_v, L, out):
    """out ((L+1)^2, 3) = C_S at theta_v, linear in theta_v between the table's rows (clamped to the ends)."""
    nt = table.shape[0]
    u = (theta_v + HALF_PI) * (nt - 1) / math.pi
    u = min(max(u, 0.0), nt - 1.0)
    i = min(int(u), nt - 2)
    t = u - i
    n = (L + 1) * (L + 1)
    for j in range(n):
        for c in range(3):
            out[j, c] = (1.0 - t) * table[i, j, c] + t * table[i + 1, j, c]


@njit(cache=True)
def omega_o_frame(t, w, R):
    """Fill R (3, 3) with the world -> omega_o-space rotation for unit tangent t and unit view w;
    returns theta_v = asin(w . t). Rows: x = t, y = the part of w normal to t (normalised), z = x cross y."""
    d = w[0] * t[0] + w[1] * t[1] + w[2] * t[2]
    d = min(1.0, max(-1.0, d))
    y0, y1, y2 = unit_rejection(w[0], w[1], w[2], t[0], t[1], t[2], d, VIEW_ALONG_TANGENT)
    R[0, 0] = t[0]
    R[0, 1] = t[1]
    R[0, 2] = t[2]
    R[1, 0] = y0
    R[1, 1] = y1
    R[1, 2] = y2
    R[2, 0] = t[1] * y2 - t[2] * y1
    R[2, 1] = t[2] * y0 - t[0] * y2
    R[2, 2] = t[0] * y1 - t[1] * y0
    return math.asin(d)
