"""Base surfaces for shell mapping: triangle meshes with (u, v) texture coordinates.

Each builder returns ``(vertices (n, 3) float64, uv (n, 2) float64, triangles (m, 3) int64)`` with
triangles counter-clockwise in (u, v) and their geometric normals on the side the shell grows to.

- ``flat_rectangle(width, height, nu, nv)``: z = 0, x in [0, width], y in [0, height];
  u = x / width, v = y / height (the identity shell map when the cloth's flat size is width x height).
- ``cylinder(radius, length, angle_deg, nu, nv)``: the part of a cylinder of axis y (through the
  origin) at polar angles phi in [-angle/2, angle/2] from +z: (r sin phi, y, r cos phi),
  u along phi, v = y / length; the shell grows outwards.
- ``sphere_drape(cloth_size, sphere_radius, nu, nv, folds, fold_amplitude)``: a square cloth of side
  ``cloth_size`` centred over a sphere of radius R at the origin, draped deterministically: the
  point at distance r from the cloth centre in direction phi lands on the sphere at polar angle
  theta = r / R (lengths kept along every radial line) up to the equator, and below it hangs straight
  down, pushed outwards by ``folds`` folds around the skirt: radial offset
  fold_amplitude h^2 / cloth_size sin^2(folds phi) at hanging length h (0 at the equator, so the
  surface stays C1 there). Lengths are kept along every radial line of the cloth.

``sphere_drape_points`` and ``cylinder_points`` are those maps at any cloth points (lengths kept: a cylinder's
angle is the cloth's width over its radius), and ``drape`` lays a fabric's curves on such a map with their
thickness along its normal (a scene's ``[[fabrics]]`` ``drape``: pipeline/runners/ingest.py).
``UvChart`` / ``uv_chart`` / ``chart_points`` do the same on any triangle mesh with texture coordinates (an
OBJ surface): a cloth point's (u, v) is found in the mesh's uv triangles (a uniform grid of uv cells lists the
triangles whose uv box meets each), its surface point is the barycentric mix of the triangle's vertices and its
normal the mix of the smoothed vertex normals, so the thickness direction is continuous across edges.

``vertex_normals``: smoothed (angle-weighted) vertex normals. ``triangle_checks`` finds degenerate
triangles (3-D area or uv area <= ``rel_eps`` x the mean) and flipped triangles (uv orientation
against the majority, or geometric normal against the smoothed vertex normals).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


def _grid_triangles(nu, nv):
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    b = a + (nv + 1)
    c = b + 1
    d = a + 1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def _grid_uv(nu, nv):
    u, v = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    return np.stack([u.ravel(), v.ravel()], 1)


def flat_rectangle(width, height, nu=4, nv=4):
    uv = _grid_uv(nu, nv)
    V = np.stack([uv[:, 0] * width, uv[:, 1] * height, np.zeros(len(uv))], 1)
    return V, uv, _grid_triangles(nu, nv)


def cylinder(radius, length, angle_deg=180.0, nu=24, nv=8):
    uv = _grid_uv(nu, nv)
    phi = np.radians(angle_deg) * (uv[:, 0] - 0.5)
    V = np.stack([radius * np.sin(phi), uv[:, 1] * length, radius * np.cos(phi)], 1)
    return V, uv, _grid_triangles(nu, nv)


def sphere_drape(cloth_size, sphere_radius, nu=32, nv=32, folds=6, fold_amplitude=0.15):
    uv = _grid_uv(nu, nv)
    V = sphere_drape_points((uv[:, 0] - 0.5) * cloth_size, (uv[:, 1] - 0.5) * cloth_size, cloth_size, sphere_radius,
                            folds, fold_amplitude)
    return V, uv, _grid_triangles(nu, nv)


def sphere_drape_points(x, y, cloth_size, sphere_radius, folds=6, fold_amplitude=0.15):
    """``sphere_drape``'s map at cloth points (x, y) measured from the cloth's centre: (n, 3) points."""
    r = np.hypot(x, y)
    phi = np.arctan2(y, x)
    R = sphere_radius
    theta = np.minimum(r / R, 0.5 * np.pi)
    hang = np.maximum(r - 0.5 * np.pi * R, 0.0)
    rad = R * np.sin(theta) + fold_amplitude * hang * (hang / cloth_size) * np.sin(folds * phi) ** 2
    return np.stack([rad * np.cos(phi), rad * np.sin(phi), R * np.cos(theta) - hang], 1)


def cylinder_points(x, y, radius):
    """A cloth laid over a cylinder of axis y (through the origin), lengths kept: cloth point (x, y), x measured
    from the cloth's centre line, goes to polar angle phi = x / radius from +z: (r sin phi, y, r cos phi)."""
    phi = np.asarray(x, np.float64) / radius
    return np.stack([radius * np.sin(phi), np.asarray(y, np.float64), radius * np.cos(phi)], 1)


