"""The shell's top and base surfaces as functions of the cloth's (u, v) (seed 001 §5.2.1, §5.3.2, §4.2).

Seed 001 starts the global-visibility shadow ray of a fibre hit at x_, "the point on the top surface of
the shell that is directly above x" (Fig. 5), and filters that visibility with a Gaussian in the flat
fabric's plane (§5.3.2). Both need the top surface at a shell texture coordinate (u, v): the shell's
top vertices are the base vertices offset along their smoothed normals by the shell thickness T
(``stages.tile.shell``), so within the prism of base triangle i the top surface is the triangle of
those offset vertices, and the point above (u, v) is their combination by the barycentric coordinates
of (u, v) in the base triangle's uv triangle. Its normal is the same combination of the vertex
normals (normalised): the shadow ray leaves the cloth only when the light is above that plane.

Light from below the fabric (seed 001 §4.2, "Extension to bottom and side fabric surfaces": an IIRTF
precomputed for light from both sides) leaves the cloth through its base: ``base_point`` is the base
surface's point below (u, v), the same barycentric combination of the base triangle's own corners,
with the same normal (a shadow ray from there leaves the cloth when the light is below that plane).

``build_top_surface(base_uv, base_triangles, base_vertices, base_normals, thickness)`` returns a
``TopSurface``: per triangle its uv corners (T, 3, 2), top corners (T, 3, 3), base corners (T, 3, 3) and
normals (T, 3, 3), and
a uniform grid over the uv domain (about one triangle per cell) listing the triangles whose uv box
meets each cell (CSR ``cell_start`` / ``cell_tris``). ``top_point(ts, u, v)`` returns
(found, x, y, z, nx, ny, nz) (``base_point`` the same on the base): (u, v) is clamped into the uv
domain's box; a point outside every triangle (a gap of the uv layout, or rounding at an edge) takes the
triangle of its cell whose barycentric coordinates are least negative.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

TopSurface = namedtuple("TopSurface", ["uv", "top", "nrm", "lo", "inv", "n", "cell_start", "cell_tris", "base"])
TopSurface.__doc__ = """The shell's top surface over (u, v) (module doc): uv (T, 3, 2), top (T, 3, 3), nrm (T, 3, 3)
float64, base (T, 3, 3) the base surface's corners; grid lo (2,), inv (2,) cells per unit uv, n (2,) int64
cells; cell_start (G + 1,), cell_tris int64."""


def build_top_surface(base_uv, base_triangles, base_vertices, base_normals, thickness) -> TopSurface:
    UV = np.asarray(base_uv, np.float64)
    F = np.asarray(base_triangles, np.int64)
    V = np.asarray(base_vertices, np.float64)
    N = np.asarray(base_normals, np.float64)
    uv = UV[F]
    top = (V + float(thickness) * N)[F]
    nrm = N[F]
    lo = UV.min(axis=0)
    hi = UV.max(axis=0)
    span = np.maximum(hi - lo, 1e-12)
    side = max(1, int(math.ceil(math.sqrt(len(F)))))
    n = np.array([side, side], np.int64)
    inv = n / span
    tlo = np.floor((uv.min(axis=1) - lo) * inv).astype(np.int64).clip(0, n - 1)
    thi = np.floor((uv.max(axis=1) - lo) * inv).astype(np.int64).clip(0, n - 1)
    cells = [[] for _ in range(int(n[0] * n[1]))]
    for t in range(len(F)):
        for i in range(tlo[t, 0], thi[t, 0] + 1):
            for j in range(tlo[t, 1], thi[t, 1] + 1):
                cells[i * n[1] + j].append(t)
    start = np.zeros(len(cells) + 1, np.int64)
    start[1:] = np.cumsum([len(c) for c in cells])
    tris = np.array([t for c in cells for t in c], np.int64)
    return TopSurface(np.ascontiguousarray(uv), np.ascontiguousarray(top), np.ascontiguousarray(nrm), lo,
                      inv, n, start, tris, np.ascontiguousarray(V[F]))


@njit(cache=True)
def _barycentric(uv, t, u, v):
    ax = uv[t, 0, 0]
    ay = uv[t, 0, 1]
    e1x = uv[t, 1, 0] - ax
    e1y = uv[t, 1, 1] - ay
    e2x = uv[t, 2, 0] - ax
    e2y = uv[t, 2, 1] - ay
    det = e1x * e2y - e1y * e2x
    if det == 0.0:
        return -np.inf, 0.0, 0.0
    px = u - ax
    py = v - ay
    b1 = (px * e2y - py * e2x) / det
    b2 = (e1x * py - e1y * px) / det
    return 1.0 - b1 - b2, b1, b2


@njit(cache=True)
def top_point(ts, u, v):
    """(found, x, y, z, nx, ny, nz): the top surface point above (u, v) and its unit normal (module doc)."""
    return _surface_point(ts, ts.top, u, v)


@njit(cache=True)
def base_point(ts, u, v):
    """(found, x, y, z, nx, ny, nz): the base surface point below (u, v) and its unit normal (module doc)."""
    return _surface_point(ts, ts.base, u, v)


@njit(cache=True)
def _surface_point(ts, T, u, v):
    """The point of the surface with triangle corners ``T`` (the top or the base) at (u, v), and its normal."""
    hi_u = ts.lo[0] + ts.n[0] / ts.inv[0]
    hi_v = ts.lo[1] + ts.n[1] / ts.inv[1]
    u = min(max(u, ts.lo[0]), hi_u)
    v = min(max(v, ts.lo[1]), hi_v)
    i = min(max(int(math.floor((u - ts.lo[0]) * ts.inv[0])), 0), ts.n[0] - 1)
    j = min(max(int(math.floor((v - ts.lo[1]) * ts.inv[1])), 0), ts.n[1] - 1)
    c = i * ts.n[1] + j
    best = -np.inf
    bt = -1
    b0 = b1 = b2 = 0.0
    for k in range(ts.cell_start[c], ts.cell_start[c + 1]):
        t = ts.cell_tris[k]
        w0, w1, w2 = _barycentric(ts.uv, t, u, v)
        m = min(w0, min(w1, w2))
        if m > best:
            best = m
            bt = t
            b0, b1, b2 = w0, w1, w2
            if m >= 0.0:
                break
    if bt < 0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0
    if best < 0.0:  # outside every triangle of the cell: clamp the weights onto the nearest one
        b0 = max(b0, 0.0)
        b1 = max(b1, 0.0)
        b2 = max(b2, 0.0)
        s = b0 + b1 + b2
        b0 /= s
        b1 /= s
        b2 /= s
    Nn = ts.nrm
    x = b0 * T[bt, 0, 0] + b1 * T[bt, 1, 0] + b2 * T[bt, 2, 0]
    y = b0 * T[bt, 0, 1] + b1 * T[bt, 1, 1] + b2 * T[bt, 2, 1]
    z = b0 * T[bt, 0, 2] + b1 * T[bt, 1, 2] + b2 * T[bt, 2, 2]
    nx = b0 * Nn[bt, 0, 0] + b1 * Nn[bt, 1, 0] + b2 * Nn[bt, 2, 0]
    ny = b0 * Nn[bt, 0, 1] + b1 * Nn[bt, 1, 1] + b2 * Nn[bt, 2, 1]
    nz = b0 * Nn[bt, 0, 2] + b1 * Nn[bt, 1, 2] + b2 * Nn[bt, 2, 2]
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nn > 0.0:
        nx /= nn
        ny /= nn
        nz /= nn
    return True, x, y, z, nx, ny, nz
