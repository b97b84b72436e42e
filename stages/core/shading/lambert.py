"""Lambertian surface: diffuse reflection from a fibre capsule's surface or the ground plane.

For validation against other renderers (e.g. Mitsuba 3 ``linearcurve`` with a ``diffuse`` BSDF):
unlike the BCSDF (a curve model with no self-shadowing), this is an ordinary opaque surface. At a hit
with outward surface normal n (``stages.core.geometry.capsule.capsule_normal``) and albedo rho,

    f(wi, wo) cos = rho / pi * max(0, n . wo)       (wo towards the light; 0 below the surface)

sampled by cosine-weighted hemisphere sampling about n: pdf(wo) = max(0, n . wo) / pi, so the
sampling weight is rho exactly. Rays leaving the surface test every fibre (including their own).

Interface (the one every model in ``stages.core.shading`` has): parameters p = albedo (rgb), frame =
the unit outward normal n, wi the direction towards the viewer (unused: the model is reciprocal and
view-independent), wo towards the light.
    lambert_eval(p, n, wi, wo) -> (r, g, b)              f cos
    lambert_pdf(p, n, wi, wo) -> pdf                      solid-angle density of lambert_sample
    lambert_sample(p, n, wi, u0, u1, u2) -> (wo, r, g, b, pdf)   weight f cos / pdf; u0 unused
    lambert_sample_into(p, n, wi, u1, u2, wo) -> (r, g, b, pdf)  the same, writing wo
    cosine_direction(n, u1, u2) -> (x, y, z)             the sampled direction alone, as a 3-tuple
"""
import math

import numpy as np
from numba import njit

from stages.core.geometry.frames import orthonormal_basis
from stages.core.turns import sincos_turn


@njit(cache=True, inline="always")
def lambert_eval(albedo, n, wi, wo):
    """f cos: (r, g, b) factor multiplying radiance arriving from wo."""
    c = n[0] * wo[0] + n[1] * wo[1] + n[2] * wo[2]
    if c <= 0.0:
        return 0.0, 0.0, 0.0
    c /= math.pi
    return albedo[0] * c, albedo[1] * c, albedo[2] * c


@njit(cache=True, inline="always")
def lambert_pdf(albedo, n, wi, wo):
    c = n[0] * wo[0] + n[1] * wo[1] + n[2] * wo[2]
    return c / math.pi if c > 0.0 else 0.0


@njit(cache=True)
def lambert_sample(albedo, n, wi, u0, u1, u2):
    """(wo, weight r, g, b, pdf) by cosine-weighted hemisphere sampling (Malley's method)."""
    wo = np.empty(3)
    r, g, b, pdf = lambert_sample_into(albedo, n, wi, u1, u2, wo)
    return wo, r, g, b, pdf


@njit(cache=True, inline="always")
def cosine_direction(n, u1, u2):
    """(x, y, z): a cosine-weighted direction about the unit n (Malley's method); its pdf is (wo . n) / pi."""
    r = math.sqrt(u1)
    sp, cp = sincos_turn(u2)
    x = r * cp
    y = r * sp
    z = math.sqrt(max(0.0, 1.0 - u1))
    (t0, t1, t2), (b0, b1, b2) = orthonormal_basis(n[0], n[1], n[2])
    return (x * t0 + y * b0 + z * n[0],
            x * t1 + y * b1 + z * n[1],
            x * t2 + y * b2 + z * n[2])


@njit(cache=True, inline="always")
def lambert_sample_into(albedo, n, wi, u1, u2, wo):
    """``lambert_sample`` writing the direction into ``wo``: (weight r, g, b, pdf)."""
    wo[0], wo[1], wo[2] = cosine_direction(n, u1, u2)
    pdf = math.sqrt(max(0.0, 1.0 - u1)) / math.pi
    if pdf <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return albedo[0], albedo[1], albedo[2], pdf