DRAPE_STEP = 1e-5   # the central differences of ``drape``'s normals, in units of the cloth's size


def drape(points, surface_map, size):
    """Points of a flat fabric (x, y in the cloth, z its height above it) draped by ``surface_map`` ((x, y) ->
    (n, 3) surface points, e.g. ``cylinder_points``): each goes to the surface point of its (x, y) plus z times
    the surface's unit normal there (from central differences of the map, ``DRAPE_STEP`` of ``size`` apart), so
    the fabric's thickness stays along the surface's normal and its lengths along the surface are the map's."""
    P = np.asarray(points, np.float64)
    h = DRAPE_STEP * size
    x, y = P[:, 0], P[:, 1]
    du = (surface_map(x + h, y) - surface_map(x - h, y)) / (2.0 * h)
    dv = (surface_map(x, y + h) - surface_map(x, y - h)) / (2.0 * h)
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return surface_map(x, y) + P[:, 2:3] * n


def face_normals(V, F):
    """Unnormalised face normals (twice the area)."""
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


def vertex_normals(V, F):
    """Angle-weighted average of the unit face normals at each vertex, normalised."""
    fn = face_normals(V, F)
    fl = np.linalg.norm(fn, axis=1)
    fn = fn / np.where(fl > 0, fl, 1.0)[:, None]
    N = np.zeros_like(V)
    for k in range(3):
        p = V[F[:, k]]
        e1 = V[F[:, (k + 1) % 3]] - p
        e2 = V[F[:, (k + 2) % 3]] - p
        c = np.einsum("ij,ij->i", e1, e2) / np.maximum(np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-300)
        ang = np.arccos(np.clip(c, -1.0, 1.0))
        np.add.at(N, F[:, k], fn * ang[:, None])
    n = np.linalg.norm(N, axis=1)
    return N / np.where(n > 0, n, 1.0)[:, None]


def triangle_checks(V, UV, F, N, rel_eps=1e-10):
    """(degenerate triangle indices, flipped triangle indices) -- see the module doc."""
    area = 0.5 * np.linalg.norm(face_normals(V, F), axis=1)
    e1 = UV[F[:, 1]] - UV[F[:, 0]]
    e2 = UV[F[:, 2]] - UV[F[:, 0]]
    uv_area = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    deg = ((area <= rel_eps * max(area.mean(), 1e-300))
           | (np.abs(uv_area) <= rel_eps * max(np.abs(uv_area).mean(), 1e-300)))
    major = 1.0 if (uv_area > 0).sum() >= (uv_area < 0).sum() else -1.0
    fn = face_normals(V, F)
    nsum = N[F[:, 0]] + N[F[:, 1]] + N[F[:, 2]]
    flipped = ~deg & ((uv_area * major <= 0) | (np.einsum("ij,ij->i", fn, nsum) <= 0))
    return np.flatnonzero(deg), np.flatnonzero(flipped)


# ------------------------------------------------------------------------------------------------ uv charts
UV_EDGE_TOL = 1e-9      # a point this far outside a triangle in barycentric terms is still on it (shared edges)
MAX_UV_CELLS = 1024     # a chart's uv grid has at most this many cells per side


class UvChart(NamedTuple):
    """A triangle mesh ready for ``chart_points``: vertices V (n, 3), smoothed unit normals N (n, 3) on the side
    of du x dv, triangle corners F (m, 3), their uv TUV (m, 3, 2), and the uv grid (lo (2,), inverse cell size
    inv (2,), cells per side G, CSR lists start (G*G + 1,) / items of the triangles meeting each cell)."""
    V: np.ndarray
    N: np.ndarray
    F: np.ndarray
    TUV: np.ndarray
    lo: np.ndarray
    inv: np.ndarray
    G: int
    start: np.ndarray
    items: np.ndarray


def uv_chart(V, UV, F) -> UvChart:
    """The ``UvChart`` of a mesh with texture coordinates (vertices split where uv differ, as the OBJ reader
    gives them). Triangles clockwise in uv are turned so every normal lies on the side of du x dv; normals are
    smoothed over vertices at one position (welded), so uv seams do not crease them."""
    V = np.asarray(V, np.float64)
    UV = np.asarray(UV, np.float64)
    F = np.asarray(F, np.int64).copy()
    e1, e2 = UV[F[:, 1]] - UV[F[:, 0]], UV[F[:, 2]] - UV[F[:, 0]]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0.0
    F[flip] = F[flip][:, [0, 2, 1]]
    pos, weld = np.unique(V, axis=0, return_inverse=True)
    N = vertex_normals(pos, weld.reshape(-1)[F])[weld.reshape(-1)]
    TUV = np.ascontiguousarray(UV[F])
    lo, hi = TUV.reshape(-1, 2).min(axis=0), TUV.reshape(-1, 2).max(axis=0)
    G = int(min(MAX_UV_CELLS, max(1, np.ceil(np.sqrt(len(F))))))
    inv = G / np.maximum(hi - lo, 1e-300)
    start, items = _bin_triangles(TUV, lo, inv, G)
    return UvChart(V, N, F, TUV, lo, inv, G, start, items)


