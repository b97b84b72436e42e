"""The two-lobe fibre BCSDF of Khungurn et al. 2015 (R and TT), as used by seed 001 (§2, §4.3, App. A).

Frame
-----
Fibre-local, x = fibre tangent ``t``. For a unit direction w: theta = asin(w . t) in [-pi/2, pi/2]
(longitudinal angle from the normal plane), phi = the azimuth around the fibre. Only the azimuth
*difference* enters, so any orthonormal (y, z) completing x gives the same values: kernels take
the world tangent and world directions.

The function (per RGB channel)
------------------------------
    S(wi, wo) = F_R(theta_i) M_R(theta_i, theta_o) N_R
              + (1 - F_R(theta_i)) C_TT M_TT(theta_i, theta_o) N_TT(phi_d)

- F_R(theta_i) = C_R + (1 - C_R)(1 - |cos theta_i|)^5                  (Fresnel-like weight)
- M_p = g(theta_o; -theta_i, beta_p) / G(-theta_i, beta_p)              (longitudinal lobe)
  with g the normalised 1D Gaussian and G(mu, beta) = int_{-pi/2}^{pi/2} g(theta; mu, beta) cos^2(theta),
  so that int M_p cos^2(theta_o) d theta_o = 1 exactly.
- N_R = 1 / (2 pi); N_TT(phi_d) = g(phi_d; 0, gamma_TT) + (1 - I) / (2 pi), phi_d = wrap(phi_o - phi_i - pi)
  into (-pi, pi], I = erf(pi / (sqrt 2 gamma_TT)) (so N_TT integrates to 1 over the circle).

Measure (the convention loomlight uses, proven by ``tests/test_bcsdf.py::test_energy``)
-----------------------------------------------------------------------------------------
``wi`` is the direction towards the viewer (the previous path vertex), ``wo`` the direction towards
the light -- Mitsuba's naming. The radiance leaving a fibre towards wi is

    L(wi) = int S(wi, wo) L_in(wo) cos(theta_o) d wo,

i.e. the value multiplied with incident radiance is S cos(theta_o) (projected measure of a curve:
the fibre's projected width per unit length scales with cos theta). Because every lobe is
normalised in its second argument, int S(wi, wo) cos(theta_o) d wo = F_R + (1 - F_R) C_TT per channel:
exactly 1 for C_TT = 1 (no truncation loss -- the Gaussians are renormalised on the interval and on
the circle), which is what makes a cloud of non-absorbing fibres in a uniform environment glow at the
environment radiance (the furnace test). The fibre does not shadow itself: the BCSDF already
integrates over its cross-section (the renderer skips the scattering segment's own neighbourhood).

Sampling
--------
Pick a lobe with probability proportional to its channel-mean weight (mean F_R, mean (1 - F_R) C_TT);
theta_o from the lobe's own longitudinal density q_p = g(theta_o) cos^2(theta_o) / G_p (``sample_longitudinal``:
draws of the Gaussian around -theta_i truncated to [-pi/2, pi/2], by inversion of its CDF, kept with
probability cos^2 theta_o), so that the sample weight S cos / pdf is the lobe's albedo share and nothing
else; where that rejection would keep fewer than ``EXACT_ACCEPTANCE_MIN`` of its draws (a narrow lobe
against the pole at grazing incidence), q_p = g / Z_p, the truncated Gaussian itself. phi_o uniform (R) or
from the mixture "truncated Gaussian with probability I, uniform otherwise" (TT, which is exactly N_TT).
``bcsdf_pdf`` is the full mixture density in solid angle:
    pdf(wo) = sum_p P_p * q_p(theta_o) * N_p(phi) / cos(theta_o),
Z_p = the Gaussian's mass inside [-pi/2, pi/2]. Why exact: sampling the Gaussian alone left a weight
Z_p / G_p cos^2(theta_o) of up to ~20 near grazing incidence, and in dense cloth those weights multiply along
the hundreds of fibre events of a path: a white cloth's estimate was heavy-tailed (0.64-0.73 over seeds for a
true 1, tests/render/test_yarn_colour.py's cloth).

Interface (the one every model in ``stages.core.shading`` has): parameters p = the packed BCSDF,
frame = the unit fibre tangent t.
    bcsdf_eval(p, t, wi, wo) -> (r, g, b)                S cos(theta_o)
    bcsdf_pdf(p, t, wi, wo) -> pdf
    bcsdf_sample(p, t, wi, u0, u1, u2) -> (wo, r, g, b, pdf)
The ``*_ctx`` forms compute everything that depends on wi once per scattering vertex (integrators).

Parameters, packed (float64[BCSDF_SIZE]):
    0:3 C_R (rgb), 3:6 C_TT (rgb), 6 beta_R, 7 beta_TT, 8 gamma_TT (radians), 9 I_TT = erf(pi/(sqrt2 gamma_TT)).
"""
import math

