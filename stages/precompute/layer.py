"""How much light a layer of the fabric lets through: its transmittance per incidence angle (for prt's global
visibility through other folds of the cloth).

Seed 001 shadows a fibre hit by "the cloth as a macroscopic solid": the global-visibility shadow ray from the
shell's top surface is blocked by any other part of the shell (§5.2.1, Fig. 5). A fabric is no solid: a
silk satin passes a good part of the light that falls on it, scattered through its fibres and through the
gaps between its yarns, and a draped cloth under a low light is lit on its shadowed side by light that
crossed the fold in front of it (on the draped damask under a light 23 degrees high, 6-12 % of `fiberpath`'s
picture per channel, all of it where prt's opaque shell left the cloth black). ``layer_transmittance``
measures, on the flat fabric of one exemplar repeated without end (``stages.precompute.periodic``), the
fraction of a directional light's power that leaves the slab through its far side:

    tau_side(cos theta) = E[ throughput of the light path when it leaves through the far side ]

for light falling on the top (side 0, travelling downwards) or on the bottom (side 1, upwards) at polar
angle theta to the fabric's normal, averaged over the azimuth and over where it falls in the period (uniform
x, y). Both the light that passes unscattered (through the gaps) and the light scattered any number of times
by the fibres count (``periodic_path`` with the fibres' materials, Russian roulette from ``rr_depth``, at
most ``max_depth`` events); light that leaves through the side it came from does not. Per side, ``NB`` bins
with centres cos theta = (i + 1/2) / NB (the table's convention: ``stages.core.layer``). The renderer
(``stages.render.integrators.prt``) multiplies a shadow ray's light by tau of every layer it crosses, read at
the crossing's angle in that layer's flat space: the light that crossed is diffuse, and standing in for it
by the light's own direction, attenuated, is an approximation that keeps a layer's total (measured on the
draped damask, docs/methods/prt.md).

Random numbers: ``uniform(seed, key, dim)`` with key = (side * NB + bin) * 2^32 + path index: dims 0-2 place
the path (x, y, azimuth), then ``DIRECTION_DIMS`` per vertex. The result is the same bytes for any thread
count (the bins are independent tasks).

API
    layer_transmittance(sc, k, z_lo, z_hi, period, mat_of_fiber, mats, *, n_bins=8, n_paths=4000, seed=0,
                        max_depth=256, rr_depth=5, max_dist=None) -> (tau (2, NB, 3), se (2, NB, 3)) float64
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.layer import FROM_ABOVE, bin_centre
from stages.core.rng import uniform
from stages.core.shading.material import CTX_SIZE
from stages.core.threads import chunk_kernel, for_chunks
from stages.precompute.iirtf import MAX_DIST_PERIODS
from stages.precompute.periodic import (
    DIRECTION_DIMS,
    PathScratch,
    PeriodicPaths,
    periodic_hit,
    periodic_path,
    periodic_scene,
    register_tally,
)

TWO_PI = 2.0 * math.pi
PATH_DIMS = 3    # per path, before its vertices: x, y, azimuth

LayerCrossing = namedtuple("LayerCrossing", ["T", "down"])
LayerCrossing.__doc__ = """What one transmittance path records (a tally of ``periodic_path``): ``T`` (3,) the throughput
of the path when it leaves through the far side (downwards when ``down``); no next-event estimation."""


@njit(cache=True)
def _no_light(tally, paths, v, mat, nf, tp, seed, key, base):
    return 0


@njit(cache=True)
def _crossed(tally, wo, tp, pdf):
    if (wo[2] < 0.0) == tally.down:
        tp0, tp1, tp2 = tp
        tally.T[0] += tp0
        tally.T[1] += tp1
        tally.T[2] += tp2


register_tally(LayerCrossing, _no_light, _crossed)


@chunk_kernel
def _layer_bins(paths, n_bins, n_paths, seed, tau, se, i0, i1):
    """Bins i0 .. i1 - 1 of the flattened (side, bin) grid into ``tau`` and ``se`` (2 NB, 3) (``for_chunks``)."""
    v = PathScratch(np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(CTX_SIZE))
    T = np.zeros(3)
    S = np.zeros(3)
    Q = np.zeros(3)
    for b in range(i0, i1):
        side = b // n_bins
        mu = bin_centre(b % n_bins, n_bins)
        st = math.sqrt(max(0.0, 1.0 - mu * mu))
        down = side == FROM_ABOVE
        dz = -mu if down else mu
        z0 = paths.z_hi if down else paths.z_lo
        for c in range(3):
            S[c] = 0.0
            Q[c] = 0.0
        for p in range(n_paths):
            key = (b << 32) + p
            x = paths.W * uniform(seed, key, 0)
            y = paths.H * uniform(seed, key, 1)
            ph = TWO_PI * uniform(seed, key, 2)
            dx = st * math.cos(ph)
            dy = st * math.sin(ph)
            h = periodic_hit(paths.scene, paths.z_lo, paths.z_hi, x, y, z0, dx, dy, dz, -1, paths.max_dist)
            if math.isinf(h.t):       # through a gap, unscattered
                T[0] = 1.0
                T[1] = 1.0
                T[2] = 1.0
            else:
                T[0] = 0.0
                T[1] = 0.0
                T[2] = 0.0
                v.wi[0] = -dx
                v.wi[1] = -dy
                v.wi[2] = -dz
                periodic_path(paths, LayerCrossing(T, down), v, h, seed, key, PATH_DIMS, DIRECTION_DIMS)
            for c in range(3):
                S[c] += T[c]
                Q[c] += T[c] * T[c]
        N = float(n_paths)
        for c in range(3):
            m = S[c] / N
            tau[b, c] = m
            se[b, c] = math.sqrt(max(Q[c] - S[c] * m, 0.0) / (N * (N - 1.0))) if n_paths > 1 else 0.0


def layer_transmittance(sc, k: int, z_lo: float, z_hi: float, period, mat_of_fiber, mats, *, n_bins: int = 8,
                        n_paths: int = 4000, seed: int = 0, max_depth: int = 256, rr_depth: int = 5, max_dist=None):
    """tau and its standard error, each (2, n_bins, 3), of exemplar ``k`` of the tiling's ShellScene ``sc`` (its slab
    z_lo..z_hi, its period): side (``stages.core.layer.FROM_ABOVE``, ``FROM_BELOW``), cos theta bin, channel
    (module doc); ``max_dist`` caps every ray (default 32 periods, as the IIRTF's)."""
    if n_bins < 1 or n_paths < 2 or max_depth < 1 or rr_depth < 1:
        raise ValueError("layer_transmittance: n_bins >= 1, n_paths >= 2, max_depth >= 1 and rr_depth >= 1")
    W, H = (float(v) for v in period)
    paths = PeriodicPaths(periodic_scene(sc, k), float(z_lo), float(z_hi), W, H,
                          np.ascontiguousarray(mat_of_fiber, np.int32), np.ascontiguousarray(mats, np.float64),
                          int(max_depth), int(rr_depth),
                          MAX_DIST_PERIODS * max(W, H) if max_dist is None else float(max_dist), 1e-7 * max(W, H))
    tau = np.zeros((2 * n_bins, 3))
    se = np.zeros((2 * n_bins, 3))
    for_chunks(_layer_bins, 2 * n_bins, paths, int(n_bins), int(n_paths), int(seed), tau, se)
    return tau.reshape(2, n_bins, 3), se.reshape(2, n_bins, 3)