@njit(cache=True)
def _cell_range(a, b, lo, inv, G):
    i0 = min(max(int((a - lo) * inv), 0), G - 1)
    i1 = min(max(int((b - lo) * inv), 0), G - 1)
    return i0, i1


@njit(cache=True)
def _triangle_cells(TUV, t, lo, inv, G):
    i0, i1 = _cell_range(TUV[t, :, 0].min(), TUV[t, :, 0].max(), lo[0], inv[0], G)
    j0, j1 = _cell_range(TUV[t, :, 1].min(), TUV[t, :, 1].max(), lo[1], inv[1], G)
    return i0, i1, j0, j1


@njit(cache=True)
def _bin_triangles(TUV, lo, inv, G):
    """CSR lists (start, items) of the triangles whose uv box meets each of the G x G cells (cell i * G + j)."""
    m = TUV.shape[0]
    start = np.zeros(G * G + 1, np.int64)
    for t in range(m):
        i0, i1, j0, j1 = _triangle_cells(TUV, t, lo, inv, G)
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                start[i * G + j + 1] += 1
    for c in range(G * G):
        start[c + 1] += start[c]
    items = np.empty(start[G * G], np.int64)
    fill = start[:-1].copy()
    for t in range(m):
        i0, i1, j0, j1 = _triangle_cells(TUV, t, lo, inv, G)
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                items[fill[i * G + j]] = t
                fill[i * G + j] += 1
    return start, items


@njit(cache=True)
def _locate(u, v, TUV, lo, inv, G, start, items, tri, bary):
    """The triangle holding each (u, v) (-1: none) and its barycentric coordinates there."""
    for k in range(u.shape[0]):
        tri[k] = -1
        if not (lo[0] - UV_EDGE_TOL <= u[k] <= lo[0] + G / inv[0] + UV_EDGE_TOL
                and lo[1] - UV_EDGE_TOL <= v[k] <= lo[1] + G / inv[1] + UV_EDGE_TOL):
            continue
        i, _ = _cell_range(u[k], u[k], lo[0], inv[0], G)
        j, _ = _cell_range(v[k], v[k], lo[1], inv[1], G)
        for q in range(start[i * G + j], start[i * G + j + 1]):
            t = items[q]
            ax, ay = TUV[t, 0, 0], TUV[t, 0, 1]
            e1x, e1y = TUV[t, 1, 0] - ax, TUV[t, 1, 1] - ay
            e2x, e2y = TUV[t, 2, 0] - ax, TUV[t, 2, 1] - ay
            det = e1x * e2y - e1y * e2x
            if det == 0.0:
                continue
            px, py = u[k] - ax, v[k] - ay
            b1 = (px * e2y - py * e2x) / det
            b2 = (e1x * py - e1y * px) / det
            b0 = 1.0 - b1 - b2
            if b0 >= -UV_EDGE_TOL and b1 >= -UV_EDGE_TOL and b2 >= -UV_EDGE_TOL:
                tri[k] = t
                bary[k, 0], bary[k, 1], bary[k, 2] = b0, b1, b2
                break


def chart_points(chart: UvChart, u, v, z):
    """(points (n, 3), outside (n,) bool): each (u, v) laid on the chart's surface, lifted z along its
    interpolated unit normal; ``outside`` marks the (u, v) no triangle holds (their points are NaN)."""
    u = np.ascontiguousarray(u, np.float64)
    v = np.ascontiguousarray(v, np.float64)
    tri = np.empty(len(u), np.int64)
    bary = np.zeros((len(u), 3))
    _locate(u, v, chart.TUV, chart.lo, chart.inv, chart.G, chart.start, chart.items, tri, bary)
    outside = tri < 0
    corners = chart.F[np.where(outside, 0, tri)]
    base = np.einsum("nk,nkd->nd", bary, chart.V[corners])
    n = np.einsum("nk,nkd->nd", bary, chart.N[corners])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    out = base + np.asarray(z, np.float64)[:, None] * n
    out[outside] = np.nan
    return out, outside
