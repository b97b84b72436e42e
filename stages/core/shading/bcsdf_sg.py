"""The fibre BCSDF convolved with a spherical Gaussian light, and the SG single-scattering blend of
seed 001 §5.2.2 (Eq. 1, Eq. 2, App. A): noise-free single scattering from an SG light with local
visibility.

Interface
---------
    bcsdf_sg_gamma(p, t, w_view, axis, lam) -> (r, g, b)          Gamma, refined form (D4b/c, D7)
    bcsdf_sg_gamma_paper(p, t, w_view, axis, lam) -> (r, g, b)    Gamma as Eq. 2 / App. A (D4a, D6)
    bcsdf_sg_gamma_model(p, t, w_view, axis, lam, model)          either, model GAMMA_REFINED | GAMMA_PAPER
    sg_light_local_ssg(p, t, w_view, axes, weights, lam_svf, axis, lam, model=GAMMA_REFINED) -> (r, g, b)
    erf_visibility(d, lam) -> float
    sg_single_scatter(p, t, w_view, axis, lam, ssdf_value_at_axis, axes, weights, lam_svf,
                      model=GAMMA_REFINED) -> (r, g, b)
and the special functions ``bessel_i0e``, ``bessel_ratio_series``, ``tt_fourier_coefficients``.

``p`` the packed BCSDF (``stages.core.shading.bcsdf``), ``t`` the unit fibre tangent, ``w_view`` the
unit direction towards the viewer, ``axis`` the SG's unit axis (towards the light), ``lam`` >= 0 its
sharpness; ``axes`` (Q, 3) and ``weights`` (Q,) the segment's sum-of-SGs visibility (§4.1,
``stages.precompute.svf``) with sharpness ``lam_svf``; ``ssdf_value_at_axis`` d_k(xi) the segment's
SSDF at the axis, an angle in radians, + visible (``stages.precompute.svf.ssdf_at``).

Normalisation (which integral each function returns, per RGB channel):
- ``bcsdf_sg_gamma*``: Gamma(xi, lam, w_v) ~ int G(w; xi, lam) S(w_v, w) cos(theta_w) dw with the
  UNNORMALISED lobe G(w; xi, lam) = exp(lam (w . xi - 1)) -- the left side of Eq. 2. S cos theta_w is
  exactly ``bcsdf_eval(p, t, w_view, w)`` (loomlight's measure: first argument towards the viewer).
  As lam -> infinity, Gamma / M(lam) -> bcsdf_eval(p, t, w_view, axis).
- ``sg_light_local_ssg``: ~ int V^ssg(w) G(w; xi, lam) S cos dw, again against the unnormalised G,
  with V^ssg(w) = sum_q w_q G(w; xi_q, lam_svf) / M(lam_svf) (§4.1, §5.2.2).
- ``sg_single_scatter``: ~ int V^loc(w) G(w; xi, lam) / M(lam) S cos dw: the single-scattered
  radiance towards the viewer from an SG light of UNIT POWER normalised as the renderer's are
  (radiance L(w) = P G(w) / M(lam), ``stages.render.lights``), i.e. Eq. 1 without V^glo. The
  renderer multiplies by the power P (rgb) and by the global visibility (§5.2.2).

Notation and frame
------------------
Fibre frame of ``bcsdf``: theta = asin(w . t) in [-pi/2, pi/2], phi the azimuth about t (``fiber_frame``).
Viewer w_v = (theta_v, phi_v) (the paper's omega_o, theta_o), light direction w = (theta, phi) (the
paper's omega_i, theta_i: the integration variable), SG axis xi = (theta', phi') (the paper's notation).
dw = cos theta d theta d phi. loomlight's BCSDF (``bcsdf`` module doc), with W_R = F_R(theta_v),
W_TT = (1 - F_R(theta_v)) C_TT per channel:
    S(w_v, w) = W_R M_R(theta_v, theta) / (2 pi) + W_TT M_TT(theta_v, theta) N_TT(phi - phi_v - pi),
    M_p = g(theta; -theta_v, beta_p) / G(-theta_v, beta_p),   g the normalised Gaussian,
    N_TT(u) = g(u; 0, gamma) on (-pi, pi] + (1 - I) / (2 pi),   I = erf(pi / (sqrt2 gamma)).

Derivation (the paper's supplement is lost; this is ours, for loomlight's definitions)
--------------------------------------------------------------------------------------
D1. Measure. Gamma = int_{-pi/2}^{pi/2} int_{-pi}^{pi} G S cos^2(theta) d phi d theta: one cos from
    bcsdf_eval's S cos theta (the paper's cos theta_i in Eq. 1, 2), one from dw.
D2. Where loomlight differs from App. A. In App. A the Fresnel weight and the normaliser are written
    as functions of theta_i and evaluated at the combined centre (B_R(theta_R, .)); loomlight's F_R
    (with |cos|), 1/G(-theta_v, beta) and C_TT depend on the VIEWER only, so W_p / G(-theta_v, beta_p)
    leaves the integral exactly. loomlight's G(mu, beta) = int g cos^2 with g normalised equals App.
    A's G(mu; beta^-2/2) (whose sqrt(lam/pi) normalises its unnormalised Gaussian), so App. A's
    1/(sqrt(2 pi) beta G) is the same factor. App. A's F_R = C_R - (1 - C_R)(1 - cos)^5 has a
    misprinted sign; loomlight's + form is used. loomlight's N_TT has the floor (1 - I)/(2 pi), which
    the paper's model does not: it is kept (D4).
D3. The SG splits exactly in the fibre frame: w . xi = cos(theta - theta') - cos theta cos theta'
    (1 - cos(phi - phi')), so
        G = exp(lam (cos(theta - theta') - 1)) * exp(-kappa (1 - cos(phi - phi'))),
        kappa(theta) = lam cos theta cos theta'.
D4. Azimuthal integrals at fixed theta:
        R:  int (1/2pi) exp(-kappa (1 - cos(phi - phi'))) d phi = I0(kappa) e^-kappa =: A_R(kappa)   (exact)
        TT: A_TT(kappa) = int N_TT(phi - phi_v - pi) exp(-kappa (1 - cos(phi - phi'))) d phi.
    (a) The paper (App. A): the Gaussian part of N_TT ~ a von Mises of concentration k = gamma^-2,
        exp(k cos u) / (2 pi I0(k)), here with loomlight's mass I. Two cosines in phi add to one:
        k cos(phi - phi_v - pi) + kappa cos(phi - phi') = lam_m cos(phi - phi*),
            lam_m = sqrt(k^2 + kappa^2 - 2 k kappa cos(phi' - phi_v))                (App. A's lambda_m)
        so A_TT ~ I I0(lam_m) e^-kappa / I0(k) + (1 - I) I0(kappa) e^-kappa, the last term loomlight's
        floor integrated like N_R. Computed as I i0e(lam_m)/i0e(k) exp(lam_m - kappa - k) + (1 - I)
        i0e(kappa), with lam_m - kappa - k = -4 k kappa cos^2((phi' - phi_v)/2) / (lam_m + kappa + k)
        (<= 0, no cancellation). Its error: the von Mises is not the Gaussian -- its peak is
        2 pi i0e(k) / (sqrt(2 pi) gamma) times the Gaussian's (1.11 at cotton's gamma = 38 deg) and its
        tails are heavier (exp(-2k) against exp(-pi^2 k / 2) at u = pi); A_TT inherits 8-12 % inside
        the lobe and up to +160 % at |u| = 3.4 gamma (fleece).
    (b) Refined, exact (kappa gamma^2 < 9): Fourier series. N_TT(u) = 1/(2 pi) + (1/pi) sum_{n>=1}
        c_n cos(n u) (c_0 = I and the floor together give the constant), c_n = int_{-pi}^{pi} g(u; 0,
        gamma) cos(n u) du = e^{-b^2} Re erf(a + i b), a = pi/(sqrt2 gamma), b = n gamma/sqrt2, i.e.
        c_n = e^{-n^2 gamma^2/2} - (-1)^n e^{-a^2} Re[S(z)/(z sqrt(pi))], z = a + ib, S erfc's
        asymptotic series to 1/z^8 (used for a >= 5, gamma <= 25.5 deg), or 64-node Gauss-Legendre
        panels (wider gamma); both to rounding (``tt_fourier_coefficients``). With exp(kappa cos x) =
        I0(kappa) + 2 sum_n I_n(kappa) cos(n x) and orthogonality,
            A_TT(kappa) = i0e(kappa) [1 + 2 sum_{n>=1} (-1)^n c_n cos(n (phi' - phi_v)) I_n(kappa)/I0(kappa)],
        summed to n = min(ceil(8.5/gamma), 10 + 8.5 sqrt(kappa)) (dropped terms < e^-36), the ratios
        I_n/I0 by Miller's backward recurrence (``bessel_ratio_series``, ~6 sqrt(kappa) steps).
    (c) Refined, kappa gamma^2 >= 9 (the SG at least 3x narrower in phi than the TT lobe, where the
        recurrence would be long): the Gaussian part as in D7, 5-node Gauss-Hermite about the product
        of the TT Gaussian (precision gamma^-2) and the SG's phi profile taken as a Gaussian (precision
        kappa) -- centre kappa D / (gamma^-2 + kappa), D = wrap(phi' - phi_v - pi), deviation
        (gamma^-2 + kappa)^-1/2 -- with the exact integrand at the nodes (the truncated Gaussian
        evaluated on the circle, exp(kappa (cos - 1)) exact); plus (1 - I) i0e(kappa). Against (b)
        over kappa gamma^2 in [9, 1e5 gamma^2] and all phi': 2.7e-4 relative where A_TT > 1e-3 of its
        peak (cotton's 38-degree gamma, from the truncation kink at u = pi), 1.5e-6 (fleece), 3e-7
        (silk).
D5. What is left is one integral in theta per lobe:
        Gamma_p = W_p / G(-theta_v, beta_p) int_{-pi/2}^{pi/2} g(theta; -theta_v, beta_p)
                  exp(lam (cos(theta - theta') - 1)) cos^2(theta) A_p(kappa(theta)) d theta.
D6. The paper's form (Eq. 2): the SG's theta profile as a Gaussian, cos(x) - 1 ~ -x^2/2 (relative
    error ~ lam x^4 / 24), and the product of the two Gaussians is one Gaussian:
        (theta + theta_v)^2 / beta^2 + lam (theta - theta')^2
            = 2 lam_p (theta - theta_p)^2 + beta^-2 lam / (beta^-2 + lam) (theta_v + theta')^2,
        lam_p = (beta^-2 + lam) / 2,  theta_p = (lam theta' - beta^-2 theta_v) / (beta^-2 + lam),
        a_p = exp(-beta^-2 lam / (beta^-2 + lam) (theta_v + theta')^2 / 2)
    (Eq. 2's lambda_R, theta_R, a_R; the printed theta_R has "-beta_R^2 theta_o", a misprint for
    beta_R^-2: only then is it the precision-weighted mean and the units agree). The slowly varying
    factor h(theta) = cos^2(theta) A_p(kappa(theta)) is taken at theta_p, and what remains is
    int_{-pi/2}^{pi/2} exp(-lam_p (theta - theta_p)^2) d theta = 1/2 sqrt(pi/lam_p) [erf(sqrt(lam_p)
    (theta - theta_p))]_{-pi/2}^{pi/2} (computed as sqrt(2 pi) sigma x ``gauss_mass``, sigma^2 =
    1/(2 lam_p), accurate in the tails). Assembled:
        Gamma_p = W_p a_p cos^2(theta_p) A_p(lam cos theta' cos theta_p) / (sqrt(2 pi) beta_p G(-theta_v,
                  beta_p)) x 1/2 sqrt(pi/lam_p) [erf]                                      (Eq. 2)
    which is Eq. 2 with B_R(theta_R, lam cos theta') = F_R cos^2 theta_R I0(lam cos theta' cos
    theta_R) e^{-lam cos theta' cos theta_R} / (sqrt(2 pi) beta_R G) and B_TT likewise with D4(a).
    ``bcsdf_sg_gamma_paper`` = D6 with D4(a).
D7. Refined form (``bcsdf_sg_gamma`` = D7 with D4(b, c)): the one-point evaluation of D6 is the
    1-node Gauss-Hermite rule for the Gaussian exp(-lam_p (theta - theta_p)^2); we use 5 nodes
    theta_k = theta_p + sigma x_k (x_k, w_k: Gauss-Hermite for exp(-x^2/2)/sqrt(2 pi), sigma^2 =
    1/(beta^-2 + lam)) on the whole remainder, the SG's exact cos profile included:
        Gamma_p = W_p / (sqrt(2 pi) beta_p G) sqrt(2 pi) sigma sum_k w_k exp(E_k) cos^2(theta_k) A_p(kappa(theta_k)),
        E_k = -(theta_k + theta_v)^2 / (2 beta_p^2) + lam (cos(theta_k - theta') - 1) + x_k^2 / 2
    (E_k = ln a_p + lam (cos x - 1 + x^2/2) at x = theta_k - theta', one exponent: no overflow), nodes
    outside (-pi/2, pi/2) dropped (cos^2 vanishes at the poles, so the cut integrand is continuous;
    keeping D6's erf normalisation instead measured several times worse near grazing), nodes with E_k < -80 (a
    factor < 2e-35) skipped. Why: the one-point form misses the curvature of cos^2 theta and of
    kappa(theta) across the lobe: 0.5 % at lam = 100 in the interior, 17-27 % at theta_v = 80 deg,
    where cos^2 halves within one sigma.
D8. Bessel I0 with exponential scaling (``bessel_i0e``): the power series sum (x^2/4)^k / (k!)^2
    (positive terms) times e^-x for x <= 20, the asymptotic series e^x / sqrt(2 pi x) sum
    ((2k-1)!!)^2 / (k! (8x)^k) beyond (its smallest term at x = 20 is ~e^-40); 1.2e-15 relative
    against scipy.special.i0e over [0, 1e6].

Visibility (§5.2.2)
-------------------
- Soft lights, sum of SGs: V^ssg G = sum_q w_q / M(lam_svf) G(.; xi_q, lam_svf) G(.; xi, lam)
  = sum_q w_q / M(lam_svf) G(.; xi_sum_q / |xi_sum_q|, |xi_sum_q|) exp(|xi_sum_q| - lam_svf - lam),
  xi_sum_q = lam_svf xi_q + lam xi (as ``stages.core.sg.sg_product``), each term convolved by Gamma:
      ``sg_light_local_ssg`` = sum_q w_q / M(lam_svf) Gamma(xi_sum_q / |xi_sum_q|, |xi_sum_q|, w_v)
                               exp(|xi_sum_q| - lam_svf - lam).
  Where |xi_sum_q| < 100 (Gamma's sharp-lobe assumption) the factor exp(|xi_sum_q| - lam_svf - lam)
  < e^-28 for lam_svf = 128 suppresses the term (the paper's argument). Terms with w_q = 0 are
  skipped. With the refined model every term is first evaluated by the paper's (cheap) form, and the
  terms above SSG_REFINE_REL = 1e-9 of that sum (in any channel) are recomputed by the refined form;
  the rest keep the paper's value (their share of the error: < 1e-9 x the paper form's < 4x).
- Sharp lights, SSDF: V~(xi) = ``erf_visibility(d_k(xi), lam)`` = 1/2 [erf(sqrt(lam/2) d) + 1]
  (computed as 1/2 erfc(-sqrt(lam/2) d), accurate in the far shadow), the result V~ Gamma. It is the
  large-lam limit of the SG's mass on the visible side of a great circle at angular distance d.
- ``sg_single_scatter``: lam <= 100: the sum-of-SGs result; lam >= 200: V~ Gamma; in between the
  linear interpolation (1 - s) ssg + s V~ Gamma, s = (lam - 100) / 100 (§5.2.2); divided by M(lam).

Accuracy (tests/core/shading/test_bcsdf_sg.py)
---------------------------------------------
Reference: composite Gauss-Legendre in the fibre angles of int G bcsdf_eval dw, converged to 1e-9.
Grid: theta_v in {-69, -29, 17, 57, 80} deg x 12 axes (on the specular cone at three azimuths, off it
by 2 and 4 SG widths and by 2 beta_R, the TT forward direction and two azimuths beside it, 83 deg
from the normal plane both ways, one unrelated), presets cotton, gabardine, fleece. Max relative error
where Gamma > 1e-2 of the grid's peak / max error over the peak:
                  refined (bcsdf_sg_gamma)              paper's form (bcsdf_sg_gamma_paper)
    lam = 100     9.1e-3 / 2.4e-3                       2.3e-1 / 1.4e-1
    lam = 200     2.4e-3 / 4.0e-4                       2.4e-1 / 7.6e-2
    lam = 1000    1.1e-3 / 8.3e-5                       2.6e-1 / 3.1e-2
(refined, per preset at lam = 100: cotton 4.4e-4, gabardine 3.0e-3, fleece 9.1e-3; the worst cases
are theta_v = 80 deg with the axis 86 deg from the normal plane; for |theta_v| <= 57 deg the refined
error is 1.1e-4 at lam = 100, 1.8e-7 at 200, 8e-9 at 1000). The paper's form with the R lobe alone is
within 5.5e-3 for
|theta_v| <= 57 deg: its large errors are D4(a)'s. Sum of SGs at lam = 50, lam_svf = 128 against a
quadrature with V^ssg in the integrand: 8e-9 (paper's form: up to 37 %). Delta limit: Gamma / M ->
bcsdf_eval as O(1/lam) (1.2e-3 at lam = 1e7 for an axis 3 beta_R off silk's cone).

Cost (one core, after compilation): bcsdf_sg_gamma ~1.5-3 us per call, the paper's form ~0.4-0.5 us
(plus the per-view setup, ~1 us, or ~6 us where bcsdf.G_norm and the wide-gamma c_n take their
quadratures); sg_single_scatter with Q = 48 ~40-90 us at lam <= 150 (paper's form ~20 us), ~2-3 us at
lam >= 200.
"""
import math

