"""Volumetric path tracer for fibre media (seed 000 §5.4).

Unidirectional path tracing through an anisotropic medium given by a density source
(``stages.render.media.medium``): free flights by delta tracking on a majorant grid
(``stages.render.media.tracking``), scattering by the fibres' BCSDF (below) or the specular micro-flake
phase function sampled exactly (weight = albedo), next-event estimation toward the lights with ratio-tracked
transmittance, multiple importance sampling (power heuristic) between light sampling and phase /
BSDF sampling for lights that a ray can hit (environment: constant, SG, envmap), Russian roulette
after ``rr_depth`` interactions, and at most ``max_depth`` path segments (Mitsuba's convention:
max_depth = 1 shows only directly visible emitters). An optional diffuse ground plane z = height
(Lambertian, RGB albedo) catches shadows, and the scene's meshes (``stages.render.meshes``: Lambertian,
two-sided, opaque) bound the free flights, scatter and block shadow rays as the ground does. Meshes that
emit are area lights: one more light for next-event estimation to pick (the fraction of the pick's random
number left over picks the triangle), with a shadow ray that stops short of the point, and a ray that hits
one gets its radiance MIS-weighted as an escaping ray gets the environment's.

Fibre phase function. A volume that stands for explicit fibres (realized or procedural: the source
knows the yarn of the covering fibre) can scatter as those fibres do: with ``mats`` holding a
material row per yarn (``stages.core.shading.material``: the yarn's fibre BCSDF dyed to its colour by
``pipeline.dye``), a collision in yarn y is fiberpath's BCSDF vertex -- next-event estimation with
S(wi, wl) cos(theta_l), sampling by the BCSDF, the sample weight S cos / pdf carrying the fibre's albedo --
at the fibre tangent there.
This is the radiative transfer of a cloud of thin opaque fibres: extinction density x projected width
(den sin(theta_t) with den = 2 / (pi r), the fibres' projected area per volume, ``pipeline.presets``),
in-scattering sigma_t(wi) int S(wi, wo) cos(theta_o) L(wo) dwo, so volpath is the homogenised limit of
fiberpath on the same fibres. As in fiberpath, the scattered and shadow rays do not meet the fibre
they leave (its medium is skipped: the BCSDF already accounts for the fibre as a whole) but meet
every other, the fibres overlapping it included (``medium_lookup``'s skip; skipping whatever
answered the lookup instead left holes where fibres overlap, and volpath was up to 10 % brighter
than fiberpath under low lights). Collisions whose yarn is unknown (voxel grids, test boxes) or
without a row (``mats`` empty: ``--set phase=microflake``) use the micro-flake phase function of
seed 000 App. A.

``VolpathIntegrator`` fields: ``medium`` (a density source, ``stages.render.media.medium``), ``majorant``
(its ``MajorantGrid``), ``lights`` (``LightTable``, ``stages.render.lights``), ``ground`` float64[4]
and ``has_ground`` (``stages.render.ground``), ``meshes`` (``SceneMeshes``; ``no_meshes()`` for none),
``max_depth``, ``rr_depth``, ``mats`` (Y, MAT_SIZE) material rows per yarn (0 rows: micro-flakes
everywhere). Its ``radiance``
(``stages.render.integrator``) reports the medium lookups and rays (free-flight and shadow queries)
of each path; the tile loop is ``stages.render.tiles``.
Speed: ``trace_path``, the free-flight tracking and the density sources' lookups (procedural, cached,
realized) are compiled without numba's reference counting, as fiberpath is: the path's vectors live on
the machine stack and no kernel returns an array, so the tile loop (``stages.render.tiles.tile_kernel``)
takes no references either. With reference counting, the atomic updates for every array of every
namedtuple a lookup unpacks (the procedural tables, the curves) took about half of the render's time.
Random numbers: uniform(seed, pixel * spp + sample, dim) with pixel jitter in dims 0-1, so the image
is a pure function of the inputs, whatever the number of threads or the tiling.
"""

