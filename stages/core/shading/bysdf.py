"""The BYSDF of seed 004 (§4.1): four-lobe yarn shading -- specular and body, at the entry point x and
at the exit point y.

The paper's displayed equations were lost; the lobes below are rebuilt from its text (§4.1, Eqs. 1-5)
and the facts of its public reference implementation (``shared/reference/bysdf.md``). This file holds
the scattering functions only: the implicit plies, the fibre tables (which give the shading frame and
the shadowing S), the choice of the exit point y, the attenuation along x -> y and the path itself are
the integrator's.

Geometry and directions
-----------------------
A ray hits a yarn at x with a shading frame: unit fibre tangent ``t`` and unit outward normal ``n``;
the anisotropic frame is (t, b = n x t, n) (t is made orthogonal to n first, Gram-Schmidt; when t lies
along n any completion of n is used). ``wi`` is the unit direction towards the viewer, ``wo`` towards
the light. At x the light either stays on the viewer's side (the *reflection side*) or refracts into
the yarn (the *transmission side*): the path continues inside along ``d`` (the direction it travels,
from x towards y), reaches the exit point y, whose outward normal is ``n_y`` (and tangent ``t_y``), and
leaves towards ``wo``. All functions return f cos (cos = |cos| of the light's direction to the normal
it leaves or arrives at) as (r, g, b) and the solid-angle pdf of the matching sampler.

The model (beta = SPEC_WEIGHT, m_r = REFLECT_WEIGHT; the paper's Eq. 1 split into the two sides)
--------------------------------------------------------------------------------------------------
    f = beta     [ KS (f_sR + f_ms)(x)  +  T_x -> A_s -> BODY_T KT (f_sT + f_keep)(y) ]  (specular, Eqs. 2-3)
      + (1-beta) [ m_r S f_bR(x)  +  (1-m_r) A_d S_y f_bT(y) ]                          (body, Eqs. 4-5)

The dye colours what crosses the yarn, on either path: the specular path's exit carries the
transmission-side body colour BODY_T per channel, as the body's exit f_bT does. (The reference's
specular path is grey, KT and sigma scalars: with its example absorbers, sigma_spec 5.5 per unit and
KT 0.1, a white yarn's cloth returns 0.15 under a white sky; without them a black one returns 0.28,
its grey specular transmission passing every colour. A dyed yarn needs both: ``pipeline.renderers.bysdf``
maps a yarn's colour to BODY_R and BODY_T with the grey absorbers off.)

The body's transmission takes its exit point y from the enter step's direction d but not its weight:
the body's share of the energy reaching the far side is (1 - beta)(1 - m_r) already, and the Fresnel
transmission of the interface at x is the specular lobes' (weighting the body's path by it too counted
the interface twice and lost beta's complement of F).

- f_sR, specular reflection at x (Eq. 2, first case): a rough dielectric (Walter et al. 2007) with an
  anisotropic GGX normal distribution D (alpha_u along t, alpha_v along b), exact dielectric Fresnel F
  (relative index eta), Smith *uncorrelated* (separable) masking-shadowing G2 = G1(wi) G1(wo) -- the
  paper names the uncorrelated form -- times the specular colour KS:
      f cos = KS F(wi.h) D(h) G1(wi) G1(wo) / (4 |wi.n|),     h = (wi + wo) / |wi + wo|.
  Sampled by visible normals (Heitz 2018) and mirror reflection: weight KS F G2 / G1(wi) = KS F G1(wo).
- T_x, refraction into the yarn at x (Eq. 2, second case; the "enter" step): only sampled, never
  evaluated against a light. A visible normal h is sampled and -wi refracted through it (eta); the
  weight is the scalar (1 - F(wi.h)) G2 / G1(wi) = (1 - F) G1(d). Its f cos is Walter's Eq. 21 with
  i = wi (index 1), o = d (index eta), times |d.n|:
      (1 - F) D(h) G1(wi) G1(d) |wi.h| |d.h| eta^2 / (|wi.n| (wi.h + eta d.h)^2),   h ∝ -(wi + eta d),
  the flux form: it carries *no* 1/eta^2 radiance scaling (Veach 1997 §5.2). The exit at y, from index
  eta back into air, would carry the inverse factor eta^2; it is left out there too, the two cancel and
  the product is the physical radiance transport. Weight and value carry the energy compensation's
  factor (``enter_compensation``, "Energy" below). ``enter_eval_pdf`` gives this value and the density
  (value = weight * pdf), for testing.
- f_sT, specular transmission out at y (Eq. 3): the rough dielectric BTDF from inside (index eta) to
  outside (index 1) with isotropic GGX alpha = ALPHA_EXIT and visible normals seen from inside (from
  -d); Walter's Eq. 21 with i = -d (index eta), o = wo (index 1), times |wo.n_y|, again the flux form:
      (1 - F) D(h) G1(-d) G1(wo) |d.h| |wo.h| / (|d.n_y| (eta d.h - wo.h)^2),   h ∝ eta d - wo;
  sampled by visible normals and refraction, weight (1 - F) G1(wo). Total internal reflection ends the
  sample (pdf 0). Times KT = KT_EXIT, the dye's BODY_T (per channel, applied by ``exit_eval_pdf``; the lobe
  alone is grey) and the specular path's weight since x (A_s times the enter step's).
- f_keep, what the exit keeps inside (the reference drops it): the light f_sT does not let out -- total
  internal reflection, the Fresnel reflection back inside and the microfacets' multiple scattering --
  stays in the yarn's fibres, scatters there and leaves diffusely: folded into the Lambertian exit at y,
  f_keep cos = (1 - E_T(d.n_y)) cos_o / pi, with E_T the exit's single-scattering transmission albedo
  (tabulated, "Energy" below). Why folded rather than followed inside: the yarn interior is the fibres
  the model does not resolve; a path continued by mirror bounces in an empty cylinder would invent a
  light guide that a fibre bundle is not, and cost a loop of ray-cylinder tests per bounce.
- f_bR, body reflection at x (Eq. 4 here; the paper's subscripts were lost): per channel with a' the
  reflection-side body colour BODY_R (used directly as the reduced albedo a'; the reference maps the
  colour to a' through a 17-entry table that was not published),
      f cos = a' cos_o / (4 pi (cos_i + cos_o)) * LS_MIX  +  R_d(a') / pi cos_o * (1 - LS_MIX),
  a Lommel-Seeliger term (Hanrahan & Krueger 1993) mixed with a diffusion term (Jensen et al. 2001):
  R_d = (a'/2)(1 + exp(-(4/3) A sqrt(3(1-a')))) exp(-sqrt(3(1-a'))), A = (1 + F_dr)/(1 - F_dr),
  F_dr = -1.440/eta^2 + 0.710/eta + 0.668 + 0.0636 eta. Why the LS mix is on the *reflection* side:
  Lommel-Seeliger is single scattering out of a half-space back through the face the light entered --
  a reflection phenomenon, meaningless for light leaving the far side. Its directional albedo is
  (a'/2)(1 - mu ln(1 + 1/mu)) <= a'/2 (mu = cos_i): alone it cannot reach albedo 1 even for a' = 1,
  because it misses the multiply scattered light. The diffusion term supplies that light with albedo
  R_d <= a' (R_d = 1 exactly at a' = 1), so for a' <= 1 every mix keeps the albedo <= 1 -- the energy
  conservation the paper states as the reason for the mix. The reference weights the two by the
  normalised (cos_i + cos_o); here the weight is the constant LS_MIX, which keeps f reciprocal and the
  albedo in closed form. The cosine-weighted sampler about n has weight f cos / (cos_o / pi).
- f_cone, the cone part of the body reflection (an extension, off by default: CONE_SHARE c = 0 is the paper's
  model): the reflection side's body term is (1 - c) f_bR + c f_cone. Every lobe of a fibre's scattering
  leaves on the cone theta_o = -theta_i about the fibre (Marschner et al. 2003; the BCSDF of the fibre
  methods), so light scattered many times among parallel fibres keeps its propagation's component along
  them and a bundle returns it around the cone u_o = -u_i (u = direction . t), not evenly. With phi_o the
  azimuth of wo about t measured from n (t is orthogonal to n: cos_o = sqrt(1 - u_o^2) cos phi_o):
      f_cone cos = A_bR(mu_i) g(u_o) cos(phi_o) / 2,
  g the logistic density of scale CONE_WIDTH about -u_i, truncated to [-1, 1]; A_bR = ``body_reflect_albedo``.
  Its albedo is A_bR(mu_i) exactly -- it moves the body reflection's light towards the cone and neither adds
  nor loses any -- and it is sampled exactly (u_o by the truncated logistic's inverse CDF, sin phi_o
  uniform), weight A_bR. Normalised per incident direction it is not reciprocal; the reciprocal form
  f ~ g(u_i + u_o) returns light in proportion to cos theta_i and loses what arrives along the fibres.
  Why (issue 53; docs/methods/bysdf.md, Limits): on the demo swatch at a fixed light elevation the fibres'
  cloth is up to 2x brighter with the camera near the light's cone than away from it, which f_bR alone
  cannot follow; fitted with c 0.6 and width 0.2 the swatch under its own lights is 9.5-10.9 % dark instead
  of 15-19 %, but its per-pixel error against the converged fibres rises (0.255 -> 0.280): off by default.
- f_bT, body transmission at y (Eq. 5): Lambertian on the outside of the exit point,
  f cos = BODY_T / pi * max(0, wo.n_y), cosine-weighted sampling about n_y (it does not depend on d).
- S (at x) and S_y (at y) are the ply-shadowing times fibre-shadowing values of §5 (the integrator's
  table lookups); they multiply the body lobes only. A_s and A_d are the Beer-Lambert attenuations
  along x -> y, raised to the number of plies crossed: (exp(-sigma |y - x|))^n_plies with
  sigma = SIGMA_SPEC and SIGMA_BODY (``attenuation``).

Energy (issue 53: the single-scattering rough dielectric loses up to 30 % at alpha 1, Heitz et al. 2016)
-------------------------------------------------------------------------------------------------------
The interface at x scatters E(wi) = E_R(wi) + E_T(wi) <= 1 of what arrives by single scattering (its
reflection and refraction albedos). The rest, 1 - E, is what light bouncing between microfacets carries:
- f_ms (Kulla & Conty 2017), on the reflection side, a share r of it: f_ms cos = r (1 - E(wi)) (1 - E(wo))
  cos_o / (pi (1 - E_avg)), E_avg = int 2 mu E(mu) dmu; reciprocal, albedo r (1 - E(wi)) exactly. r =
  E_R,avg / E_avg, the share of light the interface reflects on average (the dielectric version of
  Kulla & Conty's Fresnel-weighted split, simplified).
- the refracted share (1 - r)(1 - E(wi)) rides on the enter step: its weight is multiplied by
  ``enter_compensation`` = 1 + (1 - r)(1 - E) / E_T, keeping the single-scattering direction of d.
So reflection side + enter sum to 1 at every wi for a white interface. The albedos come from tables packed
after the parameters (``energy_tables``, computed once per (eta, alpha_exit) by ``pack_bysdf`` with the
samplers' own routines over stratified visible normals): E and E_T at x over N_ALPHA isotropic
roughnesses x N_MU cosines, E_avg and r per roughness, and E_T at y (alpha_exit, index 1/eta) over
N_MU_EXIT cosines; read with Catmull-Rom across roughness, linearly along mu. An anisotropic interface
is read at the effective roughness sqrt(sqrt(au av) alpha_w) of the direction (alpha_w: its projected
roughness, which sets its masking exactly) -- an approximation: measured, a white BYSDF keeps 0.99-1.005
of the energy at the reference's (0.2, 0.3), 0.95-1.01 at (1.0, 1.5) (tests/core/shading/test_bysdf.py).
The multiscale widening of alpha moves along the tables' roughness axis, so widened lobes stay balanced.

Sides and lobes (importance sampling, §4.1 "Importance Sampling")
-----------------------------------------------------------------
The integrator picks the reflection side with probability P_R = ``reflect_probability(p, wi, n)``
= clamp(beta F(wi.n) + (1 - beta) m_r, 0.05, 0.95) -- the share of the energy budget the model gives the
reflection side before colours, shadowing and attenuation (the paper: m_r "based on the probability of
the Fresnel term") -- and divides by it (or by 1 - P_R for the transmission side). Inside a side u0 picks
the GGX-sampled lobe or the cosine-sampled ones with probability proportional to their energy estimates:
    reflection side:   beta mean(KS) F(wi.n)   vs  beta mean(KS) r (1 - E) + (1-beta) m_r S mean(albedo of f_bR)
    transmission side: beta A KT E_T(d.n_y)    vs  beta A KT (1 - E_T(d.n_y)) + (1-beta)(1-m_r) A_d S_y mean(BODY_T)
(A: the specular path's weight since x; on the reflection side the second group's f_cone, a share
c (1-beta) m_r S mean(albedo of f_bR) of its energy, is drawn by its own sampler with that probability)
(positive for every lobe with nonzero energy); the returned pdf is the lobe mixture's and the weight
is f cos / pdf of the side. A side whose lobes all carry zero energy returns zeros and pdf 0.

Interface (all @njit; vectors float64[3] or 3-tuples; returned values are namedtuples whose directions
are 3-tuples, so nothing here allocates and the integrator may call it without reference counting)
-------------------------------------------------------------------------
    reflect_probability(p, wi, n) -> P_R
    reflect_eval_pdf(p, t, n, wi, wo, shadow) -> BysdfValue(r, g, b, pdf)
        beta f_sR + (1-beta) m_r shadow ((1-c) f_bR + c f_cone) (f cos); pdf of reflect_sample
    reflect_sample(p, t, n, wi, shadow, u0, u1, u2) -> BysdfSample(wo, r, g, b, pdf)   weight f cos / pdf
    enter_sample(p, t, n, wi, u1, u2) -> EnterSample(d, weight, pdf)                    T_x, scalar weight
    enter_eval_pdf(p, t, n, wi, d) -> (value, pdf)                                      value = weight * pdf
    exit_eval_pdf(p, t_y, n_y, d, wo, att_spec, att_body, shadow_y) -> BysdfValue
        beta att_spec BODY_T KT (f_sT + f_keep) + (1-beta)(1-m_r) att_body shadow_y f_bT; pdf of exit_sample
        (att_spec: the specular path's weight since x, its Beer-Lambert attenuation times the enter weight)
    exit_sample(p, t_y, n_y, d, att_spec, att_body, shadow_y, u0, u1, u2) -> BysdfSample
    attenuation(p, distance, n_plies) -> (A_s, A_d)
and each lobe alone (value without beta, m_r, S, A; colours included):
    spec_reflect_eval_pdf(p, t, n, wi, wo) / spec_reflect_sample(p, t, n, wi, u1, u2)       KS f_sR
    spec_exit_eval_pdf(p, t_y, n_y, d, wo) / spec_exit_sample(p, t_y, n_y, d, u1, u2)      KT f_sT
    body_reflect_eval_pdf(p, n, wi, wo) / body_reflect_sample(p, n, wi, u1, u2)            f_bR
    cone_reflect_eval_pdf(p, t, n, wi, wo) / cone_reflect_sample(p, t, n, wi, u1, u2)      f_cone
    body_exit_eval_pdf(p, n_y, wo) / body_exit_sample(p, n_y, u1, u2)                      f_bT
    ms_reflect_eval_pdf(p, t, n, wi, wo)                            KS f_ms (sampled by the side, cosine)
and the energy tables: energy_tables(eta, alpha_exit), interface_albedos(alpha, eta, mu, n_quad),
interface_energy(p, x, y, z) -> InterfaceEnergy(e, e_t, e_avg, r), enter_compensation(p, x, y, z),
exit_transmittance(p, mu_d).
A failed sample has pdf 0 (its direction is then any unit vector). Degenerate input never gives NaN:
wi at or below the surface at x (wi.n <= 1e-9), wo on the wrong side, d not leaving through n_y, grazing
directions and roughness down to ALPHA_MIN = 1e-4 (smaller values are clamped) give zeros and pdf 0.
The lobe samplers' pdfs are the densities of their *successful* samples (they integrate to the
success probability: TIR at y, refracted or reflected directions that end up on the wrong side).
Roughness widening for the multi-scale model (alpha += h_range / 10, §4.2) is done by the caller on p.

Parameters, packed (float64[BYSDF_SIZE]: N_PARAMS named values, then the energy tables;
``pack_bysdf(**named)``; defaults: the reference's example)
-----------------------------------------------------------------------------------------------------
    SPEC_WEIGHT beta (0.5)      REFLECT_WEIGHT m_r (0.5)   ALPHA_U (0.2)   ALPHA_V (0.3)   ETA (1.5)
    KS_R..KS_B specular colour (1)   ALPHA_EXIT (0.9)   KT_EXIT exit transmittance (0.1)
    BODY_R_R..B reflection-side body colour a' ((0.045, 0.015, 0))
    BODY_T_R..B transmission-side body colour (six times BODY_R)
    SIGMA_SPEC (5.5)   SIGMA_BODY (0.1)   LS_MIX Lommel-Seeliger weight of f_bR (0.5)
    CONE_SHARE c, f_cone's share of the body reflection (0)   CONE_WIDTH its logistic scale in u (0.3)
"""
import functools
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.frames import unit_rejection
from stages.core.shading.lambert import cosine_direction
from stages.core.shading.microfacet import (
    COS_EPS,
    fresnel_dielectric,
    ggx_sample_visible,
    refract,
    rough_reflect,
    rough_transmit,
)