import numpy as np
from numba import njit

from stages.core.sg import sg_mass
from stages.core.shading.bcsdf import (
    BETA_R,
    BETA_TT,
    C_R,
    C_TT,
    GAMMA_TT,
    TT_NORM,
    G_norm,
    fiber_frame,
    fresnel_R,
    gauss_mass,
    wrap_pi,
)

TWO_PI = 2.0 * math.pi
HALF_PI = 0.5 * math.pi
SQRT2 = math.sqrt(2.0)
INV_SQRT_PI = 1.0 / math.sqrt(math.pi)
I0E_SERIES_MAX = 20.0      # bessel_i0e: power series up to here, asymptotic series beyond
TT_SERIES_DEVIATIONS = 8.5  # Fourier terms n <= 8.5 / gamma: e^{-n^2 gamma^2 / 2} < e^-36
NODE_EXPONENT_MIN = -80.0   # Gauss-Hermite nodes whose factor exp(E_k) < e^-80 are skipped
GAMMA_REFINED = 0           # D4(b) + D7
GAMMA_PAPER = 1             # D4(a) + D6: Eq. 2 and App. A
SSG_LAMBDA_MAX = 100.0      # sum-of-SGs visibility at and below this sharpness (§5.2.2)
SSDF_LAMBDA_MIN = 200.0     # erf-of-SSDF visibility at and above this sharpness
AZ_GH_MIN = 9.0             # TT azimuth by Gauss-Hermite when kappa gamma^2 >= 9 (D4c), else Fourier
SSG_REFINE_REL = 1e-9       # sum-of-SGs terms below this share of the sum keep the paper's form
MILLER_LIMIT = 1e250        # Miller's backward recurrence rescales its terms past this
MILLER_RESCALE = 1e-250

