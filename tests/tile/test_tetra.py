"""Shell prisms as tetrahedra (stages/tile/tetra.py), called directly on small meshes.

References: the volume of a right prism (base area x height) and brute-force point location (every point
of a prism lies in exactly one of its tetrahedra); face matching by brute force over all face pairs
(neighbour table); the affine maps' defining property (vertices onto vertices) and their round trip.
"""
import itertools

import numpy as np

from stages.tile.base_surfaces import flat_rectangle
from stages.tile.tetra import orient_positive, signed_volumes, split_prisms, tet_geometry, tet_neighbours


def _mesh():
    """A 3 x 2 flat grid with jittered interior vertices and scrambled triangle vertex order, so the split
    sees every sorting case; the prisms are right prisms of height 0.3."""
    V, UV, F = flat_rectangle(3.0, 2.0, 3, 2)
    rng = np.random.default_rng(2)
    inner = (V[:, 0] > 0) & (V[:, 0] < 3) & (V[:, 1] > 0) & (V[:, 1] < 2)
    V[inner, :2] += rng.uniform(-0.2, 0.2, (inner.sum(), 2))
    F = np.array([np.roll(f, k) for f, k in zip(F, rng.integers(0, 3, len(F)))])
    F[::3] = F[::3, ::-1]  # some clockwise
    X = np.concatenate([V, V + [0.0, 0.0, 0.3]])
    return V, F, X


def _barycentric(P, x):
    """Barycentric coordinates of x in tetrahedron P (4, 3)."""
    M = np.column_stack([P[1] - P[0], P[2] - P[0], P[3] - P[0]])
    l123 = np.linalg.solve(M, x - P[0])
    return np.concatenate([[1.0 - l123.sum()], l123])


def test_split_covers_each_prism_exactly():
    """Reference: sum of |tet volumes| of a prism == triangle area x 0.3 (right prism); 200 random points
    of each prism lie in exactly one of its three tetrahedra (brute force over barycentric coordinates)."""
    V, F, X = _mesh()
    n = len(V)
    tets = split_prisms(F, n)
    assert tets.shape == (3 * len(F), 4)
    vol = np.abs(signed_volumes(X, tets)).reshape(-1, 3)
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    np.testing.assert_allclose(vol.sum(axis=1), area * 0.3, rtol=1e-12)
    assert np.all(vol > 1e-6)  # no degenerate tetrahedron
    rng = np.random.default_rng(3)
    for m, f in enumerate(F):
        b = rng.dirichlet(np.ones(3), 200)
        h = rng.uniform(0.0, 0.3, 200)
        pts = b @ V[f] + np.outer(h, [0.0, 0.0, 1.0])
        for x in pts:
            inside = [np.all(_barycentric(X[tets[3 * m + k]], x) >= -1e-12) for k in range(3)]
            assert sum(inside) >= 1
            # on a shared internal face a point may touch two; strictly inside, one
            strict = [np.all(_barycentric(X[tets[3 * m + k]], x) > 1e-9) for k in range(3)]
            assert sum(strict) <= 1


def test_orientation_and_neighbours_are_consistent():
    """Reference: after orient_positive every signed volume is > 0 with the same vertex sets; the neighbour
    table equals brute-force matching of all face pairs, and is symmetric (t -> s across a face, s -> t
    across the same face)."""
    V, F, X = _mesh()
    tets = orient_positive(X, split_prisms(F, len(V)))
    assert np.all(signed_volumes(X, tets) > 0)
    np.testing.assert_array_equal(np.sort(tets, axis=1), np.sort(split_prisms(F, len(V)), axis=1))
    nbr = tet_neighbours(tets)
    faces = {}
    for t, i in itertools.product(range(len(tets)), range(4)):
        faces.setdefault(frozenset(np.delete(tets[t], i)), []).append((t, i))
    assert max(len(v) for v in faces.values()) <= 2  # conforming: a face is shared by at most two
    for owners in faces.values():
        if len(owners) == 1:
            t, i = owners[0]
            assert nbr[t, i] == -1
        else:
            (t, i), (s, j) = owners
            assert nbr[t, i] == s and nbr[s, j] == t
    # boundary: bottom and top triangle of every prism, two triangles per boundary edge quad
    n_bnd = sum(len(v) == 1 for v in faces.values())
    assert n_bnd == 2 * len(F) + 2 * 2 * (3 + 2)


def test_planes_and_affine_maps():
    """Reference: the defining properties: each face plane holds its three vertices and has the fourth
    strictly on its negative side (outward normal); w2f maps the world vertices onto the flat ones and f2w
    inverts it (round trip on random points)."""
    V, F, X = _mesh()
    rng = np.random.default_rng(4)
    Q = X * [2.0, 0.5, 3.0] + rng.normal(0, 0.01, X.shape)  # some other non-degenerate vertex positions
    tets = orient_positive(Q, split_prisms(F, len(V)))
    planes, w2f, f2w = tet_geometry(X, Q, tets)
    for t in range(len(tets)):
        P = X[tets[t]]
        for i in range(4):
            n, c = planes[t, i, :3], planes[t, i, 3]
            on = [k for k in range(4) if k != i]
            scale = np.linalg.norm(n) * (1 + np.abs(P).max())
            np.testing.assert_allclose(P[on] @ n - c, 0.0, atol=1e-12 * scale)
            assert P[i] @ n - c < -1e-6 * scale
        A, Ai = w2f[t], f2w[t]
        np.testing.assert_allclose(P @ A[:, :3].T + A[:, 3], Q[tets[t]], atol=1e-12)
        x = rng.dirichlet(np.ones(4), 5) @ P
        y = x @ A[:, :3].T + A[:, 3]
        np.testing.assert_allclose(y @ Ai[:, :3].T + Ai[:, 3], x, atol=1e-12)