SPEC_WEIGHT = 0
REFLECT_WEIGHT = 1
ALPHA_U = 2
ALPHA_V = 3
ETA = 4
KS_R, KS_G, KS_B = 5, 6, 7
ALPHA_EXIT = 8
KT_EXIT = 9
BODY_R_R, BODY_R_G, BODY_R_B = 10, 11, 12
BODY_T_R, BODY_T_G, BODY_T_B = 13, 14, 15
SIGMA_SPEC = 16
SIGMA_BODY = 17
LS_MIX = 18
CONE_SHARE = 19           # the share of f_bR that leaves on the fibres' cone (f_cone; 0: the paper's model)
CONE_WIDTH = 20           # f_cone's logistic scale in u = direction . t
N_PARAMS = 21             # the named parameters; the energy tables follow them in the packed row

# the rough dielectrics' single-scattering albedos (the energy compensation's inputs), packed after the
# parameters by ``pack_bysdf`` (``energy_tables``): at x over (roughness, mu), at y over mu
N_ALPHA = 16              # roughness nodes, uniform in s = alpha / (1 + alpha) from ALPHA_MIN to ALPHA_S_MAX
ALPHA_S_MAX = 15.0 / 16.0  # s of the last node (alpha 15); rougher interfaces read the last node
N_MU = 32                 # cos nodes at x: j / (N_MU - 1)
N_MU_EXIT = 64            # cos nodes at y (from inside the critical angle makes E_T steep)
N_QUAD = 48               # each node's albedo from N_QUAD x N_QUAD stratified visible normals
E_X = N_PARAMS                     # E(alpha, mu) = E_R + E_T at x, N_ALPHA rows of N_MU
ET_X = E_X + N_ALPHA * N_MU        # E_T(alpha, mu) at x: refraction into the yarn
EAVG_X = ET_X + N_ALPHA * N_MU     # E_avg(alpha) = int 2 mu E dmu of the interpolated E
RMS_X = EAVG_X + N_ALPHA           # r(alpha): the reflected share of the interface's lost energy
ET_Y = RMS_X + N_ALPHA             # E_T(mu) at y: refraction out, alpha = ALPHA_EXIT, index 1 / eta
BYSDF_SIZE = ET_Y + N_MU_EXIT

