"""Rays through the exemplar repeated without end (stages.precompute.periodic) against brute force:
every capsule of the exemplar's fibres copied over enough periods, each intersected directly
(reference: stages.core.geometry.capsule.capsule_intersect on explicit copies)."""
import math

import numpy as np
from numba import njit

from stages.core.geometry.capsule import capsule_intersect
from stages.precompute.periodic import periodic_hit, periodic_scene


@njit
def _brute(P, R, O, f0, f1, W, H, o, d, ign_fiber, L, reach):
    best, seg, fib = np.inf, -1, -1
    for a in range(-reach, reach + 1):
        for b in range(-reach, reach + 1):
            for f in range(f0, f1):
                if f == ign_fiber:
                    continue
                for i in range(O[f], O[f + 1] - 1):
                    t = capsule_intersect(o[0], o[1], o[2], d[0], d[1], d[2],
                                          P[i, 0] + a * W, P[i, 1] + b * H, P[i, 2],
                                          P[i + 1, 0] + a * W, P[i + 1, 1] + b * H, P[i + 1, 2],
                                          max(R[i], R[i + 1]), 0.0)
                    if t < best and t < L:
                        best, seg, fib = t, i - f, f
    return best, seg, fib


def test_periodic_hit_matches_brute_force_copies(tiny_tiling):
    _, sc, art = tiny_tiling
    rng = np.random.default_rng(5)
    lo, hi = art.summary["exemplar_bounds"][0][2], art.summary["exemplar_bounds"][1][2]
    for k in range(2):
        psc = periodic_scene(sc, k)
        W, H = art["ex_period"][k]
        hits = 0
        for _ in range(60):
            o = np.array([rng.uniform(0, W), rng.uniform(0, H), rng.uniform(lo, hi)])
            z = rng.uniform(-1, 1)
            phi = rng.uniform(0, 2 * math.pi)
            d = np.array([math.sqrt(1 - z * z) * math.cos(phi), math.sqrt(1 - z * z) * math.sin(phi), z])
            ign = int(rng.integers(art["ex_fibers"][k], art["ex_fibers"][k + 1])) if rng.uniform() < 0.5 else -1
            h = periodic_hit(psc, lo, hi, *o, *d, ign, 3.0 * max(W, H))
            L = min((hi - o[2]) / d[2] if d[2] > 0 else (lo - o[2]) / d[2], 3.0 * max(W, H))
            t, seg, fib = _brute(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"][k],
                                 art["ex_fibers"][k + 1], W, H, o, d, ign, L, 4)
            if math.isinf(t):
                assert math.isinf(h.t)
                continue
            hits += 1
            assert abs(h.t - t) < 1e-9 and h.fibre == fib, (k, o, d, h, t, seg, fib)
            if h.segment != seg:  # a tie between neighbouring segments of the fibre at a shared point
                assert abs(h.segment - seg) == 1
        assert hits > 10
