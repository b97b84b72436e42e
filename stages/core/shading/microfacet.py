"""Microfacet pieces written once: Fresnel, anisotropic GGX with Smith masking, visible-normal
sampling, and the rough dielectric interface built from them, all in a local frame (x along alpha_u,
y along alpha_v, z the macro normal).

- ``fresnel_dielectric(cos_i, eta)``: unpolarised Fresnel reflectance of a dielectric interface.
- ``ggx_D``, ``ggx_lambda``, ``ggx_G1``: the anisotropic GGX distribution of micro-normals, Smith's
  Lambda and the masking G1 = 1 / (1 + Lambda) (Walter et al. 2007; Heitz 2014).
- ``ggx_sample_visible(v, au, av, u1, u2)``: a micro-normal from the distribution of normals visible
  from v, density G1(v) max(0, v.h) D(h) / v_z (Heitz 2018).
- ``refract(i, h, eta)``: -i refracted through the micro-normal h; ``(False, ...)`` under total
  internal reflection.
- ``rough_reflect(i, o, au, av, eta)`` and ``rough_transmit(i, o, au, av, eta)``: the rough dielectric
  of Walter et al. 2007 with visible-normal densities: (value, pdf) of reflection i -> o and of
  refraction i -> o across the interface (flux form: value = (1 - F) G1(o) pdf), pdf the density of
  sampling them through ``ggx_sample_visible``.

- ``rough_dielectric_eval(i, o, alpha, eta)`` and ``rough_dielectric_sample(i, alpha, eta, u0, u1, u2)``: a
  rough dielectric surface (a glass or water interface) of isotropic roughness alpha, i on the z > 0 side:
  f |o_z| of reflection or refraction (the side of o decides) in radiance form -- refraction scaled by
  1 / eta^2, the radiance of a beam narrowed by the denser side (Veach 1997 §5.2), so that a path that
  enters and leaves a closed object carries its radiance unchanged -- and its density when the micro-normal
  is sampled from the visible normals and the lobe by its Fresnel weight (u0 < F: reflect); the sample's
  weight is value / pdf = G1(o) (refraction: G1(o) / eta^2).

Directions are unit vectors pointing away from the surface point; ``COS_EPS`` is the grazing cosine at
or below which nothing scatters. Users: the BYSDF of seed 004 (``stages.core.shading.bysdf``), the meshes'
dielectric material (``stages.render.meshes``).
"""
import math

from numba import njit

COS_EPS = 1e-9            # |cos| at or below this counts as grazing: no scattering


@njit(cache=True)
def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance for light meeting the interface at cos_i (> 0, on the incident
    side) with relative index eta = n_transmitted / n_incident; 1 under total internal reflection."""
    c = min(1.0, abs(cos_i))
    sin2_t = (1.0 - c * c) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin2_t)
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    return 0.5 * (rs * rs + rp * rp)


@njit(cache=True)
def ggx_D(x, y, z, au, av):
    """Anisotropic GGX normal distribution of the unit micro-normal (x, y, z) in the local frame
    (x along alpha_u, z the macro normal): 1 / (pi au av (x^2/au^2 + y^2/av^2 + z^2)^2), 0 for z <= 0."""
    if z <= 0.0:
        return 0.0
    e = (x / au) ** 2 + (y / av) ** 2 + z * z
    return 1.0 / (math.pi * au * av * e * e)


@njit(cache=True)
def ggx_lambda(x, y, z, au, av):
    """Smith's Lambda of the unit direction (x, y, z) for anisotropic GGX (inf at z = 0)."""
    z2 = z * z
    if z2 <= 0.0:
        return math.inf
    a2 = (au * au * x * x + av * av * y * y) / z2
    return 0.5 * (math.sqrt(1.0 + a2) - 1.0)


@njit(cache=True)
def ggx_G1(x, y, z, au, av):
    """Smith masking 1 / (1 + Lambda) of direction (x, y, z) (the sidedness test is the caller's)."""
    return 1.0 / (1.0 + ggx_lambda(x, y, z, au, av))


@njit(cache=True)
def ggx_sample_visible(vx, vy, vz, au, av, u1, u2):
    """A micro-normal (hx, hy, hz) with density G1(v) max(0, v.h) D(h) / v_z: the distribution of
    visible normals seen from the local unit direction v (v_z > 0), Heitz 2018 Listing 1."""
    sx = au * vx
    sy = av * vy
    sz = vz
    ln = math.sqrt(sx * sx + sy * sy + sz * sz)
    sx /= ln
    sy /= ln
    sz /= ln
    lensq = sx * sx + sy * sy
    if lensq > 0.0:
        il = 1.0 / math.sqrt(lensq)
        t1x, t1y = -sy * il, sx * il
    else:
        t1x, t1y = 1.0, 0.0
    t2x = -sz * t1y               # T2 = Vh x T1 (T1 has no z component)
    t2y = sz * t1x
    t2z = sx * t1y - sy * t1x
    r = math.sqrt(u1)
    ph = 2.0 * math.pi * u2
    a = r * math.cos(ph)
    b = r * math.sin(ph)
    s = 0.5 * (1.0 + sz)
    b = (1.0 - s) * math.sqrt(max(0.0, 1.0 - a * a)) + s * b
    c = math.sqrt(max(0.0, 1.0 - a * a - b * b))
    nx = a * t1x + b * t2x + c * sx
    ny = a * t1y + b * t2y + c * sy
    nz = b * t2z + c * sz
    hx = au * nx
    hy = av * ny
    hz = max(0.0, nz)
    ln = math.sqrt(hx * hx + hy * hy + hz * hz)
    if ln <= 0.0:
        return 0.0, 0.0, 1.0
    return hx / ln, hy / ln, hz / ln


