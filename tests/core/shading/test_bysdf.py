"""The BYSDF of seed 004 §4.1 (stages/core/shading/bysdf.py): GGX and Fresnel closed forms, the rough
dielectric against Walter et al. 2007's equations written out independently, every sampler against its
density through the shared chi-square harness (tests/chisquare.py: check_shading_model, which also checks
the sample contract), energy (white furnace, the body albedos' closed forms), reciprocity of the
reflection side, degenerate input.

The harness calls sample(p, frame, wi, u0, u1, u2) / pdf(p, frame, wi, wo) / eval(p, frame, wi, wo);
one set of adapters below serves every BYSDF routine, with frame = [t (3), n (3), shadow, att_spec,
att_body, routine id] (for the exit routines t, n are t_y, n_y and wi is d, the direction arriving
inside), so the harness compiles once for all of them.
"""
import math

import numpy as np
import pytest
from numba import njit

from stages.core.rng import uniform
from stages.core.shading import bysdf as Y
from stages.core.shading.bysdf import (
    ALPHA_MIN,
    BYSDF_SIZE,
    P_R_MAX,
    P_R_MIN,
    attenuation,
    body_exit_eval_pdf,
    body_exit_sample,
    body_reflect_eval_pdf,
    body_reflect_sample,
    cone_reflect_eval_pdf,
    cone_reflect_sample,
    diffusion_reflectance,
    enter_eval_pdf,
    enter_sample,
    exit_eval_pdf,
    exit_sample,
    fresnel_diffuse_reflectance,
    lommel_seeliger_albedo,
    pack_bysdf,
    reflect_eval_pdf,
    reflect_probability,
    reflect_sample,
    spec_exit_eval_pdf,
    spec_exit_sample,
    spec_reflect_eval_pdf,
    spec_reflect_sample,
)
from stages.core.shading.microfacet import fresnel_dielectric, ggx_D, ggx_G1
from tests.chisquare import bin_integrals, check_shading_model, shading_draw

SPEC_R, ENTER, SPEC_T, BODY_R, BODY_T, SIDE_R, SIDE_T, WRONG_ETA, CHAIN, CHAIN_SPEC, CONE_R = range(11)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _frame(t, n, routine, shadow=1.0, att_spec=1.0, att_body=1.0):
    return np.array([*t, *n, shadow, att_spec, att_body, routine], float)


def _dir(theta_deg, phi_deg, t, n):
    """Unit direction at polar angle theta from n, azimuth phi from t (about n)."""
    t, n = np.asarray(t, float), np.asarray(n, float)
    b = np.cross(n, t)
    th, ph = math.radians(theta_deg), math.radians(phi_deg)
    return _unit(math.sin(th) * (math.cos(ph) * t + math.sin(ph) * b) + math.cos(th) * n)


# ------------------------------------------------------------------------------------------------
# adapters: one sample / pdf / eval for every routine (frame[9] = routine id)
@njit
def _cylinder_exit_normal(t, n, d):
    """Outward normal where the chord from x along d leaves a cylinder of axis t whose normal at x is n
    (n . t = 0): n_y = n - 2 (n.d) d_perp / |d_perp|^2, d_perp = d - (d.t) t."""
    dt = d[0] * t[0] + d[1] * t[1] + d[2] * t[2]
    nd = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
    ny = np.empty(3)
    l2 = 0.0
    for j in range(3):
        ny[j] = d[j] - dt * t[j]
        l2 += ny[j] * ny[j]
    if l2 <= 1e-300:
        for j in range(3):
            ny[j] = -n[j]
        return ny
    ln = 0.0
    for j in range(3):
        ny[j] = n[j] - 2.0 * nd / l2 * ny[j]
        ln += ny[j] * ny[j]
    ln = math.sqrt(ln)
    for j in range(3):
        ny[j] /= ln
    return ny


@njit
def _sample(p, fr, wi, u0, u1, u2):
    k = int(fr[9])
    t = fr[0:3]
    n = fr[3:6]
    if k == SPEC_R:
        s = spec_reflect_sample(p, t, n, wi, u1, u2)
    elif k == ENTER:
        e = enter_sample(p, t, n, wi, u1, u2)
        return e.d, e.weight, e.weight, e.weight, e.pdf
    elif k == SPEC_T:
        s = spec_exit_sample(p, t, n, wi, u1, u2)
    elif k == BODY_R:
        s = body_reflect_sample(p, n, wi, u1, u2)
    elif k == BODY_T:
        s = body_exit_sample(p, n, u1, u2)
    elif k == CONE_R:
        s = cone_reflect_sample(p, t, n, wi, u1, u2)
    elif k == SIDE_R:
        s = reflect_sample(p, t, n, wi, fr[6], u0, u1, u2)
    elif k == CHAIN or k == CHAIN_SPEC:
        # energy only (no density): enter at x, then the exit side (CHAIN) or the specular exit (CHAIN_SPEC)
        # where the chord leaves a cylinder about t; the exit's uniforms are hashed from u0 (unused by enter)
        e = enter_sample(p, t, n, wi, u1, u2)
        if e.pdf <= 0.0:
            return e.d, 0.0, 0.0, 0.0, 0.0
        ny = _cylinder_exit_normal(t, n, e.d)
        key = int(u0 * 9007199254740992.0)
        v0, v1, v2 = uniform(key, 0, 0), uniform(key, 0, 1), uniform(key, 0, 2)
        if k == CHAIN:      # the enter weight is the specular path's (the body path only takes y from d)
            s = exit_sample(p, t, ny, e.d, fr[7] * e.weight, fr[8], fr[6], v0, v1, v2)
            return s.wo, s.r, s.g, s.b, s.pdf
        s = spec_exit_sample(p, t, ny, e.d, v1, v2)
        return s.wo, e.weight * s.r, e.weight * s.g, e.weight * s.b, s.pdf
    elif k == WRONG_ETA:   # a broken sampler (test_chi_square_rejects_a_wrong_btdf_jacobian): drawn with eta 1.5
        q = p.copy()
        q[Y.ETA] = 1.5
        s = spec_exit_sample(q, t, n, wi, u1, u2)
        if s.pdf <= 0.0:
            return s.wo, 0.0, 0.0, 0.0, 0.0
        v = spec_exit_eval_pdf(p, t, n, wi, s.wo)
        if v.pdf <= 0.0:
            return s.wo, 0.0, 0.0, 0.0, 0.0
        return s.wo, v.r / v.pdf, v.g / v.pdf, v.b / v.pdf, v.pdf
    else:
        s = exit_sample(p, t, n, wi, fr[7], fr[8], fr[6], u0, u1, u2)
    return s.wo, s.r, s.g, s.b, s.pdf