_hx, _hw = np.polynomial.hermite_e.hermegauss(5)
GH_X = _hx.copy()                          # nodes for the weight exp(-x^2/2)
GH_W = _hw / math.sqrt(2.0 * math.pi)      # weights summing to 1
TT_CLOSED_FORM_MIN_A = 5.0  # c_n by erfc's asymptotic series when pi/(sqrt2 gamma) >= 5 (gamma <= 25.5 deg)
TT_GL_X, TT_GL_W = np.polynomial.legendre.leggauss(64)   # on [-1, 1]; c_n for wider gamma


# ------------------------------------------------------------------------------------------------
# special functions
@njit(cache=True)
def bessel_i0e(x):
    """I0(x) exp(-|x|) to rounding (D8)."""
    x = abs(x)
    if x <= I0E_SERIES_MAX:
        y = 0.25 * x * x
        s = 1.0
        term = 1.0
        k = 1.0
        while True:
            term *= y / (k * k)
            s += term
            if term < 1e-17 * s:
                break
            k += 1.0
        return s * math.exp(-x)
    s = 1.0
    term = 1.0
    k = 1.0
    while True:
        m = 2.0 * k - 1.0
        term *= m * m / (8.0 * k * x)
        s += term
        if term < 1e-17 * s:
            break
        k += 1.0
    return s / math.sqrt(TWO_PI * x)