ALPHA_MIN = 1e-4          # smallest GGX roughness (smaller values are clamped)
LOSS_MIN = 1e-9           # an interface that loses less energy than this gets no compensation
TANGENT_ALONG_NORMAL = 1e-9   # shading_frame: a tangent whose part normal to n is shorter is replaced
MU_FLOOR = 1e-4           # the energy tables' grazing node is computed at this cosine
ALONG_FIBRE = 1e-12       # f_cone: a direction with 1 - u^2 below this lies along t (no azimuth): density 0
CDF_MIN = 1e-16           # f_cone's inverse CDF: the drawn probability kept in [CDF_MIN, 1 - CDF_MIN] (finite u)
P_R_MIN, P_R_MAX = 0.05, 0.95
INV_PI = 1.0 / math.pi

BysdfValue = namedtuple("BysdfValue", ["r", "g", "b", "pdf"])
BysdfSample = namedtuple("BysdfSample", ["wo", "r", "g", "b", "pdf"])
EnterSample = namedtuple("EnterSample", ["d", "weight", "pdf"])

BODY_R_DEFAULT = (0.045, 0.015, 0.0)


def pack_bysdf(*, spec_weight=0.5, reflect_weight=0.5, alpha_u=0.2, alpha_v=0.3, eta=1.5, ks=1.0,
               alpha_exit=0.9, kt_exit=0.1, body_r=BODY_R_DEFAULT, body_t=tuple(6.0 * c for c in BODY_R_DEFAULT),
               sigma_spec=5.5, sigma_body=0.1, ls_mix=0.5, cone_share=0.0, cone_width=0.3):
    """float64[BYSDF_SIZE] from named values (colours: a scalar or three values), the energy tables of its
    eta and alpha_exit after them (``energy_tables``, computed once per pair). Raises ValueError
    naming the parameter for a value outside its range: weights and colours in [0, 1], roughness
    >= ALPHA_MIN, eta > 1, sigmas >= 0, everything finite."""
    p = np.zeros(BYSDF_SIZE)

    def scalar(name, v, lo, hi, lo_open=False):
        v = float(v)
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
            raise ValueError(f"pack_bysdf: {name} = {v} outside {'(' if lo_open else '['}{lo}, {hi}]")
        return v

    def colour(name, v):
        c = np.broadcast_to(np.asarray(v, dtype=np.float64), (3,))
        return [scalar(f"{name}[{k}]", c[k], 0.0, 1.0) for k in range(3)]

    p[SPEC_WEIGHT] = scalar("spec_weight", spec_weight, 0.0, 1.0)
    p[REFLECT_WEIGHT] = scalar("reflect_weight", reflect_weight, 0.0, 1.0)
    p[ALPHA_U] = scalar("alpha_u", alpha_u, ALPHA_MIN, 1e3)
    p[ALPHA_V] = scalar("alpha_v", alpha_v, ALPHA_MIN, 1e3)
    p[ETA] = scalar("eta", eta, 1.0, 10.0, lo_open=True)
    p[KS_R:KS_B + 1] = colour("ks", ks)
    p[ALPHA_EXIT] = scalar("alpha_exit", alpha_exit, ALPHA_MIN, 1e3)
    p[KT_EXIT] = scalar("kt_exit", kt_exit, 0.0, 1.0)
    p[BODY_R_R:BODY_R_B + 1] = colour("body_r", body_r)
    p[BODY_T_R:BODY_T_B + 1] = colour("body_t", body_t)
    p[SIGMA_SPEC] = scalar("sigma_spec", sigma_spec, 0.0, math.inf)
    p[SIGMA_BODY] = scalar("sigma_body", sigma_body, 0.0, math.inf)
    p[LS_MIX] = scalar("ls_mix", ls_mix, 0.0, 1.0)
    p[CONE_SHARE] = scalar("cone_share", cone_share, 0.0, 1.0)
    p[CONE_WIDTH] = scalar("cone_width", cone_width, 0.0, 1e3, lo_open=True)
    p[N_PARAMS:] = _cached_energy_tables(p[ETA], p[ALPHA_EXIT])
    return p


