"""4. Sums of spherical Gaussians (the package doc): per segment the visible solid angle nearest each of
n_sg spherical-Fibonacci axes, turned by a per-segment angle."""

import math

import numpy as np
from numba import njit, prange

from stages.core.rng import uniform
from stages.core.sg import spherical_fibonacci_axes
from stages.core.svf import pixel_solid_angle
from stages.precompute.svf.visibility import direction_table

SG_ANGLE_DIM = 0x5356       # rng dimension of the per-segment SG rotation angle ("SV")


@njit(cache=True)
def sg_angle(seed, segment_id):
    """Rotation angle about z of segment ``segment_id``'s SG axes, as stored (float32)."""
    return np.float32(2.0 * math.pi * uniform(seed, segment_id, SG_ANGLE_DIM))


@njit(cache=True, parallel=True)
def _sg_kernel(packed, seg_ids, seed, R, C, Q, angles, weights):
    D = R * C
    dirs = direction_table(R, C)
    omega = np.empty(R)
    for r in range(R):
        omega[r] = pixel_solid_angle(r, R, C)
    for s in prange(packed.shape[0]):
        a = sg_angle(seed, seg_ids[s])
        angles[s] = a
        axes = spherical_fibonacci_axes(Q, np.float64(a))
        w = np.zeros(Q)
        for i in range(D):
            if (packed[s, i >> 3] >> (7 - (i & 7))) & 1:
                r = i // C
                c = i - r * C
                x = dirs[r, c, 0]
                y = dirs[r, c, 1]
                z = dirs[r, c, 2]
                bq = 0
                bd = -np.inf
                for q in range(Q):
                    dt = x * axes[q, 0] + y * axes[q, 1] + z * axes[q, 2]
                    if dt > bd:
                        bd = dt
                        bq = q
                w[bq] += omega[r]
        for q in range(Q):
            weights[s, q] = w[q]


def sg_fit(packed, seg_ids, res_theta: int, res_phi: int, n_sg: int = 48, seed: int = 0):
    """Chunk level. (angle (S,) float32, weights (S, Q) float32): each segment's sum-of-SGs visibility
    (module doc); ``seg_ids`` (S,) the global segment ids (they key the random rotation)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    seg_ids = np.ascontiguousarray(seg_ids, np.int64).reshape(-1)
    S = packed.shape[0]
    angles = np.zeros(S, np.float32)
    weights = np.zeros((S, int(n_sg)), np.float32)
    if S:
        _sg_kernel(packed, seg_ids, int(seed), res_theta, res_phi, int(n_sg), angles, weights)
    return angles, weights


def sg_axes(angle, n_sg: int = 48):
    """(Q, 3) axes of a segment with stored rotation ``angle`` (float32)."""
    return spherical_fibonacci_axes(int(n_sg), float(np.float32(angle)))
