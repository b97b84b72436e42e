"""Ray queries of a triangle mesh: a SAH BVH over triangles, nearest hit with barycentrics, any hit.

A ``TriangleMesh`` is built once from vertices V (NV, 3) and triangles F (T, 3) (``build_triangle_mesh``):
the boxes of the triangles go through the binned-SAH builder of the fibre BVH
(``stages.core.geometry.bvh.build_bvh_nodes``) and packed for traversal:

- ``nodes`` (N, 8) float64: bounds lo(3), hi(3), then (left, right) for inner nodes or (-1 - start, count)
  for leaves, node 0 the root;
- ``tris`` (T, 10) float64 in leaf order: vertex p0 (3), edges e1 = p1 - p0 (3), e2 = p2 - p0 (3), the
  triangle's index in F.

Queries (rays o + t d, d need not be unit; t in (tmin, tmax)):

- ``mesh_intersect(mesh, ox, oy, oz, dx, dy, dz, tmin, tmax)`` -> ``TriangleHit(t, tri, b1, b2)``: the
  nearest hit, ties broken by the lower triangle index, exactly what testing every triangle gives
  (``mesh_intersect_brute``); ``tri`` -1 and t inf on a miss. The hit point is
  p0 + b1 e1 + b2 e2, its barycentric weights (1 - b1 - b2, b1, b2) on F's corners (0, 1, 2).
- ``mesh_occluded(mesh, ..., tmin, tmax)``: True when any triangle lies along the ray (shadow rays).

The ray-triangle test is Moller-Trumbore in double precision, both faces hit, with edges widened by
``BARY_EPS`` (b1 >= -eps, b2 >= -eps, b1 + b2 <= 1 + eps): with exact edges, rounding makes a ray
aimed at a shared vertex or edge miss every triangle around it now and then; widened, it finds one
or two (at the same t), so a mesh has no cracks to leak through. To find the next surface behind a hit (a
hole in a texture, another layer of the same cloth), query again with tmin = t + eps: the neighbour
that shares the hit edge lies at the same t and is not found again.

Mesh helpers (numpy): ``area_weighted_normals(V, F)`` (vertex normals, each the sum of its triangles'
area-weighted normals, normalised) and ``uv_derivatives(V, UV, F)`` (dP/du, dP/dv of every triangle
from its texture coordinates: the tangent frame of a uv-parameterised surface).
"""
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.bvh import build_bvh_nodes
from stages.core.geometry.slab import inverse_direction, slab_enter
from stages.core.geometry.stack import traversal_stack

TriangleMesh = namedtuple("TriangleMesh", ["vertices", "triangles", "nodes", "tris"])
TriangleHit = namedtuple("TriangleHit", ["t", "tri", "b1", "b2"])

TRI_SIZE = 10
BARY_EPS = 1e-10     # barycentric slack: neighbours overlap by it, so rounding never opens a crack