@functools.lru_cache(maxsize=64)
def _cached_energy_tables(eta, alpha_exit):
    t = energy_tables(eta, alpha_exit)
    t.flags.writeable = False
    return t


# ------------------------------------------------------------------------------------------------
# scalar pieces: the body albedos (Fresnel and GGX: stages.core.shading.microfacet)
@njit(cache=True)
def lommel_seeliger_albedo(mu):
    """Directional albedo of the Lommel-Seeliger term cos_o / (4 pi (mu + cos_o)) per unit a':
    (1 - mu ln(1 + 1/mu)) / 2, for mu = cos_i in (0, 1]."""
    if mu <= 0.0:
        return 0.5
    return 0.5 * (1.0 - mu * math.log1p(1.0 / mu))


@njit(cache=True)
def fresnel_diffuse_reflectance(eta):
    """F_dr, the diffuse Fresnel reflectance of Jensen et al. 2001 (polynomial fit in eta)."""
    return -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta


@njit(cache=True)
def diffusion_reflectance(a, eta):
    """R_d(a'), the total diffuse reflectance of the dipole (Jensen et al. 2001), for a' in [0, 1]."""
    f = fresnel_diffuse_reflectance(eta)
    A = (1.0 + f) / (1.0 - f)
    s = math.sqrt(3.0 * max(0.0, 1.0 - a))
    return 0.5 * a * (1.0 + math.exp(-4.0 / 3.0 * A * s)) * math.exp(-s)


@njit(cache=True)
def body_reflect_albedo(p, c, mu):
    """Directional albedo of f_bR in channel c (0, 1, 2) at mu = cos_i: LS_MIX a' LS(mu) + (1-LS_MIX) R_d(a')."""
    a = p[BODY_R_R + c]
    m = p[LS_MIX]
    return m * a * lommel_seeliger_albedo(mu) + (1.0 - m) * diffusion_reflectance(a, p[ETA])


# ------------------------------------------------------------------------------------------------
# frames: a shading frame is the 9-tuple (t, b, n) of world components
@njit(cache=True)
def shading_frame(t, n):
    """(tx, ty, tz, bx, by, bz, nx, ny, nz): t made orthogonal to the unit n, b = n x t; any completion
    of n when t is (nearly) along n."""
    c = t[0] * n[0] + t[1] * n[1] + t[2] * n[2]
    x0, x1, x2 = unit_rejection(t[0], t[1], t[2], n[0], n[1], n[2], c, TANGENT_ALONG_NORMAL)
    b0 = n[1] * x2 - n[2] * x1
    b1 = n[2] * x0 - n[0] * x2
    b2 = n[0] * x1 - n[1] * x0
    return x0, x1, x2, b0, b1, b2, n[0], n[1], n[2]


@njit(cache=True)
def flipped_frame(t, n):
    """The shading frame of (t, -n): local z points into the yarn (the exit point seen from inside)."""
    tx, ty, tz, bx, by, bz, nx, ny, nz = shading_frame(t, n)
    return tx, ty, tz, -bx, -by, -bz, -nx, -ny, -nz


@njit(cache=True)
def to_local(fr, w):
    return (w[0] * fr[0] + w[1] * fr[1] + w[2] * fr[2],
            w[0] * fr[3] + w[1] * fr[4] + w[2] * fr[5],
            w[0] * fr[6] + w[1] * fr[7] + w[2] * fr[8])


@njit(cache=True)
def to_world(fr, x, y, z):
    return (x * fr[0] + y * fr[3] + z * fr[6],
            x * fr[1] + y * fr[4] + z * fr[7],
            x * fr[2] + y * fr[5] + z * fr[8])


@njit(cache=True)
def _unit_copy(v):
    return float(v[0]), float(v[1]), float(v[2])


@njit(cache=True)
def _alphas(p):
    return max(p[ALPHA_U], ALPHA_MIN), max(p[ALPHA_V], ALPHA_MIN)


# ------------------------------------------------------------------------------------------------
# the energy the single-scattering interfaces lose, tabulated (see "Energy" in the module doc)
@njit(cache=True)
def interface_albedos(alpha, eta, mu, n_quad):
    """(E_R, E_T): the directional albedos of reflection and of refraction of the isotropic rough
    dielectric (GGX alpha, relative index eta = n_far / n_near) lit from the near side at mu = cos_i:
    the means of the samplers' weights F G1(o) and (1 - F) G1(o) over n_quad^2 stratified visible
    normals (failed samples weigh 0), i.e. what spec_reflect_sample and enter_sample / spec_exit_sample
    return, integrated."""
    ix = math.sqrt(max(0.0, 1.0 - mu * mu))
    iz = mu
    e_r = 0.0
    e_t = 0.0
    for a in range(n_quad):
        for b in range(n_quad):
            hx, hy, hz = ggx_sample_visible(ix, 0.0, iz, alpha, alpha, (a + 0.5) / n_quad, (b + 0.5) / n_quad)
            ih = ix * hx + iz * hz
            if ih <= 0.0:
                continue
            v, pdf = rough_reflect(ix, 0.0, iz, 2.0 * ih * hx - ix, 2.0 * ih * hy, 2.0 * ih * hz - iz, alpha, alpha,
                                    eta)
            if pdf > 0.0:
                e_r += v / pdf
            ok, ox, oy, oz = refract(ix, 0.0, iz, hx, hy, hz, eta)
            if ok:
                v, pdf = rough_transmit(ix, 0.0, iz, ox, oy, oz, alpha, alpha, eta)
                if pdf > 0.0:
                    e_t += v / pdf
    n2 = n_quad * n_quad
    return e_r / n2, e_t / n2


@njit(cache=True)
def table_alpha(k):
    """The roughness of node k of the tables at x."""
    s0 = ALPHA_MIN / (1.0 + ALPHA_MIN)
    s = s0 + (ALPHA_S_MAX - s0) * k / (N_ALPHA - 1)
    return s / (1.0 - s)


