"""Tiling (stages/tile/tiling.py): block grid and block-map resampling, on hand-made inputs.

References: the block count by hand (repeat x blocks per exemplar); the nearest-pixel lookup at block
centres written out pixel by pixel (rows top to bottom = v from 1 down to 0, columns = u from 0 to 1).
"""
import numpy as np

from stages.tile.tiling import block_grid, resample_block_map


def test_block_grid():
    """Reference: 3 x 2 repeats of an exemplar of 4 x 5 blocks is 12 x 10 blocks."""
    assert block_grid((3, 2), (4, 5)) == (12, 10)
    assert block_grid((1, 1), (1, 1)) == (1, 1)


def test_resample_block_map_same_size_is_a_flip_and_transpose():
    """Reference: a 2 x 3 image (R = 2 rows, C = 3 columns) at 3 x 2 blocks: block (i, j) reads column i
    and row R - 1 - j (row 0 is the top, v = 1)."""
    img = np.array([[1, 2, 3],
                    [4, 5, 6]])
    m = resample_block_map(img, 3, 2)
    assert m.dtype == np.int32 and m.shape == (3, 2)
    np.testing.assert_array_equal(m, [[4, 1], [5, 2], [6, 3]])


def test_resample_block_map_nearest_at_block_centres():
    """Reference: brute force per block: the pixel containing the block centre (u, v) = ((i + 1/2) / nbu,
    (j + 1/2) / nbv), column floor(u C), row floor((1 - v) R); for finer and coarser block grids."""
    rng = np.random.default_rng(0)
    img = rng.integers(0, 7, (5, 7))
    for nbu, nbv in ((14, 10), (3, 2), (7, 5), (9, 13)):
        m = resample_block_map(img, nbu, nbv)
        for i in range(nbu):
            for j in range(nbv):
                u, v = (i + 0.5) / nbu, (j + 0.5) / nbv
                assert m[i, j] == img[int((1.0 - v) * 5), int(u * 7)], (nbu, nbv, i, j)