@njit
def _eval_pdf(p, fr, wi, wo):
    k = int(fr[9])
    t = fr[0:3]
    n = fr[3:6]
    if k == SPEC_R:
        v = spec_reflect_eval_pdf(p, t, n, wi, wo)
    elif k == ENTER:
        f, q = enter_eval_pdf(p, t, n, wi, wo)
        return f, f, f, q
    elif k == SPEC_T or k == WRONG_ETA:
        v = spec_exit_eval_pdf(p, t, n, wi, wo)
    elif k == BODY_R:
        v = body_reflect_eval_pdf(p, n, wi, wo)
    elif k == BODY_T:
        v = body_exit_eval_pdf(p, n, wo)
    elif k == CONE_R:
        v = cone_reflect_eval_pdf(p, t, n, wi, wo)
    elif k == SIDE_R:
        v = reflect_eval_pdf(p, t, n, wi, wo, fr[6])
    else:                  # SIDE_T (the CHAIN routines are only drawn, for their weights)
        v = exit_eval_pdf(p, t, n, wi, wo, fr[7], fr[8], fr[6])
    return v.r, v.g, v.b, v.pdf


@njit
def _pdf(p, fr, wi, wo):
    return _eval_pdf(p, fr, wi, wo)[3]


@njit
def _eval(p, fr, wi, wo):
    r, g, b, _ = _eval_pdf(p, fr, wi, wo)
    return r, g, b


T0 = _unit((1.0, 0.0, 0.0))
N0 = _unit((0.0, 0.0, 1.0))
T1 = _unit((0.6, 0.48, -0.64))          # an oblique frame: t1 . n1 = 0
N1 = _unit((0.0, 0.8, 0.6))
ROUGH = dict(alpha_u=0.6, alpha_v=0.25, alpha_exit=0.4, body_r=(0.9, 0.5, 0.2), body_t=(0.8, 0.6, 0.1),
             ks=(1.0, 0.7, 0.4), kt_exit=0.6)