import numpy as np
from numba import njit

from stages.core.geometry.frames import orthonormal_basis
from stages.core.rng import uniform

# the packed row (pack_bcsdf), slot by slot
C_R = 0           # R lobe colour, 3 slots
C_TT = 3          # TT lobe colour, 3 slots
BETA_R = 6        # R longitudinal width (radians)
BETA_TT = 7       # TT longitudinal width (radians)
GAMMA_TT = 8      # TT azimuthal width (radians)
TT_NORM = 9       # I = erf(pi / (sqrt(2) gamma_TT)), N_TT's normaliser on (-pi, pi]
BCSDF_SIZE = 10
SQRT2 = math.sqrt(2.0)
INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
HALF_PI = 0.5 * math.pi
TWO_PI = 2.0 * math.pi
EXACT_ACCEPTANCE_MIN = 0.01   # sample theta_o exactly (rejection) where cos^2 accepts >= 1 % (<= 100 tries)
MAX_REJECTIONS = 2048         # tries of one exact draw; then the last try (a bias below 0.99^2048 = 1e-9)
U53 = 9007199254740992.0      # 2^53: a uniform's bits as an integer key of the rejection's random numbers

# 24-point Gauss-Legendre nodes/weights on [-1, 1] for G(mu, beta) near the interval ends.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


def pack_bcsdf(c_r, c_tt, beta_r_deg, beta_tt_deg, gamma_tt_deg):
    """Pack one material: colours in [0, 1]^3, lobe widths in degrees (> 0)."""
    p = np.zeros(BCSDF_SIZE)
    p[C_R:C_R + 3] = c_r
    p[C_TT:C_TT + 3] = c_tt
    p[BETA_R] = math.radians(beta_r_deg)
    p[BETA_TT] = math.radians(beta_tt_deg)
    p[GAMMA_TT] = math.radians(gamma_tt_deg)
    p[TT_NORM] = math.erf(math.pi / (SQRT2 * p[GAMMA_TT]))
    return p


# ------------------------------------------------------------------------------------------------
# scalar pieces
@njit(cache=True)
def gauss(x, mu, beta):
    d = (x - mu) / beta
    return INV_SQRT_2PI / beta * math.exp(-0.5 * d * d)


@njit(cache=True)
def gauss_cdf(x, mu, beta):
    """Normal CDF with mean mu and deviation beta (erfc form, accurate in the tails)."""
    return 0.5 * math.erfc(-(x - mu) / (SQRT2 * beta))


@njit(cache=True)
def gauss_mass(a, b, mu, beta):
    """Mass of N(mu, beta^2) inside [a, b], accurate when both ends are in one tail."""
    za = (a - mu) / (SQRT2 * beta)
    zb = (b - mu) / (SQRT2 * beta)
    if za > 0.0:
        return 0.5 * (math.erfc(za) - math.erfc(zb))
    if zb < 0.0:
        return 0.5 * (math.erfc(-zb) - math.erfc(-za))
    return 0.5 * (math.erf(zb) - math.erf(za))


