"""Explicit-fibre unidirectional path tracer (``--method fiberpath``).

Geometry: fibres as chains of capsules in a SAH BVH (``stages.core.bvh``), optional ground plane
(``stages.render.ground``). Materials per fibre (``materials`` rows, MAT_SIZE floats):
    0 type (0 = BCSDF of Khungurn et al. 2015, 1 = Lambertian surface), 1:11 packed BCSDF
    (``stages.core.bcsdf``), 11:14 Lambertian albedo.
Lights: ``stages.render.lights`` (all distant).

Estimator
---------
At every scattering vertex, next-event estimation takes one sample of *each* light and combines it
with BSDF sampling by the power heuristic (per light: w_light = p_l^2 / (p_l^2 + p_f^2); when a
BSDF-sampled ray escapes, light k's radiance gets p_f^2 / (p_f^2 + p_k^2)); directional lights are
delta lights, sampled only by NEE. Camera rays that escape see the environment (all non-delta
lights) unweighted. ``max_depth`` is the largest number of scattering events on a path (1 = direct
lighting only); Russian roulette from scattering event ``rr_depth`` on, survival probability
min(0.95, max channel of the throughput).

BCSDF vertices: the scattered and shadow rays start on the fibre surface and skip the segments of
the same fibre within ``ign_window`` along the chain (a curve BCSDF does not self-shadow; see
``stages.core.bcsdf`` "Measure"); the renderer passes a window wider than any fibre, i.e. the whole
fibre is skipped. Lambertian and ground vertices: rays start offset along the normal
and test everything.

Random numbers: ``uniform(seed, (row * W + col) * spp + s, dim)`` with fixed dimensions per bounce,
so the image is identical for any thread count and tile order.
"""
import math

import numpy as np
from numba import njit, prange

from ..core import bcsdf as B
from ..core.bvh import intersect, occluded
from ..core.capsule import capsule_normal
from ..core.rng import uniform
from .camera import camera_ray
from .fiber_lambert import lambert_eval, lambert_pdf, lambert_sample
from .film import add_sample
from .ground import ground_intersect
from .lights import environment_radiance, light_eval, light_pdf, light_sample

MAT_SIZE = 14
MAT_BCSDF = 0
MAT_LAMBERT = 1


def pack_material_bcsdf(bcsdf_params):
    row = np.zeros(MAT_SIZE)
    row[0] = MAT_BCSDF
    row[1:11] = bcsdf_params
    return row


def pack_material_lambert(albedo):
    row = np.zeros(MAT_SIZE)
    row[0] = MAT_LAMBERT
    row[11:14] = albedo
    return row


