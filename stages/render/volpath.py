"""Volumetric path tracer for micro-flake fibre media (seed 000 §5.4).

Unidirectional path tracing through an anisotropic medium given by a density source
(``stages.render.medium``): free flights by delta tracking on a majorant grid
(``stages.render.tracking``), scattering by the specular micro-flake phase function sampled
exactly (weight = albedo), next-event estimation toward the lights with ratio-tracked
transmittance, multiple importance sampling (power heuristic) between light sampling and phase /
BSDF sampling for lights that a ray can hit (environment: constant, SG, envmap), Russian roulette
after ``rr_depth`` interactions, and at most ``max_depth`` path segments (Mitsuba's convention:
max_depth = 1 shows only directly visible emitters). An optional diffuse ground plane z = height
(Lambertian, RGB albedo) catches shadows.

``render_tiles(med, maj, lt, cam, ground, ground_on, seed, spp, max_depth, rr_depth, tiles, out)``
renders the given image tiles on parallel threads into ``out`` (H, W, OUT_CHANNELS):
0-2 mean R, G, B (box filter); 3 alpha (fraction of camera paths that met fibres or ground);
4 depth (mean distance to the first interaction, 0 where none); 5 variance of the pixel mean of
luminance (sample variance / spp); 6 medium lookups made by the pixel's paths; 7 rays tracked
(free-flight and shadow queries).
Random numbers: uniform(seed, pixel * spp + sample, dim) with pixel jitter in dims 0-1, so the image
is a pure function of the inputs, whatever the number of threads or the tiling.

``med``: a density source (``stages.render.medium``); ``maj``: its ``MajorantGrid``;
``lt``: (lights, env, env_marginal, env_conditional) as packed by ``stages.render.lights``;
``ground``: float64[4] (height, albedo rgb) and ``ground_on`` as in ``stages.render.ground``.
"""

import numpy as np
from numba import njit

from ..core.rng import uniform
from .camera import camera_ray
from .fiber_lambert import lambert_eval, lambert_pdf, lambert_sample
from .ground import ground_intersect
from .lights import environment_radiance, light_eval, light_pdf, light_sample
from .sggx import fiber_sggx, phase_eval, phase_sample
from .tracking import track

OUT_CHANNELS = 8  # r, g, b, alpha, depth, variance, lookups, rays


@njit(cache=True)
def _power(a, b):
    a2 = a * a
    return a2 / (a2 + b * b) if a2 > 0.0 else 0.0


@njit(cache=True)
def _transmittance(med, maj, ground, ground_on, px, py, pz, wx, wy, wz, seed, index, dim):
    """Ratio-tracked transmittance toward direction w (an infinitely far light); the ground occludes."""
    if ground_intersect(ground, ground_on, pz, wz, 0.0) < np.inf:
        return 0.0, dim, 0
    res = track(med, maj, px, py, pz, wx, wy, wz, np.inf, seed, index, dim, True)
    return res[2], res[3], res[4]


@njit(cache=True)
def _escaped(lt, n, prev_pdf, dx, dy, dz):
    """Radiance of the lights a ray leaving the scene sees, MIS-weighted per light against the
    light-sampling strategy (light k picked with probability 1/NL, then its own pdf)."""
    lights, env, marg, cond = lt
    w = np.empty(3)
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
        mis = _power(prev_pdf, light_pdf(lights, k, env, marg, cond, w) / nl)
        r += lr * mis
        g += lg * mis
        b += lb * mis
    return r, g, b


