"""The 2-D DDA (digital differential analyser) that walks a ray's (x, y) projection through a grid of equal
cells, cell by cell: the shell's block walk (``stages.core.shell.traversal.block_walk``) and the SVF's walk
over whole exemplar periods (``stages.precompute.svf.visibility``).

``dda_axis(lo, hi, width, o, d)``             one axis's (step, t of the first cell boundary, t per cell)
``dda_next(i, j, tmx, tmy, stx, sty, tdx, tdy)``   the cell after (i, j): across the nearer boundary
"""
import numpy as np
from numba import njit


@njit(cache=True)
def dda_axis(lo, hi, width, o, d):
    """(step, t of the first cell boundary, t per cell) along one axis of the ray o + t d starting in the cell
    [lo, hi] of width ``width``: (0, inf, inf) when d = 0."""
    if d > 0.0:
        return 1, (hi - o) / d, width / d
    elif d < 0.0:
        return -1, (lo - o) / d, -width / d
    return 0, np.inf, np.inf


@njit(cache=True)
def dda_next(i, j, tmx, tmy, stx, sty, tdx, tdy):
    """(i, j, tmx, tmy) of the cell after (i, j): across its x boundary where that is the nearer, else its y one."""
    if tmx < tmy:
        i += stx
        tmx += tdx
    else:
        j += sty
        tmy += tdy
    return i, j, tmx, tmy
