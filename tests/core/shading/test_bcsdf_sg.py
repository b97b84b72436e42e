"""The fibre BCSDF convolved with an SG light (stages/core/shading/bcsdf_sg.py, seed 001 §5.2.2, Eq. 2,
App. A): Gamma against a converged composite Gauss-Legendre quadrature of int G bcsdf_eval dw in the
BCSDF's own angles, the paper's form against a line-by-line transcription of Eq. 2, the special
functions against scipy, the sum-of-SGs product against a direct quadrature with the visibility in
the integrand, the erf visibility against the exact SG mass behind a great circle, and the §5.2.2
blend against its two branches."""
import math

import numpy as np
import pytest
from numba import njit
from scipy import special

from stages.core import sg
from stages.core.shading import bcsdf as B, bcsdf_sg as S


def preset(name):
    from pipeline.bcsdf_presets import load_bcsdf_preset

    return load_bcsdf_preset(name)


TANGENT = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])


# ------------------------------------------------------------------------------------------------
# reference quadrature
@njit(cache=True)
def _panel_nodes(bps, gx, gw):
    n = bps.shape[0] - 1
    xs = np.empty(n * gx.shape[0])
    ws = np.empty(n * gx.shape[0])
    k = 0
    for i in range(n):
        h = 0.5 * (bps[i + 1] - bps[i])
        m = 0.5 * (bps[i + 1] + bps[i])
        for j in range(gx.shape[0]):
            xs[k] = m + h * gx[j]
            ws[k] = h * gw[j]
            k += 1
    return xs, ws


@njit(cache=True)
def _unique_sorted(pts):
    pts = np.sort(pts)
    out = np.empty(pts.shape[0])
    m = 0
    for i in range(pts.shape[0]):
        if m == 0 or pts[i] - out[m - 1] > 1e-12:
            out[m] = pts[i]
            m += 1
    return out[:m]


@njit(cache=True)
def _theta_breaks(centres, steps, n_fine, n_uniform):
    """Breakpoints on [-pi/2, pi/2]: n_uniform equal panels plus centre +- k step, k <= n_fine."""
    pts = np.empty(n_uniform + 1 + centres.shape[0] * (2 * n_fine + 1))
    k = 0
    for i in range(n_uniform + 1):
        pts[k] = -0.5 * math.pi + math.pi * i / n_uniform
        k += 1
    for c in range(centres.shape[0]):
        for i in range(-n_fine, n_fine + 1):
            x = centres[c] + i * steps[c]
            if -0.5 * math.pi < x < 0.5 * math.pi:
                pts[k] = x
                k += 1
    return _unique_sorted(pts[:k])


@njit(cache=True)
def _phi_breaks(centre, step, n_fine, n_uniform):
    """Breakpoints on [-pi, pi] (the TT azimuth u = phi - phi_v - pi: N_TT's kink sits at the ends)."""
    pts = np.empty(n_uniform + 1 + 2 * n_fine + 1)
    k = 0
    for i in range(n_uniform + 1):
        pts[k] = -math.pi + 2.0 * math.pi * i / n_uniform
        k += 1
    for i in range(-n_fine, n_fine + 1):
        pts[k] = B.wrap_pi(centre + i * step)
        k += 1
    return _unique_sorted(pts[:k])