@njit(cache=True)
def energy_tables(eta, alpha_exit):
    """float64[BYSDF_SIZE - N_PARAMS]: the tables ``pack_bysdf`` appends to a row (layout E_X .. ET_Y)."""
    out = np.empty(BYSDF_SIZE - N_PARAMS)
    o = -N_PARAMS
    fine = 4096                                 # E_avg: midpoint rule on the interpolant
    for k in range(N_ALPHA):
        alpha = table_alpha(k)
        for j in range(N_MU):
            e_r, e_t = interface_albedos(alpha, eta, _mu_node(j, N_MU), N_QUAD)
            out[o + E_X + k * N_MU + j] = min(1.0, e_r + e_t)
            out[o + ET_X + k * N_MU + j] = e_t
        e_avg = 0.0
        t_avg = 0.0
        for q in range(fine):
            mu = (q + 0.5) / fine
            f = _mu_coord(mu, N_MU)
            e_avg += 2.0 * mu * _lerp(out, o + E_X + k * N_MU, f, N_MU) / fine
            t_avg += 2.0 * mu * _lerp(out, o + ET_X + k * N_MU, f, N_MU) / fine
        out[o + EAVG_X + k] = e_avg
        out[o + RMS_X + k] = (e_avg - t_avg) / e_avg if e_avg > 0.0 else 1.0
    a = max(alpha_exit, ALPHA_MIN)
    for j in range(N_MU_EXIT):
        out[o + ET_Y + j] = interface_albedos(a, 1.0 / eta, _mu_node(j, N_MU_EXIT), N_QUAD)[1]
    return out


@njit(cache=True)
def _mu_coord(mu, n):
    """The fractional node index of mu on n nodes j / (n - 1) (clamped to [0, n - 1])."""
    return min(max(mu * (n - 1), 0.0), n - 1.0)


@njit(cache=True)
def _mu_node(j, n):
    """The cosine at which node j of n is computed: j / (n - 1), node 0 at MU_FLOOR (the grazing limit)."""
    return max(j / (n - 1), MU_FLOOR)


@njit(cache=True)
def _alpha_coord(alpha):
    s0 = ALPHA_MIN / (1.0 + ALPHA_MIN)
    f = (alpha / (1.0 + alpha) - s0) / (ALPHA_S_MAX - s0) * (N_ALPHA - 1)
    return min(max(f, 0.0), N_ALPHA - 1.0)


@njit(cache=True)
def _lerp(p, base, f, n):
    """Linear interpolation of p[base : base + n] at the fractional index f in [0, n - 1]."""
    i = min(int(f), n - 2)
    w = f - i
    return (1.0 - w) * p[base + i] + w * p[base + i + 1]


@njit(cache=True)
def _along_alpha(p, base, stride, fa, fm, n_mu):
    """Interpolation of an (N_ALPHA, n_mu) table (row k at base + k stride; n_mu = 1: one value per row) at
    the fractional roughness node fa -- Catmull-Rom across the rows (the albedos bend too fast in alpha for
    straight lines between 16 nodes), end rows repeated -- and fm along each row (linear)."""
    i = min(int(fa), N_ALPHA - 2)
    w = fa - i
    w2 = w * w
    w3 = w2 * w
    total = 0.0
    for j, c in ((i - 1, -0.5 * w3 + w2 - 0.5 * w), (i, 1.5 * w3 - 2.5 * w2 + 1.0),
                 (i + 1, -1.5 * w3 + 2.0 * w2 + 0.5 * w), (i + 2, 0.5 * w3 - 0.5 * w2)):
        row = base + min(max(j, 0), N_ALPHA - 1) * stride
        total += c * (p[row] if n_mu == 1 else _lerp(p, row, fm, n_mu))
    return total


InterfaceEnergy = namedtuple("InterfaceEnergy", ["e", "e_t", "e_avg", "r"])


@njit(cache=True)
def interface_energy(p, x, y, z):
    """InterfaceEnergy(e, e_t, e_avg, r) of the rough interface at x seen from the local unit direction
    (x, y, z) (z = cos_i): its single-scattering albedo E = E_R + E_T and refraction albedo E_T, the
    hemispherical mean E_avg and the reflected share r of what it loses. The tables are isotropic: an
    anisotropic GGX is read at the direction's projected roughness sqrt(au^2 cos^2 phi + av^2 sin^2 phi)
    (exact for its masking, Heitz 2014; an approximation for the albedo), E_avg and r at sqrt(au av)."""
    au, av = _alphas(p)
    r2 = x * x + y * y
    a_m = math.sqrt(au * av)
    a_dir = math.sqrt(a_m * math.sqrt((au * au * x * x + av * av * y * y) / r2)) if r2 > 0.0 else a_m
    fa = _alpha_coord(a_dir)
    fm = _mu_coord(z, N_MU)
    fa_m = _alpha_coord(a_m)
    return InterfaceEnergy(min(1.0, _along_alpha(p, E_X, N_MU, fa, fm, N_MU)),
                           max(0.0, _along_alpha(p, ET_X, N_MU, fa, fm, N_MU)),
                           min(1.0, _along_alpha(p, EAVG_X, 1, fa_m, 0.0, 1)),
                           min(1.0, max(0.0, _along_alpha(p, RMS_X, 1, fa_m, 0.0, 1))))


@njit(cache=True)
def exit_transmittance(p, mu_d):
    """E_T at y: the single-scattering albedo of refraction out of the yarn for d arriving at mu_d = d.n_y
    (spec_exit_sample's mean weight without KT); 0 for mu_d <= COS_EPS."""
    if mu_d <= COS_EPS:
        return 0.0
    return _lerp(p, ET_Y, _mu_coord(mu_d, N_MU_EXIT), N_MU_EXIT)


# ------------------------------------------------------------------------------------------------
# lobe: specular reflection at x (Eq. 2, first case)
@njit(cache=True)
def spec_reflect_eval_pdf(p, t, n, wi, wo):
    """KS f_sR cos: BysdfValue(r, g, b, pdf of spec_reflect_sample)."""
    fr = shading_frame(t, n)
    ix, iy, iz = to_local(fr, wi)
    ox, oy, oz = to_local(fr, wo)
    au, av = _alphas(p)
    v, pdf = rough_reflect(ix, iy, iz, ox, oy, oz, au, av, p[ETA])
    return BysdfValue(p[KS_R] * v, p[KS_G] * v, p[KS_B] * v, pdf)


@njit(cache=True)
def spec_reflect_sample(p, t, n, wi, u1, u2):
    """Visible normal, mirror reflection: BysdfSample(wo, weight = KS F G1(wo), pdf)."""
    fr = shading_frame(t, n)
    ix, iy, iz = to_local(fr, wi)
    if iz <= COS_EPS:
        return BysdfSample(_unit_copy(n), 0.0, 0.0, 0.0, 0.0)
    au, av = _alphas(p)
    hx, hy, hz = ggx_sample_visible(ix, iy, iz, au, av, u1, u2)
    ih = ix * hx + iy * hy + iz * hz
    ox, oy, oz = 2.0 * ih * hx - ix, 2.0 * ih * hy - iy, 2.0 * ih * hz - iz
    v, pdf = rough_reflect(ix, iy, iz, ox, oy, oz, au, av, p[ETA])
    wo = to_world(fr, ox, oy, oz)
    if pdf <= 0.0:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    w = v / pdf
    return BysdfSample(wo, p[KS_R] * w, p[KS_G] * w, p[KS_B] * w, pdf)