# (routine, parameters, t, n, wi (theta, phi about n; for the exit routines d), shadow, att_spec,
#  att_body[, harness options: axis (default n), res, sub]): the first of each routine runs in make test, the
# others are slow. Refraction at grazing wi concentrates d in azimuth, and GGX's horizontal micro-normals
# (D > 0 at m.n = 0) make the density of d jump to 0 along a curve: those cases need finer bins (FINE) for the
# bin integrals of the expected counts to be exact enough.
FINE = dict(res=(100, 200), sub=8)
CASES = [
    (SPEC_R, {}, T0, N0, (40.0, 30.0), 1.0, 1.0, 1.0),
    (ENTER, {}, T0, N0, (35.0, 120.0), 1.0, 1.0, 1.0),
    (SPEC_T, {}, T0, N0, (25.0, 60.0), 1.0, 1.0, 1.0),
    (BODY_R, ROUGH, T1, N1, (50.0, 10.0), 1.0, 1.0, 1.0),
    (BODY_T, ROUGH, T1, N1, (10.0, 0.0), 1.0, 1.0, 1.0),
    (CONE_R, dict(ROUGH, cone_width=0.2), T1, N1, (50.0, 20.0), 1.0, 1.0, 1.0),
    (SIDE_R, ROUGH, T1, N1, (60.0, -45.0), 0.7, 1.0, 1.0),
    (SIDE_R, dict(ROUGH, cone_share=0.6, cone_width=0.25), T1, N1, (50.0, 20.0), 0.7, 1.0, 1.0),   # the cone lobe
    (SIDE_T, ROUGH, T1, N1, (30.0, 200.0), 0.8, 0.6, 0.9),
]
SLOW_CASES = [
    (SPEC_R, dict(alpha_u=0.05, alpha_v=0.5), T1, N1, (80.0, 70.0), 1.0, 1.0, 1.0, FINE),
    (SPEC_R, dict(alpha_u=1.0, alpha_v=0.6), T0, N0, (0.0, 0.0), 1.0, 1.0, 1.0),
    (ENTER, dict(alpha_u=0.9, alpha_v=0.6, eta=1.33), T1, N1, (75.0, 20.0), 1.0, 1.0, 1.0, FINE),
    (ENTER, dict(alpha_u=0.25, alpha_v=0.15, eta=1.33), T1, N1, (80.0, 20.0), 1.0, 1.0, 1.0, FINE),
    (ENTER, dict(alpha_u=0.2, alpha_v=0.2), T0, N0, (0.0, 0.0), 1.0, 1.0, 1.0, dict(axis=T0)),  # narrow: about t
    (SPEC_T, dict(alpha_exit=0.3), T1, N1, (50.0, 10.0), 1.0, 1.0, 1.0),   # much total internal reflection
    (SPEC_T, dict(alpha_exit=1.5, eta=1.33), T0, N0, (0.0, 0.0), 1.0, 1.0, 1.0),
    (BODY_R, dict(ls_mix=1.0, body_r=(1.0, 0.3, 0.0)), T0, N0, (85.0, 0.0), 1.0, 1.0, 1.0),
    (BODY_T, {}, T0, N0, (70.0, 0.0), 1.0, 1.0, 1.0),
    (CONE_R, dict(cone_width=1.5), T0, N0, (0.0, 0.0), 1.0, 1.0, 1.0),            # wide: nearly cos(phi) / 2
    (SIDE_R, {}, T0, N0, (20.0, 0.0), 0.5, 1.0, 1.0),     # the reference's example: the spec lobe dominates
    (SIDE_R, dict(alpha_u=0.1, alpha_v=0.15, spec_weight=0.3), T1, N1, (75.0, 90.0), 1.0, 1.0, 1.0),
    (SIDE_R, dict(spec_weight=0.0, cone_share=1.0, cone_width=0.05), T0, N0, (80.0, 0.0), 1.0, 1.0, 1.0, FINE),
    (SIDE_T, {}, T0, N0, (0.0, 0.0), 1.0, 1.0, 1.0),
    (SIDE_T, dict(alpha_exit=0.2), T1, N1, (45.0, 0.0), 0.3, 1.0, 0.05),
]
NAMES = {SPEC_R: "spec_reflect", ENTER: "enter", SPEC_T: "spec_exit", BODY_R: "body_reflect",
         BODY_T: "body_exit", CONE_R: "cone_reflect", SIDE_R: "reflect_side", SIDE_T: "exit_side"}


def _run_case(case, n=200_000, seed=12):
    k, params, t, n_, (th, ph), shadow, a_s, a_b = case[:8]
    opts = dict(axis=n_, res=(40, 80), sub=6)
    opts.update(case[8] if len(case) > 8 else {})
    p = pack_bysdf(**params)
    wi = _dir(th, ph, t, n_)          # exits: d, travelling inside towards the exit's outside (d . n_y > 0)
    fr = _frame(t, n_, k, shadow, a_s, a_b)
    return check_shading_model(_sample, _pdf, _eval, p, fr, wi, n=n, seed=seed, n_contract=5000, **opts)


@pytest.mark.parametrize("case", CASES, ids=[NAMES[c[0]] for c in CASES])
def test_sampling_chi_square(case):
    """Reference: the shared chi-square harness (tests/chisquare.py: check_shading_model): 200k samples of
    each BYSDF sampler (the six lobes: visible-normal GGX reflection and refraction in and out, Heitz 2018 /
    Walter 2007; cosine-weighted body lobes; the cone lobe's truncated logistic about the fibres' cone; and
    the two side-level lobe mixtures, the reflection side's with and without its cone part) against the routine's own
    pdf in (cos theta, phi) about n, after the sample contract at 5000 samples (|wo| = 1, pdf(wo) == returned
    pdf, weight == eval(wo) / pdf). Failed samples (total internal reflection, directions below the
    surface) count as attempts: the density integrates to the success fraction."""
    res = _run_case(case)
    assert res.passed, res.message


@pytest.mark.slow
@pytest.mark.parametrize("case", SLOW_CASES, ids=[NAMES[c[0]] for c in SLOW_CASES])
def test_sampling_chi_square_more(case):
    """As test_sampling_chi_square at the other settings: grazing and normal wi, very anisotropic and very
    rough GGX, eta 1.33, an exit with much total internal reflection, the reference's example values."""
    res = _run_case(case)
    assert res.passed, res.message


def test_chi_square_rejects_a_wrong_btdf_jacobian():
    """The harness must see a wrong density: exit directions drawn with eta 1.5 but reported (weight and
    pdf, a consistent contract) by the eta 1.6 BTDF -- a different refraction Jacobian and Fresnel -- must
    fail the chi-square, so the passing tests above can fail."""
    q = pack_bysdf(alpha_exit=0.5, eta=1.6)
    res = check_shading_model(_sample, _pdf, _eval, q, _frame(T0, N0, WRONG_ETA), _dir(20.0, 0.0, T0, N0), axis=N0,
                              n=200_000, seed=3)
    assert not res.passed and res.message.startswith("chi2"), res.message


