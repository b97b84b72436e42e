"""Seed 000's yarn space (Eq. 7-9): coordinates (x, y, s) of a point about a yarn's centre curve,
x along the rotation-minimising normal n(s), y along the binormal b(s), s the arc length of the
closest curve point.

to_yarn_space(cv, c, p)         seed 000 Eq. 8-9: (x, y, s, distance^2)
from_yarn_space(cv, c, x, y, s) seed 000 Eq. 7: x n(s) + y b(s) + alpha(s)
"""
import numpy as np
from numba import njit

from .closest import closest_point_on_curve
from .frames import curve_frame_at


@njit(cache=True)
def to_yarn_space(cv, c, p):
    """seed 000 Eq. 8-9: yarn-space (x, y, z = s) of fabric-space p for curve c, and distance^2."""
    s, d2 = closest_point_on_curve(cv, c, p)
    pos, tan, n, bn = curve_frame_at(cv, c, s)
    r = p - pos
    return np.dot(r, n), np.dot(r, bn), s, d2


@njit(cache=True)
def from_yarn_space(cv, c, x, y, s):
    """seed 000 Eq. 7: f([x, y, s]) = x n(s) + y b(s) + alpha(s)."""
    pos, tan, n, bn = curve_frame_at(cv, c, s)
    return pos + x * n + y * bn