# ------------------------------------------------------------------------------------------------
# the enter step at x (Eq. 2, second case): refraction into the yarn, flux form
@njit(cache=True)
def enter_compensation(p, ix, iy, iz):
    """The factor on the enter step's weight that carries the interface's lost energy refracted:
    1 + (1 - r)(1 - E(wi)) / E_T(wi) (``interface_energy`` at the local wi); 1 where nothing is lost."""
    en = interface_energy(p, ix, iy, iz)
    loss = 1.0 - en.e
    if loss <= LOSS_MIN or en.e_t <= LOSS_MIN:
        return 1.0
    return 1.0 + (1.0 - en.r) * loss / en.e_t


@njit(cache=True)
def enter_eval_pdf(p, t, n, wi, d):
    """(value, pdf): value = c (1 - F) G1(d) pdf, the scalar f cos of refraction from wi into the yarn
    along d (the direction the path travels inside) with the energy compensation c = enter_compensation;
    pdf the density of enter_sample."""
    fr = shading_frame(t, n)
    ix, iy, iz = to_local(fr, wi)
    dx, dy, dz = to_local(fr, d)
    au, av = _alphas(p)
    v, pdf = rough_transmit(ix, iy, iz, dx, dy, dz, au, av, p[ETA])
    if pdf <= 0.0:
        return v, pdf
    return v * enter_compensation(p, ix, iy, iz), pdf


@njit(cache=True)
def enter_sample(p, t, n, wi, u1, u2):
    """EnterSample(d, weight = c (1 - F) G1(d), pdf): visible normal, refraction into the yarn
    (c = enter_compensation)."""
    fr = shading_frame(t, n)
    ix, iy, iz = to_local(fr, wi)
    if iz <= COS_EPS:
        return EnterSample(_unit_copy(n), 0.0, 0.0)
    au, av = _alphas(p)
    eta = p[ETA]
    hx, hy, hz = ggx_sample_visible(ix, iy, iz, au, av, u1, u2)
    ok, dx, dy, dz = refract(ix, iy, iz, hx, hy, hz, eta)
    if not ok or ix * hx + iy * hy + iz * hz <= 0.0:
        return EnterSample(_unit_copy(n), 0.0, 0.0)
    v, pdf = rough_transmit(ix, iy, iz, dx, dy, dz, au, av, eta)
    d = to_world(fr, dx, dy, dz)
    if pdf <= 0.0:
        return EnterSample(d, 0.0, 0.0)
    return EnterSample(d, v / pdf * enter_compensation(p, ix, iy, iz), pdf)


# ------------------------------------------------------------------------------------------------
# lobe: specular transmission out at y (Eq. 3), seen from inside: v = -d, local z = -n_y
@njit(cache=True)
def spec_exit_eval_pdf(p, t_y, n_y, d, wo):
    """KT f_sT cos: BysdfValue(r, g, b, pdf of spec_exit_sample); d the direction arriving inside."""
    fr = flipped_frame(t_y, n_y)
    dx, dy, dz = to_local(fr, d)
    ox, oy, oz = to_local(fr, wo)
    a = max(p[ALPHA_EXIT], ALPHA_MIN)
    v, pdf = rough_transmit(-dx, -dy, -dz, ox, oy, oz, a, a, 1.0 / p[ETA])
    v *= p[KT_EXIT]
    return BysdfValue(v, v, v, pdf)


@njit(cache=True)
def spec_exit_sample(p, t_y, n_y, d, u1, u2):
    """Visible normal seen from inside, refraction out: BysdfSample(wo, weight = KT (1 - F) G1(wo), pdf);
    total internal reflection is a failed sample (pdf 0)."""
    fr = flipped_frame(t_y, n_y)
    dx, dy, dz = to_local(fr, d)
    vx, vy, vz = -dx, -dy, -dz
    if vz <= COS_EPS:
        return BysdfSample(_unit_copy(n_y), 0.0, 0.0, 0.0, 0.0)
    a = max(p[ALPHA_EXIT], ALPHA_MIN)
    eta = 1.0 / p[ETA]
    hx, hy, hz = ggx_sample_visible(vx, vy, vz, a, a, u1, u2)
    ok, ox, oy, oz = refract(vx, vy, vz, hx, hy, hz, eta)
    if not ok or vx * hx + vy * hy + vz * hz <= 0.0:
        return BysdfSample(_unit_copy(n_y), 0.0, 0.0, 0.0, 0.0)
    v, pdf = rough_transmit(vx, vy, vz, ox, oy, oz, a, a, eta)
    wo = to_world(fr, ox, oy, oz)
    if pdf <= 0.0:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    w = p[KT_EXIT] * v / pdf
    return BysdfSample(wo, w, w, w, pdf)


# ------------------------------------------------------------------------------------------------
# lobe: body reflection at x (Lommel-Seeliger + diffusion) and body transmission at y (Lambertian)
@njit(cache=True)
def body_reflect_eval_pdf(p, n, wi, wo):
    """f_bR cos: BysdfValue(r, g, b, cos_o / pi)."""
    ci = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
    co = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
    if ci <= COS_EPS or co <= COS_EPS:
        return BysdfValue(0.0, 0.0, 0.0, 0.0)
    m = p[LS_MIX]
    ls = m * co / (4.0 * math.pi * (ci + co))
    dif = (1.0 - m) * co * INV_PI
    eta = p[ETA]
    a0, a1, a2 = p[BODY_R_R], p[BODY_R_G], p[BODY_R_B]
    return BysdfValue(a0 * ls + diffusion_reflectance(a0, eta) * dif,
                      a1 * ls + diffusion_reflectance(a1, eta) * dif,
                      a2 * ls + diffusion_reflectance(a2, eta) * dif, co * INV_PI)


@njit(cache=True)
def body_reflect_sample(p, n, wi, u1, u2):
    """Cosine-weighted about n: BysdfSample(wo, f_bR cos / pdf, pdf)."""
    wo = cosine_direction(n, u1, u2)
    v = body_reflect_eval_pdf(p, n, wi, wo)
    if v.pdf <= 0.0:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    return BysdfSample(wo, v.r / v.pdf, v.g / v.pdf, v.b / v.pdf, v.pdf)


@njit(cache=True)
def body_exit_eval_pdf(p, n_y, wo):
    """f_bT cos = BODY_T / pi max(0, wo.n_y): BysdfValue(r, g, b, cos_o / pi)."""
    co = wo[0] * n_y[0] + wo[1] * n_y[1] + wo[2] * n_y[2]
    if co <= COS_EPS:
        return BysdfValue(0.0, 0.0, 0.0, 0.0)
    c = co * INV_PI
    return BysdfValue(p[BODY_T_R] * c, p[BODY_T_G] * c, p[BODY_T_B] * c, c)


@njit(cache=True)
def body_exit_sample(p, n_y, u1, u2):
    """Cosine-weighted about n_y: BysdfSample(wo, BODY_T, pdf)."""
    wo = cosine_direction(n_y, u1, u2)
    v = body_exit_eval_pdf(p, n_y, wo)
    if v.pdf <= 0.0:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    return BysdfSample(wo, v.r / v.pdf, v.g / v.pdf, v.b / v.pdf, v.pdf)