@njit(cache=True)
def miller_step(n, two_over_x, j, jp):
    """One step of I_{n-1} = (2n/x) I_n + I_{n+1} from (j, jp) = (I_n, I_{n+1}) (unnormalised): (I_{n-1}, I_n,
    rescaled), both multiplied by MILLER_RESCALE when I_{n-1} passes MILLER_LIMIT."""
    jm = (n * two_over_x) * j + jp
    if jm > MILLER_LIMIT:
        return jm * MILLER_RESCALE, j * MILLER_RESCALE, True
    return jm, j, False


@njit(cache=True)
def bessel_ratio_series(x, coef, n_max):
    """sum_{n=0}^{n_max} coef[n] I_n(x) / I_0(x) for x >= 0, by Miller's backward recurrence
    I_{n-1} = (2n/x) I_n + I_{n+1} started at n_max + 20 + 6 sqrt(x) (the start error is damped by
    < e^-36), rescaled against overflow; (x/2)^n / n! below x = 1e-6."""
    if x < 1e-6:
        s = coef[0]
        if n_max >= 1:
            s += coef[1] * 0.5 * x
        if n_max >= 2:
            s += coef[2] * 0.125 * x * x
        return s
    n_s = n_max + 20 + int(6.0 * math.sqrt(x))
    two_over_x = 2.0 / x
    jp = 0.0
    j = 1.0
    for n in range(n_s, n_max, -1):     # above n_max: the recurrence alone
        j, jp, _ = miller_step(n, two_over_x, j, jp)
    s = 0.0
    for n in range(n_max, 0, -1):
        s += coef[n] * j
        j, jp, rescaled = miller_step(n, two_over_x, j, jp)
        if rescaled:
            s *= MILLER_RESCALE
    return coef[0] + s / j


