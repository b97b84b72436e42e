"""Tiling: blocks laid over the cloth's (u, v) domain (seed 001 §2, §6.4).

The cloth's flat domain is a grid of ``nbu`` x ``nbv`` blocks of size (bw, bh) (``block_grid``: a repeat
count of exemplar 0 times its blocks per side); u in [0, 1] spans nbu bw, v spans nbv bh. Block (i, j)
shows block (i mod nbx_k, j mod nby_k) of the exemplar k = block_map[i, j] chosen for it (one exemplar
everywhere for a regular weave; an integer image for patterned cloth such as damask, §6.4).

``resample_block_map(img, nbu, nbv)``: an integer image (rows top to bottom = v from 1 down to 0,
columns = u from 0 to 1) sampled at block centres (nearest), returned as (nbu, nbv) indexed [i, j].
"""
from __future__ import annotations

import numpy as np


def block_grid(repeat, ex_nblocks):
    """(nbu, nbv) blocks over the cloth: ``repeat`` copies of an exemplar of ``ex_nblocks`` blocks."""
    return int(repeat[0]) * int(ex_nblocks[0]), int(repeat[1]) * int(ex_nblocks[1])


def resample_block_map(img, nbu, nbv):
    img = np.asarray(img)
    R, C = img.shape
    cols = np.minimum(((np.arange(nbu) + 0.5) * C / nbu).astype(np.int64), C - 1)
    rows = R - 1 - np.minimum(((np.arange(nbv) + 0.5) * R / nbv).astype(np.int64), R - 1)
    return np.ascontiguousarray(img[rows][:, cols].T.astype(np.int32))