@njit(cache=True)
def _msrough_reflect(p, ei, ox, oy, co):
    """KS f_ms cos towards the local wo (ox, oy, co), co > COS_EPS, given ``ei`` = interface_energy at wi."""
    c = co * INV_PI
    if 1.0 - ei.e_avg <= LOSS_MIN:
        return BysdfValue(0.0, 0.0, 0.0, c)
    eo = interface_energy(p, ox, oy, co)
    v = ei.r * (1.0 - ei.e) * (1.0 - eo.e) / (1.0 - ei.e_avg) * c
    return BysdfValue(p[KS_R] * v, p[KS_G] * v, p[KS_B] * v, c)


@njit(cache=True)
def ms_reflect_eval_pdf(p, t, n, wi, wo):
    """KS f_ms cos, the reflected part of the interface's lost energy at x: BysdfValue(r, g, b, cos_o / pi),
    f_ms = r (1 - E(wi)) (1 - E(wo)) / (pi (1 - E_avg)) (Kulla & Conty 2017; ``interface_energy``)."""
    fr = shading_frame(t, n)
    ix, iy, ci = to_local(fr, wi)
    ox, oy, co = to_local(fr, wo)
    if ci <= COS_EPS or co <= COS_EPS:
        return BysdfValue(0.0, 0.0, 0.0, 0.0)
    return _msrough_reflect(p, interface_energy(p, ix, iy, ci), ox, oy, co)


# ------------------------------------------------------------------------------------------------
# lobe: the body reflection's cone part (module doc, f_cone)
@njit(cache=True)
def _logistic_cdf(z):
    return 0.5 * (1.0 + math.tanh(0.5 * z))


@njit(cache=True)
def _cone_pdf(s, ui, uo, co):
    """Solid-angle density of f_cone's sampler at a local wo with u_o = uo and cos_o = co, for u_i = ui:
    g(u_o) cos(phi_o) / 2, g the logistic density of scale s about -u_i truncated to [-1, 1], phi_o the azimuth
    about t from n (cos(phi_o) = co / sqrt(1 - u_o^2))."""
    r2 = 1.0 - uo * uo
    if r2 <= ALONG_FIBRE or co <= COS_EPS:
        return 0.0
    m = -ui
    mass = _logistic_cdf((1.0 - m) / s) - _logistic_cdf((-1.0 - m) / s)
    ch = math.cosh(0.5 * (uo - m) / s)
    return co / (8.0 * s * ch * ch * mass * math.sqrt(r2))


@njit(cache=True)
def _cone_direction(s, ui, u1, u2):
    """Local (x, y, z) drawn by ``_cone_pdf``: u_o = x by the truncated logistic's inverse CDF, sin(phi_o) = y / r
    uniform in [-1, 1] (density cos(phi) / 2), z = r cos(phi_o) >= 0, r = sqrt(1 - u_o^2)."""
    m = -ui
    lo = _logistic_cdf((-1.0 - m) / s)
    hi = _logistic_cdf((1.0 - m) / s)
    q = min(max(lo + u1 * (hi - lo), CDF_MIN), 1.0 - CDF_MIN)
    u = min(1.0, max(-1.0, m + s * math.log(q / (1.0 - q))))
    sp = 2.0 * u2 - 1.0
    r = math.sqrt(max(0.0, 1.0 - u * u))
    return u, r * sp, r * math.sqrt(max(0.0, 1.0 - sp * sp))


@njit(cache=True)
def cone_reflect_eval_pdf(p, t, n, wi, wo):
    """f_cone cos (without CONE_SHARE): BysdfValue(A_bR(mu_i) pdf per channel, pdf), A_bR = body_reflect_albedo."""
    fr = shading_frame(t, n)
    ix, _, mu = to_local(fr, wi)
    ox, _, co = to_local(fr, wo)
    if mu <= COS_EPS:
        return BysdfValue(0.0, 0.0, 0.0, 0.0)
    pc = _cone_pdf(p[CONE_WIDTH], ix, ox, co)
    return BysdfValue(body_reflect_albedo(p, 0, mu) * pc, body_reflect_albedo(p, 1, mu) * pc,
                      body_reflect_albedo(p, 2, mu) * pc, pc)


@njit(cache=True)
def cone_reflect_sample(p, t, n, wi, u1, u2):
    """f_cone's exact sampler: BysdfSample(wo, A_bR(mu_i) per channel, pdf)."""
    fr = shading_frame(t, n)
    ix, _, mu = to_local(fr, wi)
    x, y, z = _cone_direction(p[CONE_WIDTH], ix, u1, u2)
    wo = to_world(fr, x, y, z)
    if mu <= COS_EPS:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    v = cone_reflect_eval_pdf(p, t, n, wi, wo)
    if v.pdf <= 0.0:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    return BysdfSample(wo, v.r / v.pdf, v.g / v.pdf, v.b / v.pdf, v.pdf)


# ------------------------------------------------------------------------------------------------
# the two sides
@njit(cache=True)
def reflect_probability(p, wi, n):
    """P_R = clamp(beta F(wi.n) + (1 - beta) m_r, 0.05, 0.95): the integrator's probability of the
    reflection side at x (F = 1 for wi at or below the surface)."""
    mu = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
    F = fresnel_dielectric(mu, p[ETA]) if mu > 0.0 else 1.0
    beta = p[SPEC_WEIGHT]
    return min(P_R_MAX, max(P_R_MIN, beta * F + (1.0 - beta) * p[REFLECT_WEIGHT]))


ReflectWeights = namedtuple("ReflectWeights", ["spec", "body", "p_spec", "p_cone"])


@njit(cache=True)
def _reflect_lobe_weights(p, en, mu, shadow):
    """ReflectWeights(spec, body, p_spec, p_cone) of the reflection side: the factors on KS (f_sR + f_ms) and
    on f_bR, the probability of its GGX-sampled lobe (single scattering f_sR) against the others (f_ms, f_bR's
    diffuse part and its cone part f_cone), and, among those others, the probability of f_cone's sampler
    against the cosine-weighted one; from energy estimates at mu = wi.n (``en``: interface_energy at wi);
    p_spec < 0 when no lobe carries energy."""
    beta = p[SPEC_WEIGHT]
    k_s = beta
    k_b = (1.0 - beta) * p[REFLECT_WEIGHT] * max(shadow, 0.0)
    ks = (p[KS_R] + p[KS_G] + p[KS_B]) / 3.0
    e_s = k_s * ks * fresnel_dielectric(mu, p[ETA])
    e_body = k_b * (
        body_reflect_albedo(p, 0, mu) + body_reflect_albedo(p, 1, mu) + body_reflect_albedo(p, 2, mu)) / 3.0
    e_b = k_s * ks * en.r * max(0.0, 1.0 - en.e) + e_body
    if e_s + e_b <= 0.0:
        return ReflectWeights(k_s, k_b, -1.0, 0.0)
    return ReflectWeights(k_s, k_b, e_s / (e_s + e_b), p[CONE_SHARE] * e_body / e_b if e_b > 0.0 else 0.0)