@njit(cache=True)
def _sphere_quadrature(p, t, wv, axis, lam, vis_axes, vis_w, vis_lam, gx, gw, n_fine, n_uniform):
    """int V(w) G(w; axis, lam) bcsdf_eval(p, t, wv, w) dw, (r, g, b), V = 1 when vis_axes is empty,
    else sum_q vis_w[q] G(w; vis_axes[q], vis_lam) / M(vis_lam). Composite Gauss-Legendre in the fibre
    angles (theta, phi), dw = cos theta d theta d phi, with panels one deviation wide around the
    lobes' combined centres, the SG axis and the SG's azimuthal peak (its width 1/sqrt(kappa(theta)))
    plus equal panels over the whole sphere; bcsdf_eval's value through the per-vertex context
    (bcsdf_eval_pdf_ctx, identical to bcsdf_eval)."""
    ctx = np.empty(B.CTX_SIZE)
    B.bcsdf_context(p, t, wv, ctx)
    tv = ctx[0]
    phf = ctx[1] + math.pi
    ta, pha = B.angles(t, axis)
    centres = np.empty(3)
    steps = np.empty(3)
    for j in range(2):
        beta = p[6 + j]
        prec = 1.0 / (beta * beta) + lam
        centres[j] = (lam * ta - tv / (beta * beta)) / prec
        steps[j] = 1.0 / math.sqrt(prec)
    centres[2] = ta
    steps[2] = 1.0 / math.sqrt(max(lam, 1.0))
    ths, thw = _panel_nodes(_theta_breaks(centres, steps, n_fine, n_uniform), gx, gw)
    up = B.wrap_pi(pha - phf)
    inv_m = 1.0 / sg.sg_mass(vis_lam)
    w = np.empty(3)
    r = np.zeros(3)
    for a in range(ths.shape[0]):
        th = ths[a]
        ct = math.cos(th)
        st = math.sin(th)
        kap = lam * ct * math.cos(ta)
        us, uw = _panel_nodes(_phi_breaks(up, 1.0 / math.sqrt(max(kap, 1.0)), n_fine, n_uniform), gx, gw)
        acc = np.zeros(3)
        for b in range(us.shape[0]):
            ph = us[b] + phf
            for k in range(3):
                w[k] = st * t[k] + ct * (math.cos(ph) * ctx[10 + k] + math.sin(ph) * ctx[13 + k])
            e = lam * (w[0] * axis[0] + w[1] * axis[1] + w[2] * axis[2] - 1.0)
            if e < -700.0:
                continue
            g = math.exp(e)
            if vis_axes.shape[0] > 0:
                v = 0.0
                for q in range(vis_axes.shape[0]):
                    v += vis_w[q] * math.exp(vis_lam * (w[0] * vis_axes[q, 0] + w[1] * vis_axes[q, 1]
                                                        + w[2] * vis_axes[q, 2] - 1.0))
                g *= v * inv_m
            f0, f1, f2, _ = B.bcsdf_eval_pdf_ctx(p, ctx, t, w)
            acc[0] += uw[b] * g * f0
            acc[1] += uw[b] * g * f1
            acc[2] += uw[b] * g * f2
        r += thw[a] * ct * acc
    return r


GL8 = np.polynomial.legendre.leggauss(8)
NO_AXES = np.zeros((0, 3))
NO_W = np.zeros(0)


def gamma_quadrature(p, wv, axis, lam, order=GL8, n_fine=8, n_uniform=16):
    return _sphere_quadrature(p, TANGENT, wv, axis, lam, NO_AXES, NO_W, 1.0, order[0], order[1],
                              n_fine, n_uniform)


def test_reference_quadrature_converged():
    """The reference itself: GL8 with (8 fine, 16 uniform) panels against GL12 with (12, 40) on cases
    near the pole, the TT peak and the R cone (silk's 1-degree R lobe): agreement to 1e-9."""
    p = preset("silk")
    g12 = np.polynomial.legendre.leggauss(12)
    for lam, tv, ta, dphi in [(100.0, 0.3, -0.3, 0.0), (1000.0, 1.4, -1.45, 2.0), (200.0, 0.0, 0.0, math.pi)]:
        wv = B.from_angles(TANGENT, tv, 0.4)
        ax = B.from_angles(TANGENT, ta, 0.4 + dphi)
        lo = gamma_quadrature(p, wv, ax, lam)
        hi = gamma_quadrature(p, wv, ax, lam, g12, 12, 40)
        assert np.max(np.abs(lo / hi - 1.0)) < 1e-9


