"""Acquisition of a repeat's radiance samples (stages/precompute/btf.py, seed 002 §4).

References: a brute-force coverage test for vertical rays (a vertical line meets a capsule iff the
distance in the xy plane from the line to the segment's projection is at most its radius), over every
fibre segment of the exemplar and its 3 x 3 periodic copies, at the very points the acquisition casts
(the same counter-based random numbers): alpha is that fraction exactly, and a texel whose rays all miss
(a hole of the loose tiny weave) returns alpha 0 and zero radiance; the light grid's own reciprocity is
not assumed. Determinism: the same bytes at 1 and 2 threads.
"""
import numba
import numpy as np
import pytest

from stages.core.rng import uniform
from stages.precompute.btf import acquire_texels, texel_frames
from stages.precompute.iirtf import exemplar_slabs
from stages.precompute.periodic import periodic_scene

RES = 16
SPP = 2


def _segments_2d(art, k):
    """(a (S, 2), b (S, 2), r (S,)) of exemplar k's fibre segments projected on xy."""
    f0, f1 = int(art["ex_fibers"][k]), int(art["ex_fibers"][k + 1])
    off = art["ex_offsets"]
    P = art["ex_points"]
    R = art["ex_radius"]
    a, b, r = [], [], []
    for f in range(f0, f1):
        i0, i1 = int(off[f]), int(off[f + 1])
        a.append(P[i0:i1 - 1, :2])
        b.append(P[i0 + 1:i1, :2])
        r.append(np.maximum(R[i0:i1 - 1], R[i0 + 1:i1]))
    return np.concatenate(a), np.concatenate(b), np.concatenate(r)


def _covered(x, y, a, b, r, W, H):
    best = np.inf
    for sx in (-W, 0.0, W):
        for sy in (-H, 0.0, H):
            p = np.array([x - sx, y - sy])
            d = b - a
            t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0, 1)
            q = a + t[:, None] * d
            best = min(best, float(np.min(np.linalg.norm(p - q, axis=1) - r)))
    return best


@pytest.fixture(scope="module")
def acquired(tiny_tiling):
    from pipeline.runners.precompute import tiling_materials
    from pipeline.scene import load_scene
    from tests.helpers import ROOT

    path, sc, art = tiny_tiling
    k = 0
    slab = exemplar_slabs(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"])[k]
    W, H = (float(v) for v in art["ex_period"][k])
    mof, mats = tiling_materials(load_scene(ROOT / "data/scenes/flat_satin.toml"), art, {"tint": "yarn"})
    views = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    lights = np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [-0.8, 0.0, 0.6]])
    args = (periodic_scene(sc, k), float(slab[0]), float(slab[1]), W, H, mof, mats, RES, 0, RES * RES, views, lights,
            SPP, 5, 6, 3, 64.0 * max(W, H), 1e-9)
    return art, k, W, H, args


def test_alpha_is_the_brute_force_coverage_and_holes_are_empty(acquired):
    art, k, W, H, args = acquired
    rad, alpha, nsum, rays = acquire_texels(*args)
    a, b, r = _segments_2d(art, k)
    seed = args[13]
    holes = 0
    for texel in range(RES * RES):
        iy, ix = divmod(texel, RES)
        key0 = (texel * 2 + 0) * SPP          # view 0: straight down
        hits = 0
        rims = 0
        for s in range(SPP):
            x = (ix + uniform(seed, key0 + s, 0)) * W / RES
            y = (iy + uniform(seed, key0 + s, 1)) * H / RES
            m = _covered(x, y, a, b, r, W, H)
            if abs(m) < 1e-9 * W:            # grazing a capsule's rim: either answer is right
                rims += 1
            else:
                hits += m < 0
        assert hits / SPP - 1e-12 <= alpha[texel, 0] <= (hits + rims) / SPP + 1e-12, texel
        if hits + rims == 0:
            holes += 1
            assert np.all(rad[texel, 0] == 0.0)
    assert holes > 0, "the tiny weave should leave holes seen straight down"
    assert np.all(alpha >= 0) and np.all(alpha <= 1) and np.all(np.isfinite(rad)) and np.all(rad >= 0)
    frames = texel_frames(nsum)
    assert np.allclose(np.linalg.norm(frames, axis=2), 1.0) and np.allclose(np.einsum("ij,ij->i", frames[:, 0],
                                                                                       frames[:, 1]), 0, atol=1e-9)


def test_same_bytes_at_1_and_2_threads(acquired):
    *_, args = acquired
    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = acquire_texels(*args)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = acquire_texels(*args)
    finally:
        numba.set_num_threads(n)
    for x, y in zip(one, two):
        assert np.array_equal(x, y)
