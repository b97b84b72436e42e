"""The block map of a tiling (seed 001 §5.1, ``stages.tile``): which exemplar covers each block of the flat fabric.

The tile stage divides the flat fabric into blocks of ``block_size`` and writes, per block (i, j), the
exemplar it shows (-1: none); the map repeats periodically beyond its nbu x nbv blocks. Both the tile
stage (``stages.tile.mapping.flat_to_exemplar``: a flat point into its exemplar's space) and the ``btf``
renderer (``stages.render.integrators.btf``: which exemplar's texture a texel of the cloth reads) ask the
same question of a flat point, here.
"""
import math

from numba import njit


@njit(cache=True)
def block_of(x, y, block_size, nbu, nbv):
    """Block (i, j) of a flat point, wrapped periodically over the nbu x nbv block map, and the unwrapped
    block (ri, rj)."""
    i = int(math.floor(x / block_size[0]))
    j = int(math.floor(y / block_size[1]))
    return i % nbu, j % nbv, i, j
