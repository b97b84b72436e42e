"""Adaptive sampling (``pipeline.renderers.film``): the second pass's counts come from the neighbours, and
the estimate that keeps every sample is unbiased.

Reference: a synthetic film whose pixels draw from known distributions (a base value plus rare
bright "glints", the shape of a sharp BCSDF lobe under a directional light), so each pixel's true
mean is known in closed form. The production decision (``refine_counts``) and combination
(``add_pass``) run on it many times; the average estimate must equal the true mean within its
standard error. The same harness with the decision taken from each pixel's *own* first pass (and
its samples kept) is measurably biased low, so the test can fail.
"""
import numpy as np

from pipeline.renderers.film import Sampling, add_pass, refine_counts
from stages.render.film import F_Y, F_YY, new_film

H, W = 10, 12
SPP = 8
GLINT = 40.0


def _pixels():
    """Per pixel: base value and glint probability (a glinting block in the middle, some flat pixels)."""
    rng = np.random.default_rng(3)
    base = 0.2 + 0.8 * rng.random((H, W))
    p = np.zeros((H, W))
    p[3:8, 4:10] = 0.03
    return base, p


def _draw(rng, base, p, counts):
    """Sums and sums of squares of counts[i] samples per pixel: base * (0.5 + U) + GLINT * Bernoulli(p)."""
    s = np.zeros((H, W))
    ss = np.zeros((H, W))
    for i in range(H):
        for j in range(W):
            n = int(counts[i, j])
            if n:
                x = base[i, j] * (0.5 + rng.random(n)) + GLINT * (rng.random(n) < p[i, j])
                s[i, j] = x.sum()
                ss[i, j] = (x * x).sum()
    return s, ss


def _film(s, ss):
    film = new_film(W, H)
    film[..., F_Y] = s
    film[..., F_YY] = ss
    return film


def _own_counts(film, spp, sampling):
    """The biased rule: each pixel's second pass decided from its own first pass."""
    n = float(spp)
    mean = film[..., F_Y] / n
    var = np.maximum(film[..., F_YY] / n - mean * mean, 0.0) * n / (n - 1)
    want = np.ceil(var / (sampling.target_error * np.maximum(mean, 1e-6)) ** 2) - spp
    return np.clip(want, 0, sampling.max_spp).astype(np.int64)


def _estimates(rule, reps, seed):
    base, p = _pixels()
    rng = np.random.default_rng(seed)
    sampling = Sampling(SPP, 96, 0.1)
    out = np.empty((reps, H, W))
    extra = 0
    for r in range(reps):
        counts = np.full((H, W), SPP)
        film = _film(*_draw(rng, base, p, counts))
        more = rule(film, SPP, sampling)
        film, counts = add_pass(film, counts, _film(*_draw(rng, base, p, more)), more)
        out[r] = film[..., F_Y] / counts
        extra += more.sum()
    return out, base + GLINT * p, extra / reps


def test_second_pass_counts_ignore_the_pixel_itself():
    """A pixel's count is a function of its neighbours only: changing its own first pass changes nothing
    of its own count (the floor excludes it too), while a noisy neighbour raises it."""
    rng = np.random.default_rng(0)
    base, p = _pixels()
    film = _film(*_draw(rng, base, p, np.full((H, W), SPP)))
    sampling = Sampling(SPP, 64, 0.05)
    more = refine_counts(film, SPP, sampling)
    for i, j in [(0, 0), (5, 6), (9, 11), (4, 0)]:
        f2 = film.copy()
        f2[i, j, F_Y] *= 7.0
        f2[i, j, F_YY] *= 300.0
        assert refine_counts(f2, SPP, sampling)[i, j] == more[i, j]
    flat = _film(np.full((H, W), 8.0), np.full((H, W), 8.0))      # every sample 1: converged, no second pass
    assert not refine_counts(flat, SPP, sampling).any()
    flat[4, 4, F_YY] = 20.0                                        # one noisy pixel: its neighbours refine
    got = refine_counts(flat, SPP, sampling)
    assert got[4, 4] == 0 and np.all(got[3:6, 3:6][np.arange(9).reshape(3, 3) != 4] > 0)
    assert got.sum() == 8 * got[3, 3]


def test_keeping_every_sample_is_unbiased_and_the_own_pass_rule_is_not():
    reps = 400
    est, truth, extra = _estimates(refine_counts, reps, seed=11)
    glint = truth > 2.0
    err = est.mean(0) - truth
    se = est.std(0, ddof=1) / np.sqrt(reps)
    z = err[glint].sum() / np.sqrt((se[glint] ** 2).sum())      # the glinting block's total, in standard errors
    assert abs(z) < 4.0, z
    assert np.all(np.abs(err) < 5.0 * se + 1e-12)                 # and every pixel on its own
    assert extra > 10 * H * W                                     # the second pass did take samples
    own, _, _ = _estimates(_own_counts, reps, seed=11)
    own_err = own.mean(0) - truth
    own_z = own_err[glint].sum() / np.sqrt(((own.std(0, ddof=1) / np.sqrt(reps))[glint] ** 2).sum())
    assert own_z < -8.0, own_z                                    # pixels that missed their glints stop early, low
