"""SGGX micro-flake distribution and the specular micro-flake phase function.

The volumetric cloth model of seed 000 (§3.3, App. A) treats fibres as an anisotropic medium of
tiny mirror flakes (Jakob et al. 2010). The flake normals follow an SGGX distribution (Heitz et al.
2015), an ellipsoid described by a symmetric positive-definite 3x3 matrix S.

Parameters
----------
S : tuple of six floats (Sxx, Syy, Szz, Sxy, Sxz, Syz) -- Mitsuba's order for its 6-channel
    ``sggx`` volume.
t, sigma : a *fibre-like* distribution (Heitz 2015 §4) has its flake normals perpendicular to the
    fibre tangent t: S = (I - t t^T) + sigma^2 t t^T. sigma in (0, 1] is the fibre roughness: small
    sigma gives a thin, bright specular cone around the fibre; sigma = 1 is isotropic.

Functions (directions are unit 3-tuples pointing *away* from the scattering point)
---------
- ``fiber_sggx(tx, ty, tz, sigma)`` -> S
- ``projected_area(S, w)``: sigma(w) = sqrt(w^T S w), the flakes' projected area (Heitz Eq. 5);
  the medium's extinction is density * sigma(w) (Jakob 2010 Eq. 8).
- ``ndf(S, m)``: D(m) = 1 / (pi sqrt|S| (m^T S^-1 m)^2) (Heitz Eq. 9), normalised so that
  the integral of <w, m>^+ D(m) over the sphere is sigma(w) (D = 1/pi for S = I).
- ``phase_eval(S, wi, wo)``: specular micro-flake phase function D(wh) / (4 sigma(wi)),
  wh = (wi + wo)/|wi + wo| (Heitz Eq. 16). Reciprocity of the anisotropic medium holds for
  sigma(wi) f(wi, wo), which is symmetric.
- ``phase_sample(S, wi, u1, u2)`` -> (wo, pdf): exact importance sampling through the
  distribution of *visible* normals (Heitz 2015 App. B/C), mirror reflection of wi about the
  sampled flake normal; its pdf equals ``phase_eval`` exactly, so the sampling weight is 1.

The interface every model in ``stages.core.shading`` has (integrators call the scalar kernels above;
these are the same functions with arrays): parameters p = (sigma,), frame = the fibre tangent t, wi
towards the previous vertex, wo the scattered direction. The phase function is grey: the colour of a
collision is the medium's single-scattering albedo, applied by the integrator.
    sggx_eval(p, t, wi, wo) -> (f, f, f)
    sggx_pdf(p, t, wi, wo) -> f
    sggx_sample(p, t, wi, u0, u1, u2) -> (wo, 1, 1, 1, pdf)      u0 unused
"""
import math

import numpy as np
from numba import njit

from stages.core.geometry.frames import orthonormal_basis

INV_PI = 1.0 / math.pi


@njit(cache=True)
def fiber_sggx(tx, ty, tz, sigma):
    """Fibre-like SGGX matrix for unit tangent t and roughness sigma (Heitz 2015 §4)."""
    k = sigma * sigma - 1.0
    return (1.0 + k * tx * tx, 1.0 + k * ty * ty, 1.0 + k * tz * tz,
            k * tx * ty, k * tx * tz, k * ty * tz)


@njit(cache=True)
def _quad(S, x, y, z):
    return (S[0] * x * x + S[1] * y * y + S[2] * z * z
            + 2.0 * (S[3] * x * y + S[4] * x * z + S[5] * y * z))


@njit(cache=True)
def projected_area(S, wx, wy, wz):
    """sigma(w) = sqrt(w^T S w) (Heitz 2015 Eq. 5)."""
    q = _quad(S, wx, wy, wz)
    return math.sqrt(q) if q > 0.0 else 0.0


@njit(cache=True)
def _det(S):
    return (S[0] * S[1] * S[2] - S[0] * S[5] * S[5] - S[1] * S[4] * S[4] - S[2] * S[3] * S[3]
            + 2.0 * S[3] * S[4] * S[5])


@njit(cache=True)
def ndf(S, mx, my, mz):
    """D(m) = |S|^{3/2} / (pi (m^T adj(S) m)^2), i.e. Heitz 2015 Eq. 9 with S^-1 = adj(S)/|S|."""
    det = _det(S)
    if det <= 0.0:
        return 0.0
    # adjugate of S (symmetric)
    a00 = S[1] * S[2] - S[5] * S[5]
    a11 = S[0] * S[2] - S[4] * S[4]
    a22 = S[0] * S[1] - S[3] * S[3]
    a01 = S[4] * S[5] - S[3] * S[2]
    a02 = S[3] * S[5] - S[4] * S[1]
    a12 = S[3] * S[4] - S[0] * S[5]
    q = (a00 * mx * mx + a11 * my * my + a22 * mz * mz
         + 2.0 * (a01 * mx * my + a02 * mx * mz + a12 * my * mz))
    if q <= 0.0:
        return 0.0
    return det * math.sqrt(det) * INV_PI / (q * q)


