"""``sincos_turn``: sin and cos of 2 pi u against extended precision, and its exact quarter turns."""
import math

import numpy as np
from numba import njit

from stages.core.turns import sincos_turn

PI_LONG = np.longdouble("3.14159265358979323846264338327950288")


@njit(cache=True)
def _sincos_many(u):
    s = np.empty_like(u)
    c = np.empty_like(u)
    for i in range(u.size):
        s[i], c[i] = sincos_turn(u[i])
    return s, c


def _samples():
    rng = np.random.default_rng(20261203)
    eighths = np.arange(9) / 8.0
    u = np.concatenate([rng.random(400_000), np.arange(4097) / 4096.0,
                        np.nextafter(eighths, 2.0), np.nextafter(eighths, -1.0), [0.0, 1e-300, 1e-17]])
    return u[(u >= 0.0) & (u < 1.0)]


def test_sincos_turn_matches_extended_precision():
    assert np.finfo(np.longdouble).nmant >= 63, "the reference needs x87 extended precision"
    u = _samples()
    s, c = _sincos_many(u)
    angle = 2 * PI_LONG * u.astype(np.longdouble)
    err_s = np.abs(s.astype(np.longdouble) - np.sin(angle)).astype(np.float64)
    err_c = np.abs(c.astype(np.longdouble) - np.cos(angle)).astype(np.float64)
    assert err_s.max() < 2e-16 and err_c.max() < 2e-16, (err_s.max(), err_c.max())
    # libm on the rounded angle 2 pi u is the worse of the two (it inherits that rounding)
    libm = np.abs(np.sin(2 * np.pi * u).astype(np.longdouble) - np.sin(angle)).astype(np.float64)
    assert libm.max() > err_s.max()
    assert np.abs(s * s + c * c - 1.0).max() < 4e-16


def test_sincos_turn_is_exact_at_quarter_turns_and_odd_about_a_turn():
    assert sincos_turn(0.0) == (0.0, 1.0)
    assert sincos_turn(0.25) == (1.0, 0.0)
    assert sincos_turn(0.5) == (0.0, -1.0)
    assert sincos_turn(0.75) == (-1.0, 0.0)
    assert sincos_turn(1.0) == (0.0, 1.0)
    for u in (0.55, 0.6, 0.7, 0.8, 0.9, 2.0 / 3.0):
        s, c = sincos_turn(u)
        s2, c2 = sincos_turn(1.0 - u)   # 1 - u is exact for u >= 1/2 (Sterbenz): the angle mirrored
        assert math.isclose(s, -s2, rel_tol=0, abs_tol=2e-16) and math.isclose(c, c2, rel_tol=0, abs_tol=2e-16)
