"""A yarn's albedo under white diffuse light by an analog random walk (``pipeline.dye``'s albedo curve).

What it estimates: the fraction of the light that meets a yarn of explicit fibres (any surface scene:
``stages.core.geometry.surface``) in a uniform white environment and leaves it again, per fibre
material -- the mean radiance of the yarn's pixels when the environment's radiance is 1.

The walk (one per camera ray and material): an orthographic ray along ``direction`` from a uniform point
of the window ``corner + u span_u + v span_v`` (u, v in [0, 1)); rays that miss the fibres are not
counted. At every fibre event with incident longitudinal angle theta_i the fibre's BCSDF (Khungurn et
al. 2015, ``stages.core.shading.bcsdf``) returns exactly A(theta_i) = F_R(theta_i) + (1 - F_R(theta_i)) C_TT
of the light (grey materials: one channel), so the walk

1. absorbs the path with probability 1 - A(theta_i) (analog absorption: no weights);
2. picks the R lobe with probability F_R / A, else TT;
3. draws theta_o *exactly* from the lobe's longitudinal density M_p(theta_o) cos^2(theta_o) -- a
   truncated Gaussian around -theta_i times cos^2 -- by rejection (as ``bcsdf.sample_longitudinal``, but with
   no fallback and its own random numbers): a truncated-Gaussian sample is kept with
   probability cos^2(theta_o); phi_o from N_p (uniform for R; the wrapped Gaussian plus floor for TT);
4. traces on from the hit, skipping the fibre it leaves (as fiberpath does), and scores 1 when it escapes.

Every path scores 0 or 1, so the estimate's standard error is at most 0.5 / sqrt(rays), and a non-absorbing
material scores exactly 1 on every path (the white furnace, ``tests/render/test_yarn_colour.py``). A path
tracer's estimate of the same quantity carries weights, next-event estimation and roulette through the
hundreds of fibre events of a path in dense cloth; fiberpath's agrees with this walk since its BCSDF samples
exactly too (``stages.core.shading.bcsdf``, Sampling), but its variance grows with the path length.

Random numbers: ``uniform(seed, key, dim)`` with key = ray * K + material and dim counting up along the
walk, so results do not depend on the thread count.
"""
import math

import numpy as np
from numba import njit, prange

from stages.core.geometry.surface import Skip, surface_hit
from stages.core.geometry.wide_walk import Ray
from stages.core.rng import uniform
from stages.core.shading.bcsdf import (
    BETA_R,
    BETA_TT,
    C_R,
    C_TT,
    HALF_PI,
    angles,
    fresnel_R,
    from_angles,
    sample_azimuth,
    sample_truncated_gauss,
)

MAX_REJECTIONS = 1_000_000   # theta_o tries per event (acceptance >= ~3e-4 even for 1-degree lobes at grazing)


@njit(cache=True)
def _exact_theta(p, lobe_r, theta_i, seed, key, dim):
    """theta_o with density proportional to g(theta_o; -theta_i, beta_p) cos^2(theta_o) on [-pi/2, pi/2];
    returns (theta_o, next dim)."""
    beta = p[BETA_R] if lobe_r else p[BETA_TT]
    th = 0.0
    for _ in range(MAX_REJECTIONS):
        th = sample_truncated_gauss(uniform(seed, key, dim), -theta_i, beta, -HALF_PI, HALF_PI)
        c = math.cos(th)
        accept = uniform(seed, key, dim + 1) < c * c
        dim += 2
        if accept:
            break
    return th, dim


@njit(cache=True)
def _walk(scene, p, camera_ray, seed, key, eps, window, max_events):
    """1.0 when the path escapes, 0.0 when it is absorbed (or meets max_events); -1.0 when ``camera_ray``
    (a ``Ray``) misses the fibres."""
    ox, oy, oz, dx, dy, dz = camera_ray
    ign_f = -1
    ign_s = -1
    dim = 0
    t = np.empty(3)
    wi = np.empty(3)
    for event in range(max_events):
        h = surface_hit(scene, -1, Ray(ox, oy, oz, dx, dy, dz), eps, np.inf, Skip(ign_f, ign_s, window))
        if h.prim < 0:
            return -1.0 if event == 0 else 1.0
        ox += h.t * dx
        oy += h.t * dy
        oz += h.t * dz
        t[0] = h.tx
        t[1] = h.ty
        t[2] = h.tz
        wi[0] = -dx
        wi[1] = -dy
        wi[2] = -dz
        theta_i, phi_i = angles(t, wi)
        f_r = fresnel_R(theta_i, p[C_R])
        a = f_r + (1.0 - f_r) * p[C_TT]
        u_absorb = uniform(seed, key, dim)
        u_lobe = uniform(seed, key, dim + 1)
        u_phi = uniform(seed, key, dim + 2)
        dim += 3
        if u_absorb >= a:
            return 0.0
        lobe_r = u_lobe * a < f_r
        theta_o, dim = _exact_theta(p, lobe_r, theta_i, seed, key, dim)
        wo = from_angles(t, theta_o, sample_azimuth(p, lobe_r, phi_i, u_phi))
        dx, dy, dz = wo[0], wo[1], wo[2]
        ign_f = h.fiber
        ign_s = h.prim
    return 0.0


@njit(cache=True, parallel=True)
def yarn_albedo(scene, mats, corner, span_u, span_v, direction, n_rays, seed, eps, window, max_events):
    """(albedo (K,), standard error (K,), camera rays that met the fibres) for the K grey BCSDF rows
    ``mats`` (K, BCSDF_SIZE; channel 0 is used); camera rays along unit ``direction`` from the window
    ``corner + u span_u + v span_v`` (float64[3] each) -- see the module doc."""
    K = mats.shape[0]
    score = np.zeros((n_rays, K))
    met = np.zeros(n_rays, np.bool_)
    for i in prange(n_rays):
        u = uniform(seed, i, 1 << 40)
        v = uniform(seed, i, (1 << 40) + 1)
        ox = corner[0] + u * span_u[0] + v * span_v[0]
        oy = corner[1] + u * span_u[1] + v * span_v[1]
        oz = corner[2] + u * span_u[2] + v * span_v[2]
        for k in range(K):
            s = _walk(scene, mats[k], Ray(ox, oy, oz, direction[0], direction[1], direction[2]), seed, i * K + k,
                      eps, window, max_events)
            if s < 0.0:
                break
            met[i] = True
            score[i, k] = s
    n = max(int(met.sum()), 1)
    albedo = np.zeros(K)
    se = np.zeros(K)
    for k in range(K):
        m = 0.0
        for i in range(n_rays):
            if met[i]:
                m += score[i, k]
        m /= n
        albedo[k] = m
        se[k] = math.sqrt(max(m * (1.0 - m), 0.0) / n)
    return albedo, se, int(met.sum())