def area_weighted_normals(V, F) -> np.ndarray:
    """Vertex normals: the sum over a vertex's triangles of their cross products (twice their area times
    their unit normal), normalised; a vertex of degenerate triangles only gets (0, 0, 1)."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = np.zeros_like(V)
    for k in range(3):
        np.add.at(N, F[:, k], fn)
    n = np.linalg.norm(N, axis=1)
    N[n == 0] = (0.0, 0.0, 1.0)
    return N / np.where(n > 0, n, 1.0)[:, None]


def uv_derivatives(V, UV, F):
    """(dP/du, dP/dv) (T, 3) each: the linear map of each triangle from its texture coordinates to space,
    solved from its two edges (zero where the uv triangle is degenerate)."""
    V = np.asarray(V, np.float64)
    UV = np.asarray(UV, np.float64)
    F = np.asarray(F, np.int64)
    e1 = V[F[:, 1]] - V[F[:, 0]]
    e2 = V[F[:, 2]] - V[F[:, 0]]
    a = UV[F[:, 1]] - UV[F[:, 0]]
    b = UV[F[:, 2]] - UV[F[:, 0]]
    det = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    ok = np.abs(det) > 0
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    dpdu = (e1 * b[:, 1:2] - e2 * a[:, 1:2]) * inv
    dpdv = (e2 * a[:, 0:1] - e1 * b[:, 0:1]) * inv
    return dpdu, dpdv


@njit(cache=True)
def triangle_bounds(V, F):
    T = F.shape[0]
    lo = np.empty((T, 3))
    hi = np.empty((T, 3))
    for i in range(T):
        for k in range(3):
            a = V[F[i, 0], k]
            b = V[F[i, 1], k]
            c = V[F[i, 2], k]
            m = max(abs(a), abs(b), abs(c))
            pad = 1e-9 * m
            lo[i, k] = min(a, b, c) - pad
            hi[i, k] = max(a, b, c) + pad
    return lo, hi


@njit(cache=True)
def pack_triangles(nlo, nhi, left, right, start, count, prim, V, F):
    N = nlo.shape[0]
    nodes = np.empty((N, 8))
    for n in range(N):
        for k in range(3):
            nodes[n, k] = nlo[n, k]
            nodes[n, 3 + k] = nhi[n, k]
        if left[n] < 0:
            nodes[n, 6] = -1.0 - start[n]
            nodes[n, 7] = count[n]
        else:
            nodes[n, 6] = left[n]
            nodes[n, 7] = right[n]
    T = prim.shape[0]
    tris = np.empty((T, TRI_SIZE))
    for j in range(T):
        i = prim[j]
        for k in range(3):
            p0 = V[F[i, 0], k]
            tris[j, k] = p0
            tris[j, 3 + k] = V[F[i, 1], k] - p0
            tris[j, 6 + k] = V[F[i, 2], k] - p0
        tris[j, 9] = i
    return nodes, tris


def build_triangle_mesh(V, F) -> TriangleMesh:
    """The ``TriangleMesh`` (BVH packed for traversal) of vertices V (NV, 3) and triangles F (T, 3)."""
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    if len(F) == 0:
        nodes = np.zeros((1, 8))
        nodes[0, :3] = np.inf
        nodes[0, 3:6] = -np.inf
        nodes[0, 6] = -1.0
        return TriangleMesh(V, F, nodes, np.zeros((0, TRI_SIZE)))
    lo, hi = triangle_bounds(V, F)
    nlo, nhi, left, right, start, count, prim = build_bvh_nodes(lo, hi)
    nodes, tris = pack_triangles(nlo, nhi, left, right, start, count, prim, V, F)
    return TriangleMesh(V, F, nodes, tris)


# ------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def ray_triangle(tris, j, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Moller-Trumbore: (t, b1, b2) of the ray's hit with packed triangle j, t = inf when it misses or
    t is outside (tmin, tmax)."""
    e1x = tris[j, 3]
    e1y = tris[j, 4]
    e1z = tris[j, 5]
    e2x = tris[j, 6]
    e2y = tris[j, 7]
    e2z = tris[j, 8]
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return np.inf, 0.0, 0.0
    inv = 1.0 / det
    sx = ox - tris[j, 0]
    sy = oy - tris[j, 1]
    sz = oz - tris[j, 2]
    b1 = (sx * px + sy * py + sz * pz) * inv
    if b1 < -BARY_EPS or b1 > 1.0 + BARY_EPS:
        return np.inf, 0.0, 0.0
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    b2 = (dx * qx + dy * qy + dz * qz) * inv
    if b2 < -BARY_EPS or b1 + b2 > 1.0 + BARY_EPS:
        return np.inf, 0.0, 0.0
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if t <= tmin or t >= tmax:
        return np.inf, 0.0, 0.0
    return t, b1, b2


@njit(cache=True)
def node_links(nodes, n):
    """(leaf, a, b) of node n (the layout of ``nodes``, module doc): a leaf's first triangle and count, else the
    inner node's two children."""
    a = int(nodes[n, 6])
    b = int(nodes[n, 7])
    if a < 0:
        return True, -1 - a, b
    return False, a, b


@njit(cache=True)
def node_enter(nodes, n, ox, oy, oz, ix, iy, iz, tmin, tmax):
    """``slab_enter`` of node n's box (the bounds in its row of ``nodes``): the ray's entry distance, inf when it
    misses."""
    return slab_enter(nodes[n, 0], nodes[n, 1], nodes[n, 2], nodes[n, 3], nodes[n, 4], nodes[n, 5],
                      ox, oy, oz, ix, iy, iz, tmin, tmax)


