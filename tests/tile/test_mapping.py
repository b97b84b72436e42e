"""Maps between world, shell texture coordinates and flat / exemplar space (stages/tile/mapping.py),
called directly.

References: the per-tetrahedron affine maps take world vertices onto flat vertices and invert each other
(round trip); barycentric coordinates carry over (a world point and its flat image have the same ones);
flat -> (u, v, w) by the shell's own uvw of the vertices; ``flat_to_exemplar`` against a brute-force
search over periodic copies of the block map and exemplar blocks.
"""
import math

import numpy as np
import pytest

from stages.tile.base_surfaces import cylinder, vertex_normals
from stages.tile.mapping import block_of, flat_to_exemplar, flat_to_uvw, flat_to_world, world_to_flat
from stages.tile.shell import build_shell

FLAT = np.array([3.0, 2.0])
THICK = 0.25


@pytest.fixture(scope="module")
def shell():
    V, UV, F = cylinder(1.0, 1.5, 140.0, 8, 3)
    return build_shell(V, UV, F, vertex_normals(V, F), 0.15, FLAT, flat_thickness=THICK)


def test_vertices_map_to_vertices_and_back(shell):
    """Reference: w2f(P_i) = Q_i and f2w(Q_i) = P_i at the four vertices of every tetrahedron; flat_to_uvw
    of a flat vertex is its shell texture coordinate (u, v, w)."""
    X, Q, tets = shell["vertices"], shell["flat"], shell["tets"]
    for t in range(len(tets)):
        for i in tets[t]:
            np.testing.assert_allclose(world_to_flat(shell["w2f"], t, X[i]), Q[i], atol=1e-12)
            np.testing.assert_allclose(flat_to_world(shell["f2w"], t, Q[i]), X[i], atol=1e-12)
            np.testing.assert_allclose(flat_to_uvw(Q[i], FLAT, THICK), shell["uvw"][i], atol=1e-12)


def test_round_trip_keeps_barycentric_coordinates(shell):
    """Reference: random points of each tetrahedron (barycentric b): world -> flat gives the flat point with
    the same b, and flat -> world returns the world point (1e-12)."""
    X, Q, tets = shell["vertices"], shell["flat"], shell["tets"]
    rng = np.random.default_rng(1)
    for t in range(len(tets)):
        for b in rng.dirichlet(np.ones(4), 4):
            x = b @ X[tets[t]]
            q = np.array(world_to_flat(shell["w2f"], t, x))
            np.testing.assert_allclose(q, b @ Q[tets[t]], atol=1e-12)
            np.testing.assert_allclose(flat_to_world(shell["f2w"], t, q), x, atol=1e-12)


def _brute_exemplar(q, bs, block_map, ex_nblocks):
    """Search: the block (I, J) of the infinite plane containing q, its map entry by periodic copy
    (I - a nbu in range), and the point moved by whole exemplar periods into [0, W_k) x [0, H_k)."""
    nbu, nbv = block_map.shape
    I = next(i for i in range(-50, 50) if i * bs[0] <= q[0] < (i + 1) * bs[0])
    J = next(j for j in range(-50, 50) if j * bs[1] <= q[1] < (j + 1) * bs[1])
    i = next(i for i in range(nbu) if (I - i) % nbu == 0)
    j = next(j for j in range(nbv) if (J - j) % nbv == 0)
    k = int(block_map[i, j])
    if k < 0:
        return -1, q[0], q[1], q[2]
    W, H = ex_nblocks[k] * bs
    a = next(a for a in range(-50, 50) if 0 <= q[0] - a * W < W)
    b = next(b for b in range(-50, 50) if 0 <= q[1] - b * H < H)
    return k, q[0] - a * W, q[1] - b * H, q[2]


def test_flat_to_exemplar_against_brute_force():
    """Reference: brute-force search (above) on 2000 random points over three periods of a 6 x 4 block map
    of exemplars with 3 x 2, 2 x 4 and 1 x 1 blocks (and a hole, -1); the periodicity over the block map
    (a shift by (nbu bw, nbv bh) gives the same answer where the exemplars tile the map)."""
    bs = np.array([0.3, 0.2])
    block_map = np.array([[0, 0, 1, 1], [0, 0, 1, 1], [0, 0, 2, -1]] * 2, np.int32)
    ex_nblocks = np.array([[3, 2], [2, 4], [1, 1]], np.int64)
    rng = np.random.default_rng(2)
    P = np.c_[rng.uniform(-6 * 0.3, 12 * 0.3, 2000), rng.uniform(-4 * 0.2, 8 * 0.2, 2000), rng.uniform(0, 1, 2000)]
    for q in P:
        got = flat_to_exemplar(q, bs, block_map, ex_nblocks)
        want = _brute_exemplar(q, bs, block_map, ex_nblocks)
        assert got[0] == want[0]
        np.testing.assert_allclose(got[1:], want[1:], atol=1e-12)
        shifted = flat_to_exemplar(q + [6 * 0.3, 4 * 0.2, 0.0], bs, block_map, ex_nblocks)
        assert shifted[0] == got[0]
        if got[0] >= 0:  # in a hole the point comes back unchanged
            np.testing.assert_allclose(shifted[1:], got[1:], atol=1e-12)
        i, j, ri, rj = block_of(q[0], q[1], bs, 6, 4)
        assert (ri, rj) == (math.floor(q[0] / 0.3), math.floor(q[1] / 0.2)) and (i, j) == (ri % 6, rj % 4)
