"""A scene's meshes (``[[meshes]]``: walls, floor, furniture, area lights) as an integrator sees them.

Every mesh's triangles in scene coordinates make one ``TriangleMesh`` (``stages.core.geometry.triangles``:
a SAH BVH, nearest hit and any hit), each mesh has one material row (``stages.core.shading.material``:
a Lambertian surface or a rough dielectric), ``mat_of_tri`` gives each triangle's row. The shading normal is
the triangle's geometric normal turned towards the side the ray came from. A Lambertian surface is two-sided,
as the ground plane (``stages.render.ground``): a wall lit from behind is dark on the camera's side and light
does not pass through it. A dielectric (glass, water; ``stages.core.shading.microfacet``: GGX after Walter et
al. 2007) reflects on the arriving side and refracts through to the other, its relative index eta inside
over outside, the outside being where the triangle's counter-clockwise normal points (a closed mesh's
triangles wound outward); its rays leave from the side they go to. ``surface_eval`` and ``surface_sample``
shade either material; shadow rays stop at a dielectric as at any mesh (light through glass arrives by the
sampled paths only, as in Mitsuba 3 and pbrt).

``SceneMeshes`` fields: ``mesh`` (TriangleMesh), ``mat_of_tri`` (T,) int32, ``mats`` (NM, MAT_SIZE), and
the area lights: ``emission`` (NM, 3) the radiance each mesh emits (from both
sides, the same in every direction; 0: not a light), ``emitters`` (E,) int64 the emissive triangles
(indices into F), ``emit_cdf`` (E + 1,) their cumulative share of the emissive area, ``emit_area`` that
area, ``has_emitters``. A scene without meshes passes ``no_meshes()``, a ``NoMeshes`` (``has_emitters``
False, one unused material row, so that ``mats[mat_of_tri[tri]]`` types for both): every
query below is a stub answered per class (``stages.core.dispatch``), and for
``NoMeshes`` it is a constant, so an integrator of a mesh-free scene compiles no mesh code at all and runs
what it ran before meshes existed; a scene with meshes compiles the integrator once more, for ``SceneMeshes``.

Area lights (emissive meshes; Pharr, Jakob, Humphreys, *PBR* 4th ed. §12.2 and §13.4): next-event estimation
picks an emissive triangle by area and a point uniformly on it (``area_light_sample_into``: radiance,
the solid-angle pdf dist^2 / (cos_light A) and the distance, for a shadow ray that stops short of the
light); a ray that hits an emitter by chance receives its radiance (``emitted_radiance``) weighted by the
power heuristic against ``area_light_pdf`` (the same density), or fully when no vertex sampled the
lights before it (a camera ray).

Queries: ``meshes_hit`` -> ``TriangleHit`` (t inf, tri -1 on a miss), ``meshes_occluded`` (shadow rays),
``facing_normal_into`` (the unit normal of triangle ``tri`` facing against the ray direction d),
``surface_eval`` / ``surface_sample`` (the material of the mesh ``tri`` belongs to) and the area lights'
kernels;
for ``SceneMeshes`` each is a plain call, compiled once for every integrator. ``nee_light_sample_into``: light k
of next-event estimation, a distant light or (k = NL) the area lights, for the integrators that sample each light.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.geometry.frames import orthonormal_basis
from stages.core.geometry.triangles import TriangleHit, build_triangle_mesh, mesh_intersect, mesh_occluded
from stages.core.rng import uniform
from stages.core.shading.lambert import lambert_eval, lambert_pdf, lambert_sample_into
from stages.core.shading.material import MAT_DIELECTRIC, MAT_SIZE
from stages.core.shading.microfacet import rough_dielectric_eval, rough_dielectric_sample
from stages.render.lights import cdf_find, light_sample_into

SceneMeshes = namedtuple("SceneMeshes", ["mesh", "mat_of_tri", "mats", "emission", "emitters",
                                         "emit_cdf", "emit_area", "has_emitters"])
NoMeshes = namedtuple("NoMeshes", ["has_emitters", "mats", "mat_of_tri"])
LightSample = namedtuple("LightSample", ["r", "g", "b", "pdf", "delta", "dist"])


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
    return SceneMeshes(build_triangle_mesh(V, F), mat_of_tri, mats, emission,
                       emitters.astype(np.int64), cdf, total, total > 0.0)


def no_meshes() -> NoMeshes:
    """A scene without meshes (module doc)."""
    return NoMeshes(False, np.zeros((1, MAT_SIZE)), np.zeros(1, np.int32))


NUMBA_ONLY = "only callable from numba-compiled code"


# the queries every integrator calls (module doc): stubs, each answered below for SceneMeshes and NoMeshes
def meshes_hit(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """The nearest triangle along the ray in (tmin, tmax) (``TriangleHit``; t inf, tri -1 on a miss)."""
    raise TypeError(NUMBA_ONLY)


def meshes_occluded(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """True when a triangle lies along the ray in (tmin, tmax)."""
    raise TypeError(NUMBA_ONLY)


def facing_normal_into(sm, tri, dx, dy, dz, n):
    """Write into n the unit geometric normal of triangle ``tri`` (an index into the mesh's F) on the side
    a ray of direction d arrives from (n . d <= 0)."""
    raise TypeError(NUMBA_ONLY)


def surface_eval(sm, tri, n, wi, wo):
    """(f |cos| r, g, b, pdf of ``surface_sample``) of the material of triangle ``tri``'s mesh at a vertex whose
    normal n faces the arriving ray (towards wi): Lambertian (light on n's side only) or the rough dielectric
    (reflection on n's side, refraction from the other; module doc)."""
    raise TypeError(NUMBA_ONLY)


def surface_sample(sm, tri, n, wi, u0, u1, u2, wo):
    """A direction of the material of triangle ``tri``'s mesh into wo (n facing wi, as ``surface_eval``):
    (weight r, g, b, pdf), pdf 0 on failure. A Lambertian surface draws with (u1, u2) as
    ``lambert_sample_into``; the dielectric picks its lobe with u0 too."""
    raise TypeError(NUMBA_ONLY)


def emitted_radiance(sm, tri):
    """(r, g, b): the radiance triangle ``tri``'s mesh emits (0 for a mesh that is not a light)."""
    raise TypeError(NUMBA_ONLY)


def area_light_pdf(sm, tri, t, dx, dy, dz):
    """The solid-angle density with which ``area_light_sample_into`` picks the point at distance t along the
    unit direction d on emissive triangle ``tri``: t^2 / (|cos| A), A the emissive area."""
    raise TypeError(NUMBA_ONLY)


def area_light_sample_into(sm, px, py, pz, u0, u1, u2, w):
    """A point on the emissive triangles seen from p: an emitter picked by area (u0), a point uniform on it
    (u1, u2); the unit direction towards it into w. Returns (r, g, b, pdf, dist): the radiance it emits
    towards p, the solid-angle pdf (0 when the point cannot be used) and its distance."""
    raise TypeError(NUMBA_ONLY)


# ---- the kernels of SceneMeshes (their docs: the stubs above) --------------------------------------------
@njit(cache=True)
def _meshes_hit(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    return mesh_intersect(sm.mesh, ox, oy, oz, dx, dy, dz, tmin, tmax)


@njit(cache=True)
def _meshes_occluded(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    return mesh_occluded(sm.mesh, ox, oy, oz, dx, dy, dz, tmin, tmax)


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
def _facing_normal_into(sm, tri, dx, dy, dz, n):
    nx, ny, nz = _unit_normal(sm, tri)
    if nx * dx + ny * dy + nz * dz > 0.0:
        nx = -nx
        ny = -ny
        nz = -nz
    n[0] = nx
    n[1] = ny
    n[2] = nz


@njit(cache=True)
def _dielectric_side(sm, tri, n, row):
    """(eta across the surface from n's side, alpha, the frame (t, b) about n) of a dielectric row: eta the
    row's where n is the triangle's outward side (counter-clockwise winding), its inverse where n faces in."""
    gx, gy, gz = _unit_normal(sm, tri)
    eta = row[1] if gx * n[0] + gy * n[1] + gz * n[2] > 0.0 else 1.0 / row[1]
    t, b = orthonormal_basis(n[0], n[1], n[2])
    return eta, row[2], t, b


@njit(cache=True)
def _surface_eval(sm, tri, n, wi, wo):
    row = sm.mats[sm.mat_of_tri[tri]]
    if int(row[0]) != MAT_DIELECTRIC:
        f0, f1, f2 = lambert_eval(row[11:14], n, wi, wo)
        return f0, f1, f2, lambert_pdf(row[11:14], n, wi, wo)
    eta, alpha, t, b = _dielectric_side(sm, tri, n, row)
    value, pdf = rough_dielectric_eval(
        wi[0] * t[0] + wi[1] * t[1] + wi[2] * t[2], wi[0] * b[0] + wi[1] * b[1] + wi[2] * b[2],
        wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2], wo[0] * t[0] + wo[1] * t[1] + wo[2] * t[2],
        wo[0] * b[0] + wo[1] * b[1] + wo[2] * b[2], wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2], alpha, eta)
    return value, value, value, pdf


@njit(cache=True)
def _surface_sample(sm, tri, n, wi, u0, u1, u2, wo):
    row = sm.mats[sm.mat_of_tri[tri]]
    if int(row[0]) != MAT_DIELECTRIC:
        return lambert_sample_into(row[11:14], n, wi, u1, u2, wo)
    eta, alpha, t, b = _dielectric_side(sm, tri, n, row)
    ok, x, y, z, weight, pdf = rough_dielectric_sample(
        wi[0] * t[0] + wi[1] * t[1] + wi[2] * t[2], wi[0] * b[0] + wi[1] * b[1] + wi[2] * b[2],
        wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2], alpha, eta, u0, u1, u2)
    if not ok:
        return 0.0, 0.0, 0.0, 0.0
    for k in range(3):
        wo[k] = x * t[k] + y * b[k] + z * n[k]
    return weight, weight, weight, pdf


@njit(cache=True)
def _emitted_radiance(sm, tri):
    row = sm.mat_of_tri[tri]
    return sm.emission[row, 0], sm.emission[row, 1], sm.emission[row, 2]


@njit(cache=True)
def _area_light_pdf(sm, tri, t, dx, dy, dz):
    nx, ny, nz = _unit_normal(sm, tri)
    c = abs(nx * dx + ny * dy + nz * dz)
    if c <= 0.0:
        return 0.0
    return t * t / (c * sm.emit_area)


@njit(cache=True)
def _area_light_sample_into(sm, px, py, pz, u0, u1, u2, w):
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
    pdf = _area_light_pdf(sm, tri, dist, w[0], w[1], w[2])
    if pdf <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    r, g, bl = _emitted_radiance(sm, tri)
    return r, g, bl, pdf, dist


@njit(cache=True, inline="always")
def nee_light_sample_into(table, sm, k, px, py, pz, seed, key, dim, w):
    """Light k's sample for next-event estimation from p, its direction into w (``LightSample``: radiance, pdf,
    delta, distance): k below the number NL of distant lights of ``table`` (a ``LightTable``), that light, its two
    random numbers at dimensions dim and dim + 1; k = NL, a point on the area lights, at dim .. dim + 2. With
    dim = first + 2 k, the area lights' three dimensions follow the distant lights' pairs. A distant light's
    distance is inf."""
    if k < table.lights.shape[0]:
        r, g, b, pdf, delta = light_sample_into(table.lights, k, table.env, table.marginal, table.conditional,
                                                uniform(seed, key, dim), uniform(seed, key, dim + 1), w)
        return LightSample(r, g, b, pdf, delta, np.inf)
    r, g, b, pdf, dist = area_light_sample_into(sm, px, py, pz, uniform(seed, key, dim), uniform(seed, key, dim + 1),
                                                uniform(seed, key, dim + 2), w)
    return LightSample(r, g, b, pdf, False, dist)


# ---- the stubs' answers: the kernels above for SceneMeshes, constants for NoMeshes ----------------------
@overload(meshes_hit, inline="always")
def _ov_meshes_hit(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, ox, oy, oz, dx, dy, dz, tmin, tmax: _meshes_hit(sm, ox, oy, oz, dx, dy, dz, tmin, tmax)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, ox, oy, oz, dx, dy, dz, tmin, tmax: TriangleHit(np.inf, -1, 0.0, 0.0)


@overload(meshes_occluded, inline="always")
def _ov_meshes_occluded(sm, ox, oy, oz, dx, dy, dz, tmin, tmax):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, ox, oy, oz, dx, dy, dz, tmin, tmax: _meshes_occluded(sm, ox, oy, oz, dx, dy, dz, tmin,
                                                                               tmax)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, ox, oy, oz, dx, dy, dz, tmin, tmax: False


@overload(facing_normal_into, inline="always")
def _ov_facing_normal_into(sm, tri, dx, dy, dz, n):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, tri, dx, dy, dz, n: _facing_normal_into(sm, tri, dx, dy, dz, n)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, tri, dx, dy, dz, n: None


@overload(surface_eval, inline="always")
def _ov_surface_eval(sm, tri, n, wi, wo):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, tri, n, wi, wo: _surface_eval(sm, tri, n, wi, wo)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, tri, n, wi, wo: (0.0, 0.0, 0.0, 0.0)


@overload(surface_sample, inline="always")
def _ov_surface_sample(sm, tri, n, wi, u0, u1, u2, wo):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, tri, n, wi, u0, u1, u2, wo: _surface_sample(sm, tri, n, wi, u0, u1, u2, wo)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, tri, n, wi, u0, u1, u2, wo: (0.0, 0.0, 0.0, 0.0)


@overload(emitted_radiance, inline="always")
def _ov_emitted_radiance(sm, tri):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, tri: _emitted_radiance(sm, tri)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, tri: (0.0, 0.0, 0.0)


@overload(area_light_pdf, inline="always")
def _ov_area_light_pdf(sm, tri, t, dx, dy, dz):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, tri, t, dx, dy, dz: _area_light_pdf(sm, tri, t, dx, dy, dz)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, tri, t, dx, dy, dz: 0.0


@overload(area_light_sample_into, inline="always")
def _ov_area_light_sample_into(sm, px, py, pz, u0, u1, u2, w):
    if is_tuple_class(sm, SceneMeshes):
        return lambda sm, px, py, pz, u0, u1, u2, w: _area_light_sample_into(sm, px, py, pz, u0, u1, u2, w)
    if is_tuple_class(sm, NoMeshes):
        return lambda sm, px, py, pz, u0, u1, u2, w: (0.0, 0.0, 0.0, 0.0, 0.0)