@njit(cache=True)
def trace_path(cam, bvh, mat_of_fiber, mats, lights, env, marg, cond, ground, has_ground,
               row, col, key, seed, max_depth, rr_depth, ign_window, eps, counters):
    """Radiance (r, g, b), first-hit distance (0 on a miss) of one camera sample.

    counters[0] += rays traced (camera, scattered and shadow rays)."""
    u = uniform(seed, key, 0)
    v = uniform(seed, key, 1)
    o, d = camera_ray(cam, row, col, u, v)
    nl = lights.shape[0]
    dims_per_bounce = 4 + 2 * nl
    tp0 = 1.0
    tp1 = 1.0
    tp2 = 1.0
    L0 = 0.0
    L1 = 0.0
    L2 = 0.0
    first_t = 0.0
    ign_f = -1
    ign_s = -1
    pdf_prev = 0.0
    t_tan = np.zeros(3)
    n = np.zeros(3)
    wi = np.empty(3)
    p = np.empty(3)
    so = np.empty(3)
    wo = np.empty(3)
    ctx = np.empty(B.CTX_SIZE)
    depth = 0
    while True:
        t_hit, s = intersect(bvh, o[0], o[1], o[2], d[0], d[1], d[2], eps, np.inf, ign_f, ign_s, ign_window)
        counters[0] += 1
        tg = ground_intersect(ground, has_ground, o[2], d[2], eps)
        if tg < t_hit:
            t_hit = tg
            s = -2
        if s == -1:  # escaped: environment radiance, MIS-weighted against the previous NEE
            for k in range(nl):
                lr, lg, lb = light_eval(lights, k, env, marg, cond, d)
                if lr == 0.0 and lg == 0.0 and lb == 0.0:
                    continue
                w = 1.0
                if depth > 0:
                    pl = light_pdf(lights, k, env, marg, cond, d)
                    w = pdf_prev * pdf_prev / (pdf_prev * pdf_prev + pl * pl)
                L0 += tp0 * lr * w
                L1 += tp1 * lg * w
                L2 += tp2 * lb * w
            break
        if depth == 0:
            first_t = t_hit
        if depth >= max_depth:
            break
        for k in range(3):
            p[k] = o[k] + t_hit * d[k]
            wi[k] = -d[k]
        # shading frame
        if s >= 0:
            m = mat_of_fiber[bvh.seg_fiber[s]]
            kind = int(mats[m, 0])
            ia = bvh.seg_a[s]
            P = bvh.points
            ax = P[ia, 0]; ay = P[ia, 1]; az = P[ia, 2]
            bx = P[ia + 1, 0]; by = P[ia + 1, 1]; bz = P[ia + 1, 2]
            tl = math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2)
            if tl > 0.0:
                t_tan[0] = (bx - ax) / tl; t_tan[1] = (by - ay) / tl; t_tan[2] = (bz - az) / tl
            else:
                t_tan[0] = 1.0; t_tan[1] = 0.0; t_tan[2] = 0.0
            nx, ny, nz, _ = capsule_normal(p[0], p[1], p[2], ax, ay, az, bx, by, bz)
            n[0] = nx; n[1] = ny; n[2] = nz
            if kind == MAT_BCSDF:
                B.bcsdf_context(mats[m, 1:11], t_tan, wi, ctx)
                nf = bvh.seg_fiber[s]
                ns = s
                for k in range(3):
                    so[k] = p[k]
            else:
                nf = -1
                ns = -1
                off = 1e-3 * bvh.seg_r[s] + eps
                for k in range(3):
                    so[k] = p[k] + off * n[k]
            galb = 0
        else:
            m = -1
            kind = MAT_LAMBERT
            n[0] = 0.0; n[1] = 0.0; n[2] = 1.0 if d[2] < 0.0 else -1.0
            nf = -1
            ns = -1
            for k in range(3):
                so[k] = p[k] + eps * n[k]
            galb = 1
        base = 2 + depth * dims_per_bounce
        # next-event estimation: one sample per light
        for k in range(nl):
            wl, lr, lg, lb, pl, delta = light_sample(lights, k, env, marg, cond,
                                                     uniform(seed, key, base + 4 + 2 * k),
                                                     uniform(seed, key, base + 5 + 2 * k))
            if pl <= 0.0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
                continue
            if galb == 1:
                f0, f1, f2 = lambert_eval(n, ground[1:4], wl)
                pf = lambert_pdf(n, wl)
            elif kind == MAT_BCSDF:
                f0, f1, f2, pf = B.bcsdf_eval_pdf_ctx(mats[m, 1:11], ctx, t_tan, wl)
            else:
                f0, f1, f2 = lambert_eval(n, mats[m, 11:14], wl)
                pf = lambert_pdf(n, wl)
            if f0 == 0.0 and f1 == 0.0 and f2 == 0.0:
                continue
            counters[0] += 1
            if occluded(bvh, so[0], so[1], so[2], wl[0], wl[1], wl[2], eps, np.inf, nf, ns, ign_window):
                continue
            if ground_intersect(ground, has_ground, so[2], wl[2], eps) < np.inf:
                continue
            if delta:
                w = 1.0
            else:
                w = pl * pl / (pl * pl + pf * pf) / pl
            L0 += tp0 * f0 * lr * w
            L1 += tp1 * f1 * lg * w
            L2 += tp2 * f2 * lb * w
        # scatter
        u0 = uniform(seed, key, base + 0)
        u1 = uniform(seed, key, base + 1)
        u2 = uniform(seed, key, base + 2)
        if galb == 1:
            ws, w0, w1, w2, pf = lambert_sample(n, ground[1:4], u1, u2)
            for k in range(3):
                wo[k] = ws[k]
        elif kind == MAT_BCSDF:
            w0, w1, w2, pf = B.bcsdf_sample_ctx(mats[m, 1:11], ctx, t_tan, u0, u1, u2, wo)
        else:
            ws, w0, w1, w2, pf = lambert_sample(n, mats[m, 11:14], u1, u2)
            for k in range(3):
                wo[k] = ws[k]
        if pf <= 0.0:
            break
        tp0 *= w0
        tp1 *= w1
        tp2 *= w2
        depth += 1
        if depth >= rr_depth:
            q = min(0.95, max(tp0, max(tp1, tp2)))
            if uniform(seed, key, base + 3) >= q:
                break
            tp0 /= q
            tp1 /= q
            tp2 /= q
        pdf_prev = pf
        for k in range(3):
            o[k] = so[k]
            d[k] = wo[k]
        ign_f = nf
        ign_s = ns
    return L0, L1, L2, first_t


@njit(cache=True, parallel=True)
def render_tiles(cam, bvh, mat_of_fiber, mats, lights, env, marg, cond, ground, has_ground,
                 tiles, t_begin, t_end, spp, seed, max_depth, rr_depth, ign_window, eps,
                 film_sum, film_sq, hits, depth_sum, tile_rays):
    """Render tiles [t_begin, t_end) into the film arrays; tile_rays[t] = rays traced for tile t."""
    W = int(cam[13])
    for ti in prange(t_begin, t_end):
        r0 = tiles[ti, 0]
        c0 = tiles[ti, 1]
        r1 = tiles[ti, 2]
        c1 = tiles[ti, 3]
        counters = np.zeros(1, np.int64)
        for row in range(r0, r1):
            for col in range(c0, c1):
                for s in range(spp):
                    key = (row * W + col) * spp + s
                    r, g, b, ft = trace_path(cam, bvh, mat_of_fiber, mats, lights, env, marg, cond, ground, has_ground,
                                             row, col, key, seed, max_depth, rr_depth, ign_window, eps, counters)
                    add_sample(film_sum, film_sq, row, col, r, g, b)
                    if ft > 0.0:
                        hits[row, col] += 1.0
                        depth_sum[row, col] += ft
        tile_rays[ti] = counters[0]
