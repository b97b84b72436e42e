"""Orthonormal frames about a unit vector.

``orthonormal_basis(x, y, z)`` -> ((t0, t1, t2), (b0, b1, b2)): two unit vectors completing the unit
vector (x, y, z) to a right-handed orthonormal frame (t, b, (x, y, z)), by the branchless
construction of Duff et al. 2017 ("Building an orthonormal basis, revisited"), continuous except
across z = 0's sign change. Used wherever a model works in a local frame: the Lambertian and SGGX
samplers, the fibre BCSDF's azimuth, the spherical Gaussian light.

``face_towards_into(n, w, c_min)``: a shading normal n (float64[3], unit, changed in place) that faces
away from the unit direction w, or nearly (n.w < c_min), is bent towards w in the plane of n and w until
n.w = c_min before renormalising (it ends with n.w > 0): a perturbed shading normal seen from behind
still scatters what arrives instead of ending the path. Returns True when it bent n.

``unit_rejection(v0, v1, v2, n0, n1, n2, c, tiny)`` -> (r0, r1, r2): the unit vector along v - c n, the part
of v normal to the unit n when c = v.n (the caller passes c, clamped or not: one Gram-Schmidt step); where
that part is shorter than ``tiny`` (v along n), orthonormal_basis(n)'s first vector.
"""
import math

from numba import njit


@njit(cache=True)
def orthonormal_basis(x, y, z):
    sign = 1.0 if z >= 0.0 else -1.0
    a = -1.0 / (sign + z)
    b = x * y * a
    return (1.0 + sign * x * x * a, sign * b, -sign * x), (b, sign + y * y * a, -y)


@njit(cache=True)
def face_towards_into(n, w, c_min):
    c = n[0] * w[0] + n[1] * w[1] + n[2] * w[2]
    if c >= c_min:
        return False
    k = c_min - c
    ln = 0.0
    for q in range(3):
        n[q] += k * w[q]
        ln += n[q] * n[q]
    ln = math.sqrt(ln)
    for q in range(3):
        n[q] /= ln
    return True


@njit(cache=True)
def unit_rejection(v0, v1, v2, n0, n1, n2, c, tiny):
    r0 = v0 - c * n0
    r1 = v1 - c * n1
    r2 = v2 - c * n2
    ln = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if ln < tiny:
        return orthonormal_basis(n0, n1, n2)[0]
    return r0 / ln, r1 / ln, r2 / ln
