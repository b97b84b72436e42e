"""Half-vector light cells of the btf table (``stages.core.btf``, module doc "Half-vector light cells").

References: the cell's centre seen from a view is a grid point of the bilinear weights (exact); the cells'
solid angles against light directions binned by their half vector (an independent count); a table that is the
same radiance c in every cell, written as the acquisition writes it (cell averages with the invalid part 0),
reads back c at every direction with light (float precision) and integrates to 2 pi c under a constant sky.
"""
import math

import numpy as np
import pytest

from stages.core.btf import (
    MIN_VALID,
    cell_direction,
    half_cell_direction,
    half_cell_geometry,
    half_grid,
    half_rgb,
    half_to_hemisphere,
    half_weights,
    hemisphere_grid,
)

NX, NY = 7, 9           # not square: rows and columns cannot be swapped unnoticed
VIEW_GRID = (4, 6)


def test_cell_centres_are_the_weights_grid_points():
    """Every valid cell's centre light, seen from a view, gets weight 1 on that cell (bilinear weights at a grid
    point), and the light is a unit vector mirrored about the cell's centre half vector (``half_grid``)."""
    views = hemisphere_grid(*VIEW_GRID)
    centres = half_grid(NX, NY)
    seen = 0
    for v in views:
        for j in range(NX * NY):
            lx, ly, lz = half_cell_direction(j, NX, NY, 0.5, 0.5, *v)
            if lz <= 0.0:
                continue
            seen += 1
            assert math.isclose(lx * lx + ly * ly + lz * lz, 1.0, rel_tol=1e-12)
            h = np.array([lx, ly, lz]) + v
            assert np.allclose(h / np.linalg.norm(h), centres[j], atol=1e-12)
            idx = half_weights(NX, NY, lx, ly, lz, *v)
            w = dict()
            for i, wi in zip(idx[:4], idx[4:]):
                w[i] = w.get(i, 0.0) + wi
            assert w[j] == pytest.approx(1.0, abs=1e-9)
    assert seen > len(views) * NX * NY * 0.25


@pytest.mark.parametrize("jitter", [False, True])
def test_cell_solid_angles_against_binned_lights(jitter):
    """Each view's cells partition its hemisphere (sum 2 pi); the cells wholly inside the valid region hold the solid
    angle of an equal-area grid of 131,072 light directions binned by their half vector's cell (the binning's own
    resolution: a few hundred directions a cell, 3 %); the cells the valid fractions call empty hold under 1 % of the
    binned lights, and the rows differ by under 5 % of 2 pi in all (the rim cells, where 1 / h_z is singular)."""
    valid, solid = half_cell_geometry(*VIEW_GRID, NX, NY, jitter)
    assert np.allclose(solid.sum(axis=1), 2 * math.pi, rtol=1e-12)
    assert np.all((valid >= 0) & (valid <= 1 + 1e-12))
    lights = hemisphere_grid(256, 512)
    ix, iy = np.arange(NX * NY) % NX, np.arange(NX * NY) // NX
    corner = np.hypot(np.maximum(np.abs(-1 + 2 * ix / NX), np.abs(-1 + 2 * (ix + 1) / NX)),
                      np.maximum(np.abs(-1 + 2 * iy / NY), np.abs(-1 + 2 * (iy + 1) / NY)))   # farthest corner's |h|
    for iv in range(VIEW_GRID[0] * VIEW_GRID[1]):
        if jitter:
            sub = [cell_direction(iv, *VIEW_GRID, (a + 0.5) / 4, (b + 0.5) / 4) for a in range(4) for b in range(4)]
        else:
            sub = [cell_direction(iv, *VIEW_GRID, 0.5, 0.5)]
        binned = np.zeros(NX * NY)
        for v in sub:
            h = lights + np.asarray(v)
            h /= np.linalg.norm(h, axis=1)[:, None]
            cx = np.minimum(((h[:, 0] + 1) * 0.5 * NX).astype(int), NX - 1)
            cy = np.minimum(((h[:, 1] + 1) * 0.5 * NY).astype(int), NY - 1)
            binned += np.bincount(cy * NX + cx, minlength=NX * NY) * 2 * math.pi / len(lights) / len(sub)
        inner = (valid[iv] > 0.999) & (corner < 0.9)     # wholly valid, away from the unit circle's singularity
        assert inner.sum() >= 4
        assert np.allclose(solid[iv, inner], binned[inner], rtol=0.03)
        assert binned[valid[iv] == 0].sum() < 0.01 * 2 * math.pi   # slivers the 8 x 8 points of a cell miss
        assert np.abs(solid[iv] - binned).sum() < 0.05 * 2 * math.pi   # the rim cells' rule, all cells together


def _constant_table(c, jitter):
    """One texel's table of radiance c wherever there is light, as the acquisition averages it (valid fraction x c)."""
    valid, solid = half_cell_geometry(*VIEW_GRID, NX, NY, jitter)
    return (valid[None, :, :, None] * np.asarray(c)[None, None, None, :]).astype(np.float32), valid, solid


def test_constant_table_reads_back_everywhere_and_integrates_to_2pi():
    """A table of the same radiance c in every cell reads back c (float32) at every (l, v) with light -- grazing ones
    included, where the cells are cut by the horizon -- and 0 below the fabric; its sky sum (solid angle over valid
    fraction, per view) is 2 pi c; read on a hemisphere grid from the grid views (the Lafortune fit's input) it is
    c everywhere."""
    c = np.array([0.3, 0.5, 0.7])
    table, valid, solid = _constant_table(c, True)
    rng = np.random.default_rng(3)
    for _ in range(400):
        v = rng.normal(size=3)
        v[2] = abs(v[2])
        l = rng.normal(size=3)
        l[2] = abs(l[2])
        v /= np.linalg.norm(v)
        l /= np.linalg.norm(l)
        got = half_rgb(table, valid, 0, NX, NY, *l, *VIEW_GRID, *v)
        assert np.allclose(got, c, rtol=1e-6), (l, v, got)
    assert half_rgb(table, valid, 0, NX, NY, 0.3, 0.2, -0.1, *VIEW_GRID, 0.0, 0.0, 1.0) == (0.0, 0.0, 0.0)
    w = np.where(valid >= MIN_VALID, solid / np.maximum(valid, MIN_VALID), 0.0)
    assert np.allclose(np.einsum("vl,vlc->vc", w, table[0].astype(np.float64)), 2 * math.pi * c, rtol=1e-6)
    fit = half_to_hemisphere(table, valid, NX, NY, hemisphere_grid(*VIEW_GRID), hemisphere_grid(8, 8))
    assert np.allclose(fit, c, rtol=1e-6)