@njit(cache=True)
def mesh_intersect(mesh, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Nearest hit in (tmin, tmax) (``TriangleHit``; module doc)."""
    nodes = mesh.nodes
    tris = mesh.tris
    best_t = tmax
    best_j = -1
    best_i = -1
    best_b1 = 0.0
    best_b2 = 0.0
    if tris.shape[0] == 0:
        return TriangleHit(np.inf, -1, 0.0, 0.0)
    ix, iy, iz = inverse_direction(dx, dy, dz)
    t_root = node_enter(nodes, 0, ox, oy, oz, ix, iy, iz, tmin, best_t)
    if t_root == np.inf:
        return TriangleHit(np.inf, -1, 0.0, 0.0)
    stack, stack_t = traversal_stack()   # stack_t: entry distance of each pushed node, skipped if a nearer hit
                                         # came since
    node = 0
    sp = 0
    while True:
        leaf, a, b = node_links(nodes, node)
        if leaf:
            for j in range(a, a + b):
                t, b1, b2 = ray_triangle(tris, j, ox, oy, oz, dx, dy, dz, tmin, tmax)
                if t > best_t or t == np.inf:
                    continue
                i = int(tris[j, 9])
                if t < best_t or i < best_i:
                    best_t = t
                    best_j = j
                    best_i = i
                    best_b1 = b1
                    best_b2 = b2
        else:
            tl = node_enter(nodes, a, ox, oy, oz, ix, iy, iz, tmin, best_t)
            tr = node_enter(nodes, b, ox, oy, oz, ix, iy, iz, tmin, best_t)
            if tl != np.inf or tr != np.inf:   # go on into the nearer child, the farther one waits on the stack
                if tr < tl:
                    a, b, tl, tr = b, a, tr, tl
                if tr != np.inf:
                    stack[sp] = b
                    stack_t[sp] = tr
                    sp += 1
                node = a
                continue
        node = -1
        while sp > 0:
            sp -= 1
            if stack_t[sp] <= best_t:
                node = stack[sp]
                break
        if node < 0:
            break
    if best_j < 0:
        return TriangleHit(np.inf, -1, 0.0, 0.0)
    return TriangleHit(best_t, best_i, best_b1, best_b2)


@njit(cache=True)
def mesh_occluded(mesh, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """True when a triangle lies along the ray in (tmin, tmax)."""
    nodes = mesh.nodes
    tris = mesh.tris
    if tris.shape[0] == 0:
        return False
    ix, iy, iz = inverse_direction(dx, dy, dz)
    if node_enter(nodes, 0, ox, oy, oz, ix, iy, iz, tmin, tmax) == np.inf:
        return False
    stack, _stack_t = traversal_stack()
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        leaf, a, b = node_links(nodes, node)
        if leaf:
            for j in range(a, a + b):
                t, _b1, _b2 = ray_triangle(tris, j, ox, oy, oz, dx, dy, dz, tmin, tmax)
                if t != np.inf:
                    return True
            continue
        for c in (a, b):
            if node_enter(nodes, c, ox, oy, oz, ix, iy, iz, tmin, tmax) != np.inf:
                stack[sp] = c
                sp += 1
    return False


@njit(cache=True)
def mesh_intersect_brute(mesh, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Reference of ``mesh_intersect``: every triangle of F tested in order, nearest hit, ties to the lower
    index (the same Moller-Trumbore arithmetic on F's own vertices)."""
    V = mesh.vertices
    F = mesh.triangles
    one = np.empty((1, TRI_SIZE))
    best = TriangleHit(np.inf, -1, 0.0, 0.0)
    for i in range(F.shape[0]):
        for k in range(3):
            p0 = V[F[i, 0], k]
            one[0, k] = p0
            one[0, 3 + k] = V[F[i, 1], k] - p0
            one[0, 6 + k] = V[F[i, 2], k] - p0
        t, b1, b2 = ray_triangle(one, 0, ox, oy, oz, dx, dy, dz, tmin, tmax)
        if t < best.t:
            best = TriangleHit(t, i, b1, b2)
    return best
