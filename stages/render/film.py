"""Film: image tiles and per-pixel accumulation with a box filter.

Pixel (i, j) covers [j, j+1) x [i, i+1) of the image plane (row 0 at the top); a sample at a uniform
position inside the square with weight 1 is the box pixel filter, so a pixel's value is the mean of
its samples.

Tiles: ``tile_grid(width, height, size)`` -> int64 (T, 4) rows (row0, col0, row1, col1), row-major.
The tile loop (``stages.render.tiles``) renders each tile independently: a pixel's random numbers
come from its own index, so the image does not depend on how tiles are spread over threads.

Accumulation: ``new_film(width, height)`` -> float64 (H, W, FILM_CHANNELS), per pixel the sums over
its samples of (in channel order) R, G, B; R^2, G^2, B^2; luminance Y = 0.2126 R + 0.7152 G +
0.0722 B and Y^2; hit (1 when the camera ray met the scene); the distance to the first
interaction; medium lookups; rays.

``finalize(film, counts, variance)`` -> ``FilmImage``: ``rgb`` (H, W, 3) the mean, ``alpha`` the fraction
of samples that hit, ``depth`` the mean first-interaction distance over those samples (0 where none),
``variance`` the variance of the pixel mean (sample variance / n), all float32, and the totals
``lookups`` and ``rays``; ``counts`` is the number of samples n of every pixel (an int or an (H, W)
array). ``variance`` selects the estimator of the variance channel:
``VARIANCE_LUMINANCE`` (of the luminance; volpath) or ``VARIANCE_CHANNELS`` (each channel's, averaged
over R, G, B; fiberpath). The two methods wrote these before they shared a film and their images
stay byte-identical; one estimator for both is a change of outputs left to a later issue.
"""
from collections import namedtuple

import numpy as np
from numba import njit

FILM_CHANNELS = 12
F_R, F_G, F_B, F_RR, F_GG, F_BB, F_Y, F_YY, F_HIT, F_DEPTH, F_LOOKUPS, F_RAYS = range(FILM_CHANNELS)
VARIANCE_LUMINANCE = "luminance"
VARIANCE_CHANNELS = "channels"

FilmImage = namedtuple("FilmImage", ["rgb", "alpha", "depth", "variance", "lookups", "rays"])


def tile_grid(width, height, size):
    tiles = []
    for r0 in range(0, height, size):
        for c0 in range(0, width, size):
            tiles.append((r0, c0, min(r0 + size, height), min(c0 + size, width)))
    return np.asarray(tiles, dtype=np.int64).reshape(-1, 4)


def new_film(width, height):
    return np.zeros((height, width, FILM_CHANNELS))


@njit(cache=True, inline="always")
def add_pixel(film, row, col, sr, sg, sb, srr, sgg, sbb, sy, syy, sh, sd, sl, sn):
    """Store one pixel's sums (the tile loop adds its samples in order, then stores).
    15 parameters: the film and pixel, then the pixel's twelve running sums, which the tile loop keeps in
    registers."""
    film[row, col, F_R] = sr
    film[row, col, F_G] = sg
    film[row, col, F_B] = sb
    film[row, col, F_RR] = srr
    film[row, col, F_GG] = sgg
    film[row, col, F_BB] = sbb
    film[row, col, F_Y] = sy
    film[row, col, F_YY] = syy
    film[row, col, F_HIT] = sh
    film[row, col, F_DEPTH] = sd
    film[row, col, F_LOOKUPS] = sl
    film[row, col, F_RAYS] = sn


def finalize(film, counts, variance=VARIANCE_CHANNELS) -> FilmImage:
    n = np.broadcast_to(np.asarray(counts, np.float64), film.shape[:2])
    n3 = n[..., None]
    rgb = film[..., F_R:F_B + 1] / n3
    hits = film[..., F_HIT]
    if variance == VARIANCE_LUMINANCE:
        mean = film[..., F_Y] / n
        var = np.where(n > 1, np.maximum(film[..., F_YY] / n - mean * mean, 0.0) / np.maximum(n - 1, 1), 0.0)
    elif variance == VARIANCE_CHANNELS:
        var = (np.maximum(film[..., F_RR:F_BB + 1] / n3 - rgb * rgb, 0.0) * (n3 / np.maximum(n3 - 1, 1))
               / n3).mean(axis=2)
    else:
        raise ValueError(f"unknown variance estimator {variance!r}")
    depth = np.where(hits > 0, film[..., F_DEPTH] / np.maximum(hits, 1), 0.0)
    return FilmImage(rgb.astype(np.float32), (hits / n).astype(np.float32), depth.astype(np.float32),
                     var.astype(np.float32), int(film[..., F_LOOKUPS].sum()), int(film[..., F_RAYS].sum()))
