"""Film: image tiles for parallel rendering and per-pixel accumulation with a box filter.

Pixel (i, j) covers [j, j+1) x [i, i+1) of the image plane (row 0 at the top); a sample at a uniform
position inside the square with weight 1 is the box pixel filter, so a pixel's value is the mean of
its samples. Per pixel the film keeps the sum and the sum of squares of the sample radiance (RGB), so
``finalize`` returns the mean and the variance *of the mean* (sample variance / n), which renders write
as an optional EXR channel.

Tiles: ``tile_grid(width, height, size)`` -> int64 (T, 4) rows (row0, col0, row1, col1), row-major.
Integrators render tile t of a ``prange`` over tiles: each pixel's random numbers come from its own
index, so the image does not depend on how tiles are spread over threads.
"""
import numpy as np
from numba import njit


def tile_grid(width, height, size):
    tiles = []
    for r0 in range(0, height, size):
        for c0 in range(0, width, size):
            tiles.append((r0, c0, min(r0 + size, height), min(c0 + size, width)))
    return np.asarray(tiles, dtype=np.int64).reshape(-1, 4)


@njit(cache=True)
def add_sample(film_sum, film_sq, row, col, r, g, b):
    film_sum[row, col, 0] += r
    film_sum[row, col, 1] += g
    film_sum[row, col, 2] += b
    film_sq[row, col, 0] += r * r
    film_sq[row, col, 1] += g * g
    film_sq[row, col, 2] += b * b


def finalize(film_sum, film_sq, n):
    """(mean RGB float32 (H, W, 3), variance of the mean float32 (H, W), luminance-averaged)."""
    mean = film_sum / n
    var = np.maximum(film_sq / n - mean * mean, 0.0) * (n / max(n - 1, 1)) / n
    return mean.astype(np.float32), var.mean(axis=2).astype(np.float32)