@njit(cache=True)
def tt_fourier_coefficients(gamma, n_max, out):
    """out[n] = c_n = int_{-pi}^{pi} g(u; 0, gamma) cos(n u) du, n = 0..n_max (D4(b))."""
    a = math.pi / (SQRT2 * gamma)
    if a >= TT_CLOSED_FORM_MIN_A:
        ea = math.exp(-a * a) * INV_SQRT_PI
        for n in range(n_max + 1):
            b = n * gamma / SQRT2
            z = complex(a, b)
            iz2 = 1.0 / (z * z)
            # erfc(z) e^{z^2} z sqrt(pi) ~ 1 - 1/(2z^2) + 3/(4z^4) - 15/(8z^6) + 105/(16z^8)
            ser = 1.0 + iz2 * (-0.5 + iz2 * (0.75 + iz2 * (-1.875 + iz2 * 6.5625)))
            tail = ea * (ser / z).real
            sign = -1.0 if n % 2 == 1 else 1.0
            out[n] = math.exp(-b * b) - sign * tail
        return
    # even integrand: 2 int_0^h, h = min(pi, 12 gamma) (beyond 12 gamma the Gaussian is < e^-72), in
    # panels over which cos(n_max u) turns by at most 30 radians, 64 Gauss-Legendre nodes each
    for n in range(n_max + 1):
        out[n] = 0.0
    h = min(math.pi, 12.0 * gamma)
    n_panels = 1 + int(n_max * h / 30.0)
    hp = h / n_panels
    norm = 2.0 / (math.sqrt(TWO_PI) * gamma)
    for j in range(n_panels):
        for k in range(TT_GL_X.shape[0]):
            u = hp * (j + 0.5 * (TT_GL_X[k] + 1.0))
            gw = 0.5 * hp * TT_GL_W[k] * norm * math.exp(-0.5 * (u / gamma) ** 2)
            c1 = math.cos(u)
            cm = 1.0   # cos(0 u)
            cn = c1    # cos(1 u)
            out[0] += gw
            for n in range(1, n_max + 1):
                out[n] += gw * cn
                cn, cm = 2.0 * c1 * cn - cm, cn


