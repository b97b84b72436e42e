"""A scene's meshes (``[[meshes]]``: walls, floor, furniture) as an integrator sees them.

Every mesh's triangles in scene coordinates make one ``TriangleMesh`` (``stages.core.geometry.triangles``:
a SAH BVH, nearest hit and any hit), each mesh has one material row (``stages.core.shading.material``;
a Lambertian surface), ``mat_of_tri`` gives each triangle's row. Surfaces are two-sided, as the ground
plane (``stages.render.ground``): the shading normal is the triangle's geometric normal turned towards
the side the ray came from, so a wall lit from behind is dark on the camera's side and light does not
pass through it.

``SceneMeshes`` fields: ``mesh`` (TriangleMesh), ``mat_of_tri`` (T,) int32, ``mats`` (NM, MAT_SIZE),
``enabled`` (False for a scene without meshes: the queries answer "nothing" without a call, so a
mesh-free render runs the code it ran before meshes existed). ``no_meshes()`` is that empty value
(the same numba type as a scene's, so an integrator compiles once).

Queries (inlined into the integrator's loop): ``meshes_hit`` -> ``TriangleHit`` (t inf, tri -1 on a
miss), ``meshes_occluded`` (shadow rays), ``facing_normal_into`` (the unit normal of triangle ``tri``
facing against the ray direction d), ``mesh_albedo_into`` (the Lambertian albedo of triangle ``tri``'s mesh).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.triangles import TriangleHit, build_triangle_mesh, mesh_intersect, mesh_occluded
from stages.core.shading.material import MAT_SIZE, material_lambert_albedo

SceneMeshes = namedtuple("SceneMeshes", ["mesh", "mat_of_tri", "mats", "enabled"])


def scene_meshes(V, F, mat_of_tri, mats) -> SceneMeshes:
    """The ``SceneMeshes`` of vertices V (NV, 3), triangles F (T, 3), each triangle's material row and the rows."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    return SceneMeshes(build_triangle_mesh(np.asarray(V, np.float64).reshape(-1, 3), F),
                       np.ascontiguousarray(mat_of_tri, np.int32),
                       np.ascontiguousarray(mats, np.float64).reshape(-1, MAT_SIZE),
                       len(F) > 0)


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


@njit(cache=True, inline="always")
def facing_normal_into(sm, tri, dx, dy, dz, n):
    """Write into n the unit geometric normal of triangle ``tri`` (an index into the mesh's F) on the side
    a ray of direction d arrives from (n . d <= 0)."""
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
    if nx * dx + ny * dy + nz * dz > 0.0:
        length = -length
    n[0] = nx / length
    n[1] = ny / length
    n[2] = nz / length


@njit(cache=True, inline="always")
def mesh_albedo_into(sm, tri, out):
    """Write into out the Lambertian albedo (rgb) of the mesh triangle ``tri`` belongs to."""
    a = material_lambert_albedo(sm.mats[sm.mat_of_tri[tri]])
    for k in range(3):
        out[k] = a[k]