# ------------------------------------------------------------------------------------------------
# special functions
def test_bessel_i0e_matches_scipy():
    """bessel_i0e against scipy.special.i0e on [0, 60] (both branches, the switch at 20) and
    log-spaced to 1e6: relative error < 5e-15."""
    xs = np.concatenate([np.linspace(0.0, 60.0, 6001), np.geomspace(1e-8, 1e6, 3000), [19.999999, 20.0, 20.000001]])
    ours = np.array([S.bessel_i0e(x) for x in xs])
    assert np.max(np.abs(ours / special.i0e(xs) - 1.0)) < 5e-15
    assert S.bessel_i0e(-3.0) == S.bessel_i0e(3.0)


def test_bessel_ratio_series_matches_scipy():
    """sum_n c_n I_n(x)/I_0(x) (Miller's recurrence) against scipy.special.ive ratios, random c_n,
    x from 1e-8 to 1e5: relative error < 1e-12 (of the sum of |terms|)."""
    rng = np.random.default_rng(3)
    for x in [1e-8, 1e-3, 0.3, 2.0, 19.0, 150.0, 3000.0, 1e5]:
        coef = rng.normal(size=41)
        ours = S.bessel_ratio_series(x, coef, 40)
        terms = coef * special.ive(np.arange(41), x) / special.i0e(x)
        assert abs(ours - terms.sum()) < 1e-12 * np.abs(terms).sum()


@pytest.mark.parametrize("gamma_deg", [5.0, 19.823, 25.0, 26.0, 38.269, 75.0])
def test_tt_fourier_coefficients(gamma_deg):
    """c_n of the Gaussian truncated to (-pi, pi] (closed form with erfc's asymptotic series for
    gamma <= 25.5 deg, Gauss-Legendre beyond) against scipy.integrate.quad of g cos(n u): < 1e-13."""
    from scipy.integrate import quad

    gamma = math.radians(gamma_deg)
    n_max = 60
    out = np.empty(n_max + 1)
    S.tt_fourier_coefficients(gamma, n_max, out)
    for n in range(n_max + 1):
        ref = quad(lambda u, n=n: math.exp(-0.5 * (u / gamma) ** 2) / (math.sqrt(2 * math.pi) * gamma)
                   * math.cos(n * u), -math.pi, math.pi, limit=500, epsabs=1e-14, points=[0.0])[0]
        assert abs(out[n] - ref) < 1e-13, (n, out[n], ref)
    assert abs(out[0] - math.erf(math.pi / (math.sqrt(2.0) * gamma))) < 1e-13   # c_0 = I


# ------------------------------------------------------------------------------------------------
# Gamma against quadrature
THETA_VIEWS = (-1.2, -0.5, 0.3, 1.0, 1.4)
PHI_VIEW = 0.4


def gamma_cases(lam, beta_r):
    """(theta_v, theta', phi') of the test grid: on the specular cone (three azimuths), off it by 2 and
    4 SG widths and by 2 beta_R, the TT forward direction and two azimuths beside it, axes 83 deg from
    the normal plane (nearly along the fibre, both signs), and one unrelated axis."""
    s = 1.0 / math.sqrt(lam)
    out = []
    for tv in THETA_VIEWS:
        for ta, dphi in [(-tv, 0.0), (-tv, 0.7), (-tv, 1.6), (-tv + 2 * s, 1.0), (-tv - 4 * s, 1.0),
                         (-tv + 2 * beta_r, 1.0), (-tv, math.pi), (-tv + 0.1, math.pi - 0.3),
                         (-tv, math.pi - 0.8), (1.45, 0.5), (-1.45, 2.5), (0.3, 2.0)]:
            out.append((tv, max(-1.5, min(1.5, ta)), PHI_VIEW + dphi))
    return out


