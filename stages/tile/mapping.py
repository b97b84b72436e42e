"""Maps between world space, shell texture coordinates (u, v, w) and flat / exemplar space.

Within tetrahedron ``tet`` the shell map is affine (barycentric, piecewise linear over the shell):
- ``world_to_flat(w2f, tet, p)`` / ``flat_to_world(f2w, tet, q)``: the per-tetrahedron affine maps of
  ``tetra.tet_geometry`` (directions map by the linear part only: fibre tangents by f2w, normals by the
  transpose of w2f, as in ``stages.core.shell.traversal``);
- ``flat_to_uvw(q, flat_size, thickness)``: (X / flat_size_x, Y / flat_size_y, Z / thickness);
- ``flat_to_exemplar(q, block, ...)``: flat point -> (exemplar, point in that exemplar) by the block map
  (``tiling``): block (i, j) = floor(X / bw), floor(Y / bh) wrapped periodically over the map; its
  exemplar k; the point shifted by whole exemplar periods into [0, W_k) x [0, H_k) (the block itself:
  ``stages.core.blocks.block_of``, which the btf renderer shares).
"""

from numba import njit

from stages.core.blocks import block_of


@njit(cache=True)
def affine_apply(M, tet, x, y, z):
    return (M[tet, 0, 0] * x + M[tet, 0, 1] * y + M[tet, 0, 2] * z + M[tet, 0, 3],
            M[tet, 1, 0] * x + M[tet, 1, 1] * y + M[tet, 1, 2] * z + M[tet, 1, 3],
            M[tet, 2, 0] * x + M[tet, 2, 1] * y + M[tet, 2, 2] * z + M[tet, 2, 3])


@njit(cache=True)
def world_to_flat(w2f, tet, p):
    return affine_apply(w2f, tet, p[0], p[1], p[2])


@njit(cache=True)
def flat_to_world(f2w, tet, q):
    return affine_apply(f2w, tet, q[0], q[1], q[2])


@njit(cache=True)
def flat_to_uvw(q, flat_size, thickness):
    return q[0] / flat_size[0], q[1] / flat_size[1], q[2] / thickness


@njit(cache=True)
def flat_to_exemplar(q, block_size, block_map, ex_nblocks):
    """(exemplar k or -1, x, y, z in exemplar k's space)."""
    nbu = block_map.shape[0]
    nbv = block_map.shape[1]
    i, j, ri, rj = block_of(q[0], q[1], block_size, nbu, nbv)
    k = block_map[i, j]
    if k < 0:
        return -1, q[0], q[1], q[2]
    bx = ri - (ri % ex_nblocks[k, 0])
    by = rj - (rj % ex_nblocks[k, 1])
    return k, q[0] - bx * block_size[0], q[1] - by * block_size[1], q[2]
