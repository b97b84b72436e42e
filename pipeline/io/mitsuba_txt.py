"""Mitsuba 3 curve text: realized fibres as ``x y z r`` lines, a blank line between curves.

``write_mitsuba_txt(path, pts, rad, off)`` writes every control point of the polylines
``pts[off[f]:off[f + 1]]`` with its radius, 9 significant digits each (``loomlight export``).
"""
from __future__ import annotations


def write_mitsuba_txt(path, pts, rad, off):
    """Mitsuba 3 curve text: one 'x y z r' line per control point, a blank line between curves."""
    import numpy as np

    rows = np.concatenate([pts.astype(np.float64), rad.astype(np.float64)[:, None]], axis=1)
    lines = [" ".join(f"{v:.9g}" for v in row) for row in rows.tolist()]
    ends = set((off[1:] - 1).tolist())
    with open(path, "w") as f:
        for i, line in enumerate(lines):
            f.write(line)
            f.write("\n")
            if i in ends and i != len(lines) - 1:
                f.write("\n")
