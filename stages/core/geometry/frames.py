"""Orthonormal frames about a unit vector.

``orthonormal_basis(x, y, z)`` -> ((t0, t1, t2), (b0, b1, b2)): two unit vectors completing the unit
vector (x, y, z) to a right-handed orthonormal frame (t, b, (x, y, z)), by the branchless
construction of Duff et al. 2017 ("Building an orthonormal basis, revisited"), continuous except
across z = 0's sign change. Used wherever a model works in a local frame: the Lambertian and SGGX
samplers, the fibre BCSDF's azimuth, the spherical Gaussian light.
"""
from numba import njit


@njit(cache=True)
def orthonormal_basis(x, y, z):
    sign = 1.0 if z >= 0.0 else -1.0
    a = -1.0 / (sign + z)
    b = x * y * a
    return (1.0 + sign * x * x * a, sign * b, -sign * x), (b, sign + y * y * a, -y)