def gamma_errors(name, lam, fn):
    """(max relative error where Gamma > 1e-2 of the grid's peak, max |error| / peak, the same relative
    error over the views |theta_v| <= 57 deg only, peak)."""
    p = preset(name)
    ref, ours, views = [], [], []
    for tv, ta, pa in gamma_cases(lam, p[6]):
        wv = B.from_angles(TANGENT, tv, PHI_VIEW)
        ax = B.from_angles(TANGENT, ta, pa)
        ref.append(gamma_quadrature(p, wv, ax, lam))
        ours.append(np.array(fn(p, TANGENT, wv, ax, lam)))
        views.append(tv)
    ref = np.array(ref)
    ours = np.array(ours)
    peak = ref.max()
    big = ref > 1e-2 * peak
    rel = np.abs(ours / np.where(big, ref, 1.0) - 1.0)
    inner = big & (np.abs(np.array(views)) <= 1.01)[:, None]
    return np.max(rel[big]), np.max(np.abs(ours - ref)) / peak, np.max(rel[inner]), peak


# Bounds over the three presets (module doc, Accuracy): (max relative error where Gamma > 1e-2 of the
# grid's peak, max |error| / peak, max relative error for |theta_v| <= 57 deg). Measured worst:
# lam = 100: 9.1e-3, 2.4e-3, 1.1e-4; lam = 200: 2.4e-3, 4.0e-4, 1.8e-7; lam = 1000: 1.1e-3, 8.3e-5,
# 8.1e-9 -- the first two at theta_v = 80 deg with the axis 86 deg from the normal plane (the lobe
# against the pole, where the theta integrand is cut at pi/2).
# Cotton's broad TT lobe (27 x 38 deg) dominates since its R lobe is a dielectric's 0.047 (issue 52; it was
# 0.96): away from grazing the 5-node theta rule is then 1.2e-3 / 1.7e-3 / 3.0e-6 off, lam = 100 / 200 / 1000
# (and 4.6e-3 / 5.8e-4 / 5.6e-4 / 1.3e-4 for the first two bounds at lam = 200 and 1000), its own bounds.
GAMMA_BOUNDS = {100.0: (1.2e-2, 3e-3, 2e-4), 200.0: (3.5e-3, 6e-4, 1e-6), 1000.0: (1.5e-3, 1.2e-4, 1e-7)}
GAMMA_BOUNDS_BROAD_TT = {100.0: (1.2e-2, 3e-3, 1.6e-3), 200.0: (6e-3, 8e-4, 2.2e-3), 1000.0: (1.5e-3, 1.8e-4, 4e-6)}


@pytest.mark.parametrize("lam", [100.0, 200.0, 1000.0])
@pytest.mark.parametrize("name", ["cotton", "gabardine", "fleece"])
def test_gamma_against_quadrature(name, lam):
    """bcsdf_sg_gamma (refined Eq. 2: exact azimuth, 5-node theta rule) against the converged
    quadrature of int G bcsdf_eval dw on the gamma_cases grid: relative error, error relative to the
    grid's peak, and relative error away from grazing views, within GAMMA_BOUNDS."""
    rel, ab, inner, peak = gamma_errors(name, lam, S.bcsdf_sg_gamma)
    print(f"{name} lam={lam:g}: max rel {rel:.2e}, max abs/peak {ab:.2e}, |theta_v| <= 57 deg {inner:.2e}")
    assert peak > 0.0
    rel_bound, abs_bound, inner_bound = (GAMMA_BOUNDS_BROAD_TT if name == "cotton" else GAMMA_BOUNDS)[lam]
    assert rel < rel_bound
    assert ab < abs_bound
    assert inner < inner_bound


def test_gamma_delta_limit():
    """As lam -> infinity G -> M(lam) delta(w - axis), so Gamma / M(lam) -> bcsdf_eval(p, t, w_view,
    axis), with an O(1/lam) remainder (measured 1.2e-3 at lam = 1e7 and 1.2e-5 at 1e9 for an axis 3
    beta_R off the cone): against silk's 1-degree R lobe, three axes, within 2e-3 at lam = 1e7 and 2e-5
    at lam = 1e9."""
    p = preset("silk")
    for lam, tol in ((1e7, 2e-3), (1e9, 2e-5)):
        for tv, ta, dphi in [(0.3, -0.31, 0.9), (-0.6, 0.55, math.pi - 0.2), (1.0, -0.95, 2.0)]:
            wv = B.from_angles(TANGENT, tv, PHI_VIEW)
            ax = B.from_angles(TANGENT, ta, PHI_VIEW + dphi)
            ours = np.array(S.bcsdf_sg_gamma(p, TANGENT, wv, ax, lam)) / sg.sg_mass(lam)
            ref = np.array(B.bcsdf_eval(p, TANGENT, wv, ax))
            assert np.max(np.abs(ours / ref - 1.0)) < tol