@njit(cache=True)
def erf_visibility(d, lam):
    """1/2 [erf(sqrt(lam/2) d) + 1] (§5.2.2), d = the SSDF (radians, + visible)."""
    return 0.5 * math.erfc(-math.sqrt(0.5 * lam) * d)


# ------------------------------------------------------------------------------------------------
# Gamma
@njit(cache=True)
def _az_tt_paper(kap, k, I, chs):
    """D4(a): I i0e(lam_m)/i0e(k) exp(lam_m - kappa - k) + (1 - I) i0e(kappa); chs = cos^2((phi'-phi_v)/2)."""
    s = k + kap
    lm = math.sqrt(max(0.0, s * s - 4.0 * k * kap * chs))
    expo = -4.0 * k * kap * chs / (lm + s) if lm + s > 0.0 else 0.0
    return I * bessel_i0e(lm) / bessel_i0e(k) * math.exp(expo) + (1.0 - I) * bessel_i0e(kap)


@njit(cache=True)
def _lobe_paper(theta_v, theta_a, cos_a, lam, beta, tt, k, I, chs):
    """D6 for one lobe, without W_p / G: a_p [erf] cos^2 A_p / (sqrt(2 pi) beta)."""
    b2 = 1.0 / (beta * beta)
    prec = b2 + lam
    theta_p = (lam * theta_a - b2 * theta_v) / prec
    d = theta_v + theta_a
    a_p = math.exp(-0.5 * b2 * lam / prec * d * d)
    sigma = 1.0 / math.sqrt(prec)
    # 1/2 sqrt(pi/lam_p) [erf(sqrt(lam_p)(theta - theta_p))]_{-pi/2}^{pi/2}
    bracket = math.sqrt(TWO_PI) * sigma * gauss_mass(-HALF_PI, HALF_PI, theta_p, sigma)
    ct = math.cos(theta_p)
    kap = lam * cos_a * ct
    if tt:
        az = _az_tt_paper(kap, k, I, chs)
    else:
        az = bessel_i0e(kap)
    return a_p * bracket * ct * ct * az / (math.sqrt(TWO_PI) * beta)


@njit(cache=True)
def _az_tt_gh(kap, dphi, gamma, I):
    """D4(c): A_TT for kappa gamma^2 >= AZ_GH_MIN, 5-node Gauss-Hermite about the product of the two
    Gaussians (precision gamma^-2 + kappa, centre kappa D / (gamma^-2 + kappa)), D = wrap(phi' - phi_v
    - pi); the truncated Gaussian evaluated where it is, on the circle; + the floor (1 - I) i0e(kappa)."""
    D = wrap_pi(dphi - math.pi)
    g2 = 1.0 / (gamma * gamma)
    prec = g2 + kap
    centre = kap * D / prec
    sigma = 1.0 / math.sqrt(prec)
    acc = 0.0
    for k in range(GH_X.shape[0]):
        x = GH_X[k]
        u = centre + sigma * x
        uw = wrap_pi(u)
        acc += GH_W[k] * math.exp(-0.5 * g2 * uw * uw + kap * (math.cos(u - D) - 1.0) + 0.5 * x * x)
    return acc * sigma / gamma + (1.0 - I) * bessel_i0e(kap)


@njit(cache=True)
def _lobe_refined(theta_v, theta_a, cos_a, lam, beta, tt, base, coef, n_gamma, gamma, I, dphi):
    """D7 for one lobe, without W_p / G."""
    b2 = 1.0 / (beta * beta)
    prec = b2 + lam
    theta_p = (lam * theta_a - b2 * theta_v) / prec
    sigma = 1.0 / math.sqrt(prec)
    acc = 0.0
    for k in range(GH_X.shape[0]):
        x = GH_X[k]
        th = theta_p + sigma * x
        if abs(th) >= HALF_PI:
            continue
        d = th + theta_v
        e = -0.5 * b2 * d * d + lam * (math.cos(th - theta_a) - 1.0) + 0.5 * x * x
        if e < NODE_EXPONENT_MIN:
            continue
        ct = math.cos(th)
        kap = lam * cos_a * ct
        if tt:
            if kap * gamma * gamma >= AZ_GH_MIN:
                az = _az_tt_gh(kap, dphi, gamma, I)
            else:
                _fourier_coefficients(gamma, n_gamma, base, coef, dphi)
                n_max = min(n_gamma, 10 + int(8.5 * math.sqrt(kap)))
                az = bessel_i0e(kap) * bessel_ratio_series(kap, coef, n_max)
        else:
            az = bessel_i0e(kap)
        acc += GH_W[k] * math.exp(e) * ct * ct * az
    return acc * sigma / beta


