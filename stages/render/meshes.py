"""A scene's meshes (``[[meshes]]``: walls, floor, furniture, area lights) as an integrator sees them.

Every mesh's triangles in scene coordinates make one ``TriangleMesh`` (``stages.core.geometry.triangles``:
a SAH BVH, nearest hit and any hit), each mesh has one material row (``stages.core.shading.material``;
a Lambertian surface), ``mat_of_tri`` gives each triangle's row. Surfaces are two-sided, as the ground
plane (``stages.render.ground``): the shading normal is the triangle's geometric normal turned towards
the side the ray came from, so a wall lit from behind is dark on the camera's side and light does not
pass through it.

``SceneMeshes`` fields: ``mesh`` (TriangleMesh), ``mat_of_tri`` (T,) int32, ``mats`` (NM, MAT_SIZE),
``enabled`` (False for a scene without meshes: the queries answer "nothing" without a call, so a
mesh-free render runs the code it ran before meshes existed), and the area lights: ``emission`` (NM, 3)
the radiance each mesh emits (from both sides, the same in every direction; 0: not a light),
``emitters`` (E,) int64 the emissive triangles (indices into F), ``emit_cdf`` (E + 1,) their cumulative
share of the emissive area, ``emit_area`` that area, ``has_emitters``. ``no_meshes()`` is the empty value
(the same numba type as a scene's, so an integrator compiles once).

Area lights (emissive meshes; Pharr, Jakob, Humphreys, *PBR* 4th ed. §12.2 and §13.4): next-event estimation
picks an emissive triangle by area and a point uniformly on it (``area_light_sample_into``: radiance,
the solid-angle pdf dist^2 / (cos_light A) and the distance, for a shadow ray that stops short of the
light); a ray that hits an emitter by chance receives its radiance (``emitted_radiance``) weighted by the
power heuristic against ``area_light_pdf`` (the same density), or fully when no vertex sampled the
lights before it (a camera ray).

Queries: ``meshes_hit`` -> ``TriangleHit`` (t inf, tri -1 on a miss) and ``meshes_occluded`` (shadow rays),
inlined into the integrator's loop so that a scene without meshes pays no call; ``facing_normal_into`` (the
unit normal of triangle ``tri`` facing against the ray direction d), ``mesh_albedo_into`` (the Lambertian
albedo of the mesh ``tri`` belongs to) and the area lights' kernels are plain calls, compiled once for every
integrator (inlined, they cost each integrator's compile time and bought nothing measurable).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.triangles import TriangleHit, build_triangle_mesh, mesh_intersect, mesh_occluded
from stages.core.shading.material import MAT_SIZE, material_lambert_albedo
from stages.render.lights import cdf_find

SceneMeshes = namedtuple("SceneMeshes", ["mesh", "mat_of_tri", "mats", "enabled", "emission", "emitters",
                                         "emit_cdf", "emit_area", "has_emitters"])


def triangle_areas(V, F) -> np.ndarray:
    """The area of every triangle of F (T,)."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64).reshape(-1, 3)
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def scene_meshes(V, F, mat_of_tri, mats, emission=None) -> SceneMeshes:
    """The ``SceneMeshes`` of vertices V (NV, 3), triangles F (T, 3), each triangle's material row, the rows and
    each row's emitted radiance (NM, 3) (None: nothing emits)."""
    V = np.asarray(V, np.float64).reshape(-1, 3)
    F = np.asarray(F, np.int64).reshape(-1, 3)
    mats = np.ascontiguousarray(mats, np.float64).reshape(-1, MAT_SIZE)
    mat_of_tri = np.ascontiguousarray(mat_of_tri, np.int32)
    emission = np.zeros((len(mats), 3)) if emission is None else np.ascontiguousarray(emission, np.float64)
    area = triangle_areas(V, F)
    emitters = np.flatnonzero((emission[mat_of_tri].max(axis=1) > 0.0) & (area > 0.0)) if len(F) else \
        np.zeros(0, np.int64)
    cdf = np.concatenate([[0.0], np.cumsum(area[emitters])])
    total = float(cdf[-1])
    cdf = cdf / total if total > 0.0 else cdf
    return SceneMeshes(build_triangle_mesh(V, F), mat_of_tri, mats, len(F) > 0, emission,
                       emitters.astype(np.int64), cdf, total, total > 0.0)


def no_meshes() -> SceneMeshes:
    """A scene without meshes (module doc)."""
    return scene_meshes(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int32), np.zeros((1, MAT_SIZE)))