# ------------------------------------------------------------------------------------------------
# the paper's form
def eq2_transcription(p, wv, axis, lam):
    """Eq. 2 with App. A's B_R, B_TT, written out with scipy (i0, erf), in loomlight's terms: F_R and
    G at the viewer's theta (module doc D2), Gaussian mass I on the von Mises, + (1 - I) uniform."""
    tv, phv = B.angles(TANGENT, wv)
    ta, pha = B.angles(TANGENT, axis)
    out = np.zeros(3)
    for lobe in (0, 1):
        beta = p[6 + lobe]
        b2 = beta ** -2
        lam_p = 0.5 * b2 + 0.5 * lam
        th_p = (-b2 * tv + lam * ta) / (b2 + lam)
        a_p = math.exp(-b2 * lam / (b2 + lam) * (tv + ta) ** 2 / 2)
        erf_term = 0.5 * math.sqrt(math.pi / lam_p) * (special.erf(math.sqrt(lam_p) * (math.pi / 2 - th_p))
                                                      - special.erf(math.sqrt(lam_p) * (-math.pi / 2 - th_p)))
        lc = lam * math.cos(ta) * math.cos(th_p)
        common = math.cos(th_p) ** 2 / (math.sqrt(2 * math.pi) * beta * B.G_norm(-tv, beta))
        if lobe == 0:
            bfun = common * special.i0e(lc)
        else:
            k = p[8] ** -2
            lam_m = math.sqrt(k * k + lc * lc - 2 * k * lc * math.cos(pha - phv))
            von_mises = special.i0e(lam_m) * math.exp(lam_m - lc - k) / special.i0e(k)
            bfun = common * (p[9] * von_mises + (1 - p[9]) * special.i0e(lc))
        for c in range(3):
            f = B.fresnel_R(tv, p[c])
            w = f if lobe == 0 else (1 - f) * p[3 + c]
            out[c] += a_p * w * bfun * erf_term
    return out


def test_paper_form_is_eq2():
    """bcsdf_sg_gamma_paper against the line-by-line transcription of Eq. 2 / App. A above, 200 random
    views and axes, two presets, lam in [100, 3000]: relative difference < 1e-11."""
    rng = np.random.default_rng(7)
    for name in ("gabardine", "cotton"):
        p = preset(name)
        for _ in range(100):
            wv = rng.normal(size=3)
            wv /= np.linalg.norm(wv)
            tv, phv = B.angles(TANGENT, wv)
            ax = B.from_angles(TANGENT, -tv + rng.normal() * 0.2, phv + rng.uniform(-math.pi, math.pi))
            lam = rng.uniform(100.0, 3000.0)
            ref = eq2_transcription(p, wv, ax, lam)
            ours = np.array(S.bcsdf_sg_gamma_paper(p, TANGENT, wv, ax, lam))
            assert np.all(np.abs(ours - ref) <= 1e-11 * np.abs(ref) + 1e-300)


