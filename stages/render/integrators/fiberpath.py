"""Explicit-fibre unidirectional path tracer (``--method fiberpath``).

Geometry: a surface scene (``stages.core.geometry.surface``): realized fibres as chains of capsules
traced by Embree 4 (``EmbreeFibers``, the renderer's default) or in loomlight's SAH BVH (``FiberBVH``),
or tiled exemplars under a shell map (``ShellScene``); the same estimator runs on all three. Optional
ground plane (``stages.render.ground``) and the scene's meshes (``stages.render.meshes``: walls, floor,
furniture). Materials: packed rows (``stages.core.shading.material``: the
BCSDF of Khungurn et al. 2015 or a Lambertian surface), one per fibre through ``mat_of_fiber``, a
Lambertian row for the ground and one per mesh (a mesh's Lambertian or rough dielectric row, shaded through
``stages.render.meshes``: ``surface_eval``, ``surface_sample``). Lights: ``stages.render.lights``
(distant) and the meshes that emit (area lights, ``stages.render.meshes``).

``FiberpathIntegrator`` fields: ``scene`` (EmbreeFibers | FiberBVH | ShellScene), ``mat_of_fiber`` (F,) int32 row of
each fibre, ``mats`` (NM, MAT_SIZE), ``ground_mat`` (MAT_SIZE,) the ground's Lambertian row,
``lights`` (``LightTable``), ``ground`` float64[4] and ``has_ground`` (``stages.render.ground``),
``meshes`` (``SceneMeshes``; ``no_meshes()`` for a scene without),
``max_depth``, ``rr_depth``, ``ign_window``, ``eps`` (ray offset, scene units).

Estimator
---------
At every scattering vertex, next-event estimation takes one sample of *each* light and combines it with
BSDF sampling by the power heuristic (per light: w_light = p_l^2 / (p_l^2 + p_f^2); when a BSDF-sampled
ray escapes, light k's radiance gets p_f^2 / (p_f^2 + p_k^2)); directional lights are delta lights,
sampled only by NEE. Area lights (emissive meshes) are one more light: NEE takes one point on them
(picked by area), its shadow ray stops short of it, and a BSDF-sampled ray that hits one gets its
radiance weighted against that sampling's density; a camera ray that hits one sees it unweighted. Camera
rays that escape see the environment (all non-delta lights) unweighted. ``max_depth`` is the largest
number of scattering events on a path (1 = direct lighting only); Russian roulette from scattering event
``rr_depth`` on, survival probability min(0.95, max channel of the throughput).

BCSDF vertices (curve materials): the scattered and shadow rays start on the fibre surface and skip
the segments of the same fibre within ``ign_window`` along the chain (a curve BCSDF does not
self-shadow; see ``stages.core.shading.bcsdf`` "Measure"); the renderer passes a window wider than
any fibre, i.e. the whole fibre is skipped. Lambertian, ground and mesh vertices: rays start offset
along the normal towards the side they leave into (the side the ray came from, but for a dielectric's
refraction) and test everything. Rays leaving a fibre of a
shell scene start in the tetrahedron of the hit.

Random numbers: ``uniform(seed, index, dim)`` for camera sample ``index`` (``stages.render.tiles``):
dimensions 0-1 place the sample in its pixel, then 4 + 2 NL per scattering event (lobe, direction,
roulette, one pair per light), and 3 more when meshes emit (the area lights' point), so the image is
identical for any thread count and tile order.

Speed: the estimator is compiled without numba's reference counting (``trace_path``, and the tile
loop with it: ``stages.render.tiles.tile_kernel``). The path's vectors live on the machine stack and
the BVH and shell queries take no references and allocate nothing, so no atomic reference-count
update touches the scene's arrays per ray; with two threads those updates had cost more than the
shading (``bench/bench_mitsuba.py``). What the loop calls per vertex (the Embree query, the material and
light kernels) is inlined: as a call, numba passes each array as its ~7 fields, and those ~40 stack
words per call were 5-10 % of the loop's own time in ``perf``. Azimuths come from
``stages.core.turns.sincos_turn``, not libm.
"""
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.geometry.stack import stack_array, stack_vector3
from stages.core.geometry.surface import Skip, surface_hit, surface_occluded
from stages.core.geometry.wide_walk import Ray
from stages.core.rng import uniform
from stages.core.sampling import continue_path, path_step, power_heuristic
from stages.core.shading.material import (
    CTX_SIZE,
    material_eval_pdf,
    material_is_curve,
    material_prepare,
)
from stages.render.ground import ground_intersect
from stages.render.integrator import PathSample, radiance
from stages.render.lights import add_escaped_radiance
from stages.render.meshes import (
    area_light_pdf,
    emitted_radiance,
    facing_normal_into,
    meshes_hit,
    meshes_occluded,
    nee_light_sample_into,
    surface_eval,
    surface_sample,
)

