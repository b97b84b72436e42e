"""Error against a converged reference, and error against time: the equal-error comparison.

A method's picture at render time t differs from the fibres' converged answer R by its bias (what
the method computes that the fibres do not) and by its Monte Carlo noise (which falls as 1/t). With
the squared error measured per pixel and averaged, the two add:

    E(t)^2 = b^2 + c / t                                                          (1)

b is the method's **bias floor** against the fibres (no budget takes it lower), c its **noise
constant** (the squared error one second of rendering leaves). The comparison renders each method
at a doubling sequence of budgets, measures E^2 at each, fits (1), and asks the user's question:
which method reaches a given error first (Veach-style efficiency, 1 / (variance x time), measured
against a reference rather than against itself).

Error of one picture (``relative_error``), over the reference's *cloth pixels* (alpha > 0.5):

    e_i^2 = (1/3) sum_c (t_ic - r_ic)^2 / d_i^2,   d_i = max(Y(r_i), FLOOR x mean_cloth Y(r))
    E^2   = mean_i e_i^2 - mean_i s_i^2,           s_i^2 = (1/3) sum_c var(r_ic) / d_i^2        (2)

with Y the luminance and var(r_ic) the variance of the reference pixel's mean, measured from its
independent batches (``batch_mean``). The reference is itself a Monte Carlo estimate: its noise adds
mean s_i^2 to the expected squared difference, and (2) takes it off (E^2 may come out negative for a
test within the reference's noise; it is reported as measured, E = sign(E^2) sqrt(|E^2|)). The
floor FLOOR = 0.1 of the cloth's mean luminance keeps near-black pixels (deep shadow between
yarns) from dominating a relative measure. The uncertainty of E^2 is the standard error of the mean
over pixels of e_i^2 - s_i^2 (pixels are independent estimates), plus the uncertainty of the
variance estimates (relative sqrt(2 / (K - 1)) for K batches) on the subtracted term.

The fit (``fit_bias_noise``): weighted linear least squares of (1) in (b^2, c) over the measured
points, weights 1 / (uncertainty of E^2)^2 with the uncertainty floored at 5 % of E^2 (so that a
method whose points all sit far above the reference's noise is fitted in relative terms), both
parameters kept >= 0 (a negative one is fixed at 0 and the other refitted), with the parameters'
standard errors from the fit's covariance.

Time to an error level L (``time_to_error``): the measured points decide whether L is reached; the
fit only interpolates between the two measured points that bracket L (the first point at or below
L and the one before it). A method already at or below L at its smallest budget reaches it "at most"
then; one whose last point is above L has not reached it (and never will if b > L).

Reference: Veach 1997 §2.4 (efficiency = 1 / (variance x time)); seed 001 Table 2 and seed 004
compare methods at equal quality.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

CLOTH_ALPHA = 0.5           # a pixel is cloth where the reference's alpha (fraction of camera rays that hit)
                            # exceeds this
DENOMINATOR_FLOOR = 0.1     # d_i >= this x the cloth's mean luminance: near-black pixels do not dominate (2)
FIT_REL_FLOOR = 0.05        # the fit's uncertainty of a point is at least this fraction of its E^2
LUMA = np.array([0.2126, 0.7152, 0.0722])


# ------------------------------------------------------------------------------------------------
# a reference from independent batches
@dataclass(frozen=True)
class BatchStatistics:
    mean: np.ndarray          # (H, W, 3) the mean of the batch images
    variance: np.ndarray      # (H, W, 3) the variance of that mean: sample variance over batches / K
    batches: int


def batch_mean(images) -> BatchStatistics:
    """The mean of K >= 2 independent batch images (equal samples each) and the variance of that mean
    per pixel and channel, sum_k (x_k - mean)^2 / (K (K - 1))."""
    x = np.asarray(images, np.float64)
    k = x.shape[0]
    if k < 2:
        raise ValueError("the variance of a mean needs at least two independent batches")
    mean = x.mean(axis=0)
    var = ((x - mean) ** 2).sum(axis=0) / (k * (k - 1))
    return BatchStatistics(mean, var, k)


def cloth_mask(alpha: np.ndarray) -> np.ndarray:
    return np.asarray(alpha) > CLOTH_ALPHA


def denominators(ref: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """d_i of (2): the reference pixel's luminance, floored at DENOMINATOR_FLOOR x the cloth's mean."""
    y = np.asarray(ref, np.float64) @ LUMA
    floor = DENOMINATOR_FLOOR * float(y[mask].mean()) if mask.any() else 0.0
    return np.maximum(y, max(floor, 1e-12))


@dataclass(frozen=True)
class ReferenceNoise:
    pixel_median: float       # median over cloth pixels of the relative standard error sqrt(s_i^2)
    pixel_p95: float
    mean: float               # relative standard error of the cloth's mean luminance


def reference_noise(ref: np.ndarray, variance: np.ndarray, alpha: np.ndarray) -> ReferenceNoise:
    """How converged a reference is: its per-pixel relative standard error over the cloth (median,
    95th percentile) and the relative standard error of its mean luminance over the cloth."""
    mask = cloth_mask(alpha)
    if not mask.any():
        raise ValueError("the reference has no cloth pixels (alpha > 0.5)")
    d = denominators(ref, mask)
    s = np.sqrt(np.asarray(variance, np.float64).mean(axis=2)) / d
    y = np.asarray(ref, np.float64) @ LUMA
    var_y = np.asarray(variance, np.float64) @ (LUMA ** 2)
    n = int(mask.sum())
    mean_se = math.sqrt(float(var_y[mask].sum())) / n / max(float(y[mask].mean()), 1e-30)
    return ReferenceNoise(float(np.median(s[mask])), float(np.percentile(s[mask], 95)), mean_se)


# ------------------------------------------------------------------------------------------------
# the error of one picture against the reference, (2)
@dataclass(frozen=True)
class PictureError:
    e2: float                 # E^2 of (2): mean squared relative error less the reference's noise
    e2_se: float              # its standard error
    raw_e2: float             # mean e_i^2 before the subtraction
    ref_noise_e2: float       # mean s_i^2, what was subtracted
    mean_ratio: tuple         # per channel: the test's cloth mean over the reference's
    pixels: int

    @property
    def error(self) -> float:
        """E = sign(E^2) sqrt(|E^2|): the relative RMSE after the noise subtraction."""
        return math.copysign(math.sqrt(abs(self.e2)), self.e2)


def relative_error(test: np.ndarray, ref: np.ndarray, ref_variance: np.ndarray, alpha: np.ndarray,
                   batches: int) -> PictureError:
    """E^2 of (2) of ``test`` against ``ref`` (linear RGB, (H, W, 3)) over the reference's cloth pixels,
    ``ref_variance`` the variance of the reference's pixel means from ``batches`` independent batches."""
    t, r = np.asarray(test, np.float64), np.asarray(ref, np.float64)
    mask = cloth_mask(alpha)
    if not mask.any():
        raise ValueError("the reference has no cloth pixels (alpha > 0.5)")
    d2 = denominators(r, mask)[mask] ** 2
    e2 = ((t[mask] - r[mask]) ** 2).mean(axis=1) / d2
    s2 = np.asarray(ref_variance, np.float64)[mask].mean(axis=1) / d2
    n = e2.size
    diff = e2 - s2
    se_pixels = float(diff.std(ddof=1)) / math.sqrt(n) if n > 1 else float("inf")
    se_variance = float(s2.mean()) * math.sqrt(2.0 / max(batches - 1, 1)) / math.sqrt(n)
    tm, rm = t[mask].mean(axis=0), r[mask].mean(axis=0)
    return PictureError(float(diff.mean()), math.hypot(se_pixels, se_variance), float(e2.mean()), float(s2.mean()),
                        tuple(float(v) for v in tm / np.maximum(rm, 1e-30)), n)