def test_paper_form_errors():
    """The measured error of the paper's form (module doc D4a, D6), against the same quadrature, for
    the record and against regressions: the R lobe alone (C_TT = 0) is within 2 % for |theta_v| <= 57
    deg at lam >= 100; the full BCSDF's TT lobe carries the von Mises error, > 5 % on gabardine's
    grid (which the refined form holds under 1.2 %)."""
    p = preset("gabardine").copy()
    p_r = p.copy()
    p_r[3:6] = 0.0
    worst_r = 0.0
    for lam in (100.0, 1000.0):
        for tv in (-1.0, -0.3, 0.5):
            for ta, dphi in [(-tv, 0.0), (-tv, 1.6), (-tv + 2 / math.sqrt(lam), 1.0), (-tv, math.pi)]:
                wv = B.from_angles(TANGENT, tv, PHI_VIEW)
                ax = B.from_angles(TANGENT, ta, PHI_VIEW + dphi)
                ref = gamma_quadrature(p_r, wv, ax, lam)
                ours = np.array(S.bcsdf_sg_gamma_paper(p_r, TANGENT, wv, ax, lam))
                worst_r = max(worst_r, np.max(np.abs(ours / ref - 1.0)))
    print(f"paper form, R lobe: max rel {worst_r:.2e}")
    assert worst_r < 2e-2
    rel_paper, _, _, _ = gamma_errors("gabardine", 200.0, S.bcsdf_sg_gamma_paper)
    print(f"paper form, gabardine lam=200: max rel {rel_paper:.2e}")
    assert rel_paper > 5e-2


# ------------------------------------------------------------------------------------------------
# visibility
def test_erf_visibility_limits():
    """erf_visibility: 1/2 at d = 0, -> 1 (visible) and -> 0 (occluded) far from the boundary,
    V(d) + V(-d) = 1, and 1/2 [erf(1) + 1] one width sqrt(2/lam) inside the visible side (§5.2.2)."""
    for lam in (100.0, 200.0, 1000.0):
        assert S.erf_visibility(0.0, lam) == 0.5
        assert S.erf_visibility(math.pi, lam) == 1.0
        assert S.erf_visibility(-math.pi, lam) < 1e-100
        for d in (0.01, 0.05, 0.2):
            assert abs(S.erf_visibility(d, lam) + S.erf_visibility(-d, lam) - 1.0) < 1e-15
        w = math.sqrt(2.0 / lam)
        assert abs(S.erf_visibility(w, lam) - 0.5 * (math.erf(1.0) + 1.0)) < 1e-15


def test_erf_visibility_is_sg_behind_a_great_circle():
    """The motivation of §5.2.2: the fraction of a normalised SG's mass on the visible side of a
    great circle at angular distance d from its axis (exact: 1-D quadrature of the fraction of each
    circle about the axis that lies in the half-space) approaches erf_visibility(d, lam) as lam grows:
    within 0.02 at lam = 200 and 0.005 at lam = 1000, |d| <= 4 widths."""
    from scipy.integrate import quad

    for lam, tol in ((200.0, 0.02), (1000.0, 0.005)):
        for d in np.linspace(-4.0, 4.0, 9) / math.sqrt(lam):
            alpha = 0.5 * math.pi - d    # angle between the axis and the visible half-space's pole

            def ring(psi, alpha=alpha, lam=lam):
                c = -math.cos(psi) * math.cos(alpha) / max(math.sin(psi) * math.sin(alpha), 1e-300)
                frac = 0.0 if c >= 1.0 else (1.0 if c <= -1.0 else math.acos(c) / math.pi)
                return frac * math.exp(lam * (math.cos(psi) - 1.0)) * 2 * math.pi * math.sin(psi)

            mass = quad(ring, 0.0, math.pi, points=[abs(d), 10 / math.sqrt(lam)], limit=400, epsabs=1e-14)[0]
            assert abs(mass / sg.sg_mass(lam) - S.erf_visibility(d, lam)) < tol


def ssg_setup(seed):
    """A synthetic sum-of-SGs visibility: the §4.1 Fibonacci axes (Q = 48, upper hemisphere of the
    world frame, turned by a random angle), random weights of the order of a cell's solid angle with a
    quarter of them zero (occluded cells)."""
    rng = np.random.default_rng(seed)
    axes = sg.spherical_fibonacci_axes(48, rng.uniform(0.0, 2.0 * math.pi))
    weights = rng.uniform(0.0, 2.0 * 2.0 * math.pi / 48, size=48)
    weights[rng.permutation(48)[:12]] = 0.0
    return axes, weights