@njit(cache=True)
def std_normal_quantile(p):
    """Inverse standard normal CDF (Acklam's rational approximation + one Halley step, ~1e-15)."""
    if p <= 0.0:
        return -40.0
    if p >= 1.0:
        return 40.0
    a0, a1, a2, a3, a4, a5 = (-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                              1.383577518672690e+02, -3.066479806614716e+01, 2.506628277459239e+00)
    b0, b1, b2, b3, b4 = (-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                          6.680131188771972e+01, -1.328068155288572e+01)
    c0, c1, c2, c3, c4, c5 = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                              -2.549732539343734e+00, 4.374664141464968e+00, 2.938163982698783e+00)
    d0, d1, d2, d3 = 7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00, 3.754408661907416e+00
    plow = 0.02425
    if p < plow:
        q = math.sqrt(-2.0 * math.log(p))
        x = (((((c0 * q + c1) * q + c2) * q + c3) * q + c4) * q + c5) / ((((d0 * q + d1) * q + d2) * q + d3) * q + 1.0)
    elif p <= 1.0 - plow:
        q = p - 0.5
        r = q * q
        x = ((((((a0 * r + a1) * r + a2) * r + a3) * r + a4) * r + a5) * q
             / (((((b0 * r + b1) * r + b2) * r + b3) * r + b4) * r + 1.0))
    else:
        q = math.sqrt(-2.0 * math.log(1.0 - p))
        x = -(((((c0 * q + c1) * q + c2) * q + c3) * q + c4) * q + c5) / ((((d0 * q + d1) * q + d2) * q + d3) * q + 1.0)
    # Halley refinement against the erfc-based CDF
    e = 0.5 * math.erfc(-x / SQRT2) - p
    u = e * math.sqrt(2.0 * math.pi) * math.exp(0.5 * x * x)
    return x - u / (1.0 + 0.5 * x * u)


@njit(cache=True)
def sample_truncated_gauss(u, mu, beta, a, b):
    """x in [a, b] with density g(x; mu, beta) / mass, by inversion of the CDF (one uniform)."""
    za = (a - mu) / beta
    zb = (b - mu) / beta
    if za > 0.0:  # whole interval in the upper tail: invert the mirrored CDF for precision
        qa = 0.5 * math.erfc(za / SQRT2)
        qb = 0.5 * math.erfc(zb / SQRT2)
        z = -std_normal_quantile(qa - u * (qa - qb))
    else:
        pa = 0.5 * math.erfc(-za / SQRT2)
        pb = 0.5 * math.erfc(-zb / SQRT2)
        z = std_normal_quantile(pa + u * (pb - pa))
    x = mu + beta * z
    return min(max(x, a), b)


@njit(cache=True)
def longitudinal_density(theta_o, mu, beta, exact, inv_norm):
    """Density in theta of ``sample_longitudinal``: g(theta) cos^2(theta) / G when ``exact``, else
    g(theta) / Z (``inv_norm`` = 1 / G or 1 / Z, ``sampling_normaliser``)."""
    d = gauss(theta_o, mu, beta) * inv_norm
    if exact:
        c = math.cos(theta_o)
        d *= c * c
    return d


@njit(cache=True)
def sampling_normaliser(mu, beta):
    """(exact, 1 / normaliser) of the longitudinal sampler of a lobe g(theta; mu, beta) on [-pi/2, pi/2]:
    exact (density g cos^2 / G, the lobe's own M, so the sample weight carries no cos^2 / E[cos^2] ratio)
    where rejection accepts at least EXACT_ACCEPTANCE_MIN of the Gaussian's draws (G / Z), else the
    truncated Gaussian itself (g / Z). (False, 0) for a lobe with no mass."""
    z = gauss_mass(-HALF_PI, HALF_PI, mu, beta)
    if z <= 0.0:
        return False, 0.0
    g = G_norm(mu, beta)
    if g >= EXACT_ACCEPTANCE_MIN * z:
        return True, 1.0 / g
    return False, 1.0 / z


