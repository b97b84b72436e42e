"""Distant lights: directional, constant environment, spherical Gaussian, lat-long environment map.

Every light is infinitely far away, so it is a function of direction only. Directions ``w`` passed
to and returned by these kernels point *towards* the light (from the shading point).

Types and parameters (Mitsuba 3 conventions)
--------------------------------------------
- ``directional``: ``direction`` = the direction light travels (stored negated, towards the light),
  ``irradiance`` E measured perpendicular to the beam: a Lambertian surface of albedo rho facing it
  reflects rho E / pi. A delta light: ``light_sample`` returns E with pdf 0 and ``delta`` True;
  ``light_eval`` is 0 (a path never hits it by chance).
- ``constant``: radiance L from every direction; sampled uniformly on the sphere (pdf 1/(4 pi)).
- ``sg`` (spherical Gaussian): lobe G(w) = exp(lambda (w . axis - 1)) of sharpness lambda, normalised by
  M(lambda) = int G dw = 2 pi (1 - exp(-2 lambda)) / lambda. ``power`` P is the lobe's total radiance
  integral int L(w) dw (W m^-2 for a distant light: the irradiance a surface facing the axis would
  receive for lambda -> infinity), so L(w) = P G(w) / M(lambda). Sampled exactly:
  cos = 1 + log(u + (1 - u) exp(-2 lambda)) / lambda, pdf = G / M.
- ``envmap``: a lat-long RGB image (H, W, 3), radiance = ``scale`` x pixel (piecewise constant, no
  filtering). Orientation: Mitsuba 3's lat-long map in its local frame (y up, u = 0 looking down -z)
  rotated so local y is world +z (Mitsuba ``to_world = rotate([1, 0, 0], 90)``): a world direction
  (sin phi sin theta, cos phi sin theta, cos theta) reads u = phi / (2 pi) (wrapped to [0, 1)),
  v = theta / pi; row 0 is the zenith. Importance sampled by a 2D CDF over pixels with weights
  mean(rgb) x sin(theta_row) (uniform weights when the image is black); within a pixel (u, v) is
  uniform, so pdf(w) = P_pixel H W / (2 pi^2 sin theta) exactly.

Packed layout
-------------
``lights``: float64 (NL, LIGHT_SIZE), one row per light:
    0 type (0 directional, 1 constant, 2 sg, 3 envmap), 1:4 rgb (irradiance | radiance | power | scale),
    4:7 unit direction towards the light (directional) or lobe axis (sg), 7 sharpness lambda,
    8 1 / M(lambda).
``env`` float32 (H, W, 3), ``env_marginal`` float64 (H + 1,) row CDF, ``env_conditional`` float64
(H, W + 1) column CDFs: at most one envmap per scene; scenes without one pass a 1 x 1 black map
(``envmap_tables``). Integrators take the four together as a ``LightTable``.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.frames import orthonormal_basis
from stages.core.sampling import power_heuristic
from stages.core.turns import sincos_turn

LightTable = namedtuple("LightTable", ["lights", "env", "marginal", "conditional"])

LIGHT_SIZE = 9
DIRECTIONAL = 0
CONSTANT = 1
SG = 2
ENVMAP = 3
TWO_PI = 2.0 * math.pi
INV_4PI = 1.0 / (4.0 * math.pi)


def sg_normaliser(sharpness):
    """M(lambda) = 2 pi (1 - exp(-2 lambda)) / lambda."""
    return TWO_PI * (-math.expm1(-2.0 * sharpness)) / sharpness


def pack_light(kind, rgb, direction=(0.0, 0.0, 1.0), sharpness=0.0):
    row = np.zeros(LIGHT_SIZE)
    row[0] = {"directional": DIRECTIONAL, "constant": CONSTANT, "sg": SG, "envmap": ENVMAP}[kind]
    row[1:4] = rgb
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    row[4:7] = -d if kind == "directional" else d
    row[7] = sharpness
    row[8] = 1.0 / sg_normaliser(sharpness) if kind == "sg" else 0.0
    return row


def envmap_tables(img=None):
    """(env float32 (H, W, 3), marginal CDF (H+1,), conditional CDFs (H, W+1)) for an image or none."""
    if img is None:
        img = np.zeros((1, 1, 3), np.float32)
    img = np.ascontiguousarray(img, dtype=np.float32)
    H, W = img.shape[:2]
    theta = (np.arange(H) + 0.5) * math.pi / H
    w = img.astype(np.float64).mean(axis=2) * np.sin(theta)[:, None]
    if not np.any(w > 0):
        w = np.repeat(np.sin(theta)[:, None], W, axis=1)
    cond = np.zeros((H, W + 1))
    cond[:, 1:] = np.cumsum(w, axis=1)
    row = cond[:, -1].copy()
    marg = np.zeros(H + 1)
    marg[1:] = np.cumsum(row)
    marg /= marg[-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        cond = np.where(row[:, None] > 0, cond / row[:, None], np.linspace(0, 1, W + 1)[None, :])
    marg[-1] = 1.0
    cond[:, -1] = 1.0
    return img, marg, cond


# ------------------------------------------------------------------------------------------------
@njit(cache=True)
def env_uv(w):
    """(u, v) in [0, 1)^2 of a world direction (see the orientation above)."""
    u = math.atan2(w[0], w[1]) / TWO_PI
    if u < 0.0:
        u += 1.0
    if u >= 1.0:
        u = 0.0
    v = math.acos(min(1.0, max(-1.0, w[2]))) / math.pi
    return u, v


@njit(cache=True)
def cdf_find(cdf, x):
    """Largest i with cdf[i] <= x, clamped to [0, len(cdf) - 2]."""
    lo = 0
    hi = cdf.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _env_pixel(env, u, v):
    H = env.shape[0]
    W = env.shape[1]
    i = min(int(v * H), H - 1)
    j = min(int(u * W), W - 1)
    return i, j


@njit(cache=True)
def light_eval(lights, k, env, marg, cond, w):
    """Radiance (r, g, b) arriving from direction w (towards the light); 0 for delta lights."""
    t = lights[k, 0]
    if t == CONSTANT:
        return lights[k, 1], lights[k, 2], lights[k, 3]
    if t == SG:
        c = w[0] * lights[k, 4] + w[1] * lights[k, 5] + w[2] * lights[k, 6]
        g = math.exp(lights[k, 7] * (c - 1.0)) * lights[k, 8]
        return lights[k, 1] * g, lights[k, 2] * g, lights[k, 3] * g
    if t == ENVMAP:
        u, v = env_uv(w)
        i, j = _env_pixel(env, u, v)
        return lights[k, 1] * env[i, j, 0], lights[k, 2] * env[i, j, 1], lights[k, 3] * env[i, j, 2]
    return 0.0, 0.0, 0.0


@njit(cache=True)
def light_pdf(lights, k, env, marg, cond, w):
    """Solid-angle density with which ``light_sample`` produces w (0 for delta lights)."""
    t = lights[k, 0]
    if t == CONSTANT:
        return INV_4PI
    if t == SG:
        c = w[0] * lights[k, 4] + w[1] * lights[k, 5] + w[2] * lights[k, 6]
        return math.exp(lights[k, 7] * (c - 1.0)) * lights[k, 8]
    if t == ENVMAP:
        H = env.shape[0]
        W = env.shape[1]
        u, v = env_uv(w)
        i, j = _env_pixel(env, u, v)
        p = (marg[i + 1] - marg[i]) * (cond[i, j + 1] - cond[i, j]) * H * W
        s = math.sqrt(max(0.0, 1.0 - w[2] * w[2]))
        if s <= 0.0:
            return 0.0
        return p / (2.0 * math.pi * math.pi * s)
    return 0.0


@njit(cache=True)
def light_sample(lights, k, env, marg, cond, u1, u2):
    """Sample a direction towards light k: (w, r, g, b, pdf, delta).

    Non-delta lights return the radiance from w and its solid-angle pdf; a directional light returns
    its irradiance, pdf 1 and delta = True (the caller multiplies without dividing)."""
    w = np.empty(3)
    r, g, b, pdf, delta = light_sample_into(lights, k, env, marg, cond, u1, u2, w)
    return w, r, g, b, pdf, delta


@njit(cache=True, inline="always")
def light_sample_into(lights, k, env, marg, cond, u1, u2, w):
    """``light_sample`` writing the direction into ``w``: (r, g, b, pdf, delta)."""
    t = lights[k, 0]
    if t == DIRECTIONAL:
        w[0] = lights[k, 4]
        w[1] = lights[k, 5]
        w[2] = lights[k, 6]
        return lights[k, 1], lights[k, 2], lights[k, 3], 1.0, True
    if t == CONSTANT:
        z = 1.0 - 2.0 * u1
        s = math.sqrt(max(0.0, 1.0 - z * z))
        sp, cp = sincos_turn(u2)
        w[0] = s * cp
        w[1] = s * sp
        w[2] = z
        return lights[k, 1], lights[k, 2], lights[k, 3], INV_4PI, False
    if t == SG:
        lam = lights[k, 7]
        c = 1.0 + math.log(u1 + (1.0 - u1) * math.exp(-2.0 * lam)) / lam
        c = min(1.0, max(-1.0, c))
        s = math.sqrt(max(0.0, 1.0 - c * c))
        sin_ph, cos_ph = sincos_turn(u2)
        a0 = lights[k, 4]
        a1 = lights[k, 5]
        a2 = lights[k, 6]
        (x0, x1, x2), (y0, y1, y2) = orthonormal_basis(a0, a1, a2)
        cp = s * cos_ph
        sp = s * sin_ph
        w[0] = cp * x0 + sp * y0 + c * a0
        w[1] = cp * x1 + sp * y1 + c * a1
        w[2] = cp * x2 + sp * y2 + c * a2
        n = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        w /= n
        r, g, b = light_eval(lights, k, env, marg, cond, w)
        return r, g, b, light_pdf(lights, k, env, marg, cond, w), False
    # envmap: row from the marginal, column from that row's conditional, uniform inside the pixel
    H = env.shape[0]
    W = env.shape[1]
    i = cdf_find(marg, u1)
    pm = marg[i + 1] - marg[i]
    fv = (u1 - marg[i]) / pm if pm > 0.0 else 0.5
    j = cdf_find(cond[i], u2)
    pc = cond[i, j + 1] - cond[i, j]
    fu = (u2 - cond[i, j]) / pc if pc > 0.0 else 0.5
    fv = min(max(fv, 1e-9), 1.0 - 1e-9)
    fu = min(max(fu, 1e-9), 1.0 - 1e-9)
    v = (i + fv) / H
    u = (j + fu) / W
    st, ct = sincos_turn(0.5 * v)   # theta = pi v
    sp, cp = sincos_turn(u)         # phi = 2 pi u
    w[0] = sp * st
    w[1] = cp * st
    w[2] = ct
    if st <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, False
    pdf = pm * pc * H * W / (2.0 * math.pi * math.pi * st)
    return lights[k, 1] * env[i, j, 0], lights[k, 2] * env[i, j, 1], lights[k, 3] * env[i, j, 2], pdf, False


@njit(cache=True, inline="always")
def add_escaped_radiance(table, d, mis, pdf_prev, tp0, tp1, tp2, L0, L1, L2):
    """(L0, L1, L2) plus what a path of throughput (tp0, tp1, tp2) escaping along ``d`` receives from the
    lights of ``table`` (a ``LightTable``): each light's radiance weighted, when ``mis`` (a vertex that
    sampled the lights sent the ray), by the power heuristic of the direction's pdf ``pdf_prev`` against
    the light's own (``stages.core.sampling``)."""
    for k in range(table.lights.shape[0]):
        lr, lg, lb = light_eval(table.lights, k, table.env, table.marginal, table.conditional, d)
        if lr == 0.0 and lg == 0.0 and lb == 0.0:
            continue
        w = 1.0
        if mis:
            pl = light_pdf(table.lights, k, table.env, table.marginal, table.conditional, d)
            w = power_heuristic(pdf_prev, pl)
        L0 += tp0 * lr * w
        L1 += tp1 * lg * w
        L2 += tp2 * lb * w
    return L0, L1, L2


@njit(cache=True)
def environment_radiance(lights, env, marg, cond, w):
    """Total radiance of all non-delta lights from direction w (what an escaping ray sees)."""
    r = 0.0
    g = 0.0
    b = 0.0
    for k in range(lights.shape[0]):
        lr, lg, lb = light_eval(lights, k, env, marg, cond, w)
        r += lr
        g += lg
        b += lb
    return r, g, b
