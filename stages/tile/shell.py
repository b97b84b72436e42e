"""The shell: a base surface offset along its smoothed vertex normals (seed 001 §2, Porumbescu et al. 2005).

Given a base mesh (vertices V, texture coordinates UV, triangles F), vertex normals N and the shell
thickness T (world units; ``flat_thickness``, the exemplar's thickness, defaults to T), the shell's
vertices are the base vertices (w = 0) and V + T N (w = 1); its shell texture coordinates are (u, v, w).
Flat (tiled exemplar) space is
    X = u * flat_size[0],  Y = v * flat_size[1],  Z = w * flat_thickness,
where flat_size is the size of the tiled cloth (blocks per side x block size): the shell map takes each
tetrahedron of the shell onto the tetrahedron with the same vertices in flat space, by barycentric
coordinates (piecewise linear). ``volume`` is each tetrahedron's world volume, signed so that it is
positive where the prism is not inverted (the offset does not fold over).

``build_shell`` returns a dict of arrays: ``vertices`` (2n, 3), ``uvw`` (2n, 3), ``flat`` (2n, 3),
``tets`` (3m, 4), ``neighbours``, ``planes``, ``w2f``, ``f2w``, ``volume``, and the boundary faces
``bnd_tri`` (B, 3, 3), ``bnd_tet``, ``bnd_face``, ``bnd_normal`` (outward).
"""
from __future__ import annotations

import numpy as np

from .tetra import orient_positive, signed_volumes, split_prisms, tet_geometry, tet_neighbours


def build_shell(V, UV, F, N, thickness, flat_size, flat_thickness=None):
    n = len(V)
    flat_thickness = thickness if flat_thickness is None else flat_thickness
    X = np.concatenate([V, V + thickness * N])
    uvw = np.concatenate([np.c_[UV, np.zeros(n)], np.c_[UV, np.ones(n)]])
    flat = uvw * np.array([flat_size[0], flat_size[1], flat_thickness])
    tets = split_prisms(F, n)
    # orientation relative to the base triangle's side: a tetrahedron of a good prism has the sign of the
    # corresponding flat tetrahedron (flat space is a right-handed slab grown to +Z)
    vol_w = signed_volumes(X, tets)
    vol_f = signed_volumes(flat, tets)
    volume = vol_w * np.sign(vol_f)
    tets = orient_positive(flat, tets)
    planes, w2f, f2w = tet_geometry(X, flat, tets)
    nbr = tet_neighbours(tets)
    bt, bf = np.nonzero(nbr < 0)
    tri = np.empty((len(bt), 3, 3))
    for k in range(len(bt)):
        o = [j for j in range(4) if j != bf[k]]
        tri[k] = X[tets[bt[k], o]]
    bn = planes[bt, bf, :3]
    return {"vertices": X, "uvw": uvw, "flat": flat, "tets": tets, "neighbours": nbr, "planes": planes,
            "w2f": w2f, "f2w": f2w, "volume": volume, "bnd_tri": tri, "bnd_tet": bt.astype(np.int64),
            "bnd_face": bf.astype(np.int64), "bnd_normal": bn}