# ------------------------------------------------------------------------------------------------
# closed forms: GGX, Fresnel, packing
@njit
def _ndf_theta_phi(th, ph, au, av, wx, wy, wz, visible):
    """D(m) cos(theta) sin(theta) (visible: G1(w) <w, m>^+ D(m) sin(theta)) at m(theta, phi) about z."""
    out = np.empty(th.shape[0])
    for k in range(th.shape[0]):
        s = math.sin(th[k])
        mx, my, mz = s * math.cos(ph[k]), s * math.sin(ph[k]), math.cos(th[k])
        D = ggx_D(mx, my, mz, au, av)
        if visible:
            out[k] = ggx_G1(wx, wy, wz, au, av) * max(0.0, wx * mx + wy * my + wz * mz) * D * s
        else:
            out[k] = D * mz * s
    return out


@pytest.mark.parametrize("au, av", [(0.2, 0.3), pytest.param(0.05, 0.5, marks=pytest.mark.slow),
                                    pytest.param(1.0, 0.9, marks=pytest.mark.slow)])
def test_ggx_normalisation(au, av):
    """Reference: an NDF's projected area is 1, int D(m) (m.n) dm = 1 (Walter 2007 Eq. 4), and the
    distribution of visible normals is normalised, int G1(w) <w, m>^+ D(m) dm = w.n (Heitz 2014 Eq. 2 /
    Heitz 2018 Eq. 1: Smith's Lambda consistent with D) -- by Gauss-Legendre over (theta, phi)."""
    bounds = ((0.0, 0.5 * math.pi), (-math.pi, math.pi))
    val = bin_integrals(lambda x, y: _ndf_theta_phi(x, y, au, av, 0.0, 0.0, 1.0, False), bounds, (400, 64), sub=4)
    assert val.sum() == pytest.approx(1.0, abs=2e-4)
    w = _dir(70.0, 35.0, T0, N0)
    val = bin_integrals(lambda x, y: _ndf_theta_phi(x, y, au, av, w[0], w[1], w[2], True), bounds, (400, 64), sub=4)
    assert val.sum() == pytest.approx(w[2], rel=5e-4)


def _walter(i, o, n, t, au, av, eta_i, eta_o):
    """Walter et al. 2007 Eqs. 20-21 written out independently (numpy, Fresnel from Eq. 22, D and Smith G1
    of anisotropic GGX in the frame (t, n x t, n), G = G1(i) G1(o)): f(i, o) |o.n|."""
    b = np.cross(n, t)

    def loc(w):
        return np.array([w @ t, w @ b, w @ n])

    def G1(w, h):
        x, y, z = loc(w)
        lam = 0.5 * (math.sqrt(1.0 + (au * au * x * x + av * av * y * y) / (z * z)) - 1.0)
        return float((w @ h) / (w @ n) > 0) / (1.0 + lam)

    def D(h):
        x, y, z = loc(h)
        return float(z > 0) / (math.pi * au * av * ((x / au) ** 2 + (y / av) ** 2 + z * z) ** 2)

    def F(c, eta):  # Walter Eq. 22, eta = eta_t / eta_i
        g2 = eta * eta - 1.0 + c * c
        if g2 < 0:
            return 1.0
        g = math.sqrt(g2)
        return 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1.0 + ((c * (g + c) - 1.0) / (c * (g - c) + 1.0)) ** 2)

    if (i @ n) * (o @ n) > 0:                                      # Eq. 20, reflection
        h = np.sign(i @ n) * (i + o)
        h /= np.linalg.norm(h)
        return F(abs(i @ h), eta_o / eta_i) * G1(i, h) * G1(o, h) * D(h) / (4.0 * abs(i @ n))
    h = -(eta_i * i + eta_o * o)                                      # Eq. 16 and 21, refraction
    h /= np.linalg.norm(h)
    h *= np.sign(h @ n)
    ih, oh = i @ h, o @ h
    return (abs(ih) * abs(oh) / abs(i @ n) * eta_o ** 2 * (1.0 - F(abs(ih), eta_o / eta_i)) * G1(i, h) * G1(o, h)
            * D(h) / (eta_i * ih + eta_o * oh) ** 2)


def test_rough_dielectric_matches_walter():
    """Reference: Walter et al. 2007 Eqs. 20 (reflection) and 21 (transmission), written out independently
    above: spec_reflect_eval_pdf = KS f_r |wo.n|; enter_eval_pdf = f_t |d.n| with i = wi (index 1) and
    o = d (index eta) -- Eq. 21's eta_o^2 is the flux form, no 1/eta^2 radiance scaling; spec_exit_eval_pdf =
    KT f_t |wo.n| with i = -d (index eta) and o = wo (index 1), at 200 random pairs each (enter divided by
    its energy compensation, a factor of wi alone: test_energy_tables_match_the_samplers)."""
    p = pack_bysdf(**ROUGH)
    au, av, eta, a = ROUGH["alpha_u"], ROUGH["alpha_v"], 1.5, ROUGH["alpha_exit"]
    rng = np.random.default_rng(12)
    up = lambda w: w if w @ N1 > 0 else w - 2 * (w @ N1) * N1     # noqa: E731
    nonzero = np.zeros(3, int)                 # reflection, enter, exit pairs with a nonzero reference
    for _ in range(200):
        wi, wo = up(_unit(rng.normal(size=3))), up(_unit(rng.normal(size=3)))
        refs = (_walter(wi, wo, N1, T1, au, av, 1.0, eta), _walter(wi, -wo, N1, T1, au, av, 1.0, eta),
                _walter(-wi, wo, -N1, T1, a, a, eta, 1.0))
        np.testing.assert_allclose(spec_reflect_eval_pdf(p, T1, N1, wi, wo)[:3], np.array(ROUGH["ks"]) * refs[0],
                                   rtol=1e-10, atol=1e-300)
        c = Y.enter_compensation(p, *Y.to_local(Y.shading_frame(T1, N1), wi))   # the energy compensation
        assert enter_eval_pdf(p, T1, N1, wi, -wo)[0] / c == pytest.approx(refs[1], rel=1e-10, abs=1e-300)
        # d = wi arrives inside and leaves along wo
        assert spec_exit_eval_pdf(p, T1, N1, wi, wo)[0] == pytest.approx(ROUGH["kt_exit"] * refs[2], rel=1e-10,
                                                                         abs=1e-300)
        nonzero += np.array(refs) > 0
    assert np.all(nonzero >= 30), nonzero


