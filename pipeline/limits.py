"""Accepted ranges of the numbers loomlight reads from files and the command line.

- NaN and inf are refused everywhere (TOML files: ``pipeline.toml_file``; curve files: their readers).
- Coordinates lie within +-``MAX_COORD`` scene units (curve control points, camera, light vectors):
  beyond, float32 positions have lost their digits and the segment grids, frames and tables overflow.
- Lengths (radii, spacings, scales) are finite, positive and at most ``MAX_LENGTH``.
- Light values (irradiance, radiance, power) are at most ``MAX_LIGHT``.

The schemas (``schemas/*.schema.json``) state the same limits; input beyond them is refused with
the limit in the message, never published.
"""
from __future__ import annotations

import math

from .errors import LoomError

MAX_COORD = 1e6
MAX_LENGTH = 1e6
MAX_LIGHT = 1e9


def check_positive(value, place: str, file=None, upper: float = MAX_LENGTH):
    """``value`` when it is finite, > 0 and <= ``upper``, else a LoomError naming ``place``."""
    if value is not None and not (math.isfinite(value) and 0 < value <= upper):
        limit = f"at most {upper:g}" if math.isfinite(upper) else "finite"
        raise LoomError(file, place, f"must be positive and {limit}, got {value}")
    return value


def coordinate_problem(values) -> str | None:
    """Why a row of coordinates is refused (non-finite, or beyond +-MAX_COORD), None when accepted."""
    for v in values:
        if not math.isfinite(v):
            return f"non-finite coordinate {list(values)}"
        if abs(v) > MAX_COORD:
            return f"coordinate {v:g} is beyond +-{MAX_COORD:g} scene units"
    return None


def first_bad_row(points) -> int:
    """Index of the first row of an (n, 3) array with a non-finite or out-of-range coordinate, or -1."""
    import numpy as np

    pts = np.asarray(points, dtype=np.float64)
    bad = ~(np.abs(pts) <= MAX_COORD).all(axis=1)
    return int(np.argmax(bad)) if bad.any() else -1
