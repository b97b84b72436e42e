"""Optional ground plane: the infinite plane z = height, Lambertian with RGB albedo, seen from both sides.

The plane's shading normal faces the side the ray came from, so a camera below the plane sees its
underside lit the same way. Materials on it use ``stages.core.shading.lambert`` (the Lambertian kernels
take any normal). Packed as float64[4]: height, albedo rgb; ``ground_intersect`` returns inf when the
scene has no ground (pass ``enabled`` False).
"""
import math

from numba import njit


@njit(cache=True)
def ground_intersect(ground, enabled, oz, dz, tmin):
    """Distance t > tmin along a ray (origin height oz, direction z-component dz) to the plane, or inf."""
    if not enabled or dz == 0.0:
        return math.inf
    t = (ground[0] - oz) / dz
    if t > tmin:
        return t
    return math.inf