def test_fresnel_closed_forms():
    """Reference: Fresnel equations: normal incidence ((eta - 1)/(eta + 1))^2; 1 beyond the critical angle
    asin(1/eta) from the dense side; the same reflectance from both sides along a refracted pair (Stokes
    relations: cos_t from Snell's law); F_dr(1) = 0.0016 (Jensen 2001's fit nearly vanishes at a matched
    interface) and R_d(1) = 1 (no absorption: all light comes back), R_d(0) = 0, R_d <= a'."""
    for eta in (1.33, 1.5, 2.0):
        assert fresnel_dielectric(1.0, eta) == pytest.approx(((eta - 1) / (eta + 1)) ** 2, rel=1e-12)
        crit = math.asin(1.0 / eta)
        assert fresnel_dielectric(math.cos(crit + 1e-6), 1.0 / eta) == 1.0
        for ci in (0.9, 0.5, 0.1):
            ct = math.sqrt(1.0 - (1.0 - ci * ci) / eta ** 2)
            assert fresnel_dielectric(ct, 1.0 / eta) == pytest.approx(fresnel_dielectric(ci, eta), rel=1e-12)
    assert fresnel_diffuse_reflectance(1.0) == pytest.approx(0.0016, abs=1e-12)
    assert diffusion_reflectance(1.0, 1.5) == pytest.approx(1.0, rel=1e-14)
    assert diffusion_reflectance(0.0, 1.5) == 0.0
    for a in np.linspace(0.0, 1.0, 11):
        assert 0.0 <= diffusion_reflectance(a, 1.5) <= a + 1e-15