@njit(cache=True)
def sample_longitudinal(u, mu, beta, exact):
    """theta_o in [-pi/2, pi/2] with density ``longitudinal_density``. Exact: truncated-Gaussian draws
    kept with probability cos^2(theta); the first draw inverts ``u``, the next ones and the acceptance
    tests use uniforms hashed from u's bits (``stages.core.rng``), so the result is a function of u."""
    th = sample_truncated_gauss(u, mu, beta, -HALF_PI, HALF_PI)
    if not exact:
        return th
    key = int(u * U53)
    for k in range(MAX_REJECTIONS):
        c = math.cos(th)
        if uniform(key, k, 0) < c * c:
            return th
        th = sample_truncated_gauss(uniform(key, k, 1), mu, beta, -HALF_PI, HALF_PI)
    return th


@njit(cache=True)
def G_norm(mu, beta):
    """G(mu, beta) = int_{-pi/2}^{pi/2} g(theta; mu, beta) cos^2 theta d theta.

    Closed form 1/2 (1 + exp(-2 beta^2) cos 2mu) when the Gaussian lies inside the interval
    (7 deviations: the mass outside is < 3e-12); otherwise 24-point Gauss-Legendre on each side of
    the mean over the window [mu - 9 beta, mu + 9 beta] clipped to the interval.
    """
    if abs(mu) + 7.0 * beta <= HALF_PI:
        return 0.5 * (1.0 + math.exp(-2.0 * beta * beta) * math.cos(2.0 * mu))
    lo = max(-HALF_PI, mu - 9.0 * beta)
    hi = min(HALF_PI, mu + 9.0 * beta)
    if hi <= lo:
        return 0.0
    cut = min(max(mu, lo), hi)  # split at the mean: each piece is at most 9 deviations wide
    return _gl_gauss_cos2(lo, cut, mu, beta) + _gl_gauss_cos2(cut, hi, mu, beta)


@njit(cache=True)
def _gl_gauss_cos2(lo, hi, mu, beta):
    if hi <= lo:
        return 0.0
    half = 0.5 * (hi - lo)
    mid = 0.5 * (hi + lo)
    s = 0.0
    for k in range(_GL_X.shape[0]):
        th = mid + half * _GL_X[k]
        c = math.cos(th)
        s += _GL_W[k] * gauss(th, mu, beta) * c * c
    return s * half


@njit(cache=True)
def longitudinal_M(theta_i, theta_o, beta):
    """M_p(theta_i, theta_o) = g(theta_o; -theta_i, beta) / G(-theta_i, beta)."""
    G = G_norm(-theta_i, beta)
    if G <= 0.0:
        return 0.0
    return gauss(theta_o, -theta_i, beta) / G


@njit(cache=True)
def wrap_pi(x):
    """Wrap an angle into (-pi, pi]."""
    y = x + math.pi
    y = y - TWO_PI * math.floor(y / TWO_PI)   # in [0, 2 pi)
    if y <= 0.0:
        y += TWO_PI
    return y - math.pi


@njit(cache=True)
def azimuthal_N_tt(phi_d, gamma, I):
    """N_TT(phi_d) = g(phi_d; 0, gamma) + (1 - I)/(2 pi) on (-pi, pi]."""
    return gauss(phi_d, 0.0, gamma) + (1.0 - I) / TWO_PI


@njit(cache=True)
def fresnel_R(theta_i, c):
    m = 1.0 - abs(math.cos(theta_i))
    m2 = m * m
    return c + (1.0 - c) * m2 * m2 * m


# ------------------------------------------------------------------------------------------------
# frame helpers: (theta, phi) of a world direction about tangent t
@njit(cache=True)
def fiber_frame(t):
    """An orthonormal (y, z) completing x = t (stages.core.geometry.frames)."""
    (y0, y1, y2), (z0, z1, z2) = orthonormal_basis(t[0], t[1], t[2])
    return y0, y1, y2, z0, z1, z2