def error_map(test: np.ndarray, ref: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Per-pixel relative error e_i of (2) (NaN off the cloth), for the error-map pictures."""
    t, r = np.asarray(test, np.float64), np.asarray(ref, np.float64)
    mask = cloth_mask(alpha)
    d = denominators(r, mask)
    e = np.sqrt(((t - r) ** 2).mean(axis=2)) / d
    return np.where(mask, e, np.nan)


# ------------------------------------------------------------------------------------------------
# error against time, (1)
@dataclass(frozen=True)
class NoiseFit:
    b2: float                 # the squared bias floor
    c: float                  # the noise constant (squared relative error x seconds)
    b2_se: float
    c_se: float
    points: int

    @property
    def floor(self) -> float:
        """The bias floor b = sqrt(b^2)."""
        return math.sqrt(max(self.b2, 0.0))

    @property
    def floor_se(self) -> float:
        """Standard error of b (of b^2 propagated; b^2's own where b is 0)."""
        return self.b2_se / (2.0 * self.floor) if self.floor > 0 else math.sqrt(self.b2_se)

    def e2(self, t):
        return self.b2 + self.c / np.asarray(t, np.float64)

    def time_at(self, level: float) -> float:
        """The time at which (1) reaches E = level; inf where the floor is at or above it."""
        gap = level * level - self.b2
        return self.c / gap if gap > 0 else math.inf


def _weighted_lsq(x, y, w, fixed):
    """Least squares of y = p0 + p1 x with weights w; ``fixed`` maps a parameter index to its value.
    Returns (p, cov)."""
    cols = [np.ones_like(x), x]
    free = [i for i in (0, 1) if i not in fixed]
    rhs = y - sum(fixed[i] * cols[i] for i in fixed)
    A = np.stack([cols[i] for i in free], axis=1) * np.sqrt(w)[:, None]
    bvec = rhs * np.sqrt(w)
    normal = A.T @ A
    cov_free = np.linalg.pinv(normal)
    sol = cov_free @ (A.T @ bvec)
    p = np.zeros(2)
    cov = np.zeros((2, 2))
    for k, i in enumerate(free):
        p[i] = sol[k]
        for m, j in enumerate(free):
            cov[i, j] = cov_free[k, m]
    for i, v in fixed.items():
        p[i] = v
    # scale by the reduced chi-square where there are spare points (the uncertainties given are estimates)
    dof = len(x) - len(free)
    if dof > 0:
        chi2 = float(np.sum(w * (y - p[0] - p[1] * x) ** 2)) / dof
        cov = cov * max(chi2, 1.0)
    return p, cov


def fit_bias_noise(times, e2, e2_se) -> NoiseFit:
    """Fit E^2 = b^2 + c / t (1) to measured (t_k, E^2_k, se_k), b^2 >= 0 and c >= 0 (module doc)."""
    t = np.asarray(times, np.float64)
    y = np.asarray(e2, np.float64)
    se = np.asarray(e2_se, np.float64)
    if t.size < 2:
        raise ValueError("fitting a bias floor and a noise constant needs at least two budgets")
    if np.any(t <= 0):
        raise ValueError("render times must be positive")
    x = 1.0 / t
    sigma = np.maximum(se, FIT_REL_FLOOR * np.abs(y))
    sigma = np.maximum(sigma, 1e-30)
    w = 1.0 / sigma ** 2
    p, cov = _weighted_lsq(x, y, w, {})
    free_se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    if p[0] < 0 and p[1] < 0:
        p, cov = np.zeros(2), np.zeros((2, 2))
    elif p[0] < 0:
        p, cov = _weighted_lsq(x, y, w, {0: 0.0})
    elif p[1] < 0:
        p, cov = _weighted_lsq(x, y, w, {1: 0.0})
    p = np.maximum(p, 0.0)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    se = np.where(se > 0, se, free_se)   # a parameter held at 0: the free fit's uncertainty says how far from 0
    return NoiseFit(float(p[0]), float(p[1]), float(se[0]), float(se[1]), int(t.size))


@dataclass(frozen=True)
class TimeToError:
    level: float
    time: float | None        # seconds; None where the measured points do not reach the level
    bound: str                # "" (interpolated between two measured points), "<=" (at the first budget already),
                              # ">" (the last point is still above: time is the last point's)
    floor_blocks: bool        # the fitted floor is at or above the level: no budget reaches it


def time_to_error(level: float, times, errors, fit: NoiseFit) -> TimeToError:
    """When the measured errors E(t_k) (times increasing) reach ``level`` (module doc)."""
    t = np.asarray(times, np.float64)
    e = np.asarray(errors, np.float64)
    blocked = fit.floor >= level
    below = np.nonzero(e <= level)[0]
    if below.size == 0:
        return TimeToError(level, float(t[-1]), ">", blocked)
    k = int(below[0])
    if k == 0:
        return TimeToError(level, float(t[0]), "<=", blocked)
    lo, hi = float(t[k - 1]), float(t[k])
    tf = fit.time_at(level)
    if not (lo <= tf <= hi):   # the fit disagrees with the bracketing points: interpolate them in log-log
        e0, e1 = max(float(e[k - 1]), 1e-30), max(float(e[k]), 1e-30)
        f = (math.log(level) - math.log(e0)) / (math.log(e1) - math.log(e0)) if e1 != e0 else 1.0
        tf = math.exp(math.log(lo) + f * (math.log(hi) - math.log(lo)))
    return TimeToError(level, tf, "", blocked)


def speedup(reference: TimeToError, method: TimeToError) -> tuple[float | None, str]:
    """The reference method's time over the method's at one error level, with its bound: "" exact,
    ">=" a lower bound, "<=" an upper bound; (None, "") where neither time says anything."""
    if reference.time is None or method.time is None or method.time <= 0:
        return None, ""
    if method.bound == ">":
        return None, ""    # the method has not reached the level: no time to compare
    r = reference.time / method.time
    ref_b, m_b = reference.bound, method.bound
    if ref_b == ">" and m_b in ("", "<="):
        return r, ">="     # the reference needs more than its last time, the method at most its own
    if ref_b == "" and m_b == "<=":
        return r, ">="
    if ref_b == "<=" and m_b == "":
        return r, "<="
    if ref_b == "<=" and m_b == "<=":
        return r, "~"       # both at their first budget: the ratio of those budgets says little
    return r, ""


def equal_time_spp(target_time: float, seconds_per_spp: float, largest: int = 1 << 16) -> int:
    """Samples per pixel that spend ``target_time`` at ``seconds_per_spp`` (at least 1, at most ``largest``)."""
    if seconds_per_spp <= 0 or not math.isfinite(seconds_per_spp):
        raise ValueError("seconds per sample must be positive")
    return int(min(max(round(target_time / seconds_per_spp), 1), largest))
