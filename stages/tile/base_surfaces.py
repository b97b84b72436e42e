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

``vertex_normals``: smoothed (angle-weighted) vertex normals. ``triangle_checks`` finds degenerate
triangles (3-D area or uv area <= ``rel_eps`` x the mean) and flipped triangles (uv orientation
against the majority, or geometric normal against the smoothed vertex normals).
"""
from __future__ import annotations

import numpy as np


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