@njit(cache=True)
def angles(t, w):
    """(theta, phi) of unit w in the fibre frame of unit tangent t."""
    y0, y1, y2, z0, z1, z2 = fiber_frame(t)
    sx = w[0] * t[0] + w[1] * t[1] + w[2] * t[2]
    sx = min(1.0, max(-1.0, sx))
    wy = w[0] * y0 + w[1] * y1 + w[2] * y2
    wz = w[0] * z0 + w[1] * z1 + w[2] * z2
    return math.asin(sx), math.atan2(wz, wy)


@njit(cache=True)
def from_angles(t, theta, phi):
    y0, y1, y2, z0, z1, z2 = fiber_frame(t)
    st = math.sin(theta)
    ct = math.cos(theta)
    cp = math.cos(phi) * ct
    sp = math.sin(phi) * ct
    w = np.empty(3)
    w[0] = st * t[0] + cp * y0 + sp * z0
    w[1] = st * t[1] + cp * y1 + sp * z1
    w[2] = st * t[2] + cp * y2 + sp * z2
    n = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    return w / n


# ------------------------------------------------------------------------------------------------
# the BCSDF in angle form
@njit(cache=True)
def bcsdf_eval_angles(p, theta_i, phi_i, theta_o, phi_o):
    """S(wi, wo) per channel (r, g, b) from fibre-frame angles."""
    m_r = longitudinal_M(theta_i, theta_o, p[BETA_R])
    m_tt = longitudinal_M(theta_i, theta_o, p[BETA_TT])
    phi_d = wrap_pi(phi_o - phi_i - math.pi)
    n_tt = azimuthal_N_tt(phi_d, p[GAMMA_TT], p[TT_NORM])
    n_r = 1.0 / TWO_PI
    f0 = fresnel_R(theta_i, p[C_R])
    f1 = fresnel_R(theta_i, p[C_R + 1])
    f2 = fresnel_R(theta_i, p[C_R + 2])
    s0 = f0 * m_r * n_r + (1.0 - f0) * p[C_TT] * m_tt * n_tt
    s1 = f1 * m_r * n_r + (1.0 - f1) * p[C_TT + 1] * m_tt * n_tt
    s2 = f2 * m_r * n_r + (1.0 - f2) * p[C_TT + 2] * m_tt * n_tt
    return s0, s1, s2


@njit(cache=True)
def lobe_probability_R(p, theta_i):
    """Probability of sampling the R lobe (channel-mean weights); -1 when both lobes are black."""
    a_r = 0.0
    a_tt = 0.0
    for c in range(3):
        f = fresnel_R(theta_i, p[C_R + c])
        a_r += f
        a_tt += (1.0 - f) * p[C_TT + c]
    if a_r + a_tt <= 0.0:
        return -1.0
    return a_r / (a_r + a_tt)


@njit(cache=True)
def bcsdf_pdf_angles(p, theta_i, phi_i, theta_o, phi_o):
    """Solid-angle density of ``bcsdf_sample`` at (theta_o, phi_o)."""
    pr = lobe_probability_R(p, theta_i)
    if pr < 0.0:
        return 0.0
    co = math.cos(theta_o)
    if co <= 0.0:
        return 0.0
    pdf = 0.0
    if pr > 0.0:
        exact, inv = sampling_normaliser(-theta_i, p[BETA_R])
        pdf += pr * longitudinal_density(theta_o, -theta_i, p[BETA_R], exact, inv) / TWO_PI
    if pr < 1.0:
        exact, inv = sampling_normaliser(-theta_i, p[BETA_TT])
        phi_d = wrap_pi(phi_o - phi_i - math.pi)
        pdf += ((1.0 - pr) * longitudinal_density(theta_o, -theta_i, p[BETA_TT], exact, inv)
                * azimuthal_N_tt(phi_d, p[GAMMA_TT], p[TT_NORM]))
    return pdf / co


