"""The Monte Carlo vocabulary every path tracer and precompute of loomlight shares, written once.

- ``power_heuristic(a, b)``: the multiple-importance-sampling weight of a sample drawn by a strategy
  of density ``a`` against one of density ``b``, Veach's power heuristic with exponent 2,
  a^2 / (a^2 + b^2) (Veach 1997, Eq. 9.13); 0 where ``a`` is 0 (that strategy could not have drawn it).
  Callers that fold the weight into an estimator f / a write ``power_heuristic(a, b) / a``.
- ``roulette_survival(t0, t1, t2)``: Russian roulette's survival probability from a path's RGB
  throughput, its largest channel capped at ``RR_MAX_SURVIVAL`` so that every path can end; a path
  that survives divides its throughput by it (unbiased: E[survive / q] = 1).
- ``continue_path(mat, ctx, t, n, wi, roulette, seed, key, base, tp, wo)``: a fibre path's scattering step at
  a vertex of material ``mat`` (``stages.core.shading.material``): the next direction sampled into ``wo``
  from the uniforms of dimensions ``base`` .. ``base + 2``, the throughput ``tp`` weighted by f cos / pdf and,
  when ``roulette``, Russian roulette decided by the uniform of dimension ``base + 3``; returns a
  ``PathStep`` (alive, pdf, the new throughput); ``path_step(s0, s1, s2, pf, roulette, seed, key, base, tp)``
  is its second half, for a vertex whose sample comes from elsewhere (a mesh's material).
- ``NO_HIT``: the distance a query answers when it found nothing (no surface, no fibre within the
  window); finite, so that comparisons and products with zero stay ordinary numbers.

The integrators (``stages.render.integrators.fiberpath``, ``.bysdf``, ``.volpath``) and the precomputes
(``stages.precompute.iirtf``, ``.btf``) call these; each draws its own uniforms from its own dimensions
(``stages.core.rng``), so every decision stays a pure function of the path's keys.
"""
from collections import namedtuple

from numba import njit

from stages.core.rng import uniform
from stages.core.shading.material import material_sample

# A path whose throughput stays near 1 (white fibres in dense cloth meet hundreds of fibres) survives each
# roulette with this and divides by it: 0.95 made a survivor of 300 events weigh 0.95^-300 = 5e6, and a white
# cloth's picture heavy-tailed (a non-absorbing cloth averaged 0.98-1.71 over seeds); 0.999^-300 = 1.35.
RR_MAX_SURVIVAL = 0.999
NO_HIT = 1e300

PathStep = namedtuple("PathStep", ["alive", "pdf", "tp"])
PathStep.__doc__ = """continue_path's answer: whether the path goes on, the sampled direction's pdf, its throughput
(r, g, b)."""


@njit(cache=True, inline="always")
def power_heuristic(a, b):
    """a^2 / (a^2 + b^2), 0 where a is 0."""
    a2 = a * a
    return a2 / (a2 + b * b) if a2 > 0.0 else 0.0


@njit(cache=True, inline="always")
def roulette_survival(t0, t1, t2):
    """min(RR_MAX_SURVIVAL, max(t0, t1, t2)): the probability that a path of throughput (t0, t1, t2) goes on."""
    return min(RR_MAX_SURVIVAL, max(t0, max(t1, t2)))


@njit(cache=True, inline="always")
def continue_path(mat, ctx, t, n, wi, roulette, seed, key, base, tp, wo):
    """The scattering step of a fibre path at a vertex (material row ``mat``, its prepared context ``ctx``,
    tangent ``t``, normal ``n``, towards-the-viewer ``wi``): a direction sampled into ``wo`` from the
    uniforms (seed, key, base .. base + 2), the throughput ``tp`` (r, g, b) times f cos / pdf, then, if
    ``roulette``, Russian roulette with the uniform (seed, key, base + 3). Dead (``alive`` False) where the
    sample has no density or the roulette ends it."""
    s0, s1, s2, pf = material_sample(mat, ctx, t, n, wi, uniform(seed, key, base), uniform(seed, key, base + 1),
                                     uniform(seed, key, base + 2), wo)
    return path_step(s0, s1, s2, pf, roulette, seed, key, base, tp)


@njit(cache=True, inline="always")
def path_step(s0, s1, s2, pf, roulette, seed, key, base, tp):
    """``continue_path`` after its sample (weight s, density pf): the throughput times the weight, then, if
    ``roulette``, Russian roulette with the uniform (seed, key, base + 3)."""
    tp0 = tp[0]
    tp1 = tp[1]
    tp2 = tp[2]
    if pf <= 0.0:
        return PathStep(False, pf, (tp0, tp1, tp2))
    tp0 *= s0
    tp1 *= s1
    tp2 *= s2
    if roulette:
        q = roulette_survival(tp0, tp1, tp2)
        if uniform(seed, key, base + 3) >= q:
            return PathStep(False, pf, (tp0, tp1, tp2))
        tp0 /= q
        tp1 /= q
        tp2 /= q
    return PathStep(True, pf, (tp0, tp1, tp2))
