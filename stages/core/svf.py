"""The segment visibility function's representations as the renderer reads them (seed 001 §4.1, §5.2).

Pixel grid: pixel (r, c) of a res_theta x res_phi image is centred at theta = (r + 1/2) pi / res_theta
(from +z), phi = (c + 1/2) 2 pi / res_phi (``pixel_direction``), with solid angle
(cos(r pi/res_theta) - cos((r+1) pi/res_theta)) 2 pi/res_phi (``pixel_solid_angle``); images are flat,
index r res_phi + c. Directions are in exemplar (flat fabric) space, z up.

- ``ssdf_reconstruct(mean, basis, coeffs_k, out)``: a segment's PCA-reconstructed SSDF, the whole image;
- ``ssdf_at(mean, basis, coeffs_k, res_theta, res_phi, w)``: its bilinear value at direction w through
  the four pixel centres around it, reconstructing only those four (phi wraps, theta clamps);
  ``ssdf_visible``: its sign (§5.2.1); ``image_at``: the same lookup in a full image;
- ``ssg_visibility(axes, weights, lam, w)``: the sum of normalised SGs V^ssg(w) (§4.1).
The precompute stage (``stages.precompute.svf``) builds them; the ``prt`` renderer reads them.
"""
import math

import numpy as np
from numba import njit

from stages.core.sg import sg_mass


@njit(cache=True)
def pixel_direction(r, c, res_theta, res_phi):
    """Unit direction of pixel (r, c)'s centre."""
    th = (r + 0.5) * math.pi / res_theta
    ph = (c + 0.5) * 2.0 * math.pi / res_phi
    st = math.sin(th)
    return st * math.cos(ph), st * math.sin(ph), math.cos(th)


@njit(cache=True)
def pixel_solid_angle(r, res_theta, res_phi):
    """Solid angle of a pixel of row r."""
    d = math.pi / res_theta
    return (math.cos(r * d) - math.cos((r + 1) * d)) * (2.0 * math.pi / res_phi)


@njit(cache=True)
def ssdf_reconstruct(mean, basis, coeffs_k, out):
    """out (D,) = mean + sum_j coeffs_k[j] basis[j]: the segment's PCA-reconstructed SSDF."""
    D = mean.shape[0]
    for d in range(D):
        out[d] = mean[d]
    for j in range(basis.shape[0]):
        c = np.float64(coeffs_k[j])
        for d in range(D):
            out[d] += c * basis[j, d]


@njit(cache=True)
def bilinear_pixels(res_theta, res_phi, w):
    """(r0, r1, fr, c0, c1, fc): the four pixel centres around direction w (unit) and the weights
    (value = (1-fr)((1-fc) v[r0,c0] + fc v[r0,c1]) + fr(...r1...)); phi wraps, theta clamps."""
    z = min(1.0, max(-1.0, w[2]))
    th = math.acos(z)
    ph = math.atan2(w[1], w[0])
    if ph < 0.0:
        ph += 2.0 * math.pi
    u = th * res_theta / math.pi - 0.5
    if u <= 0.0:
        r0, r1, fr = 0, 0, 0.0
    elif u >= res_theta - 1:
        r0, r1, fr = res_theta - 1, res_theta - 1, 0.0
    else:
        r0 = int(math.floor(u))
        r1 = r0 + 1
        fr = u - r0
    v = ph * res_phi / (2.0 * math.pi) - 0.5
    cf = math.floor(v)
    fc = v - cf
    c0 = int(cf) % res_phi
    c1 = (c0 + 1) % res_phi
    return r0, r1, fr, c0, c1, fc


@njit(cache=True)
def image_at(img, res_theta, res_phi, w):
    """Bilinear value of a flat (D,) image (e.g. a reconstructed SSDF) at direction w."""
    r0, r1, fr, c0, c1, fc = bilinear_pixels(res_theta, res_phi, w)
    a = (1.0 - fc) * img[r0 * res_phi + c0] + fc * img[r0 * res_phi + c1]
    b = (1.0 - fc) * img[r1 * res_phi + c0] + fc * img[r1 * res_phi + c1]
    return (1.0 - fr) * a + fr * b


@njit(cache=True)
def _pixel_value(mean, basis, coeffs_k, i):
    y = np.float64(mean[i])
    for j in range(basis.shape[0]):
        y += np.float64(coeffs_k[j]) * basis[j, i]
    return y


@njit(cache=True)
def ssdf_at(mean, basis, coeffs_k, res_theta, res_phi, w):
    """The reconstructed SSDF of a segment at direction w (bilinear; only four pixels reconstructed)."""
    r0, r1, fr, c0, c1, fc = bilinear_pixels(res_theta, res_phi, w)
    a = (1.0 - fc) * _pixel_value(mean, basis, coeffs_k, r0 * res_phi + c0) + \
        fc * _pixel_value(mean, basis, coeffs_k, r0 * res_phi + c1)
    b = (1.0 - fc) * _pixel_value(mean, basis, coeffs_k, r1 * res_phi + c0) + \
        fc * _pixel_value(mean, basis, coeffs_k, r1 * res_phi + c1)
    return (1.0 - fr) * a + fr * b


@njit(cache=True)
def ssdf_visible(mean, basis, coeffs_k, res_theta, res_phi, w):
    """Local visibility from the SSDF's sign (§5.2.1): True when ssdf_at > 0."""
    return ssdf_at(mean, basis, coeffs_k, res_theta, res_phi, w) > 0.0


@njit(cache=True)
def ssg_visibility(axes, weights, lam, w):
    """V^ssg(w) = sum_q weights[q] G(w; axes[q], lam) / M(lam) (§4.1)."""
    acc = 0.0
    for q in range(axes.shape[0]):
        acc += weights[q] * math.exp(lam * (w[0] * axes[q, 0] + w[1] * axes[q, 1] + w[2] * axes[q, 2] - 1.0))
    return acc / sg_mass(lam)