@njit(cache=True)
def bcsdf_sample_angles(p, theta_i, phi_i, u0, u1, u2):
    """Sample (theta_o, phi_o); u0 picks the lobe, u1 theta, u2 phi. Returns (theta_o, phi_o, ok)."""
    pr = lobe_probability_R(p, theta_i)
    if pr < 0.0:
        return 0.0, 0.0, False
    if u0 < pr:
        return _sample_lobe_angles(p, theta_i, phi_i, True, sampling_normaliser(-theta_i, p[BETA_R])[0], u1, u2)
    return _sample_lobe_angles(p, theta_i, phi_i, False, sampling_normaliser(-theta_i, p[BETA_TT])[0], u1, u2)


@njit(cache=True)
def _sample_lobe_angles(p, theta_i, phi_i, lobe_r, exact, u1, u2):
    """(theta_o, phi_o, True) from lobe R (``lobe_r``) or TT: theta by ``sample_longitudinal`` (u1),
    phi uniform (R) or from N_TT (u2)."""
    theta_o = sample_longitudinal(u1, -theta_i, p[BETA_R] if lobe_r else p[BETA_TT], exact)
    return theta_o, sample_azimuth(p, lobe_r, phi_i, u2), True


@njit(cache=True)
def sample_azimuth(p, lobe_r, phi_i, u):
    """phi_o of lobe R (uniform) or TT (N_TT: the truncated Gaussian around phi_i + pi with probability I,
    uniform otherwise -- exactly N_TT) from one uniform."""
    if lobe_r:
        return wrap_pi(TWO_PI * u)
    I = p[TT_NORM]
    if u < I:
        phi_d = sample_truncated_gauss(u / I, 0.0, p[GAMMA_TT], -math.pi, math.pi)
    else:
        phi_d = TWO_PI * (u - I) / (1.0 - I) - math.pi
    return wrap_pi(phi_d + phi_i + math.pi)


# ------------------------------------------------------------------------------------------------
# world-space interface for the integrator
@njit(cache=True)
def bcsdf_eval(p, t, wi, wo):
    """S(wi, wo) cos(theta_o): the factor that multiplies radiance arriving from wo (see Measure)."""
    ti, phi_i = angles(t, wi)
    to, phi_o = angles(t, wo)
    s0, s1, s2 = bcsdf_eval_angles(p, ti, phi_i, to, phi_o)
    c = math.cos(to)
    return s0 * c, s1 * c, s2 * c


@njit(cache=True)
def bcsdf_pdf(p, t, wi, wo):
    ti, phi_i = angles(t, wi)
    to, phi_o = angles(t, wo)
    return bcsdf_pdf_angles(p, ti, phi_i, to, phi_o)


@njit(cache=True)
def bcsdf_sample(p, t, wi, u0, u1, u2):
    """(wo, weight r, g, b = S cos(theta_o) / pdf, pdf); pdf = 0 when nothing can be sampled."""
    ti, phi_i = angles(t, wi)
    to, phi_o, ok = bcsdf_sample_angles(p, ti, phi_i, u0, u1, u2)
    if not ok:
        return np.zeros(3), 0.0, 0.0, 0.0, 0.0
    wo = from_angles(t, to, phi_o)
    pdf = bcsdf_pdf_angles(p, ti, phi_i, to, phi_o)
    if pdf <= 0.0:
        return wo, 0.0, 0.0, 0.0, 0.0
    s0, s1, s2 = bcsdf_eval_angles(p, ti, phi_i, to, phi_o)
    c = math.cos(to) / pdf
    return wo, s0 * c, s1 * c, s2 * c, pdf


# ------------------------------------------------------------------------------------------------
# per-vertex context: everything that depends on wi only, computed once per scattering vertex
CTX_THETA_I = 0   # theta_i
CTX_PHI_I = 1     # phi_i
CTX_F_R = 2       # F_R per channel, 3 slots
CTX_INV_G_R = 5   # 1 / G_R (the R lobe's longitudinal normaliser)
CTX_INV_G_TT = 6  # 1 / G_TT
CTX_INV_Z_R = 7   # the R lobe's sampling normaliser: 1 / G_R when sampled exactly, else 1 / Z_R
CTX_INV_Z_TT = 8  # the TT lobe's
CTX_P_R = 9       # P_R, the probability of sampling the R lobe
CTX_Y = 10        # the fibre frame's y axis, 3 slots
CTX_Z = 13        # its z axis, 3 slots
CTX_EXACT_R = 16  # 1.0 when the R lobe's theta is sampled exactly (``sampling_normaliser``), else 0.0
CTX_EXACT_TT = 17  # the TT lobe's
CTX_SIZE = 18