def test_pack_defaults_and_ranges():
    """Reference: bysdf.md's example values (alpha_u 0.2, alpha_v 0.3, eta 1.5, ks 1, alpha_exit 0.9,
    kt_exit 0.1, sigma 5.5 / 0.1, m_r 0.5, body colours (0.045, 0.015, 0) and six times that) and the
    documented ranges (ValueError naming the parameter)."""
    p = pack_bysdf()
    assert p.shape == (BYSDF_SIZE,)
    expect = {Y.SPEC_WEIGHT: 0.5, Y.REFLECT_WEIGHT: 0.5, Y.ALPHA_U: 0.2, Y.ALPHA_V: 0.3, Y.ETA: 1.5, Y.KS_R: 1.0,
              Y.KS_G: 1.0, Y.KS_B: 1.0, Y.ALPHA_EXIT: 0.9, Y.KT_EXIT: 0.1, Y.BODY_R_R: 0.045, Y.BODY_R_G: 0.015,
              Y.BODY_R_B: 0.0, Y.BODY_T_R: 0.27, Y.BODY_T_G: 0.09, Y.BODY_T_B: 0.0, Y.SIGMA_SPEC: 5.5,
              Y.SIGMA_BODY: 0.1, Y.LS_MIX: 0.5, Y.CONE_SHARE: 0.0, Y.CONE_WIDTH: 0.3}
    assert sorted(expect) == list(range(Y.N_PARAMS))
    for k, v in expect.items():
        assert p[k] == pytest.approx(v, rel=1e-15)
    for bad in (dict(eta=1.0), dict(alpha_u=0.0), dict(spec_weight=1.2), dict(body_r=(0.5, 1.1, 0.0)),
                dict(sigma_body=-1.0), dict(ls_mix=float("nan")), dict(cone_share=1.5), dict(cone_width=0.0)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            pack_bysdf(**bad)


def test_attenuation_and_side_probability():
    """References: Beer-Lambert along the chord raised to the plies crossed, (exp(-sigma L))^n (§4.1), and
    P_R = clamp(beta F(wi.n) + (1 - beta) m_r, 0.05, 0.95) (this module's definition), with F the exact
    Fresnel reflectance."""
    p = pack_bysdf()
    a_s, a_d = attenuation(p, 0.3, 2.0)
    assert a_s == pytest.approx(math.exp(-5.5 * 0.3) ** 2, rel=1e-14)
    assert a_d == pytest.approx(math.exp(-0.1 * 0.3) ** 2, rel=1e-14)
    wi = _dir(60.0, 0.0, T0, N0)
    assert reflect_probability(p, wi, N0) == pytest.approx(0.5 * fresnel_dielectric(0.5, 1.5) + 0.25, rel=1e-14)
    assert reflect_probability(pack_bysdf(spec_weight=0.0, reflect_weight=1.0), wi, N0) == P_R_MAX
    assert reflect_probability(pack_bysdf(spec_weight=0.0, reflect_weight=0.0), wi, N0) == P_R_MIN


# ------------------------------------------------------------------------------------------------
# energy
WHITE = dict(ks=1.0, kt_exit=1.0, body_r=1.0, body_t=1.0, ls_mix=0.0)   # the diffusion term alone: R_d(1) = 1


def _albedo(p, t, n, wi, routine, N, seed):
    """Monte Carlo albedo (mean weight per channel, failed samples weigh 0) and its standard error, from N
    samples of a routine through the harness's draw loop."""
    _, w, _ = shading_draw(_sample, p, _frame(t, n, routine), wi, N, seed)
    return w.mean(axis=0), w.std(axis=0) / math.sqrt(N)


def _furnace(p, theta, phi, n_samples, seed):
    """(albedo, standard error) of the whole BYSDF at wi (theta, phi about N1 from T1): the reflection side's
    mean weight plus the enter step times the exit side's (exit point on a cylinder about t); every lobe and
    side <= 1 + 3 sigma on the way, the white channels equal."""
    wi = _dir(theta, phi, T1, N1)
    est = [_albedo(p, T1, N1, wi, k, n_samples, seed + k) for k in (SIDE_R, CHAIN, SPEC_R, ENTER, CHAIN_SPEC, BODY_R)]
    m = np.array([e[0] for e in est])
    sd = np.array([e[1] for e in est])
    assert np.allclose(m, m[:, :1]) and np.allclose(sd, sd[:, :1])       # white: the channels agree
    for k, name in enumerate(("reflection side", "enter x exit side", "spec reflection", "enter",
                              "enter x spec exit", "body reflection")):
        assert m[k, 0] <= 1.0 + 3.0 * sd[k, 0] + 1e-12, f"{name} albedo {m[k, 0]:.5f} +- {sd[k, 0]:.5f} > 1"
    return m[0, 0] + m[1, 0], math.hypot(sd[0, 0], sd[1, 0])


TABLE_TOL = 3e-3   # the energy tables' interpolation and quadrature error (test_energy_tables_match_the_samplers)


@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
def test_white_furnace(alpha):
    """Reference: energy conservation of a non-absorbing model (white furnace): with KS = KT = 1, white body
    colours (the diffusion term alone, R_d(1) = 1), no attenuation or shadowing, the BYSDF's albedo -- the
    reflection side (single-scattering GGX, the Kulla-Conty lobe f_ms, the body) plus enter (compensated)
    times the exit side (specular refraction out plus the light total internal reflection keeps, folded
    into the Lambertian exit) -- is 1 at every wi, within 4 sigma and the tables' TABLE_TOL, for an isotropic
    rough interface at x and y; each lobe <= 1. Without the compensation the interface alone loses up to
    30 % at alpha 1 and the exit up to 60 % (test_energy_tables_match_the_samplers)."""
    p = pack_bysdf(alpha_u=alpha, alpha_v=alpha, alpha_exit=alpha, **WHITE)
    for theta in (0.0, 45.0, 80.0):
        total, sd = _furnace(p, theta, 30.0, 50_000, 5)
        print(f"alpha {alpha}: theta_i {theta:4.0f}  BYSDF albedo {total:.4f} +- {sd:.4f}")
        assert total == pytest.approx(1.0, abs=4.0 * sd + TABLE_TOL)


@pytest.mark.parametrize("au, av, low, high", [(0.2, 0.3, 0.99, 1.005), pytest.param(1.0, 1.5, 0.95, 1.01,
                                                                                      marks=pytest.mark.slow)])
def test_white_furnace_anisotropic(au, av, low, high):
    """As test_white_furnace for an anisotropic interface at x, whose tables are read at an effective
    roughness (``interface_energy``: an approximation). Measured bands, stated here: the reference's
    roughness (0.2, 0.3) keeps 0.99-1.005 of the energy at every wi, (1.0, 1.5) 0.95-1.01."""
    p = pack_bysdf(alpha_u=au, alpha_v=av, **WHITE)
    for theta in (0.0, 45.0, 80.0):
        for phi in (0.0, 45.0, 90.0):
            total, sd = _furnace(p, theta, phi, 50_000, 7)
            print(f"alpha {au}/{av}: theta_i {theta:4.0f} phi {phi:4.0f}  BYSDF albedo {total:.4f} +- {sd:.4f}")
            assert low - 4.0 * sd <= total <= high + 4.0 * sd, (theta, phi, total)


@pytest.mark.slow
@pytest.mark.parametrize("alpha", [0.2, 0.5, 2.0])
def test_white_furnace_more(alpha):
    """As test_white_furnace at more roughnesses and eta 1.33, with 400k samples."""
    p = pack_bysdf(alpha_u=alpha, alpha_v=alpha, alpha_exit=alpha, eta=1.33, **WHITE)
    for theta in (0.0, 30.0, 60.0, 85.0):
        total, sd = _furnace(p, theta, 0.0, 400_000, 9)
        print(f"alpha {alpha}: theta_i {theta:4.0f}  BYSDF albedo {total:.4f} +- {sd:.4f}")
        assert total == pytest.approx(1.0, abs=4.0 * sd + TABLE_TOL)


def test_energy_tables_match_the_samplers():
    """Reference: brute force through the samplers themselves. The packed tables' single-scattering
    albedos -- E_R (= E - E_T) and E_T of the interface at x, E_T of the exit from inside -- equal the
    Monte Carlo mean weights of spec_reflect_sample, enter_sample (divided by its compensation) and
    spec_exit_sample / KT within 4 sigma + TABLE_TOL, at roughnesses between the table's nodes. And the
    single-scattering loss they compensate is what Heitz et al. 2016 describe: < 0.5 % at alpha 0.05, > 8 %
    at alpha 1 at every wi; E_avg is the cosine-weighted mean of the interpolated E (trapezoid check)."""
    for alpha in (0.05, 0.3, 1.0):
        p = pack_bysdf(alpha_u=alpha, alpha_v=alpha, alpha_exit=alpha, eta=1.4, ks=1.0, kt_exit=0.5)
        fr = Y.shading_frame(T0, N0)
        for theta in (0.0, 50.0, 80.0):
            wi = _dir(theta, 0.0, T0, N0)
            ix, iy, iz = Y.to_local(fr, wi)
            en = Y.interface_energy(p, ix, iy, iz)
            r, sr = _albedo(p, T0, N0, wi, SPEC_R, 40_000, 3)
            t, st = _albedo(p, T0, N0, wi, ENTER, 40_000, 4)
            c = Y.enter_compensation(p, ix, iy, iz)
            assert r[0] == pytest.approx(en.e - en.e_t, abs=4.0 * sr[0] + TABLE_TOL)
            assert t[0] / c == pytest.approx(en.e_t, abs=4.0 * st[0] / c + TABLE_TOL)
            loss = 1.0 - en.e
            assert (loss < 5e-3) if alpha == 0.05 and theta < 60.0 else (loss > 0.08 if alpha == 1.0 else True), loss
            d = _dir(theta, 0.0, T0, N0)           # arriving inside, leaving through n_y = N0 at cos theta
            x, sx = _albedo(p, T0, N0, d, SPEC_T, 40_000, 5)
            assert x[0] / 0.5 == pytest.approx(Y.exit_transmittance(p, float(d @ N0)), abs=8.0 * sx[0] + TABLE_TOL)
        mu = np.linspace(0.0, 1.0, 20001)
        e = np.array([Y.interface_energy(p, math.sqrt(1.0 - m * m), 0.0, m).e for m in mu])
        f = 2.0 * mu * e
        e_avg = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(mu)))
        assert Y.interface_energy(p, 0.0, 0.0, 1.0).e_avg == pytest.approx(e_avg, abs=1e-4)