from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class, runtime_value
from stages.core.geometry.stack import stack_array, stack_vector3
from stages.core.rng import uniform
from stages.core.sampling import power_heuristic, roulette_survival
from stages.core.shading.lambert import lambert_eval, lambert_pdf, lambert_sample_into
from stages.core.shading.material import CTX_SIZE, material_eval_pdf, material_prepare, material_sample
from stages.core.shading.sggx import fiber_sggx, phase_eval, phase_sample
from stages.render.ground import ground_intersect
from stages.render.integrator import PathSample, radiance
from stages.render.lights import environment_radiance, light_eval, light_pdf, light_sample_into
from stages.render.media.medium import PAGED_OUT_YARN
from stages.render.media.tracking import track
from stages.render.meshes import (
    area_light_pdf,
    area_light_sample_into,
    emitted_radiance,
    facing_normal_into,
    meshes_hit,
    meshes_occluded,
    surface_eval,
    surface_sample,
)

VolpathIntegrator = namedtuple("VolpathIntegrator", ["medium", "majorant", "lights", "ground", "has_ground",
                                                     "meshes", "max_depth", "rr_depth", "mats"])

SURFACE_OFFSET = 1e-7   # rays leave the ground or a mesh this far off it, relative to 1 + |the point|'s largest
AREA_SHADOW_SHORT = 1e-6   # a shadow ray to a point on an area light stops this fraction of its length short


@njit(cache=True, _nrt=False)
def _transmittance(it, px, py, pz, wx, wy, wz, reach, seed, index, dim, skip_fibre):
    """Ratio-tracked transmittance through the integrator's medium toward direction w up to distance ``reach``
    (inf: a distant light; short of a point on an area light), not counting fibre ``skip_fibre``; the ground
    and the meshes occlude."""
    if ground_intersect(it.ground, it.has_ground, pz, wz, 0.0) < reach:
        return 0.0, dim, 0
    if meshes_occluded(it.meshes, px, py, pz, wx, wy, wz, 0.0, reach):
        return 0.0, dim, 0
    fl = track(it.medium, it.majorant, px, py, pz, wx, wy, wz, reach, seed, index, runtime_value(dim),
               runtime_value(True), runtime_value(skip_fibre))
    return fl.transmittance, fl.dim, fl.lookups


@njit(cache=True, _nrt=False)
def _escaped(lt, n, prev_pdf, dx, dy, dz):
    """Radiance of the lights a ray leaving the scene sees, MIS-weighted per light against the
    light-sampling strategy (light k picked with probability 1/NL, then its own pdf)."""
    lights, env, marg, cond = lt
    w = stack_vector3()
    w[0] = dx
    w[1] = dy
    w[2] = dz
    if n == 0:
        return environment_radiance(lights, env, marg, cond, w)
    nl = lights.shape[0]
    r = 0.0
    g = 0.0
    b = 0.0
    for k in range(nl):
        lr, lg, lb = light_eval(lights, k, env, marg, cond, w)
        if lr == 0.0 and lg == 0.0 and lb == 0.0:
            continue
        mis = power_heuristic(prev_pdf, light_pdf(lights, k, env, marg, cond, w) / nl)
        r += lr * mis
        g += lg * mis
        b += lb * mis
    return r, g, b


@njit(cache=True, _nrt=False)
def _add_light(it, px, py, pz, lw, reach, seed, index, dim, skip_fibre, lpdf, ldelta, pdf_scatter, scale, a0, a1,
               a2, Lr, Lg, Lb):
    """(Lr, Lg, Lb, dim, lookups) after next-event estimation toward the light sample lw from p: L += a c with
    c = scale x the transmittance (``_transmittance`` up to ``reach``, not counting fibre ``skip_fibre``) x the
    MIS weight against scattering's pdf (1 for a delta light) / the light's pdf; L unchanged where the light is
    shadowed.
    20 parameters: the integrator, the point, light direction and distance, the random stream (seed, index,
    dim), the skipped fibre, the two pdfs and whether the light is a delta, the scale, the path's unshadowed
    contribution per channel and the radiance so far, all scalars kept in registers."""
    tr, dim, lk = _transmittance(it, px, py, pz, lw[0], lw[1], lw[2], reach, seed, index, dim, skip_fibre)
    if tr > 0.0:
        c = scale * tr * (1.0 if ldelta else power_heuristic(lpdf, pdf_scatter)) / lpdf
        Lr += a0 * c
        Lg += a1 * c
        Lb += a2 * c
    return Lr, Lg, Lb, dim, lk