@njit(cache=True)
def refract(ix, iy, iz, hx, hy, hz, eta):
    """(ok, ox, oy, oz): -i refracted through the micro-normal h (i.h > 0), relative index eta;
    ok False under total internal reflection."""
    c = ix * hx + iy * hy + iz * hz
    sin2_t = (1.0 - c * c) / (eta * eta)
    if sin2_t >= 1.0:
        return False, 0.0, 0.0, 0.0
    k = c / eta - math.sqrt(1.0 - sin2_t)
    return True, -ix / eta + k * hx, -iy / eta + k * hy, -iz / eta + k * hz


@njit(cache=True)
def rough_reflect(ix, iy, iz, ox, oy, oz, au, av, eta):
    """(F D G1(i) G1(o) / (4 i_z), pdf) of reflection i -> o, both with z > COS_EPS."""
    if iz <= COS_EPS or oz <= COS_EPS:
        return 0.0, 0.0
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    ln = math.sqrt(hx * hx + hy * hy + hz * hz)
    hx /= ln
    hy /= ln
    hz /= ln
    ih = ix * hx + iy * hy + iz * hz
    D = ggx_D(hx, hy, hz, au, av)
    if ih <= 0.0 or D <= 0.0:
        return 0.0, 0.0
    g1i = ggx_G1(ix, iy, iz, au, av)
    pdf = g1i * D / (4.0 * iz)                  # G1(i) (i.h) D / i_z  *  1 / (4 i.h)
    return fresnel_dielectric(ih, eta) * ggx_G1(ox, oy, oz, au, av) * pdf, pdf


@njit(cache=True)
def rough_transmit(ix, iy, iz, ox, oy, oz, au, av, eta):
    """(value, pdf) of refraction i -> o across the interface, i on the z > 0 side (index 1), o on the
    other (relative index eta = n_o / n_i); flux form value = (1 - F) G1(o) pdf, pdf the density of
    visible-normal sampling and refraction (Walter 2007 Eq. 17 Jacobian)."""
    if iz <= COS_EPS or oz >= -COS_EPS:
        return 0.0, 0.0
    hx, hy, hz = ix + eta * ox, iy + eta * oy, iz + eta * oz
    ln = math.sqrt(hx * hx + hy * hy + hz * hz)
    if ln <= 1e-12:
        return 0.0, 0.0
    if hz < 0.0:
        ln = -ln
    hx /= ln
    hy /= ln
    hz /= ln
    ih = ix * hx + iy * hy + iz * hz
    oh = ox * hx + oy * hy + oz * hz
    if ih <= 0.0 or oh >= 0.0:
        return 0.0, 0.0
    D = ggx_D(hx, hy, hz, au, av)
    if D <= 0.0:
        return 0.0, 0.0
    den = ih + eta * oh
    if den == 0.0:
        return 0.0, 0.0
    jac = eta * eta * (-oh) / (den * den)       # d omega_h / d omega_o
    pdf = ggx_G1(ix, iy, iz, au, av) * ih * D / iz * jac
    F = fresnel_dielectric(ih, eta)
    return (1.0 - F) * ggx_G1(ox, oy, oz, au, av) * pdf, pdf


@njit(cache=True)
def rough_dielectric_eval(ix, iy, iz, ox, oy, oz, alpha, eta):
    """(f |o_z|, pdf) of the rough dielectric surface (module doc) from i (z > 0) to o on either side, eta =
    n(z < 0 side) / n(z > 0 side); pdf = the visible-normal density times the chosen lobe's Fresnel weight,
    which is the lobe's flux-form value over G1(o)."""
    if oz > 0.0:
        value, _ = rough_reflect(ix, iy, iz, ox, oy, oz, alpha, alpha, eta)
        scale = 1.0
    else:
        value, _ = rough_transmit(ix, iy, iz, ox, oy, oz, alpha, alpha, eta)
        scale = 1.0 / (eta * eta)
    if value <= 0.0:
        return 0.0, 0.0
    return value * scale, value / ggx_G1(ox, oy, oz, alpha, alpha)


@njit(cache=True)
def rough_dielectric_sample(ix, iy, iz, alpha, eta, u0, u1, u2):
    """(ok, ox, oy, oz, weight, pdf): a direction of the rough dielectric surface from i (z > 0): a visible
    micro-normal from (u1, u2), reflection about it when u0 < F(i.h) (always under total internal
    reflection), else refraction through it; weight = value / pdf of ``rough_dielectric_eval``."""
    if iz <= COS_EPS:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0
    hx, hy, hz = ggx_sample_visible(ix, iy, iz, alpha, alpha, u1, u2)
    ih = ix * hx + iy * hy + iz * hz
    if ih <= 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0
    if u0 < fresnel_dielectric(ih, eta):
        ox, oy, oz = 2.0 * ih * hx - ix, 2.0 * ih * hy - iy, 2.0 * ih * hz - iz
        if oz <= 0.0:       # reflected below the surface: no sample (the evaluation would read a refraction)
            return False, 0.0, 0.0, 1.0, 0.0, 0.0
    else:
        ok, ox, oy, oz = refract(ix, iy, iz, hx, hy, hz, eta)
        if not ok or oz >= 0.0:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0
    value, pdf = rough_dielectric_eval(ix, iy, iz, ox, oy, oz, alpha, eta)
    if pdf <= 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0
    return True, ox, oy, oz, value / pdf, pdf
