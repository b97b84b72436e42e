"""Woven yarn centrelines from an interlacement matrix.

Input: ``over`` (ends, picks) boolean (True where warp end e is over weft pick p, see
``weave.py``), ``spacing_x`` between neighbouring warp ends, ``spacing_y`` between neighbouring
weft picks, yarn radii ``radius_warp`` and ``radius_weft``, ``crimp`` (undulation amplitude in
yarn radii) and ``samples_per_cell`` (s >= 2 control points per thread crossing).

Geometry (fabric space, z-up, centred on the origin): warp end e runs along +y at
x_e = (e - (E-1)/2) spacing_x; weft pick p runs along +x at y_p = (p - (P-1)/2) spacing_y. At the
crossing (e, p) the warp centre is at z = +crimp radius_warp where it is over, -crimp radius_warp
where under; the weft the opposite with its own radius. With crimp = 1 the two centres are
r_warp + r_weft apart in z at every crossing: the yarns touch without interpenetrating there.
Between crossing centres the height follows a half cosine (1 - cos(pi f))/2, so the centreline
is C1 with level tangents over each crossing and flat along floats. Each curve runs half a cell
beyond the first and last crossing (⌊s/2⌋/s cells), sampled every 1/s cell; the coordinate
along the yarn strictly increases, so no two consecutive points coincide. The points serve as
polyline or Catmull-Rom control points.

Returns (warp, weft): arrays (E, Nw, 3) and (P, Nf, 3), float64.
"""
from __future__ import annotations

import numpy as np


def crossing_levels(over: np.ndarray, amplitude: float, warp: bool) -> np.ndarray:
    """Height of each yarn at its crossings: (E, P) for warp, (P, E) for weft."""
    over = np.asarray(over, dtype=bool)
    if warp:
        return np.where(over, amplitude, -amplitude)
    return np.where(over.T, -amplitude, amplitude)


def cosine_profile(levels: np.ndarray, samples_per_cell: int) -> tuple[np.ndarray, np.ndarray]:
    """levels (C, K) at crossing coordinates 0..K-1 -> (q (N,), heights (C, N)), half-cosine blend."""
    s = int(samples_per_cell)
    if s < 2:
        raise ValueError(f"samples_per_cell must be >= 2, got {s}")
    C, K = levels.shape
    h = s // 2
    n = (K - 1) * s + 2 * h + 1
    q = (np.arange(n) - h) / s
    fl = np.floor(q)
    i0 = np.clip(fl.astype(np.int64), 0, K - 1)
    i1 = np.clip(fl.astype(np.int64) + 1, 0, K - 1)
    w = 0.5 * (1.0 - np.cos(np.pi * (q - fl)))
    z = levels[:, i0] + (levels[:, i1] - levels[:, i0]) * w[None, :]
    return q, z


def woven_curves(over: np.ndarray, spacing_x: float, spacing_y: float, radius_warp: float,
                 radius_weft: float, crimp: float = 1.0, samples_per_cell: int = 6):
    over = np.asarray(over, dtype=bool)
    if over.ndim != 2 or over.size == 0:
        raise ValueError(f"interlacement matrix must be 2-D and non-empty, got shape {over.shape}")
    if spacing_x <= 0 or spacing_y <= 0 or radius_warp <= 0 or radius_weft <= 0 or crimp < 0:
        raise ValueError("spacings and radii must be positive, crimp non-negative")
    E, P = over.shape
    xs = (np.arange(E) - (E - 1) / 2.0) * spacing_x
    ys = (np.arange(P) - (P - 1) / 2.0) * spacing_y

    q, zw = cosine_profile(crossing_levels(over, crimp * radius_warp, True), samples_per_cell)
    warp = np.empty((E, len(q), 3))
    warp[:, :, 0] = xs[:, None]
    warp[:, :, 1] = (q - (P - 1) / 2.0)[None, :] * spacing_y
    warp[:, :, 2] = zw

    q, zf = cosine_profile(crossing_levels(over, crimp * radius_weft, False), samples_per_cell)
    weft = np.empty((P, len(q), 3))
    weft[:, :, 0] = (q - (E - 1) / 2.0)[None, :] * spacing_x
    weft[:, :, 1] = ys[:, None]
    weft[:, :, 2] = zf
    return warp, weft


def crossing_index(samples_per_cell: int, k: int) -> int:
    """Index of the control point that lies over crossing k along a yarn."""
    return samples_per_cell // 2 + k * samples_per_cell