@pytest.mark.parametrize("name", ["silk", "fleece"])
def test_ssg_product_against_quadrature(name):
    """sg_light_local_ssg (§5.2.2: the soft SG broken into the products with the visibility's SGs,
    each convolved by Gamma) against a direct quadrature of int V^ssg(w) G(w; xi, lam) bcsdf_eval dw
    with the visibility in the integrand, lam = 50 (soft), lam_svf = 128, three views and axes:
    relative error < 1e-7 per channel (measured 8e-9: the products' sharpnesses are 78-178 and the
    views are away from grazing, where the refined Gamma is accurate to ~1e-8; the paper's form is
    off by up to 37 % on the same cases)."""
    p = preset(name)
    axes, weights = ssg_setup(11)
    lam, lam_svf = 50.0, 128.0
    t = np.array([1.0, 0.2, 0.1]) / np.linalg.norm([1.0, 0.2, 0.1])   # fibre lying in the fabric plane
    for wv, xi in [((0.3, 0.0, 0.95), (-0.2, 0.3, 0.93)), ((-0.5, 0.5, 0.7), (0.6, -0.3, 0.74)),
                   ((0.1, -0.8, 0.59), (0.1, 0.8, 0.59))]:
        wv = np.array(wv) / np.linalg.norm(wv)
        xi = np.array(xi) / np.linalg.norm(xi)
        ours = np.array(S.sg_light_local_ssg(p, t, wv, axes, weights, lam_svf, xi, lam))
        ref = _sphere_quadrature(p, t, wv, xi, lam, axes, weights, lam_svf, GL8[0], GL8[1], 8, 48)
        assert np.max(np.abs(ours / ref - 1.0)) < 1e-7, (ours, ref)


def test_single_scatter_blend():
    """sg_single_scatter (§5.2.2, unit-power SG: divided by M(lam)): the sum-of-SGs result at and below
    lam = 100, erf_visibility(d) Gamma at and above 200, and in between exactly the linear
    interpolation (1 - s) ssg + s V Gamma, s = (lam - 100) / 100, of the two branches at that lam."""
    p = preset("gabardine")
    axes, weights = ssg_setup(5)
    t = np.array([1.0, 0.2, 0.1]) / np.linalg.norm([1.0, 0.2, 0.1])
    wv = np.array([0.3, 0.0, 0.95]) / np.linalg.norm([0.3, 0.0, 0.95])
    xi = np.array([-0.2, 0.1, 0.97]) / np.linalg.norm([-0.2, 0.1, 0.97])
    d = 0.03
    for lam in (50.0, 100.0, 130.0, 150.0, 199.0, 200.0, 400.0):
        m = sg.sg_mass(lam)
        a = np.array(S.sg_light_local_ssg(p, t, wv, axes, weights, 128.0, xi, lam)) / m
        b = S.erf_visibility(d, lam) * np.array(S.bcsdf_sg_gamma(p, t, wv, xi, lam)) / m
        s = min(1.0, max(0.0, (lam - 100.0) / 100.0))
        ours = np.array(S.sg_single_scatter(p, t, wv, xi, lam, d, axes, weights, 128.0))
        assert np.allclose(ours, (1 - s) * a + s * b, rtol=1e-13, atol=0.0)
        if lam <= 100.0:
            assert np.allclose(ours, a, rtol=1e-14, atol=0.0)
        if lam >= 200.0:
            assert np.allclose(ours, b, rtol=1e-14, atol=0.0)
    # the paper's form is selectable through the same entry points
    lam = 150.0
    ours = np.array(S.sg_single_scatter(p, t, wv, xi, lam, d, axes, weights, 128.0, S.GAMMA_PAPER))
    a = np.array(S.sg_light_local_ssg(p, t, wv, axes, weights, 128.0, xi, lam, S.GAMMA_PAPER))
    b = S.erf_visibility(d, lam) * np.array(S.bcsdf_sg_gamma_paper(p, t, wv, xi, lam))
    assert np.allclose(ours, 0.5 * (a + b) / sg.sg_mass(lam), rtol=1e-13, atol=0.0)
