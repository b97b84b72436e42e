"""Perspective pinhole camera (Mitsuba 3 conventions).

Parameters
----------
origin, target, up : look-at frame. The image's right axis is normalise(forward x up).
fov : full *horizontal* field of view in degrees.
width, height : image size in pixels. Pixel (i, j) covers [j, j+1) x [i, i+1) of the image
    plane with row i = 0 at the *top*; a box pixel filter integrates over that square.

Packed layout (float64[15]): origin(3), forward(3), right(3), up(3), tan(fov/2), width, height.
"""
import math

import numpy as np
from numba import njit

CAM_SIZE = 15


def pack_camera(origin, target, up, fov_deg, width, height):
    fwd = target - origin
    fwd = fwd / np.linalg.norm(fwd)
    right = np.cross(fwd, up)
    right = right / np.linalg.norm(right)
    cup = np.cross(right, fwd)
    out = np.empty(CAM_SIZE)
    out[0:3] = origin
    out[3:6] = fwd
    out[6:9] = right
    out[9:12] = cup
    out[12] = math.tan(math.radians(fov_deg) * 0.5)
    out[13] = width
    out[14] = height
    return out


@njit(cache=True, fastmath=False)
def camera_ray(cam, row, col, u, v):
    """Ray through image point (col + u, row + v), u, v in [0, 1). Returns (origin, unit direction)."""
    o = np.empty(3)
    d = np.empty(3)
    camera_ray_into(cam, row, col, u, v, o, d)
    return o, d


@njit(cache=True, fastmath=False)
def camera_ray_into(cam, row, col, u, v, o, d):
    """``camera_ray`` writing the origin and unit direction into ``o`` and ``d``."""
    w = cam[13]
    h = cam[14]
    t = cam[12]
    sx = (2.0 * (col + u) / w - 1.0) * t
    sy = (1.0 - 2.0 * (row + v) / h) * t * h / w
    for k in range(3):
        d[k] = cam[3 + k] + sx * cam[6 + k] + sy * cam[9 + k]
    n = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    for k in range(3):
        d[k] /= n
        o[k] = cam[k]


@njit(cache=True)
def project_to_pixel(cam, p):
    """Inverse of ``camera_ray``: (col, row) image coordinates of world point p, and depth along forward."""
    d0 = p[0] - cam[0]
    d1 = p[1] - cam[1]
    d2 = p[2] - cam[2]
    z = d0 * cam[3] + d1 * cam[4] + d2 * cam[5]
    x = (d0 * cam[6] + d1 * cam[7] + d2 * cam[8]) / z
    y = (d0 * cam[9] + d1 * cam[10] + d2 * cam[11]) / z
    w = cam[13]
    h = cam[14]
    t = cam[12]
    col = (x / t + 1.0) * 0.5 * w
    row = (1.0 - y / (t * h / w)) * 0.5 * h
    return col, row, z