@njit(cache=True, inline="always")
def meshes_hit(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """The nearest triangle along the ray in (tmin, tmax) (``TriangleHit``; tri -1 on a miss)."""
    if not sm.enabled:
        return TriangleHit(np.inf, -1, 0.0, 0.0)
    return mesh_intersect(sm.mesh, ox, oy, oz, dx, dy, dz, tmin, tmax)


@njit(cache=True, inline="always")
def meshes_occluded(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """True when a triangle lies along the ray in (tmin, tmax)."""
    return sm.enabled and mesh_occluded(sm.mesh, ox, oy, oz, dx, dy, dz, tmin, tmax)


@njit(cache=True)
def _unit_normal(sm, tri):
    """The unit geometric normal (e1 x e2 normalised) of triangle ``tri`` (an index into the mesh's F)."""
    V = sm.mesh.vertices
    F = sm.mesh.triangles
    a = F[tri, 0]
    b = F[tri, 1]
    c = F[tri, 2]
    e1x = V[b, 0] - V[a, 0]
    e1y = V[b, 1] - V[a, 1]
    e1z = V[b, 2] - V[a, 2]
    e2x = V[c, 0] - V[a, 0]
    e2y = V[c, 1] - V[a, 1]
    e2z = V[c, 2] - V[a, 2]
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    return nx / length, ny / length, nz / length


@njit(cache=True)
def facing_normal_into(sm, tri, dx, dy, dz, n):
    """Write into n the unit geometric normal of triangle ``tri`` (an index into the mesh's F) on the side
    a ray of direction d arrives from (n . d <= 0)."""
    nx, ny, nz = _unit_normal(sm, tri)
    if nx * dx + ny * dy + nz * dz > 0.0:
        nx = -nx
        ny = -ny
        nz = -nz
    n[0] = nx
    n[1] = ny
    n[2] = nz


@njit(cache=True)
def mesh_albedo_into(sm, tri, out):
    """Write into out the Lambertian albedo (rgb) of the mesh triangle ``tri`` belongs to."""
    a = material_lambert_albedo(sm.mats[sm.mat_of_tri[tri]])
    for k in range(3):
        out[k] = a[k]


@njit(cache=True)
def emitted_radiance(sm, tri):
    """(r, g, b): the radiance triangle ``tri``'s mesh emits (0 for a mesh that is not a light)."""
    row = sm.mat_of_tri[tri]
    return sm.emission[row, 0], sm.emission[row, 1], sm.emission[row, 2]


@njit(cache=True)
def area_light_pdf(sm, tri, t, dx, dy, dz):
    """The solid-angle density with which ``area_light_sample_into`` picks the point at distance t along the
    unit direction d on emissive triangle ``tri``: t^2 / (|cos| A), A the emissive area."""
    nx, ny, nz = _unit_normal(sm, tri)
    c = abs(nx * dx + ny * dy + nz * dz)
    if c <= 0.0:
        return 0.0
    return t * t / (c * sm.emit_area)


@njit(cache=True)
def area_light_sample_into(sm, px, py, pz, u0, u1, u2, w):
    """A point on the emissive triangles seen from p: an emitter picked by area (u0), a point uniform on it
    (u1, u2); the unit direction towards it into w. Returns (r, g, b, pdf, dist): the radiance it emits
    towards p, the solid-angle pdf (0 when the point cannot be used) and its distance."""
    j = cdf_find(sm.emit_cdf, u0)
    tri = sm.emitters[j]
    V = sm.mesh.vertices
    F = sm.mesh.triangles
    a = F[tri, 0]
    b = F[tri, 1]
    c = F[tri, 2]
    su = math.sqrt(u1)
    wa = 1.0 - su
    wb = su * (1.0 - u2)
    wc = su * u2
    qx = wa * V[a, 0] + wb * V[b, 0] + wc * V[c, 0]
    qy = wa * V[a, 1] + wb * V[b, 1] + wc * V[c, 1]
    qz = wa * V[a, 2] + wb * V[b, 2] + wc * V[c, 2]
    dx = qx - px
    dy = qy - py
    dz = qz - pz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    w[0] = dx / dist
    w[1] = dy / dist
    w[2] = dz / dist
    pdf = area_light_pdf(sm, tri, dist, w[0], w[1], w[2])
    if pdf <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    r, g, bl = emitted_radiance(sm, tri)
    return r, g, bl, pdf, dist