@njit(cache=True, _nrt=False)
def _scattered(br, bg, bb, w0, w1, w2, wsc):
    """(the throughput times the sample weight (w0, w1, w2), the sampled direction in ``wsc``)."""
    return br * w0, bg * w1, bb * w2, wsc[0], wsc[1], wsc[2]


@njit(cache=True, inline="always")
def fibre_phase(yarn, mats):
    """True when the collision is with a fibre of a yarn that has a material row (fibre phase function;
    model -1 marks a yarn that scatters by micro-flakes)."""
    return 0 <= yarn < mats.shape[0] and mats[yarn, 0] >= 0.0


@njit(cache=True, _nrt=False)
def trace_path(it, o, d, seed, index):
    """``PathSample`` of the camera ray (o, d) of camera sample ``index`` (see the module doc)."""
    med = it.medium
    maj = it.majorant
    lt = it.lights
    ground = it.ground
    ground_on = it.has_ground
    max_depth = it.max_depth
    rr_depth = it.rr_depth
    mats = it.mats
    ox = o[0]
    oy = o[1]
    oz = o[2]
    dx = d[0]
    dy = d[1]
    dz = d[2]
    lights, env, marg, cond = lt
    nl = lights.shape[0]
    sm = it.meshes
    n_pick = nl + 1 if sm.has_emitters else nl   # next-event estimation picks one light; the area lights are one
    Lr = 0.0
    Lg = 0.0
    Lb = 0.0
    br = 1.0
    bg = 1.0
    bb = 1.0
    dim = 2
    lookups = 0
    rays = 0
    n = 0
    prev_pdf = 0.0  # pdf of the direction sampled at the previous interaction
    hit = 0.0
    first_t = 0.0
    # per-path vectors on the machine stack (the estimator takes no references: module doc, "Speed")
    nrm = stack_vector3()
    wi = stack_vector3()
    tan = stack_vector3()
    wsc = stack_vector3()
    lw = stack_vector3()
    ctx = stack_array(CTX_SIZE, np.float64)
    alb = stack_vector3()
    for k in range(3):
        nrm[k] = 0.0
        lw[k] = 0.0
    skip = np.int64(-1)  # the fibre the ray leaves after a fibre-phase collision (not met again)
    while True:
        tg = ground_intersect(ground, ground_on, oz, dz, 1e-9)   # the nearest opaque surface: the ground ...
        mh = meshes_hit(it.meshes, ox, oy, oz, dx, dy, dz, 0.0, tg)   # ... or a mesh
        if mh.tri >= 0:
            tg = mh.t
        fl = track(med, maj, ox, oy, oz, dx, dy, dz, tg, seed, index, runtime_value(dim), runtime_value(False),
                   runtime_value(skip))
        rays += 1
        collided = fl.collided
        t = fl.t
        dim = fl.dim
        lookups += fl.lookups
        if collided and fl.point.yarn == PAGED_OUT_YARN:
            break  # the medium could not answer yet (medium.PAGED_OUT): this sample's pixel is rendered again
        if not collided and tg == np.inf:
            er, eg, eb = _escaped(lt, n, prev_pdf, dx, dy, dz)
            Lr += br * er
            Lg += bg * eg
            Lb += bb * eb
            break
        if n == 0:
            hit = 1.0
            first_t = t if collided else tg
        if not collided and mh.tri >= 0 and sm.has_emitters:   # an area light, MIS-weighted against its NEE
            er, eg, eb = emitted_radiance(sm, mh.tri)
            if er > 0.0 or eg > 0.0 or eb > 0.0:
                w = 1.0
                if n > 0:
                    w = power_heuristic(prev_pdf, area_light_pdf(sm, mh.tri, tg, dx, dy, dz) / n_pick)
                Lr += br * er * w
                Lg += bg * eg * w
                Lb += bb * eb * w
        n += 1
        if n >= max_depth:
            break
        u1 = uniform(seed, index, dim)
        u2 = uniform(seed, index, dim + 1)
        u3 = uniform(seed, index, dim + 2)
        u4 = uniform(seed, index, dim + 3)
        u5 = uniform(seed, index, dim + 4)
        dim += 5
        next_skip = np.int64(-1)
        # the vertex p: the collision, or the surface's point just off it towards the arriving ray
        if collided:
            px = ox + t * dx
            py = oy + t * dy
            pz = oz + t * dz
        else:
            # a Lambertian surface (the ground or a mesh), shading normal toward the arriving ray
            px = ox + tg * dx
            py = oy + tg * dy
            if mh.tri >= 0:   # its material: surface_eval / surface_sample
                facing_normal_into(it.meshes, mh.tri, dx, dy, dz, nrm)
                pz = oz + tg * dz
                soff = SURFACE_OFFSET * (1.0 + max(abs(px), abs(py), abs(pz)))
                px += soff * nrm[0]
                py += soff * nrm[1]
                pz += soff * nrm[2]
            else:
                nrm[0] = 0.0
                nrm[1] = 0.0
                nrm[2] = 1.0 if dz < 0.0 else -1.0
                for q in range(3):
                    alb[q] = ground[1 + q]
                soff = SURFACE_OFFSET * (1.0 + abs(ground[0]))
                pz = ground[0] + nrm[2] * soff
        # next-event estimation picks one light
        reach = np.inf
        if n_pick > 0:
            k = min(int(u3 * n_pick), n_pick - 1)
            if k < nl:
                ler, leg, leb, lpdf, ldelta = light_sample_into(lights, k, env, marg, cond, u1, u2, lw)
            else:   # the area lights, seen from p; the pick's leftover fraction picks the triangle
                ler, leg, leb, lpdf, dist = area_light_sample_into(sm, px, py, pz, min(u3 * n_pick - k, 1.0), u1, u2,
                                                                   lw)
                ldelta = False
                reach = dist * (1.0 - AREA_SHADOW_SHORT)
            lpdf /= n_pick
        else:
            ler = leg = leb = lpdf = 0.0
            ldelta = False
        if collided and fibre_phase(fl.point.yarn, mats):
            # the fibre's own scattering function: fiberpath's vertex (module doc, "Fibre phase function")
            m = fl.point
            mat = mats[m.yarn]
            tan[0] = m.tx
            tan[1] = m.ty
            tan[2] = m.tz
            wi[0] = -dx
            wi[1] = -dy
            wi[2] = -dz
            material_prepare(mat, tan, tan, wi, ctx)  # (a curve material ignores the normal argument)
            if lpdf > 0.0:
                f0, f1, f2, pf = material_eval_pdf(mat, ctx, tan, tan, wi, lw)
                if f0 > 0.0 or f1 > 0.0 or f2 > 0.0:
                    Lr, Lg, Lb, dim, lk = _add_light(it, px, py, pz, lw, reach, seed, index, dim, m.fibre, lpdf,
                                                     ldelta, pf, 1.0, br * ler * f0, bg * leg * f1, bb * leb * f2,
                                                     Lr, Lg, Lb)
                    lookups += lk
                    rays += 1
            u6 = uniform(seed, index, dim)
            dim += 1
            w0, w1, w2, pdf = material_sample(mat, ctx, tan, tan, wi, u6, u4, u5, wsc)
            if pdf <= 0.0:
                break
            br, bg, bb, wx, wy, wz = _scattered(br, bg, bb, w0, w1, w2, wsc)
            prev_pdf = pdf
            next_skip = m.fibre
        elif collided:
            m = fl.point
            br *= m.albedo_r
            bg *= m.albedo_g
            bb *= m.albedo_b
            S = fiber_sggx(m.tx, m.ty, m.tz, m.roughness)
            if lpdf > 0.0:
                f = phase_eval(S, -dx, -dy, -dz, lw[0], lw[1], lw[2])
                if f > 0.0:
                    Lr, Lg, Lb, dim, lk = _add_light(it, px, py, pz, lw, reach, seed, index, dim,
                                                     runtime_value(-1), lpdf, ldelta, f, f, br * ler, bg * leg,
                                                     bb * leb, Lr, Lg, Lb)
                    lookups += lk
                    rays += 1
            wx, wy, wz, pdf = phase_sample(S, -dx, -dy, -dz, u4, u5)
            if pdf <= 0.0:
                break
            prev_pdf = pdf
        else:   # the surface (p just off it towards the arriving ray, its normal; the ground's albedo)
            wi[0] = -dx
            wi[1] = -dy
            wi[2] = -dz
            if lpdf > 0.0:
                if mh.tri >= 0:
                    fr, fg, fb, pf = surface_eval(it.meshes, mh.tri, nrm, wi, lw)
                else:
                    fr, fg, fb = lambert_eval(alb, nrm, wi, lw)
                    pf = lambert_pdf(alb, nrm, wi, lw)
                if fr > 0.0 or fg > 0.0 or fb > 0.0:
                    # the shadow ray leaves from the light's side (a dielectric's refraction: the far side)
                    back = 2.0 * soff if lw[0] * nrm[0] + lw[1] * nrm[1] + lw[2] * nrm[2] < 0.0 else 0.0
                    Lr, Lg, Lb, dim, lk = _add_light(it, px - back * nrm[0], py - back * nrm[1], pz - back * nrm[2],
                                                     lw, reach, seed, index, dim, runtime_value(-1), lpdf, ldelta,
                                                     pf, 1.0, br * ler * fr, bg * leg * fg, bb * leb * fb,
                                                     Lr, Lg, Lb)
                    lookups += lk
                    rays += 1
            if mh.tri >= 0:
                # a dielectric picks its lobe with u3, the number that picked the light: next-event estimation
                # and the continuation are separate terms of the estimate, each unbiased over u3
                wr, wg, wb, pdf = surface_sample(it.meshes, mh.tri, nrm, wi, u3, u4, u5, wsc)
            else:
                wr, wg, wb, pdf = lambert_sample_into(alb, nrm, wi, u4, u5, wsc)
            if pdf <= 0.0:
                break
            br, bg, bb, wx, wy, wz = _scattered(br, bg, bb, wr, wg, wb, wsc)
            prev_pdf = pdf
            if wx * nrm[0] + wy * nrm[1] + wz * nrm[2] < 0.0:   # refracted: it leaves from the far side
                px -= 2.0 * soff * nrm[0]
                py -= 2.0 * soff * nrm[1]
                pz -= 2.0 * soff * nrm[2]
        ox = px
        oy = py
        oz = pz
        dx = wx
        dy = wy
        dz = wz
        skip = next_skip
        if n >= rr_depth:
            q = roulette_survival(br, bg, bb)
            u = uniform(seed, index, dim)
            dim += 1
            if u >= q:
                break
            br /= q
            bg /= q
            bb /= q
    return PathSample(Lr, Lg, Lb, hit, first_t, lookups, rays)


# stages.render.tiles.tile_kernel: trace_path takes no references, so the tile loop need not either
VolpathIntegrator.reference_free = True


@overload(radiance)
def _volpath_radiance(integ, o, d, seed, index):
    if is_tuple_class(integ, VolpathIntegrator):
        return lambda integ, o, d, seed, index: trace_path(integ, o, d, seed, index)