@njit(cache=True)
def bcsdf_context(p, t, wi, ctx):
    """Fill ``ctx`` (float64[CTX_SIZE]) for viewer direction wi at a fibre of unit tangent t."""
    y0, y1, y2, z0, z1, z2 = fiber_frame(t)
    sx = min(1.0, max(-1.0, wi[0] * t[0] + wi[1] * t[1] + wi[2] * t[2]))
    ti = math.asin(sx)
    ctx[CTX_THETA_I] = ti
    ctx[CTX_PHI_I] = math.atan2(wi[0] * z0 + wi[1] * z1 + wi[2] * z2, wi[0] * y0 + wi[1] * y1 + wi[2] * y2)
    for c in range(3):
        ctx[CTX_F_R + c] = fresnel_R(ti, p[C_R + c])
    g = G_norm(-ti, p[BETA_R])
    ctx[CTX_INV_G_R] = 1.0 / g if g > 0.0 else 0.0
    g = G_norm(-ti, p[BETA_TT])
    ctx[CTX_INV_G_TT] = 1.0 / g if g > 0.0 else 0.0
    exact, inv = sampling_normaliser(-ti, p[BETA_R])
    ctx[CTX_INV_Z_R] = inv
    ctx[CTX_EXACT_R] = 1.0 if exact else 0.0
    exact, inv = sampling_normaliser(-ti, p[BETA_TT])
    ctx[CTX_INV_Z_TT] = inv
    ctx[CTX_EXACT_TT] = 1.0 if exact else 0.0
    ctx[CTX_P_R] = lobe_probability_R(p, ti)
    ctx[CTX_Y] = y0
    ctx[CTX_Y + 1] = y1
    ctx[CTX_Y + 2] = y2
    ctx[CTX_Z] = z0
    ctx[CTX_Z + 1] = z1
    ctx[CTX_Z + 2] = z2


@njit(cache=True)
def _eval_pdf_ctx_angles(p, ctx, theta_o, phi_o):
    co = math.cos(theta_o)
    if co <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    ti = ctx[CTX_THETA_I]
    g_r = gauss(theta_o, -ti, p[BETA_R])
    g_tt = gauss(theta_o, -ti, p[BETA_TT])
    m_r = g_r * ctx[CTX_INV_G_R]
    m_tt = g_tt * ctx[CTX_INV_G_TT]
    n_tt = azimuthal_N_tt(wrap_pi(phi_o - ctx[CTX_PHI_I] - math.pi), p[GAMMA_TT], p[TT_NORM])
    n_r = 1.0 / TWO_PI
    s0 = ctx[CTX_F_R] * m_r * n_r + (1.0 - ctx[CTX_F_R]) * p[C_TT] * m_tt * n_tt
    s1 = ctx[CTX_F_R + 1] * m_r * n_r + (1.0 - ctx[CTX_F_R + 1]) * p[C_TT + 1] * m_tt * n_tt
    s2 = ctx[CTX_F_R + 2] * m_r * n_r + (1.0 - ctx[CTX_F_R + 2]) * p[C_TT + 2] * m_tt * n_tt
    pr = ctx[CTX_P_R]
    pdf = 0.0
    if pr >= 0.0:
        c2 = co * co
        q_r = g_r * ctx[CTX_INV_Z_R] * (c2 if ctx[CTX_EXACT_R] > 0.0 else 1.0)
        q_tt = g_tt * ctx[CTX_INV_Z_TT] * (c2 if ctx[CTX_EXACT_TT] > 0.0 else 1.0)
        pdf = (pr * q_r * n_r + (1.0 - pr) * q_tt * n_tt) / co
    return s0 * co, s1 * co, s2 * co, pdf