@njit(cache=True)
def phase_eval(S, wix, wiy, wiz, wox, woy, woz):
    """Specular micro-flake phase function f(wi -> wo) = D(wh) / (4 sigma(wi)) (Heitz 2015 Eq. 16)."""
    hx = wix + wox
    hy = wiy + woy
    hz = wiz + woz
    n = math.sqrt(hx * hx + hy * hy + hz * hz)
    if n < 1e-12:
        return 0.0
    s = projected_area(S, wix, wiy, wiz)
    if s <= 0.0:
        return 0.0
    return 0.25 * ndf(S, hx / n, hy / n, hz / n) / s


@njit(cache=True)
def sample_visible_normal(S, wix, wiy, wiz, u1, u2):
    """A flake normal drawn from D_wi(m) = <wi, m>^+ D(m) / sigma(wi) (Heitz 2015 App. C)."""
    wk, wj = orthonormal_basis(wix, wiy, wiz)
    # S expressed in the frame (wk, wj, wi)
    s_jj = _quad(S, wj[0], wj[1], wj[2])
    s_ii = _quad(S, wix, wiy, wiz)
    s_kj = (S[0] * wk[0] * wj[0] + S[1] * wk[1] * wj[1] + S[2] * wk[2] * wj[2]
            + S[3] * (wk[0] * wj[1] + wk[1] * wj[0]) + S[4] * (wk[0] * wj[2] + wk[2] * wj[0])
            + S[5] * (wk[1] * wj[2] + wk[2] * wj[1]))
    s_ki = (S[0] * wk[0] * wix + S[1] * wk[1] * wiy + S[2] * wk[2] * wiz
            + S[3] * (wk[0] * wiy + wk[1] * wix) + S[4] * (wk[0] * wiz + wk[2] * wix)
            + S[5] * (wk[1] * wiz + wk[2] * wiy))
    s_ji = (S[0] * wj[0] * wix + S[1] * wj[1] * wiy + S[2] * wj[2] * wiz
            + S[3] * (wj[0] * wiy + wj[1] * wix) + S[4] * (wj[0] * wiz + wj[2] * wix)
            + S[5] * (wj[1] * wiz + wj[2] * wiy))
    det = _det(S)
    sqrt_det = math.sqrt(det) if det > 0.0 else 0.0
    inv_sqrt_ii = 1.0 / math.sqrt(s_ii)
    tmp = math.sqrt(max(s_jj * s_ii - s_ji * s_ji, 1e-300))
    mk0 = sqrt_det / tmp
    mj0 = -inv_sqrt_ii * (s_ki * s_ji - s_kj * s_ii) / tmp
    mj1 = inv_sqrt_ii * tmp
    mi0 = inv_sqrt_ii * s_ki
    mi1 = inv_sqrt_ii * s_ji
    mi2 = inv_sqrt_ii * s_ii
    # uniform point on the unit disk, lifted to the hemisphere
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    u = r * math.cos(phi)
    v = r * math.sin(phi)
    w = math.sqrt(max(1.0 - u * u - v * v, 0.0))
    a = u * mk0 + v * mj0 + w * mi0
    b = v * mj1 + w * mi1
    c = w * mi2
    mx = a * wk[0] + b * wj[0] + c * wix
    my = a * wk[1] + b * wj[1] + c * wiy
    mz = a * wk[2] + b * wj[2] + c * wiz
    n = math.sqrt(mx * mx + my * my + mz * mz)
    return mx / n, my / n, mz / n


@njit(cache=True)
def phase_sample(S, wix, wiy, wiz, u1, u2):
    """(wo_x, wo_y, wo_z, pdf): mirror wi about a visible flake normal; pdf == phase_eval."""
    mx, my, mz = sample_visible_normal(S, wix, wiy, wiz, u1, u2)
    c = 2.0 * (wix * mx + wiy * my + wiz * mz)
    wox = c * mx - wix
    woy = c * my - wiy
    woz = c * mz - wiz
    n = math.sqrt(wox * wox + woy * woy + woz * woz)
    wox /= n
    woy /= n
    woz /= n
    return wox, woy, woz, phase_eval(S, wix, wiy, wiz, wox, woy, woz)


@njit(cache=True)
def sggx_eval(p, t, wi, wo):
    f = phase_eval(fiber_sggx(t[0], t[1], t[2], p[0]), wi[0], wi[1], wi[2], wo[0], wo[1], wo[2])
    return f, f, f


@njit(cache=True)
def sggx_pdf(p, t, wi, wo):
    return phase_eval(fiber_sggx(t[0], t[1], t[2], p[0]), wi[0], wi[1], wi[2], wo[0], wo[1], wo[2])


@njit(cache=True)
def sggx_sample(p, t, wi, u0, u1, u2):
    wo = np.empty(3)
    wo[0], wo[1], wo[2], pdf = phase_sample(fiber_sggx(t[0], t[1], t[2], p[0]), wi[0], wi[1], wi[2], u1, u2)
    if pdf <= 0.0:
        return wo, 0.0, 0.0, 0.0, 0.0
    return wo, 1.0, 1.0, 1.0, pdf