@njit(cache=True)
def _view_setup(p, t, w_view):
    """Viewer-only quantities: (theta_v, phi_v, frame y, z, 1/G_R, 1/G_TT, n_gamma) and the TT Fourier
    coefficients 2 (-1)^n c_n (index 0: 1) of D4(b)."""
    y0, y1, y2, z0, z1, z2 = fiber_frame(t)
    sv = min(1.0, max(-1.0, w_view[0] * t[0] + w_view[1] * t[1] + w_view[2] * t[2]))
    theta_v = math.asin(sv)
    phi_v = math.atan2(w_view[0] * z0 + w_view[1] * z1 + w_view[2] * z2,
                       w_view[0] * y0 + w_view[1] * y1 + w_view[2] * y2)
    g = G_norm(-theta_v, p[BETA_R])
    inv_g_r = 1.0 / g if g > 0.0 else 0.0
    g = G_norm(-theta_v, p[BETA_TT])
    inv_g_tt = 1.0 / g if g > 0.0 else 0.0
    n_gamma = int(math.ceil(TT_SERIES_DEVIATIONS / p[GAMMA_TT]))
    base = np.empty(n_gamma + 1)
    base[0] = -1.0   # filled on first use (_fourier_coefficients)
    return theta_v, phi_v, y0, y1, y2, z0, z1, z2, inv_g_r, inv_g_tt, n_gamma, base


@njit(cache=True)
def _fourier_coefficients(gamma, n_gamma, base, coef, dphi):
    """coef[n] = 2 (-1)^n c_n cos(n dphi), coef[0] = 1 (D4(b)); base[n] = 2 (-1)^n c_n is computed once
    per view (base[0] < 0 marks it unset), coef once per axis (coef[0] < 0 marks it unset)."""
    if base[0] < 0.0:
        tt_fourier_coefficients(gamma, n_gamma, base)
        base[0] = 1.0
        for n in range(1, n_gamma + 1):
            base[n] *= -2.0 if n % 2 == 1 else 2.0
    if coef[0] < 0.0:
        c1 = math.cos(dphi)   # cos(n dphi) by the Chebyshev recurrence
        cm = 1.0
        cn = c1
        coef[0] = 1.0
        for n in range(1, n_gamma + 1):
            coef[n] = base[n] * cn
            cn, cm = 2.0 * c1 * cn - cm, cn


@njit(cache=True)
def _gamma_setup(p, t, setup, coef, axis, lam, model):
    theta_v, phi_v, y0, y1, y2, z0, z1, z2, inv_g_r, inv_g_tt, n_gamma, base = setup
    sa = min(1.0, max(-1.0, axis[0] * t[0] + axis[1] * t[1] + axis[2] * t[2]))
    theta_a = math.asin(sa)
    cos_a = math.sqrt(max(0.0, 1.0 - sa * sa))
    phi_a = math.atan2(axis[0] * z0 + axis[1] * z1 + axis[2] * z2, axis[0] * y0 + axis[1] * y1 + axis[2] * y2)
    dphi = phi_a - phi_v
    L_r = 0.0
    L_tt = 0.0
    if model == GAMMA_PAPER:
        c = math.cos(0.5 * dphi)
        chs = c * c
        if inv_g_r > 0.0:
            L_r = _lobe_paper(theta_v, theta_a, cos_a, lam, p[BETA_R], False, 0.0, 0.0, chs) * inv_g_r
        if inv_g_tt > 0.0:
            L_tt = _lobe_paper(theta_v, theta_a, cos_a, lam, p[BETA_TT], True, 1.0 / (p[GAMMA_TT] * p[GAMMA_TT]),
                               p[TT_NORM], chs) * inv_g_tt
    else:
        if inv_g_r > 0.0:
            L_r = _lobe_refined(theta_v, theta_a, cos_a, lam, p[BETA_R], False, base, coef, n_gamma, p[GAMMA_TT],
                                p[TT_NORM], dphi) * inv_g_r
        if inv_g_tt > 0.0:
            coef[0] = -1.0
            L_tt = _lobe_refined(theta_v, theta_a, cos_a, lam, p[BETA_TT], True, base, coef, n_gamma, p[GAMMA_TT],
                                 p[TT_NORM], dphi) * inv_g_tt
    f = fresnel_R(theta_v, p[C_R])
    out0 = f * L_r + (1.0 - f) * p[C_TT] * L_tt
    f = fresnel_R(theta_v, p[C_R + 1])
    out1 = f * L_r + (1.0 - f) * p[C_TT + 1] * L_tt
    f = fresnel_R(theta_v, p[C_R + 2])
    out2 = f * L_r + (1.0 - f) * p[C_TT + 2] * L_tt
    return out0, out1, out2


@njit(cache=True)
def bcsdf_sg_gamma_model(p, t, w_view, axis, lam, model):
    """Gamma (unnormalised SG, see Normalisation) by ``model`` GAMMA_REFINED or GAMMA_PAPER."""
    setup = _view_setup(p, t, w_view)
    coef = np.empty(setup[10] + 1)
    return _gamma_setup(p, t, setup, coef, axis, lam, model)


@njit(cache=True)
def bcsdf_sg_gamma(p, t, w_view, axis, lam):
    """Gamma(axis, lam, w_view) ~ int G(w; axis, lam) bcsdf_eval(p, t, w_view, w) dw, refined (D4b, D7)."""
    return bcsdf_sg_gamma_model(p, t, w_view, axis, lam, GAMMA_REFINED)


