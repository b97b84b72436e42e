"""Sine and cosine of a fraction of a turn: ``sincos_turn(u)`` = (sin 2 pi u, cos 2 pi u).

Every sampler that turns a uniform number into an azimuth (cosine-weighted hemispheres, the constant
sky, spherical-Gaussian lobes, the envmap's pixel) wants sin and cos of 2 pi u for u in [0, 1).
libm's ``sincos`` takes a general argument and reduces it modulo pi / 2 in extended precision; it
was 4-5 % of a Lambertian fiberpath render in ``perf`` (a call per sampled direction, never inlined,
never vectorised).

Here the reduction is exact and the rest is inline arithmetic:

- *Quarter turns.* q = the nearest integer to 4u, f = u - q / 4. The subtraction is exact (Sterbenz:
  for q != 0, u lies within a factor 2 of q / 4), so |f| <= 1/8 carries no reduction error, unlike
  2 pi u, whose rounding libm then reduces faithfully (sin(2 pi * 0.5) is 1.2e-16 there, 0 here).
- *The octant.* theta = 2 pi f in [-pi/4, pi/4]; sin theta and cos theta from their Taylor series to
  theta^15 and theta^16 (the next terms are below 7e-17 and 3e-18 on that range), in Horner form.
- *Rotation.* (sin, cos) of 2 pi u = (sin, cos) of theta turned by q quarter turns.

Accuracy against extended precision: absolute error below 2e-16 (``tests/core/test_turns.py``, 0.4 M
values of u; 1.7e-16 at most on 2 M, where libm's sin(2 pi u) is off by up to 6.9e-16, the rounding of 2 pi u),
exactly 0 and +-1 at quarter turns, sin^2 + cos^2 = 1 within 4e-16.
"""
import math

from numba import njit

TWO_PI = 2.0 * math.pi

# Taylor coefficients: sin = x + x^3 S3 + ... + x^15 S15, cos = 1 + x^2 C2 + ... + x^16 C16
S3, S5, S7, S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
S11, S13, S15 = -1.0 / 39916800.0, 1.0 / 6227020800.0, -1.0 / 1307674368000.0
C2, C4, C6, C8 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0
C10, C12, C14, C16 = -1.0 / 3628800.0, 1.0 / 479001600.0, -1.0 / 87178291200.0, 1.0 / 20922789888000.0


@njit(cache=True, inline="always")
def sincos_turn(u):
    """(sin 2 pi u, cos 2 pi u), exactly reduced by quarter turns (module doc)."""
    q = math.floor(4.0 * u + 0.5)
    x = TWO_PI * (u - 0.25 * q)   # in [-pi/4, pi/4]; the subtraction is exact
    x2 = x * x
    s = x + x * x2 * (S3 + x2 * (S5 + x2 * (S7 + x2 * (S9 + x2 * (S11 + x2 * (S13 + x2 * S15))))))
    c = 1.0 + x2 * (C2 + x2 * (C4 + x2 * (C6 + x2 * (C8 + x2 * (C10 + x2 * (C12 + x2 * (C14 + x2 * C16)))))))
    quarter = int(q) & 3
    if quarter == 0:
        return s, c
    if quarter == 1:
        return c, -s
    if quarter == 2:
        return -s, -c
    return -c, s