@njit(cache=True)
def reflect_eval_pdf(p, t, n, wi, wo, shadow):
    """The reflection side at x: BysdfValue of beta KS (f_sR + f_ms) + (1 - beta) m_r shadow ((1 - c) f_bR
    + c f_cone) (f cos, c = CONE_SHARE) and the pdf of reflect_sample."""
    fr = shading_frame(t, n)
    ix, iy, mu = to_local(fr, wi)
    if mu <= COS_EPS:
        return BysdfValue(0.0, 0.0, 0.0, 0.0)
    ei = interface_energy(p, ix, iy, mu)
    k = _reflect_lobe_weights(p, ei, mu, shadow)
    k_s, k_b, q, w_c = k.spec, k.body, k.p_spec, k.p_cone
    if q < 0.0:
        return BysdfValue(0.0, 0.0, 0.0, 0.0)
    s = spec_reflect_eval_pdf(p, t, n, wi, wo)
    ox, oy, co = to_local(fr, wo)
    m = _msrough_reflect(p, ei, ox, oy, co) if co > COS_EPS else BysdfValue(0.0, 0.0, 0.0, 0.0)
    b = body_reflect_eval_pdf(p, n, wi, wo)
    c = p[CONE_SHARE]
    kd = k_b * (1.0 - c)
    f0 = k_s * (s.r + m.r) + kd * b.r
    f1 = k_s * (s.g + m.g) + kd * b.g
    f2 = k_s * (s.b + m.b) + kd * b.b
    pc = 0.0
    if c > 0.0:                                # f_cone (the paper's model, c = 0, skips its albedos)
        pc = _cone_pdf(p[CONE_WIDTH], ix, ox, co)
        kc = k_b * c * pc
        f0 += kc * body_reflect_albedo(p, 0, mu)
        f1 += kc * body_reflect_albedo(p, 1, mu)
        f2 += kc * body_reflect_albedo(p, 2, mu)
    return BysdfValue(f0, f1, f2, q * s.pdf + (1.0 - q) * ((1.0 - w_c) * b.pdf + w_c * pc))


@njit(cache=True)
def reflect_sample(p, t, n, wi, shadow, u0, u1, u2):
    """The reflection side at x: u0 picks the GGX-sampled lobe, the cone lobe or the cosine-sampled ones, (u1, u2)
    the direction;
    BysdfSample(wo, f cos / pdf, pdf) with reflect_eval_pdf's value and mixture pdf."""
    ix, iy, mu = to_local(shading_frame(t, n), wi)
    if mu <= COS_EPS:
        return BysdfSample(_unit_copy(n), 0.0, 0.0, 0.0, 0.0)
    k = _reflect_lobe_weights(p, interface_energy(p, ix, iy, mu), mu, shadow)
    q = k.p_spec
    if q < 0.0:
        return BysdfSample(_unit_copy(n), 0.0, 0.0, 0.0, 0.0)
    if u0 < q:
        s = spec_reflect_sample(p, t, n, wi, u1, u2)
    elif u0 - q < k.p_cone * (1.0 - q):        # the cone part of the body (p_cone = 0: never)
        s = cone_reflect_sample(p, t, n, wi, u1, u2)
    else:
        s = body_reflect_sample(p, n, wi, u1, u2)
    if s.pdf <= 0.0:                           # the lobe's sample failed: so does the side's
        return BysdfSample(s.wo, 0.0, 0.0, 0.0, 0.0)
    wo = s.wo
    v = reflect_eval_pdf(p, t, n, wi, wo, shadow)
    if v.pdf <= 0.0:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    return BysdfSample(wo, v.r / v.pdf, v.g / v.pdf, v.b / v.pdf, v.pdf)


ExitWeights = namedtuple("ExitWeights", ["spec", "body", "kept", "p_spec"])


@njit(cache=True)
def _exit_lobe_weights(p, d, n_y, att_spec, att_body, shadow_y):
    """ExitWeights(spec, body, kept, p_spec) of the transmission side at y: the factor on KT f_sT, on
    f_bT, the Lambertian weight of the specular path's light the exit keeps inside (KT spec (1 - E_T(d.n_y)),
    folded into the body exit), and the probability of the GGX-sampled lobe (< 0: no energy). The dye's
    BODY_T on the specular path is the caller's (``exit_eval_pdf``); the energies here carry its mean."""
    beta = p[SPEC_WEIGHT]
    k_s = beta * max(att_spec, 0.0)
    k_b = (1.0 - beta) * (1.0 - p[REFLECT_WEIGHT]) * max(att_body, 0.0) * max(shadow_y, 0.0)
    e_t = exit_transmittance(p, d[0] * n_y[0] + d[1] * n_y[1] + d[2] * n_y[2])
    dye = (p[BODY_T_R] + p[BODY_T_G] + p[BODY_T_B]) / 3.0
    kept = k_s * p[KT_EXIT] * (1.0 - e_t)
    e_s = k_s * p[KT_EXIT] * e_t * dye
    e_b = (kept + k_b) * dye
    if e_s + e_b <= 0.0:
        return ExitWeights(k_s, k_b, kept, -1.0)
    return ExitWeights(k_s, k_b, kept, e_s / (e_s + e_b))


@njit(cache=True)
def exit_eval_pdf(p, t_y, n_y, d, wo, att_spec, att_body, shadow_y):
    """The transmission side at y: BysdfValue of beta att_spec BODY_T KT (f_sT + (1 - E_T(d.n_y)) cos_o / pi)
    + (1 - beta)(1 - m_r) att_body shadow_y f_bT (f cos) and the pdf of exit_sample; d the direction the
    path arrives along inside, att_spec the specular path's weight since x (its Beer-Lambert attenuation
    times the enter step's weight)."""
    k = _exit_lobe_weights(p, d, n_y, att_spec, att_body, shadow_y)
    if k.p_spec < 0.0:
        return BysdfValue(0.0, 0.0, 0.0, 0.0)
    s = spec_exit_eval_pdf(p, t_y, n_y, d, wo)
    b = body_exit_eval_pdf(p, n_y, wo)         # BODY_T cos_o / pi
    f = k.spec * s.r + (k.kept + k.body) * b.pdf    # per unit dye (f_sT is grey: s.r = s.g = s.b)
    return BysdfValue(p[BODY_T_R] * f, p[BODY_T_G] * f, p[BODY_T_B] * f, k.p_spec * s.pdf + (1.0 - k.p_spec) * b.pdf)


@njit(cache=True)
def exit_sample(p, t_y, n_y, d, att_spec, att_body, shadow_y, u0, u1, u2):
    """The transmission side at y: u0 picks the specular or the Lambertian lobes, (u1, u2) the direction;
    BysdfSample(wo, f cos / pdf, pdf) with exit_eval_pdf's value and mixture pdf."""
    q = _exit_lobe_weights(p, d, n_y, att_spec, att_body, shadow_y).p_spec
    if q < 0.0:
        return BysdfSample(_unit_copy(n_y), 0.0, 0.0, 0.0, 0.0)
    if u0 < q:
        s = spec_exit_sample(p, t_y, n_y, d, u1, u2)
    else:
        s = body_exit_sample(p, n_y, u1, u2)
    if s.pdf <= 0.0:     # failed (total internal reflection at y: that light is the Lambertian lobe's `kept`)
        return BysdfSample(s.wo, 0.0, 0.0, 0.0, 0.0)
    wo = s.wo
    v = exit_eval_pdf(p, t_y, n_y, d, wo, att_spec, att_body, shadow_y)
    if v.pdf <= 0.0:
        return BysdfSample(wo, 0.0, 0.0, 0.0, 0.0)
    return BysdfSample(wo, v.r / v.pdf, v.g / v.pdf, v.b / v.pdf, v.pdf)


@njit(cache=True)
def attenuation(p, distance, n_plies):
    """(A_s, A_d) = (exp(-sigma |y - x|))^n_plies for sigma = SIGMA_SPEC and SIGMA_BODY (Beer-Lambert
    along the chord x -> y, raised to the number of plies crossed, §4.1)."""
    s = max(distance, 0.0) * max(n_plies, 0.0)
    return math.exp(-p[SIGMA_SPEC] * s), math.exp(-p[SIGMA_BODY] * s)