@njit(cache=True)
def bcsdf_sg_gamma_paper(p, t, w_view, axis, lam):
    """Gamma exactly in the form of Eq. 2 / App. A in loomlight's terms (D4a, D6)."""
    return bcsdf_sg_gamma_model(p, t, w_view, axis, lam, GAMMA_PAPER)


# ------------------------------------------------------------------------------------------------
# local visibility (§5.2.2)
@njit(cache=True)
def _ssg(p, t, setup, coef, axes, weights, lam_svf, axis, lam, model):
    """sum_q w_q / M(lam_svf) Gamma(xi_sum_q / |xi_sum_q|, |xi_sum_q|) exp(|xi_sum_q| - lam_svf - lam).
    Refined model: every term first by the paper's form (cheap); the terms whose paper value exceeds
    SSG_REFINE_REL of the paper sum (per channel) are then recomputed by the refined form."""
    inv_m = 1.0 / sg_mass(lam_svf)
    Q = axes.shape[0]
    xis = np.empty((Q, 3))
    lams = np.empty(Q)
    scales = np.empty(Q)
    vals = np.empty((Q, 3))
    tot = np.zeros(3)
    for q in range(Q):
        wq = weights[q]
        scales[q] = 0.0
        vals[q, 0] = 0.0
        vals[q, 1] = 0.0
        vals[q, 2] = 0.0
        if wq == 0.0:
            continue
        sx = lam_svf * axes[q, 0] + lam * axis[0]
        sy = lam_svf * axes[q, 1] + lam * axis[1]
        sz = lam_svf * axes[q, 2] + lam * axis[2]
        ls = math.sqrt(sx * sx + sy * sy + sz * sz)
        scales[q] = wq * inv_m * math.exp(ls - lam_svf - lam)
        lams[q] = ls
        if ls > 0.0:
            xis[q, 0] = sx / ls
            xis[q, 1] = sy / ls
            xis[q, 2] = sz / ls
        else:   # the product is the constant scale: any axis, lam = 0
            xis[q, 0] = t[0]
            xis[q, 1] = t[1]
            xis[q, 2] = t[2]
        g0, g1, g2 = _gamma_setup(p, t, setup, coef, xis[q], ls, GAMMA_PAPER)
        vals[q, 0] = scales[q] * g0
        vals[q, 1] = scales[q] * g1
        vals[q, 2] = scales[q] * g2
        tot[0] += vals[q, 0]
        tot[1] += vals[q, 1]
        tot[2] += vals[q, 2]
    if model == GAMMA_PAPER:
        return tot[0], tot[1], tot[2]
    r0 = 0.0
    r1 = 0.0
    r2 = 0.0
    for q in range(Q):
        if scales[q] == 0.0:
            continue
        if (vals[q, 0] > SSG_REFINE_REL * tot[0] or vals[q, 1] > SSG_REFINE_REL * tot[1]
                or vals[q, 2] > SSG_REFINE_REL * tot[2]):
            g0, g1, g2 = _gamma_setup(p, t, setup, coef, xis[q], lams[q], GAMMA_REFINED)
            r0 += scales[q] * g0
            r1 += scales[q] * g1
            r2 += scales[q] * g2
        else:
            r0 += vals[q, 0]
            r1 += vals[q, 1]
            r2 += vals[q, 2]
    return r0, r1, r2


@njit(cache=True)
def sg_light_local_ssg(p, t, w_view, axes, weights, lam_svf, axis, lam, model=GAMMA_REFINED):
    """~ int V^ssg(w) G(w; axis, lam) bcsdf_eval(p, t, w_view, w) dw (unnormalised SG), §5.2.2."""
    setup = _view_setup(p, t, w_view)
    coef = np.empty(setup[10] + 1)
    return _ssg(p, t, setup, coef, axes, weights, lam_svf, axis, lam, model)


@njit(cache=True)
def sg_single_scatter(p, t, w_view, axis, lam, ssdf_value_at_axis, axes, weights, lam_svf,
                      model=GAMMA_REFINED):
    """~ int V^loc(w) G(w; axis, lam) / M(lam) bcsdf_eval(p, t, w_view, w) dw: single scattering from a
    unit-power SG light (the renderer multiplies by P), the §5.2.2 blend of the two visibilities."""
    setup = _view_setup(p, t, w_view)
    coef = np.empty(setup[10] + 1)
    inv_m = 1.0 / sg_mass(lam)
    s = (lam - SSG_LAMBDA_MAX) / (SSDF_LAMBDA_MIN - SSG_LAMBDA_MAX)
    s = min(1.0, max(0.0, s))
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    b0 = 0.0
    b1 = 0.0
    b2 = 0.0
    if s < 1.0:
        a0, a1, a2 = _ssg(p, t, setup, coef, axes, weights, lam_svf, axis, lam, model)
    if s > 0.0:
        v = erf_visibility(ssdf_value_at_axis, lam)
        g0, g1, g2 = _gamma_setup(p, t, setup, coef, axis, lam, model)
        b0 = v * g0
        b1 = v * g1
        b2 = v * g2
    return (((1.0 - s) * a0 + s * b0) * inv_m, ((1.0 - s) * a1 + s * b1) * inv_m,
            ((1.0 - s) * a2 + s * b2) * inv_m)