@njit(cache=True)
def bcsdf_eval_pdf_ctx(p, ctx, t, wo):
    """(S cos(theta_o) r, g, b, pdf) at light direction wo: ``bcsdf_eval`` and ``bcsdf_pdf`` in one."""
    sx = min(1.0, max(-1.0, wo[0] * t[0] + wo[1] * t[1] + wo[2] * t[2]))
    wy = wo[0] * ctx[CTX_Y] + wo[1] * ctx[CTX_Y + 1] + wo[2] * ctx[CTX_Y + 2]
    wz = wo[0] * ctx[CTX_Z] + wo[1] * ctx[CTX_Z + 1] + wo[2] * ctx[CTX_Z + 2]
    return _eval_pdf_ctx_angles(p, ctx, math.asin(sx), math.atan2(wz, wy))


@njit(cache=True)
def bcsdf_sample_ctx(p, ctx, t, u0, u1, u2, wo):
    """Sample into ``wo`` (float64[3]); returns (weight r, g, b = S cos / pdf, pdf), pdf 0 on failure."""
    pr = ctx[CTX_P_R]
    if pr < 0.0:
        return 0.0, 0.0, 0.0, 0.0
    lobe_r = u0 < pr
    exact = (ctx[CTX_EXACT_R] if lobe_r else ctx[CTX_EXACT_TT]) > 0.0
    to, phi_o, _ = _sample_lobe_angles(p, ctx[CTX_THETA_I], ctx[CTX_PHI_I], lobe_r, exact, u1, u2)
    st = math.sin(to)
    ct = math.cos(to)
    cp = math.cos(phi_o) * ct
    sp = math.sin(phi_o) * ct
    for k in range(3):
        wo[k] = st * t[k] + cp * ctx[10 + k] + sp * ctx[13 + k]
    n = math.sqrt(wo[0] * wo[0] + wo[1] * wo[1] + wo[2] * wo[2])
    for k in range(3):
        wo[k] /= n
    f0, f1, f2, pdf = _eval_pdf_ctx_angles(p, ctx, to, phi_o)
    if pdf <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return f0 / pdf, f1 / pdf, f2 / pdf, pdf


@njit(cache=True)
def bcsdf_albedo(p, theta_i):
    """Closed form of int S(wi, wo) cos(theta_o) d wo = F_R + (1 - F_R) C_TT per channel."""
    out = np.empty(3)
    for c in range(3):
        f = fresnel_R(theta_i, p[C_R + c])
        out[c] = f + (1.0 - f) * p[C_TT + c]
    return out


def _mean_fresnel_tail(nodes=64):
    """cos^2-weighted mean over theta in [-pi/2, pi/2] of (1 - |cos theta|)^5 (Gauss-Legendre)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    c = np.cos(HALF_PI * x)
    return float(np.sum(w * c * c * (1.0 - c) ** 5) / np.sum(w * c * c))


MEAN_FRESNEL_TAIL = _mean_fresnel_tail()


def bcsdf_mean_albedo(p):
    """Single-scattering albedo of a fibre in an isotropic radiance field: the albedo
    A(theta_i) = F_R + (1 - F_R) C_TT (``bcsdf_albedo``) averaged over incidence with weight
    cos^2(theta_i) (the fibre's projected width times the solid angle at theta_i), i.e. the fraction
    of the light a randomly lit fibre intercepts that it scatters. F_R is linear in C_R, so the mean is
    F + (1 - F) C_TT with F = C_R + (1 - C_R) m, m = the weighted mean of (1 - |cos|)^5
    (``MEAN_FRESNEL_TAIL``). ``p`` may also be an (..., BCSDF_SIZE) array. A volume standing for these
    fibres takes it as its albedo (``pipeline.renderers.volpath``)."""
    p = np.asarray(p, np.float64)
    f = p[..., 0:3] + (1.0 - p[..., 0:3]) * MEAN_FRESNEL_TAIL
    return f + (1.0 - f) * p[..., 3:6]
