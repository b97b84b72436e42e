"""Perspective pinhole camera (Mitsuba 3 conventions).

Parameters
----------
origin, target, up : look-at frame. The image's right axis is normalise(forward x up).
fov : full *horizontal* field of view in degrees.
width, height : image size in pixels. Pixel (i, j) covers [j, j+1) x [i, i+1) of the image
    plane with row i = 0 at the *top*; a box pixel filter integrates over that square.

Packed layout (float64[CAM_SIZE]), read by name: origin(3) at ``CAM_ORIGIN``, forward(3) at ``CAM_FORWARD``,
right(3) at ``CAM_RIGHT``, up(3) at ``CAM_UP``, tan(fov/2) ``CAM_TAN_HALF_FOV``, width ``CAM_WIDTH``, height
``CAM_HEIGHT``.
"""
import math

import numpy as np
from numba import njit

CAM_ORIGIN = 0
CAM_FORWARD = 3
CAM_RIGHT = 6
CAM_UP = 9
CAM_TAN_HALF_FOV = 12
CAM_WIDTH = 13
CAM_HEIGHT = 14
CAM_SIZE = 15


def pack_camera(origin, target, up, fov_deg, width, height):
    fwd = target - origin
    fwd = fwd / np.linalg.norm(fwd)
    right = np.cross(fwd, up)
    right = right / np.linalg.norm(right)
    cup = np.cross(right, fwd)
    out = np.empty(CAM_SIZE)
    out[CAM_ORIGIN:CAM_ORIGIN + 3] = origin
    out[CAM_FORWARD:CAM_FORWARD + 3] = fwd
    out[CAM_RIGHT:CAM_RIGHT + 3] = right
    out[CAM_UP:CAM_UP + 3] = cup
    out[CAM_TAN_HALF_FOV] = math.tan(math.radians(fov_deg) * 0.5)
    out[CAM_WIDTH] = width
    out[CAM_HEIGHT] = height
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
    w = cam[CAM_WIDTH]
    h = cam[CAM_HEIGHT]
    t = cam[CAM_TAN_HALF_FOV]
    sx = (2.0 * (col + u) / w - 1.0) * t
    sy = (1.0 - 2.0 * (row + v) / h) * t * h / w
    for k in range(3):
        d[k] = cam[CAM_FORWARD + k] + sx * cam[CAM_RIGHT + k] + sy * cam[CAM_UP + k]
    n = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    for k in range(3):
        d[k] /= n
        o[k] = cam[CAM_ORIGIN + k]


@njit(cache=True)
def project_to_pixel(cam, p):
    """Inverse of ``camera_ray``: (col, row) image coordinates of world point p, and depth along forward."""
    d0 = p[0] - cam[CAM_ORIGIN]
    d1 = p[1] - cam[CAM_ORIGIN + 1]
    d2 = p[2] - cam[CAM_ORIGIN + 2]
    z = d0 * cam[CAM_FORWARD] + d1 * cam[CAM_FORWARD + 1] + d2 * cam[CAM_FORWARD + 2]
    x = (d0 * cam[CAM_RIGHT] + d1 * cam[CAM_RIGHT + 1] + d2 * cam[CAM_RIGHT + 2]) / z
    y = (d0 * cam[CAM_UP] + d1 * cam[CAM_UP + 1] + d2 * cam[CAM_UP + 2]) / z
    w = cam[CAM_WIDTH]
    h = cam[CAM_HEIGHT]
    t = cam[CAM_TAN_HALF_FOV]
    col = (x / t + 1.0) * 0.5 * w
    row = (1.0 - y / (t * h / w)) * 0.5 * h
    return col, row, z