@pytest.mark.parametrize("ls_mix", [1.0, 0.0])
def test_body_reflection_albedo(ls_mix):
    """References: the Lommel-Seeliger directional albedo a'/2 (1 - mu ln(1 + 1/mu)) (Hanrahan & Krueger
    1993's single scattering from a half-space, integrated over the hemisphere) and the dipole's total
    diffuse reflectance R_d (Jensen et al. 2001): the Monte Carlo albedo of body_reflect_sample at four mu
    and three a' matches within 4 sigma; the closed form of LS is also checked by quadrature."""
    a = (1.0, 0.5, 0.1)
    p = pack_bysdf(ls_mix=ls_mix, body_r=a, eta=1.4)
    for theta in (0.0, 40.0, 70.0, 89.0):
        wi = _dir(theta, 0.0, T0, N0)
        mu = float(wi @ N0)
        m, sd = _albedo(p, T0, N0, wi, BODY_R, 50_000, 21)
        for c in range(3):
            ref = a[c] * lommel_seeliger_albedo(mu) if ls_mix == 1.0 else diffusion_reflectance(a[c], 1.4)
            assert m[c] == pytest.approx(ref, abs=4.0 * sd[c] + 1e-13)
        if ls_mix == 1.0:
            x, w = np.polynomial.legendre.leggauss(200)
            c_o = 0.5 * (x + 1.0)
            quad = float(np.sum(0.5 * w * 2.0 * math.pi * c_o / (4.0 * math.pi * (mu + c_o))))
            assert lommel_seeliger_albedo(mu) == pytest.approx(quad, rel=1e-3 if mu < 0.05 else 1e-9)


@pytest.mark.parametrize("share, width", [(1.0, 0.3), (0.6, 0.05)])
def test_cone_lobe_energy_and_cone(share, width):
    """Reference: the cone part of the body reflection redistributes the body's light, it neither adds nor
    loses any: with cone_share s the body reflection's Monte Carlo albedo (the reflection side with no
    specular share, so the body alone) is still the diffusion term's R_d(a') per channel within 4 sigma, at
    incidence across the fibre (u_i = 0), along it (u_i = 0.94) and between; and the light leaves around the
    fibres' cone u_o = -u_i (propagation along the fibre kept): f towards the cone's direction in the
    plane of t and n is over five times f towards its mirror about the normal plane (u_o = +u_i, the
    backscatter direction), which only the diffuse part (1 - s) reaches."""
    a = (1.0, 0.5, 0.1)
    p = pack_bysdf(spec_weight=0.0, reflect_weight=1.0, body_r=a, ls_mix=0.0, cone_share=share, cone_width=width)
    for theta, phi in ((0.0, 0.0), (40.0, 90.0), (70.0, 0.0), (70.0, 45.0)):
        wi = _dir(theta, phi, T1, N1)
        m, sd = _albedo(p, T1, N1, wi, SIDE_R, 50_000, 31)
        for c in range(3):
            assert m[c] == pytest.approx(diffusion_reflectance(a[c], 1.5), abs=4.0 * sd[c] + 1e-12)
    wi = _dir(50.0, 0.0, T1, N1)                       # u_i = sin 50 deg along t
    on_cone = _dir(50.0, 180.0, T1, N1)                # u_o = -u_i
    mirror = _dir(50.0, 0.0, T1, N1)                   # u_o = +u_i (the backscatter direction)
    f_on = reflect_eval_pdf(p, T1, N1, wi, on_cone, 1.0)
    f_off = reflect_eval_pdf(p, T1, N1, wi, mirror, 1.0)
    assert f_on.r > 5.0 * f_off.r