FiberpathIntegrator = namedtuple("FiberpathIntegrator", [
    "scene", "mat_of_fiber", "mats", "ground_mat", "lights", "ground", "has_ground", "meshes",
    "max_depth", "rr_depth", "ign_window", "eps"])

ON_FIBRE = 0     # what a path vertex lies on
ON_GROUND = 1
ON_MESH = 2


@njit(cache=True, inline="always")
def _trace(it, o, d, seed, key):
    """``PathSample`` of the camera ray (o, d) of camera sample ``key`` (see the module doc)."""
    lights = it.lights.lights
    eps = it.eps
    nl = lights.shape[0]
    sm = it.meshes
    area_dim = 4 + 2 * nl            # the area lights' three dimensions follow the distant lights' pairs
    dims_per_bounce = area_dim + 3 if sm.has_emitters else area_dim
    n_nee = nl + 1 if sm.has_emitters else nl   # the area lights are one more light
    tp0 = 1.0
    tp1 = 1.0
    tp2 = 1.0
    L0 = 0.0
    L1 = 0.0
    L2 = 0.0
    first_t = 0.0
    rays = 0
    ign_f = -1
    ign_s = -1
    cell = -1
    pdf_prev = 0.0
    t_tan = stack_vector3()   # per-path vectors live on the machine stack, not the heap
    n = stack_vector3()
    for k in range(3):
        t_tan[k] = 0.0
        n[k] = 0.0
    wi = stack_vector3()
    p = stack_vector3()
    so = stack_vector3()
    wo = stack_vector3()
    ctx = stack_array(CTX_SIZE, np.float64)
    wl = stack_vector3()
    depth = 0
    while True:
        h = surface_hit(it.scene, cell, Ray(o[0], o[1], o[2], d[0], d[1], d[2]), eps, np.inf,
                        Skip(ign_f, ign_s, it.ign_window))
        t_hit = h.t
        rays += 1
        on = ON_FIBRE
        tg = ground_intersect(it.ground, it.has_ground, o[2], d[2], eps)
        if tg < t_hit:
            t_hit = tg
            on = ON_GROUND
        mh = meshes_hit(it.meshes, o[0], o[1], o[2], d[0], d[1], d[2], eps, t_hit)
        if mh.tri >= 0:
            t_hit = mh.t
            on = ON_MESH
        if h.prim < 0 and on == ON_FIBRE:  # escaped: environment radiance, MIS-weighted against the previous NEE
            L0, L1, L2 = add_escaped_radiance(it.lights, d, depth > 0, pdf_prev, tp0, tp1, tp2, L0, L1, L2)
            break
        if depth == 0:
            first_t = t_hit
        if on == ON_MESH and sm.has_emitters:   # an area light: its radiance, MIS-weighted against its NEE
            er, eg, eb = emitted_radiance(sm, mh.tri)
            if er > 0.0 or eg > 0.0 or eb > 0.0:
                w = 1.0
                if depth > 0:
                    w = power_heuristic(pdf_prev, area_light_pdf(sm, mh.tri, t_hit, d[0], d[1], d[2]))
                L0 += tp0 * er * w
                L1 += tp1 * eg * w
                L2 += tp2 * eb * w
        if depth >= it.max_depth:
            break
        for k in range(3):
            p[k] = o[k] + t_hit * d[k]
            wi[k] = -d[k]
        # the vertex: its material, shading frame and where continuation rays start
        if on == ON_FIBRE:
            mat = it.mats[it.mat_of_fiber[h.fiber]]
            t_tan[0] = h.tx
            t_tan[1] = h.ty
            t_tan[2] = h.tz
            n[0] = h.nx
            n[1] = h.ny
            n[2] = h.nz
            if material_is_curve(mat):
                nf = h.fiber
                ns = h.prim
                for k in range(3):
                    so[k] = p[k]
            else:
                nf = -1
                ns = -1
                off = 1e-3 * h.radius + eps
                for k in range(3):
                    so[k] = p[k] + off * n[k]
            next_cell = h.cell
        else:   # the ground or a mesh: an opaque two-sided surface
            if on == ON_GROUND:
                mat = it.ground_mat
                n[0] = 0.0
                n[1] = 0.0
                n[2] = 1.0 if d[2] < 0.0 else -1.0
            else:
                mat = it.meshes.mats[it.meshes.mat_of_tri[mh.tri]]
                facing_normal_into(it.meshes, mh.tri, d[0], d[1], d[2], n)
            nf = -1
            ns = -1
            for k in range(3):
                so[k] = p[k] + eps * n[k]
            next_cell = -1
        material_prepare(mat, t_tan, n, wi, ctx)
        base = 2 + depth * dims_per_bounce
        # next-event estimation: one sample per light, and one point on the area lights (light nl)
        for k in range(n_nee):
            lr, lg, lb, pl, delta, dist = nee_light_sample_into(it.lights, sm, k, so[0], so[1], so[2], seed, key,
                                                                base + 4 + 2 * k, wl)
            reach = dist - eps     # a shadow ray to an area light stops short of its surface (inf: distant)
            if pl <= 0.0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
                continue
            if on == ON_MESH:
                f0, f1, f2, pf = surface_eval(it.meshes, mh.tri, n, wi, wl)
            else:
                f0, f1, f2, pf = material_eval_pdf(mat, ctx, t_tan, n, wi, wl)
            if f0 == 0.0 and f1 == 0.0 and f2 == 0.0:
                continue
            rays += 1
            # the shadow ray leaves from the light's side of the surface (a dielectric's refraction: the far side)
            side = eps if on == ON_FIBRE or wl[0] * n[0] + wl[1] * n[1] + wl[2] * n[2] >= 0.0 else -eps
            sx = so[0] if side > 0.0 else p[0] + side * n[0]
            sy = so[1] if side > 0.0 else p[1] + side * n[1]
            sz = so[2] if side > 0.0 else p[2] + side * n[2]
            if surface_occluded(it.scene, next_cell, Ray(sx, sy, sz, wl[0], wl[1], wl[2]), eps, reach,
                                Skip(nf, ns, it.ign_window)):
                continue
            if ground_intersect(it.ground, it.has_ground, sz, wl[2], eps) < reach:
                continue
            if meshes_occluded(it.meshes, sx, sy, sz, wl[0], wl[1], wl[2], eps, reach):
                continue
            if delta:
                w = 1.0
            else:
                w = power_heuristic(pl, pf) / pl
            L0 += tp0 * f0 * lr * w
            L1 += tp1 * f1 * lg * w
            L2 += tp2 * f2 * lb * w
        # scatter: the next direction, the throughput, Russian roulette from event rr_depth on
        roulette = depth + 1 >= it.rr_depth
        if on == ON_MESH:
            s0, s1, s2, pf = surface_sample(it.meshes, mh.tri, n, wi, uniform(seed, key, base),
                                            uniform(seed, key, base + 1), uniform(seed, key, base + 2), wo)
            step = path_step(s0, s1, s2, pf, roulette, seed, key, base, (tp0, tp1, tp2))
            if wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2] < 0.0:   # refracted: it leaves from the far side
                for k in range(3):
                    so[k] = p[k] - eps * n[k]
        else:
            step = continue_path(mat, ctx, t_tan, n, wi, roulette, seed, key, base, (tp0, tp1, tp2), wo)
        if not step.alive:
            break
        tp0, tp1, tp2 = step.tp
        depth += 1
        pdf_prev = step.pdf
        for k in range(3):
            o[k] = so[k]
            d[k] = wo[k]
        ign_f = nf
        ign_s = ns
        cell = next_cell
    return PathSample(L0, L1, L2, 1.0 if first_t > 0.0 else 0.0, first_t, 0, rays)


@njit(cache=True, _nrt=False)
def trace_path(it, o, d, seed, key):
    """``PathSample`` of the camera ray (o, d) of camera sample ``key`` (see the module doc), compiled
    without reference counting: no atomic reference-count updates on the scene's arrays per call,
    which with two threads cost more than the shading."""
    return _trace(it, o, d, seed, key)


# stages.render.tiles.tile_kernel: the tile loop may be compiled without reference counting too
FiberpathIntegrator.reference_free = True


@overload(radiance)
def _fiberpath_radiance(integ, o, d, seed, index):
    if is_tuple_class(integ, FiberpathIntegrator):
        return lambda integ, o, d, seed, index: trace_path(integ, o, d, seed, index)
