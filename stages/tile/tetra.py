"""Shell prisms as tetrahedra, and the per-tetrahedron geometry the traversal needs.

Prism split (``split_prisms``): the prism over base triangle (a, b, c) with top vertices (A, B, C)
(top index = base index + n) is cut into three tetrahedra after sorting a < b < c:
(a, b, c, C), (a, b, B, C), (a, A, B, C). Every quadrilateral side face is then cut along the diagonal
from its lower-index base vertex to its higher-index top vertex, whichever prism it belongs to, so
neighbouring prisms share their side faces exactly (a conforming tetrahedral mesh: no cracks).

Per tetrahedron (``tet_geometry``), with world vertices P_i and flat (exemplar-space) vertices Q_i:
- ``planes`` (T, 4, 4): face i (opposite vertex i) as (n, c) with n . x = c on the face and n pointing
  out of the tetrahedron (n not normalised);
- ``w2f`` (T, 3, 4): the affine map world -> flat, x -> Q0 + [Q1-Q0 Q2-Q0 Q3-Q0][P1-P0 P2-P0 P3-P0]^-1 (x - P0)
  (the piecewise-linear shell map of Porumbescu et al. 2005: barycentric coordinates carried over);
- ``f2w`` (T, 3, 4): its inverse;
- ``volume`` (T,): signed volume det[P1-P0, P2-P0, P3-P0] / 6 of the tetrahedron as split, positive
  when the shell grows to the side of the base triangle's normal.
``tet_neighbours``: (T, 4) the tetrahedron across face i, -1 on the shell boundary.
"""
from __future__ import annotations

import numpy as np


def split_prisms(F, n):
    """(T = 3m, 4) vertex indices into the shell vertex array [base (n); top (n)]."""
    F = np.asarray(F, np.int64)
    s = np.sort(F, axis=1)
    a, b, c = s[:, 0], s[:, 1], s[:, 2]
    A, B, C = a + n, b + n, c + n
    t1 = np.stack([a, b, c, C], 1)
    t2 = np.stack([a, b, B, C], 1)
    t3 = np.stack([a, A, B, C], 1)
    return np.stack([t1, t2, t3], 1).reshape(-1, 4)


def signed_volumes(X, tets):
    P0 = X[tets[:, 0]]
    return np.einsum("ij,ij->i", np.cross(X[tets[:, 1]] - P0, X[tets[:, 2]] - P0), X[tets[:, 3]] - P0) / 6.0


def orient_positive(X, tets):
    """Swap two vertices of every negatively oriented tetrahedron (faces stay the same set)."""
    tets = tets.copy()
    neg = signed_volumes(X, tets) < 0
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    return tets


def _affine(src, dst):
    """(T, 3, 4) affine maps taking tetrahedra src (T, 4, 3) onto dst (T, 4, 3)."""
    S = np.transpose(src[:, 1:] - src[:, :1], (0, 2, 1))  # columns = edges
    D = np.transpose(dst[:, 1:] - dst[:, :1], (0, 2, 1))
    M = D @ np.linalg.inv(S)
    off = dst[:, 0] - np.einsum("tij,tj->ti", M, src[:, 0])
    return np.concatenate([M, off[:, :, None]], axis=2)


def tet_geometry(X, Q, tets):
    """planes, w2f, f2w for world vertex positions X and flat positions Q (see module doc)."""
    P = X[tets]  # (T, 4, 3)
    planes = np.empty((len(tets), 4, 4))
    for i in range(4):
        o = [k for k in range(4) if k != i]
        p0, p1, p2 = P[:, o[0]], P[:, o[1]], P[:, o[2]]
        nrm = np.cross(p1 - p0, p2 - p0)
        c = np.einsum("ij,ij->i", nrm, p0)
        side = np.einsum("ij,ij->i", nrm, P[:, i]) - c
        sgn = np.where(side > 0, -1.0, 1.0)
        planes[:, i, :3] = nrm * sgn[:, None]
        planes[:, i, 3] = c * sgn
    Qt = Q[tets]
    return planes, _affine(P, Qt), _affine(Qt, P)


def tet_neighbours(tets):
    """(T, 4) index of the tetrahedron sharing face i (opposite vertex i), -1 where none."""
    T = len(tets)
    faces = np.empty((T, 4, 3), np.int64)
    for i in range(4):
        faces[:, i] = tets[:, [k for k in range(4) if k != i]]
    f = np.sort(faces.reshape(-1, 3), axis=1)
    order = np.lexsort((f[:, 2], f[:, 1], f[:, 0]))
    fs = f[order]
    same = np.all(fs[1:] == fs[:-1], axis=1)
    nbr = -np.ones(4 * T, np.int64)
    idx = np.flatnonzero(same)
    a, b = order[idx], order[idx + 1]
    nbr[a] = b // 4
    nbr[b] = a // 4
    return nbr.reshape(T, 4)
