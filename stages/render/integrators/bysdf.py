"""Yarn-level path tracer with the BYSDF (``--method bysdf``, seed 004).

Geometry: yarn tubes only (``stages.core.yarn.tubes``): the ingest stage's splines as capsule
chains in the fibre tracer's SAH BVH, one "fibre" per yarn. Plies and fibres are implicit
(``stages.core.yarn.shading_points``): a ray that enters a tube is followed on its elliptical cross-section to
the first ply it meets; a ray that meets no ply passes on through the yarn. Shading: the four-lobe
BYSDF (``stages.core.shading.bysdf``) with ply and fibre shadowing.

``BysdfIntegrator`` fields: ``bvh`` (FiberBVH of the tube pieces), ``cv`` (the yarns' ``Curves``),
``pieces`` (``TubePieces``), ``types`` (tuple of ``YarnType``, one per yarn type, padded to 4, 8, ...
entries by the setup so that a scene's count of types does not make numba compile again:
``pipeline.renderers.bysdf.padded_types``), ``yarn_type`` (Y,) int32, ``yarn_key`` (Y,) int64 random key of
each yarn (fibre-table switching), ``params`` (Y,
BYSDF_SIZE) the BYSDF of each yarn, ``lights`` (``LightTable``), ``ground`` float64[4] and
``has_ground`` (``stages.render.ground``), ``ground_albedo`` (3,), ``meshes`` (``stages.render.meshes``:
the scene's Lambertian meshes, two-sided like the ground; ``no_meshes()`` for none), ``mode`` (MODE_NEAR, MODE_FAR,
MODE_MULTISCALE), ``K`` offsets per far / multiscale vertex, ``falloff`` (multiscale weights),
``pixel_angle`` (radians per pixel: the camera ray cone), ``max_depth``, ``rr_depth``, ``window``
(tube pieces skipped around the one a ray leaves), ``eps``, ``max_passes`` (yarns a ray may pass
through between two scattering events).

Estimator
---------
At a yarn vertex x (the ply hit) the BYSDF splits into a reflection side (specular and body
reflection at x) and a transmission side (refraction into the yarn at x by the specular lobe's GGX,
the straight path to the exit point y on the far side of the envelope, Beer-Lambert attenuation
raised to the number of plies crossed, then specular and body transmission out at y). One side is
chosen with probability P_R (``reflect_probability``) and its estimate divided by it; the enter step's
weight is the specular path's (passed to the exit side with A_s), the body's transmission only takes y
from its direction. A shading normal that the fibre tables tilt away from the viewer (wi.n below
``SHADING_COS_MIN``) is bent towards it first (``face_towards_into``): dropping such hits lost about 6 %
of a white yarn's light at every scattering event. On the chosen
side, next-event estimation takes one sample of each light and combines it with the side's BYSDF
sampling by the power heuristic, as ``stages.render.integrators.fiberpath`` does; delta lights by NEE alone.
Shadow rays and continuation rays pass through yarns whose plies they miss (the same implicit
test), so NEE and BYSDF sampling see the same scene. ``max_depth`` counts scattering events (default
4, as the reference implementation); Russian roulette from ``rr_depth`` on.

Modes (seed 004 §4.2): ``near`` shades the point of the ray's own offset; ``far`` shades the mean of
the near BYSDF over K offsets stratified over the whole yarn (h in [-1, 1]): the vertex passes the
ray on with the fraction of offsets that meet no ply, and otherwise is the mixture of the offsets
that do (evaluation: their mean; sampling: one of them, uniformly; pdf: the mean); ``multiscale``
takes the offsets of the ray cone's footprint (width = path length x ``pixel_angle``), aggregates
normal, tangent and shadowing (``stages.core.yarn.shading_points.aggregate``) and widens the specular roughness by the
offset range / 10; a vanishing footprint gives back ``near``, and a footprint as wide as the yarn (an
offset range of 2 or more) shades as ``far`` (seed 004: near when the range is small, far when the
pixel spans the yarn).

Speed: the estimator (``trace_path`` and everything it calls per ray) is compiled without numba's
reference counting, as ``stages.render.integrators.fiberpath`` is: the path's vectors and the
K offsets' scratch live on the machine stack, the shading model and the implicit ply and fibre kernels
return 3-tuples, and the yarn frames are read without taking references on the curves' arrays. With
reference counting, the atomic updates of every array of every namedtuple a kernel unpacks (a yarn
type's tables, the curves, the tube pieces) took about half of the render's time.

Random numbers: ``uniform(seed, key, dim)``, dimensions 0-1 for the pixel, then EVENT_DIMS + 2 NL per
event (a scattering vertex or a pass through a yarn): side, offset pick, lobe and direction, roulette,
refraction, far pass-through, offset jitter, and one pair per light.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class, runtime_value
from stages.core.geometry.frames import face_towards_into
from stages.core.geometry.stack import stack_array, stack_vector3
from stages.core.geometry.surface import Skip, surface_hit
from stages.core.geometry.wide_walk import Ray
from stages.core.rng import uniform
from stages.core.sampling import power_heuristic, roulette_survival
from stages.core.shading import bysdf as B
from stages.core.shading.bysdf import BYSDF_SIZE
from stages.core.shading.lambert import lambert_eval, lambert_pdf, lambert_sample_into
from stages.core.yarn.implicit_plies import plies_crossed, ply_blocks
from stages.core.yarn.implicit_tables import ply_shadow_lookup
from stages.core.yarn.shading_points import aggregate, near_point, offset_of, offset_points
from stages.core.yarn.tubes import (
    cylinder_span,
    dir_from_yarn,
    point_from_yarn,
    to_yarn_into,
    yarn_hit_frame,
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

MODE_NEAR, MODE_FAR, MODE_MULTISCALE = 0, 1, 2
MODES = ("near", "far", "multiscale")
K_MAX = 256
K3_MAX = 3 * K_MAX   # a literal size for the stack arrays of K_MAX points
EVENT_DIMS = 12
SHADING_COS_MIN = 1e-3   # the least cosine of the viewer to a shading normal (``face_towards_into``)
D_SIDE, D_PICK, D_LOBE, D_DIR1, D_DIR2, D_RR, D_ENTER1, D_ENTER2, D_PASS, D_JITTER = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9

BysdfIntegrator = namedtuple("BysdfIntegrator", [
    "bvh", "cv", "pieces", "types", "yarn_type", "yarn_key", "params", "lights", "ground", "has_ground",
    "ground_albedo", "meshes", "mode", "K", "falloff", "pixel_angle", "max_depth", "rr_depth", "window", "eps",
    "max_passes"])


@njit(cache=True, _nrt=False)
def enter_yarn(it, h, ox, oy, oz, dx, dy, dz, o, d):
    """(frame, length inside) of the ray that hit tube piece h.prim at h.t, its yarn-space entry written
    into o and direction into d; length < 0 when the straight envelope at the hit misses the ray (a bend)."""
    px = ox + h.t * dx
    py = oy + h.t * dy
    pz = oz + h.t * dz
    j = it.bvh.seg_a[h.prim]
    fr = yarn_hit_frame(it.cv, it.pieces, j, px, py, pz)
    to_yarn_into(fr, px, py, pz, dx, dy, dz, o, d)
    R = it.types[it.yarn_type[fr.curve]].radius
    u0, u1 = cylinder_span(o, d, R)
    if not (u1 > u0) or not math.isfinite(u0) or not math.isfinite(u1):
        return fr, -1.0
    for k in range(3):
        o[k] += u0 * d[k]
    return fr, u1 - u0


@njit(cache=True, _nrt=False)
def yarn_dir(fr, w, out):
    out[0] = w[0] * fr.nx + w[1] * fr.ny + w[2] * fr.nz
    out[1] = w[0] * fr.bx + w[1] * fr.by + w[2] * fr.bz
    out[2] = w[0] * fr.tx + w[1] * fr.ty + w[2] * fr.tz


@njit(cache=True, _nrt=False)
def visible(it, ox, oy, oz, dx, dy, dz, ign_y, ign_s, reach):
    """(visible, rays): True when the ray (d a unit vector) reaches distance ``reach`` (inf: a distant light; an
    area light's distance, less the offset, for a point on it): every yarn tube on its way is passed through
    (its plies missed) and neither the ground nor a mesh is in the way."""
    o = stack_vector3()
    d = stack_vector3()
    rays = 0
    if ground_intersect(it.ground, it.has_ground, oz, dz, it.eps) < reach:
        return False, rays
    if meshes_occluded(it.meshes, ox, oy, oz, dx, dy, dz, it.eps, reach):
        return False, rays
    x0 = ox
    y0 = oy
    z0 = oz
    for _ in range(it.max_passes):
        tmax = reach
        if reach < np.inf:   # what is left of the way after the yarns passed through
            tmax = reach - ((ox - x0) * dx + (oy - y0) * dy + (oz - z0) * dz)
            if tmax <= it.eps:
                return True, rays
        h = surface_hit(it.bvh, -1, Ray(ox, oy, oz, dx, dy, dz), it.eps, tmax, Skip(ign_y, ign_s, it.window))
        rays += 1
        if h.prim < 0:
            return True, rays
        fr, um = enter_yarn(it, h, ox, oy, oz, dx, dy, dz, o, d)
        if um > 0.0:
            yt = it.types[it.yarn_type[fr.curve]]
            if ply_blocks(yt.tp, o, d, um, yt.tol, yt.max_iter, yt.search):
                return False, rays
            for k in range(3):
                o[k] += um * d[k]
        ox, oy, oz = point_from_yarn(fr, o)
        ign_y = fr.curve
        ign_s = h.prim
    return False, rays


@njit(cache=True, _nrt=False)
def side_eval_pdf(prow, reflect, wi, wl, m, slot_t, slot_n, slot_s, ty, ny, din, att_s, att_d, s_y):
    """(f cos r, g, b, pdf) of the chosen side towards wl (yarn space): the reflection side's mean over the
    m shaded offsets, or the transmission side at the exit point.
    14 parameters: the BYSDF row, the side, the directions and the side's shading state (the reflection side's m
    shaded points, the transmission side's exit and attenuations) as the path loop holds them."""
    if not reflect:
        v = B.exit_eval_pdf(prow, ty, ny, din, wl, att_s, att_d, s_y)
        return v.r, v.g, v.b, v.pdf
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    pf = 0.0
    for s in range(m):
        a0, a1, a2, ap = B.reflect_eval_pdf(prow, slot_t[s], slot_n[s], wi, wl, slot_s[s])
        f0 += a0
        f1 += a1
        f2 += a2
        pf += ap
    return f0 / m, f1 / m, f2 / m, pf / m


@njit(cache=True, _nrt=False)
def next_event(it, fr, seed, key, base, sx, sy, sz, ign_y, ign_s, tp, L, side_w, prow, reflect, wi, m, slot_t, slot_n,
               slot_s, ty, ny, din, att_s, att_d, s_y):
    """Next-event estimation at a yarn vertex from (sx, sy, sz): one sample of each light (and one point on the
    area lights), MIS-weighted against the side's sampling, added to L; returns the rays traced.
    26 parameters: the vertex's random stream, point and skip, the throughput and radiance, and the side's whole
    shading state (``side_eval_pdf``'s) as ``trace_path`` holds it in its own scratch arrays."""
    lights = it.lights.lights
    wl = stack_vector3()
    wlk = stack_vector3()
    rays = 0
    nl = lights.shape[0]
    n_nee = nl + 1 if it.meshes.has_emitters else nl    # the area lights are one more light (light nl)
    for k in range(n_nee):
        lr, lg, lb, pl, delta, dist = nee_light_sample_into(it.lights, it.meshes, k, sx, sy, sz, seed, key,
                                                            base + EVENT_DIMS + 2 * k, wlk)
        reach = dist - it.eps     # a shadow ray to an area light stops short of its surface (inf: distant)
        if pl <= 0.0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
            continue
        yarn_dir(fr, wlk, wl)
        f0, f1, f2, pf = side_eval_pdf(prow, reflect, wi, wl, m, slot_t, slot_n, slot_s, ty, ny, din, att_s, att_d, s_y)
        if f0 == 0.0 and f1 == 0.0 and f2 == 0.0:
            continue
        vis, nr = visible(it, sx, sy, sz, wlk[0], wlk[1], wlk[2], ign_y, ign_s, reach)
        rays += nr
        if not vis:
            continue
        # side_w x the power heuristic over pl, in this order of products (side_w * power_heuristic(pl, pf) / pl
        # rounds differently)
        w = side_w if delta else side_w * pl * pl / (pl * pl + pf * pf) / pl
        L[0] += tp[0] * f0 * lr * w
        L[1] += tp[1] * f1 * lg * w
        L[2] += tp[2] * f2 * lb * w
    return rays


@njit(cache=True, _nrt=False)
def trace_path(it, o, d, seed, key):
    """``PathSample`` of the camera ray (o, d) of camera sample ``key`` (see the module doc)."""
    lights = it.lights.lights
    nl = lights.shape[0]
    sm = it.meshes
    area_dim = EVENT_DIMS + 2 * nl     # the area lights' three dimensions follow the distant lights' pairs
    D = area_dim + 3 if sm.has_emitters else area_dim
    n_nee = nl + 1 if sm.has_emitters else nl       # the area lights are one more light
    K = it.K
    tp = stack_vector3()
    L = stack_vector3()
    for q in range(3):
        tp[q] = 1.0
        L[q] = 0.0
    first_t = 0.0
    rays = 0
    ign_y = -1
    ign_s = -1
    pdf_prev = 0.0
    path_len = 0.0
    depth = 0
    event = 0
    passes = 0
    # per-path scratch on the machine stack (K <= K_MAX offsets; filled before it is read)
    xs = stack_array(K3_MAX, np.float64).reshape((K_MAX, 3))
    ts = stack_array(K3_MAX, np.float64).reshape((K_MAX, 3))
    ns = stack_array(K3_MAX, np.float64).reshape((K_MAX, 3))
    shadow = stack_array(K_MAX, np.float64)
    hit = stack_array(K_MAX, np.bool_)
    slot_x = stack_array(K3_MAX, np.float64).reshape((K_MAX, 3))
    slot_t = stack_array(K3_MAX, np.float64).reshape((K_MAX, 3))
    slot_n = stack_array(K3_MAX, np.float64).reshape((K_MAX, 3))
    slot_s = stack_array(K_MAX, np.float64)
    prow = stack_array(BYSDF_SIZE, np.float64)
    wi = stack_vector3()
    wow = stack_vector3()
    wlk = stack_vector3()
    gn = stack_vector3()      # the normal and albedo of an opaque surface vertex (the ground or a mesh)
    alb = stack_vector3()
    oy = stack_vector3()
    dy = stack_vector3()
    v = stack_vector3()      # the last scattering vertex (where the lights were sampled)
    no_exit = (0.0, 0.0, 0.0)   # the exit-point arguments of the reflection side (unused there)
    while True:
        h = surface_hit(it.bvh, -1, Ray(o[0], o[1], o[2], d[0], d[1], d[2]), it.eps, np.inf,
                        Skip(ign_y, ign_s, it.window))
        rays += 1
        t_hit = h.t
        on_surface = False    # on an opaque surface: the ground or a mesh
        tg = ground_intersect(it.ground, it.has_ground, o[2], d[2], it.eps)
        if tg < t_hit:
            t_hit = tg
            on_surface = True
        mh = meshes_hit(it.meshes, o[0], o[1], o[2], d[0], d[1], d[2], it.eps, t_hit)
        if mh.tri >= 0:
            t_hit = mh.t
            on_surface = True
        if h.prim < 0 and not on_surface:  # escaped: environment, MIS-weighted against the last NEE
            L[0], L[1], L[2] = add_escaped_radiance(it.lights, d, depth > 0, pdf_prev, tp[0], tp[1], tp[2],
                                                    L[0], L[1], L[2])
            break
        if depth == 0 and first_t == 0.0:
            first_t = path_len + t_hit
        if mh.tri >= 0 and sm.has_emitters:   # an area light: its radiance, MIS-weighted against its NEE
            er, eg, eb = emitted_radiance(sm, mh.tri)
            if er > 0.0 or eg > 0.0 or eb > 0.0:
                w = 1.0
                if depth > 0:   # the light's density at its distance from the vertex that sampled it
                    dist = math.sqrt((o[0] + t_hit * d[0] - v[0]) ** 2 + (o[1] + t_hit * d[1] - v[1]) ** 2
                                     + (o[2] + t_hit * d[2] - v[2]) ** 2)
                    w = power_heuristic(pdf_prev, area_light_pdf(sm, mh.tri, dist, d[0], d[1], d[2]))
                L[0] += tp[0] * er * w
                L[1] += tp[1] * eg * w
                L[2] += tp[2] * eb * w
        path_len += t_hit
        base = 2 + event * D
        event += 1
        if on_surface:
            if depth >= it.max_depth:
                break
            px = o[0] + t_hit * d[0]
            py = o[1] + t_hit * d[1]
            pz = o[2] + t_hit * d[2]
            if mh.tri >= 0:   # its material: surface_eval / surface_sample
                facing_normal_into(it.meshes, mh.tri, d[0], d[1], d[2], gn)
            else:
                gn[0] = 0.0
                gn[1] = 0.0
                gn[2] = 1.0 if d[2] < 0.0 else -1.0
                for k in range(3):
                    alb[k] = it.ground_albedo[k]
            for k in range(3):
                wi[k] = -d[k]
            sx = px + it.eps * gn[0]
            sy = py + it.eps * gn[1]
            sz = pz + it.eps * gn[2]
            for k in range(n_nee):   # one sample per light, one point on the area lights (light nl)
                lr, lg, lb, pl, delta, dist = nee_light_sample_into(it.lights, sm, k, sx, sy, sz, seed, key,
                                                                    base + EVENT_DIMS + 2 * k, wlk)
                reach = dist - it.eps
                if pl <= 0.0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
                    continue
                if mh.tri >= 0:
                    f0, f1, f2, pf = surface_eval(it.meshes, mh.tri, gn, wi, wlk)
                else:
                    f0, f1, f2 = lambert_eval(alb, gn, wi, wlk)
                    pf = lambert_pdf(alb, gn, wi, wlk)
                if f0 == 0.0 and f1 == 0.0 and f2 == 0.0:
                    continue
                # from the light's side of the surface (a dielectric's refraction: the far side); nothing to
                # skip, typed as a yarn hit's (yarn, segment) so visible compiles once
                flip = wlk[0] * gn[0] + wlk[1] * gn[1] + wlk[2] * gn[2] < 0.0
                lx = px - it.eps * gn[0] if flip else sx
                ly = py - it.eps * gn[1] if flip else sy
                lz = pz - it.eps * gn[2] if flip else sz
                vis, nr = visible(it, lx, ly, lz, wlk[0], wlk[1], wlk[2], np.int32(-1), np.int64(-1), reach)
                rays += nr
                if not vis:
                    continue
                w = 1.0 if delta else power_heuristic(pl, pf) / pl
                L[0] += tp[0] * f0 * lr * w
                L[1] += tp[1] * f1 * lg * w
                L[2] += tp[2] * f2 * lb * w
            if mh.tri >= 0:
                w0, w1, w2, pf = surface_sample(it.meshes, mh.tri, gn, wi, uniform(seed, key, base + D_LOBE),
                                                uniform(seed, key, base + D_DIR1), uniform(seed, key, base + D_DIR2),
                                                wow)
            else:
                w0, w1, w2, pf = lambert_sample_into(alb, gn, wi, uniform(seed, key, base + D_DIR1),
                                                     uniform(seed, key, base + D_DIR2), wow)
            if pf <= 0.0:
                break
            tp[0] *= w0
            tp[1] *= w1
            tp[2] *= w2
            if wow[0] * gn[0] + wow[1] * gn[1] + wow[2] * gn[2] < 0.0:   # refracted: it leaves from the far side
                sx = px - it.eps * gn[0]
                sy = py - it.eps * gn[1]
                sz = pz - it.eps * gn[2]
            o[0] = sx
            o[1] = sy
            o[2] = sz
            for k in range(3):
                d[k] = wow[k]
            ign_y = -1
            ign_s = -1
        else:
            fr, um = enter_yarn(it, h, o[0], o[1], o[2], d[0], d[1], d[2], oy, dy)
            c = fr.curve
            yt = it.types[it.yarn_type[c]]
            R = yt.radius
            ykey = it.yarn_key[c]
            # the offsets this vertex shades (slots); m = 0: the ray passes on through the yarn
            m = 0
            dh = path_len * it.pixel_angle / R   # the ray cone's footprint in offsets (h spans 2 across the yarn)
            if um > 0.0:
                if it.mode == MODE_FAR or (it.mode == MODE_MULTISCALE and dh >= 2.0):
                    h0 = offset_of(oy, dy, R)
                    nh = offset_points(yt, ykey, oy, dy, h0, -1.0, 1.0, K, uniform(seed, key, base + D_JITTER),
                                       xs, ts, ns, shadow, hit)
                    if nh > 0 and uniform(seed, key, base + D_PASS) * K < nh:
                        for k in range(K):
                            if hit[k]:
                                for q in range(3):
                                    slot_x[m, q] = xs[k, q]
                                    slot_t[m, q] = ts[k, q]
                                    slot_n[m, q] = ns[k, q]
                                slot_s[m] = shadow[k]
                                m += 1
                    for q in range(it.params.shape[1]):
                        prow[q] = it.params[c, q]
                else:
                    sp = near_point(yt, ykey, oy, dy, um)
                    for q in range(it.params.shape[1]):
                        prow[q] = it.params[c, q]
                    if sp.hit:
                        m = 1
                        for q in range(3):
                            slot_x[0, q] = sp.x[q]
                            slot_t[0, q] = sp.t[q]
                            slot_n[0, q] = sp.n[q]
                        slot_s[0] = sp.shadow
                        if it.mode == MODE_MULTISCALE:
                            h0 = offset_of(oy, dy, R)
                            lo = max(-1.0, h0 - 0.5 * dh)
                            hi = min(1.0, h0 + 0.5 * dh)
                            offset_points(yt, ykey, oy, dy, h0, lo, hi, K, uniform(seed, key, base + D_JITTER),
                                          xs, ts, ns, shadow, hit)
                            at, an, ash = aggregate(sp.x, xs, ts, ns, shadow, hit, K, R, it.falloff)
                            if ash > 0.0:
                                for q in range(3):
                                    slot_t[0, q] = at[q]
                                    slot_n[0, q] = an[q]
                                slot_s[0] = ash
                            prow[B.ALPHA_U] += (hi - lo) / 10.0
                            prow[B.ALPHA_V] += (hi - lo) / 10.0
            if m == 0:  # pass through: continue from where the ray leaves the envelope
                passes += 1
                if passes > it.max_passes:
                    break
                if um > 0.0:
                    for q in range(3):
                        oy[q] += um * dy[q]
                ex, ey, ez = point_from_yarn(fr, oy)
                path_len -= t_hit  # the path length is measured to the next hit from the origin
                path_len += math.sqrt((ex - o[0]) ** 2 + (ey - o[1]) ** 2 + (ez - o[2]) ** 2)
                o[0] = ex
                o[1] = ey
                o[2] = ez
                ign_y = c
                ign_s = h.prim
                continue
            if depth >= it.max_depth:
                break
            for q in range(3):
                wi[q] = -dy[q]
            for k in range(m):  # fibre-perturbed normals seen from behind: bent towards the viewer (energy kept)
                face_towards_into(slot_n[k], wi, SHADING_COS_MIN)
            # the side: reflection at x, or transmission to y
            pr = 0.0
            for k in range(m):
                pr += B.reflect_probability(prow, wi, slot_n[k])
            pr /= m
            pick = min(m - 1, int(uniform(seed, key, base + D_PICK) * m))
            if uniform(seed, key, base + D_SIDE) < pr:
                side_w = 1.0 / pr
                x = slot_x[pick]
                sx, sy, sz = point_from_yarn(fr, x)
                rays += next_event(it, fr, seed, key, base, sx, sy, sz, c, h.prim, tp, L, side_w, prow,
                                   runtime_value(True), wi, m, slot_t, slot_n, slot_s, no_exit, no_exit, no_exit, 1.0,
                                   1.0, 1.0)
                wv, w0, w1, w2, pf = B.reflect_sample(prow, slot_t[pick], slot_n[pick], wi, slot_s[pick],
                                                      uniform(seed, key, base + D_LOBE),
                                                      uniform(seed, key, base + D_DIR1),
                                                      uniform(seed, key, base + D_DIR2))
                if pf <= 0.0:
                    break
                if m > 1:  # the mixture over the offsets
                    f0, f1, f2, pm = side_eval_pdf(prow, True, wi, wv, m, slot_t, slot_n, slot_s, no_exit, no_exit,
                                                   no_exit, 1.0, 1.0, 1.0)
                    if pm <= 0.0:
                        break
                    w0 = f0 / pm
                    w1 = f1 / pm
                    w2 = f2 / pm
                    pf = pm
                tp[0] *= w0 * side_w
                tp[1] *= w1 * side_w
                tp[2] *= w2 * side_w
                dir_from_yarn(fr, wv, wow)
                o[0] = sx
                o[1] = sy
                o[2] = sz
            else:
                side_w = 1.0 / (1.0 - pr)
                x = slot_x[pick]
                din, w_in, p_in = B.enter_sample(prow, slot_t[pick], slot_n[pick], wi,
                                                 uniform(seed, key, base + D_ENTER1),
                                                 uniform(seed, key, base + D_ENTER2))
                if p_in <= 0.0 or w_in <= 0.0:
                    break
                _, u_hi = cylinder_span(x, din, R)
                if not (u_hi > 0.0) or not math.isfinite(u_hi):
                    break
                yq = (x[0] + u_hi * din[0], x[1] + u_hi * din[1], x[2] + u_hi * din[2])
                crossed = plies_crossed(yt.tp, x, din, u_hi, yt.tol, yt.max_iter, yt.search)
                crossed = max(1, crossed)
                ell = u_hi / R
                # the specular path carries the enter step's weight; the body path only took y from d
                att_s = math.exp(-prow[B.SIGMA_SPEC] * ell * crossed) * w_in
                att_d = math.exp(-prow[B.SIGMA_BODY] * ell * crossed)
                nr_ = math.sqrt(yq[0] * yq[0] + yq[1] * yq[1])
                ny = (yq[0] / nr_, yq[1] / nr_, 0.0)
                ty = (0.0, 0.0, 1.0)
                s_y = ply_shadow_lookup(yt.tables, yt.tp, math.atan2(yq[1], yq[0]), yq[2])
                tp[0] *= side_w
                tp[1] *= side_w
                tp[2] *= side_w
                sx, sy, sz = point_from_yarn(fr, yq)
                rays += next_event(it, fr, seed, key, base, sx, sy, sz, c, h.prim, tp, L, 1.0, prow,
                                   runtime_value(False), wi, m, slot_t, slot_n, slot_s, ty, ny, din, att_s, att_d, s_y)
                wv, w0, w1, w2, pf = B.exit_sample(prow, ty, ny, din, att_s, att_d, s_y,
                                                   uniform(seed, key, base + D_LOBE), uniform(seed, key, base + D_DIR1),
                                                   uniform(seed, key, base + D_DIR2))
                if pf <= 0.0:
                    break
                tp[0] *= w0
                tp[1] *= w1
                tp[2] *= w2
                dir_from_yarn(fr, wv, wow)
                o[0] = sx
                o[1] = sy
                o[2] = sz
            for q in range(3):
                d[q] = wow[q]
            ign_y = c
            ign_s = h.prim
            pdf_prev = pf
        for q in range(3):
            v[q] = o[q]
        depth += 1
        passes = 0
        if depth >= it.rr_depth:
            qv = roulette_survival(tp[0], tp[1], tp[2])
            if uniform(seed, key, base + D_RR) >= qv:
                break
            tp[0] /= qv
            tp[1] /= qv
            tp[2] /= qv
        if on_surface:
            pdf_prev = pf
    return PathSample(L[0], L[1], L[2], 1.0 if first_t > 0.0 else 0.0, first_t, 0, rays)


# stages.render.tiles.tile_kernel: trace_path takes no references, so the tile loop need not either
BysdfIntegrator.reference_free = True


@overload(radiance)
def _bysdf_radiance(integ, o, d, seed, index):
    if is_tuple_class(integ, BysdfIntegrator):
        return lambda integ, o, d, seed, index: trace_path(integ, o, d, seed, index)