# ------------------------------------------------------------------------------------------------
# reciprocity, degenerate input
def test_reflection_side_reciprocity():
    """Reference: Helmholtz reciprocity of the reflection side's BRDF (Walter 2007's rough dielectric
    reflection with separable Smith G2; the symmetric Lommel-Seeliger and constant diffusion terms; the
    cone part, normalised per incident direction, is not reciprocal and is off here, as by default):
    f(wi, wo) = (f cos)(wi, wo) / |wo.n| equals (f cos)(wo, wi) / |wi.n| for 300 random pairs."""
    p = pack_bysdf(**ROUGH)
    rng = np.random.default_rng(8)
    checked = 0
    for _ in range(300):
        a, b = _unit(rng.normal(size=3)), _unit(rng.normal(size=3))
        a[:] = a if a @ N1 > 0 else a - 2 * (a @ N1) * N1
        b[:] = b if b @ N1 > 0 else b - 2 * (b @ N1) * N1
        f_ab = np.array(reflect_eval_pdf(p, T1, N1, a, b, 0.7)[:3]) / (b @ N1)
        f_ba = np.array(reflect_eval_pdf(p, T1, N1, b, a, 0.7)[:3]) / (a @ N1)
        np.testing.assert_allclose(f_ab, f_ba, rtol=1e-10, atol=1e-300)
        checked += f_ab[0] > 0.0
    assert checked == 300


def test_degenerate_input():
    """Reference: the module's contract -- wi at or below the surface, wo on the wrong side, grazing
    directions, roughness at ALPHA_MIN, a tangent along the normal and a d that does not leave through n_y
    give finite zeros and pdf 0 (or finite values), never NaN; a tangent not orthogonal to n is
    orthogonalised (the same values as the orthogonal tangent)."""
    p_tiny = pack_bysdf(alpha_u=ALPHA_MIN, alpha_v=ALPHA_MIN, alpha_exit=ALPHA_MIN)
    below = _dir(120.0, 10.0, T0, N0)
    graze = _unit((1.0, 0.0, 0.0))
    up = _dir(30.0, 10.0, T0, N0)
    for p in (pack_bysdf(), p_tiny):
        for t in (T0, N0):
            for wi in (below, graze):
                assert tuple(reflect_eval_pdf(p, t, N0, wi, up, 1.0)) == (0.0, 0.0, 0.0, 0.0)
                assert reflect_sample(p, t, N0, wi, 1.0, 0.3, 0.4, 0.5).pdf == 0.0
                assert enter_sample(p, t, N0, wi, 0.4, 0.5).pdf == 0.0
                assert enter_eval_pdf(p, t, N0, wi, -up) == (0.0, 0.0)
            assert tuple(reflect_eval_pdf(p, t, N0, up, below, 1.0)) == (0.0, 0.0, 0.0, 0.0)
            assert enter_eval_pdf(p, t, N0, up, up) == (0.0, 0.0)          # "refraction" to the outside
            # d arriving from outside (d . n_y < 0): no specular exit; body exit is independent of d
            assert spec_exit_eval_pdf(p, t, N0, below, up).pdf == 0.0
            assert spec_exit_sample(p, t, N0, below, 0.2, 0.7).pdf == 0.0
            assert tuple(exit_eval_pdf(p, t, N0, up, below, 1.0, 1.0, 1.0)) == (0.0, 0.0, 0.0, 0.0)
            # a tangent not orthogonal to n: Gram-Schmidt, the same values as the orthogonal one
            skew = _unit(T1 + 0.4 * N1)
            np.testing.assert_allclose(reflect_eval_pdf(p, skew, N1, _dir(40, 0, T1, N1), _dir(30, 100, T1, N1), 1.0),
                                       reflect_eval_pdf(p, T1, N1, _dir(40, 0, T1, N1), _dir(30, 100, T1, N1), 1.0),
                                       rtol=1e-12)
            # zero energy everywhere: pdf 0
            assert reflect_eval_pdf(pack_bysdf(ks=0.0, body_r=0.0), t, N0, up, up, 1.0).pdf == 0.0
            assert exit_sample(p, t, N0, -up, 0.0, 0.0, 1.0, 0.5, 0.5, 0.5).pdf == 0.0
            for u in ((0.0, 0.0, 0.0), (0.999999, 0.999999, 0.999999), (0.5, 1e-300, 0.25)):
                for wi in (up, _dir(89.9999999, 0.0, T0, N0)):
                    vals = [*reflect_sample(p, t, N0, wi, 1.0, *u)[1:], *enter_sample(p, t, N0, wi, *u[1:])[1:],
                            *exit_sample(p, t, N0, -wi, 1.0, 1.0, 1.0, *u)[1:],
                            *exit_eval_pdf(p, t, N0, -wi, up, 1.0, 1.0, 1.0),
                            *reflect_eval_pdf(p, t, N0, wi, up, 1.0)]
                    assert np.all(np.isfinite(vals)), (u, wi, vals)