@njit(cache=True)
def trace_path(med, maj, lt, ground, ground_on, ox, oy, oz, dx, dy, dz, seed, index, max_depth, rr_depth):
    """Radiance along one camera ray: (r, g, b, hit, first distance, lookups, rays)."""
    lights, env, marg, cond = lt
    nl = lights.shape[0]
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
    nrm = np.zeros(3)
    alb = np.empty(3)
    alb[0] = ground[1]
    alb[1] = ground[2]
    alb[2] = ground[3]
    while True:
        tg = ground_intersect(ground, ground_on, oz, dz, 1e-9)
        res = track(med, maj, ox, oy, oz, dx, dy, dz, tg, seed, index, dim, False)
        rays += 1
        collided = res[0]
        t = res[1]
        dim = res[3]
        lookups += res[4]
        if not collided and tg == np.inf:
            er, eg, eb = _escaped(lt, n, prev_pdf, dx, dy, dz)
            Lr += br * er
            Lg += bg * eg
            Lb += bb * eb
            break
        if n == 0:
            hit = 1.0
            first_t = t if collided else tg
        n += 1
        if n >= max_depth:
            break
        u1 = uniform(seed, index, dim)
        u2 = uniform(seed, index, dim + 1)
        u3 = uniform(seed, index, dim + 2)
        u4 = uniform(seed, index, dim + 3)
        u5 = uniform(seed, index, dim + 4)
        dim += 5
        if nl > 0:
            k = min(int(u3 * nl), nl - 1)
            lw, ler, leg, leb, lpdf, ldelta = light_sample(lights, k, env, marg, cond, u1, u2)
            lpdf /= nl
        else:
            lw = nrm
            ler = leg = leb = lpdf = 0.0
            ldelta = False
        if collided:
            px = ox + t * dx
            py = oy + t * dy
            pz = oz + t * dz
            br *= res[9]
            bg *= res[10]
            bb *= res[11]
            S = fiber_sggx(res[6], res[7], res[8], res[12])
            if lpdf > 0.0:
                f = phase_eval(S, -dx, -dy, -dz, lw[0], lw[1], lw[2])
                if f > 0.0:
                    tr, dim, lk = _transmittance(med, maj, ground, ground_on, px, py, pz, lw[0], lw[1], lw[2],
                                                 seed, index, dim)
                    lookups += lk
                    rays += 1
                    if tr > 0.0:
                        c = f * tr * (1.0 if ldelta else _power(lpdf, f)) / lpdf
                        Lr += br * ler * c
                        Lg += bg * leg * c
                        Lb += bb * leb * c
            wx, wy, wz, pdf = phase_sample(S, -dx, -dy, -dz, u4, u5)
            if pdf <= 0.0:
                break
            prev_pdf = pdf
        else:
            # Lambertian ground, shading normal toward the arriving ray
            nrm[0] = 0.0
            nrm[1] = 0.0
            nrm[2] = 1.0 if dz < 0.0 else -1.0
            px = ox + tg * dx
            py = oy + tg * dy
            pz = ground[0] + nrm[2] * 1e-7 * (1.0 + abs(ground[0]))
            if lpdf > 0.0:
                fr, fg, fb = lambert_eval(nrm, alb, lw)
                if fr > 0.0 or fg > 0.0 or fb > 0.0:
                    tr, dim, lk = _transmittance(med, maj, ground, ground_on, px, py, pz, lw[0], lw[1], lw[2],
                                                 seed, index, dim)
                    lookups += lk
                    rays += 1
                    if tr > 0.0:
                        c = tr * (1.0 if ldelta else _power(lpdf, lambert_pdf(nrm, lw))) / lpdf
                        Lr += br * ler * fr * c
                        Lg += bg * leg * fg * c
                        Lb += bb * leb * fb * c
            wo, wr, wg, wb, pdf = lambert_sample(nrm, alb, u4, u5)
            if pdf <= 0.0:
                break
            br *= wr
            bg *= wg
            bb *= wb
            wx = wo[0]
            wy = wo[1]
            wz = wo[2]
            prev_pdf = pdf
        ox = px
        oy = py
        oz = pz
        dx = wx
        dy = wy
        dz = wz
        if n >= rr_depth:
            q = min(max(br, bg, bb), 0.95)
            u = uniform(seed, index, dim)
            dim += 1
            if u >= q:
                break
            br /= q
            bg /= q
            bb /= q
    return Lr, Lg, Lb, hit, first_t, lookups, rays


@njit(cache=True, nogil=True)
def render_tile(med, maj, lt, cam, ground, ground_on, seed, spp, max_depth, rr_depth, row0, col0, row1, col1, out):
    """Render pixels [row0, row1) x [col0, col1) into out (H, W, OUT_CHANNELS); releases the GIL."""
    W = int(cam[13])
    for row in range(row0, row1):
        for col in range(col0, col1):
            pix = row * W + col
            sr = 0.0
            sg = 0.0
            sb = 0.0
            sy = 0.0
            syy = 0.0
            sh = 0.0
            sd = 0.0
            sl = 0.0
            sn = 0.0
            for s in range(spp):
                index = pix * spp + s
                o, d = camera_ray(cam, row, col, uniform(seed, index, 0), uniform(seed, index, 1))
                r, g, b, hit, ft, lk, nr = trace_path(med, maj, lt, ground, ground_on, o[0], o[1], o[2],
                                                      d[0], d[1], d[2], seed, index, max_depth, rr_depth)
                sr += r
                sg += g
                sb += b
                y = 0.2126 * r + 0.7152 * g + 0.0722 * b
                sy += y
                syy += y * y
                sh += hit
                sd += ft
                sl += lk
                sn += nr
            out[row, col, 0] = sr / spp
            out[row, col, 1] = sg / spp
            out[row, col, 2] = sb / spp
            out[row, col, 3] = sh / spp
            out[row, col, 4] = sd / sh if sh > 0.0 else 0.0
            mean = sy / spp
            out[row, col, 5] = max(syy / spp - mean * mean, 0.0) / (spp - 1) if spp > 1 else 0.0
            out[row, col, 6] = sl
            out[row, col, 7] = sn


def render_tiles(med, maj, lt, cam, ground, ground_on, seed, spp, max_depth, rr_depth, tiles, out, threads=None):
    """Render the tiles (rows of (row0, col0, row1, col1), ``stages.render.film.tile_grid``) into
    out (H, W, OUT_CHANNELS) on ``threads`` threads (default: numba's thread count). Each tile is a
    GIL-free numba call; pixels depend only on their own random numbers, so the result does not
    depend on the thread count. (Threads rather than ``prange``: numba's parallel loops cannot take
    sources nested as namedtuples of namedtuples, such as the procedural tables.)"""
    import numba

    n = int(threads or numba.get_num_threads())
    args = (med, maj, lt, cam, ground, bool(ground_on), int(seed), int(spp), int(max_depth), int(rr_depth))
    tiles = np.asarray(tiles, np.int64).reshape(-1, 4)
    if n <= 1 or len(tiles) <= 1:
        for t in tiles:
            render_tile(*args, t[0], t[1], t[2], t[3], out)
        return out
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=n) as ex:
        list(ex.map(lambda t: render_tile(*args, t[0], t[1], t[2], t[3], out), tiles))
    return out
