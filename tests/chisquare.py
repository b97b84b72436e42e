"""The one chi-square harness for every sampling routine (after Mitsuba 3's ``ChiSquareTest``).

A sampler's samples, mapped to a 2D parameterisation (x, y) over a rectangle, are histogrammed on a
``res`` grid. The expected count of each bin is N times the integral of the sampler's claimed density
over the bin (Gauss-Legendre, ``sub`` x ``sub`` nodes per bin). Bins expecting fewer than ``min_expected``
samples are pooled into one. Pearson's statistic is compared with the chi-square distribution
(dof = bins - 1) at the significance ``alpha`` with a Šidák correction for ``n_tests`` tests run
together: alpha_1 = 1 - (1 - alpha)^(1 / n_tests). A bin with no expected mass but observed
samples fails outright, as does a density whose total integral is far from 1.

Directions use ``directions_to_xy`` (x = cos theta about ``axis``, y = phi in [-pi, pi]): the density
with respect to (cos theta, phi) equals the solid-angle density, so ``pdf_xy`` is the sampler's pdf.
A sampler with its own parameterisation (e.g. (theta, phi) for narrow fibre lobes) passes its own
map and density with respect to it.

    res = chi2_test(xy, pdf_xy, bounds=((-1, 1), (-math.pi, math.pi)), res=(40, 80))
    assert res.passed, res.message

One adapter per sampling interface draws the samples in a numba loop (u = ``uniform(seed, k, dim)``),
checks the sample contract and runs ``chi2_test``; every sampling test goes through one of them:
- ``check_shading_model(sample, pdf, eval, p, frame, wi, ...)``: the shading interface of
  ``stages.core.shading`` (bcsdf, lambert, sggx; material rows through thin wrappers): weight ==
  eval / pdf and pdf(sample) == the returned pdf, then chi-square in (cos theta, phi) or (theta, phi);
- ``check_light(lights, k, env, marg, cond, ...)``: ``stages.render.lights``: returned radiance ==
  light_eval, returned pdf == light_pdf, then chi-square on the sphere or in the envmap's (u, v);
- ``chi2_test_1d`` for one-dimensional samplers (free-flight distances, normal variates) and
  ``z_score_test`` for standardised differences of two estimators (sum of squares against chi-square).
Samplers of other shapes (the yarn model's cross-section and hair-tree distributions) call
``chi2_test`` with their own map and density.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import stats

from stages.core.rng import uniform
from stages.render.lights import light_eval, light_pdf, light_sample


@dataclass
class Chi2Result:
    passed: bool
    p_value: float
    statistic: float
    dof: int
    significance: float
    integral: float
    message: str


def frame_from_axis(axis):
    """Orthonormal (u, v, w = axis)."""
    w = np.asarray(axis, float)
    w = w / np.linalg.norm(w)
    a = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, w)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    return u, v, w


def directions_to_xy(dirs, axis=(0.0, 0.0, 1.0)):
    """(cos theta, phi) of unit directions (N, 3) about ``axis``."""
    u, v, w = frame_from_axis(axis)
    d = np.asarray(dirs, float)
    return np.stack([np.clip(d @ w, -1.0, 1.0), np.arctan2(d @ v, d @ u)], axis=-1)


def xy_to_directions(x, y, axis=(0.0, 0.0, 1.0)):
    """Inverse of ``directions_to_xy`` (x = cos theta, y = phi); arrays of any shape -> (..., 3)."""
    u, v, w = frame_from_axis(axis)
    s = np.sqrt(np.clip(1.0 - x * x, 0.0, None))
    return (s * np.cos(y))[..., None] * u + (s * np.sin(y))[..., None] * v + np.asarray(x)[..., None] * w


def bin_integrals(pdf_xy, bounds, res, sub=6):
    """Integral of ``pdf_xy`` (vectorised over flat arrays x, y) over each bin: array (nx, ny)."""
    (x0, x1), (y0, y1) = bounds
    nx, ny = res
    gx, gw = np.polynomial.legendre.leggauss(sub)
    hx = (x1 - x0) / nx
    hy = (y1 - y0) / ny
    cx = x0 + (np.arange(nx) + 0.5) * hx
    cy = y0 + (np.arange(ny) + 0.5) * hy
    X = (cx[:, None] + 0.5 * hx * gx[None, :]).reshape(-1)          # (nx*sub)
    Y = (cy[:, None] + 0.5 * hy * gx[None, :]).reshape(-1)          # (ny*sub)
    XX, YY = np.meshgrid(X, Y, indexing="ij")
    vals = np.asarray(pdf_xy(XX.ravel(), YY.ravel()), float).reshape(nx, sub, ny, sub)
    w = np.outer(gw, gw) * (0.25 * hx * hy)
    return np.einsum("aibj,ij->ab", vals, w)


def chi2_test(xy, pdf_xy, bounds, res=(40, 80), sub=6, alpha=0.01, n_tests=1,
              min_expected=5.0, n_total=None, integral_tol=1e-2) -> Chi2Result:
    """Pearson chi-square of the histogram of ``xy`` (N, 2) against ``pdf_xy`` integrated per bin.

    ``n_total`` is the number of sampling attempts when some attempts produced no sample (those are
    missing from ``xy``); the density then integrates to the success fraction.
    """
    xy = np.asarray(xy, float)
    n = int(n_total if n_total is not None else len(xy))
    (x0, x1), (y0, y1) = bounds
    nx, ny = res
    obs, _, _ = np.histogram2d(xy[:, 0], xy[:, 1], bins=[nx, ny], range=[[x0, x1], [y0, y1]])
    integ = bin_integrals(pdf_xy, bounds, res, sub)
    total = float(integ.sum())
    exp = integ * n
    sig = 1.0 - (1.0 - alpha) ** (1.0 / n_tests)
    outside = len(xy) - obs.sum()
    if outside > 0:
        return Chi2Result(False, 0.0, math.inf, 0, sig, total, f"{int(outside)} samples outside the domain")
    if n_total is None and abs(total - 1.0) > integral_tol:
        return Chi2Result(False, 0.0, math.inf, 0, sig, total, f"density integrates to {total:.6f}, not 1")
    o = obs.ravel()
    e = exp.ravel()
    zero = e <= 1e-12 * n
    if np.any(o[zero] > 0):
        k = int(np.sum(o[zero]))
        return Chi2Result(False, 0.0, math.inf, 0, sig, total, f"{k} samples in bins of zero expected mass")
    small = (e < min_expected) & ~zero
    oo = list(o[~small & ~zero])
    ee = list(e[~small & ~zero])
    pooled_o, pooled_e = float(o[small].sum()), float(e[small].sum())
    if n_total is not None:  # attempts that produced no sample form a bin of their own
        pooled_o += n - len(xy)
        pooled_e += n * (1.0 - total)
    if pooled_e > 0:
        oo.append(pooled_o)
        ee.append(pooled_e)
    oo = np.asarray(oo)
    ee = np.asarray(ee)
    stat = float(np.sum((oo - ee) ** 2 / ee))
    dof = len(oo) - 1
    if dof < 1:
        return Chi2Result(False, 0.0, stat, dof, sig, total, "too few populated bins for a chi-square test")
    p = float(stats.chi2.sf(stat, dof))
    ok = p >= sig
    msg = f"chi2 = {stat:.1f}, dof = {dof}, p = {p:.4g} (significance {sig:.3g}), density integral {total:.6f}"
    return Chi2Result(ok, p, stat, dof, sig, total, msg)


# ------------------------------------------------------------------------------------------------
# more parameterisations
def directions_to_theta_phi(dirs, axis=(0.0, 0.0, 1.0)):
    """(theta, phi) of unit directions (N, 3): theta = asin(d . axis) in [-pi/2, pi/2] (the fibre's
    longitudinal angle), phi the azimuth as in ``directions_to_xy``. The density with respect to
    (theta, phi) is the solid-angle density times cos(theta)."""
    u, v, w = frame_from_axis(axis)
    d = np.asarray(dirs, float)
    return np.stack([np.arcsin(np.clip(d @ w, -1.0, 1.0)), np.arctan2(d @ v, d @ u)], axis=-1)


def theta_phi_to_directions(theta, phi, axis=(0.0, 0.0, 1.0)):
    """Inverse of ``directions_to_theta_phi``; arrays of any shape -> (..., 3)."""
    return xy_to_directions(np.sin(theta), phi, axis)


def chi2_test_1d(x, pdf_x, bounds, bins=40, **kw) -> Chi2Result:
    """``chi2_test`` of one-dimensional samples (a single bin across a dummy second axis)."""
    x = np.asarray(x, float)
    xy = np.stack([x, np.full(len(x), 0.5)], axis=-1)
    return chi2_test(xy, lambda a, b: pdf_x(a), (tuple(bounds), (0.0, 1.0)), res=(bins, 1), **kw)


def z_score_test(z, alpha=1e-3) -> Chi2Result:
    """Standardised differences z (each standard normal under the null, independent): the sum of
    squares against chi-square with len(z) degrees of freedom (p >= alpha), and no single |z| above
    the two-sided normal quantile at the Šidák-corrected alpha over len(z) tests."""
    z = np.asarray(z, float).ravel()
    stat = float(np.sum(z * z))
    dof = int(z.size)
    p = float(stats.chi2.sf(stat, dof))
    zmax = float(stats.norm.isf(0.5 * (1.0 - (1.0 - alpha) ** (1.0 / dof))))
    worst = float(np.abs(z).max())
    ok = p >= alpha and worst < zmax
    msg = (f"chi2 = {stat:.1f}, dof = {dof}, p = {p:.4g} (significance {alpha:.3g}); "
           f"max |z| = {worst:.2f} (limit {zmax:.2f})")
    return Chi2Result(ok, p, stat, dof, alpha, float("nan"), msg)


# ------------------------------------------------------------------------------------------------
# adapter: the shading interface of stages.core.shading (bcsdf, lambert, sggx; material rows wrapped)
#     <m>_sample(p, frame, wi, u0, u1, u2) -> (wo, r, g, b, pdf)   weight = eval / pdf; pdf 0 = no sample
#     <m>_pdf(p, frame, wi, wo) -> pdf                             solid-angle density of <m>_sample
#     <m>_eval(p, frame, wi, wo) -> (r, g, b)                      f cos
@njit
def shading_draw(sample, p, frame, wi, n, seed):
    """n samples with u_d = uniform(seed, k, d): (wo (n, 3), weight (n, 3), pdf (n,))."""
    wo = np.empty((n, 3))
    wt = np.empty((n, 3))
    pdf = np.empty(n)
    for k in range(n):
        w, r, g, b, q = sample(p, frame, wi, uniform(seed, k, 0), uniform(seed, k, 1), uniform(seed, k, 2))
        wo[k, 0] = w[0]
        wo[k, 1] = w[1]
        wo[k, 2] = w[2]
        wt[k, 0] = r
        wt[k, 1] = g
        wt[k, 2] = b
        pdf[k] = q
    return wo, wt, pdf


@njit
def shading_pdf_many(pdf, p, frame, wi, W):
    out = np.empty(W.shape[0])
    for k in range(W.shape[0]):
        out[k] = pdf(p, frame, wi, W[k])
    return out


@njit
def shading_eval_many(ev, p, frame, wi, W):
    out = np.empty((W.shape[0], 3))
    for k in range(W.shape[0]):
        r, g, b = ev(p, frame, wi, W[k])
        out[k, 0] = r
        out[k, 1] = g
        out[k, 2] = b
    return out


@njit
def shading_pdf_xy(pdf, p, frame, wi, x, y, u, v, w, theta):
    """pdf at the directions of (x, y) about the orthonormal frame (u, v, w = axis): x = cos theta
    (theta = False) or x = theta (theta = True, density times cos theta: the (theta, phi) measure)."""
    out = np.empty(x.shape[0])
    d = np.empty(3)
    for k in range(x.shape[0]):
        c = math.sin(x[k]) if theta else x[k]
        s = math.sqrt(max(0.0, 1.0 - c * c))
        cp = s * math.cos(y[k])
        sp = s * math.sin(y[k])
        for j in range(3):
            d[j] = cp * u[j] + sp * v[j] + c * w[j]
        out[k] = pdf(p, frame, wi, d) * (math.cos(x[k]) if theta else 1.0)
    return out


def _contract(wo, weight, q, ok, pdf_at, eval_at, n_contract, rtol):
    """Message of the first broken sample contract, or '' (unit wo, pdf(wo) == pdf, weight == eval / pdf)."""
    idx = np.flatnonzero(ok)[:n_contract]
    if len(idx) == 0:
        return "no sample succeeded"
    W = np.ascontiguousarray(wo[idx])
    err = np.abs(np.linalg.norm(W, axis=1) - 1.0).max()
    if err > 1e-9:
        return f"contract: sampled directions are not unit (|1 - |wo|| up to {err:.3g})"
    pq = pdf_at(W)
    bad = ~np.isclose(pq, q[idx], rtol=rtol, atol=0.0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        return (f"contract: pdf(sample) = {pq[k]:.9g} but the sampler returned {q[idx][k]:.9g} "
                f"({int(bad.sum())} of {len(idx)})")
    ref = eval_at(W) / q[idx][:, None]
    bad = ~np.all(np.isclose(weight[idx], ref, rtol=rtol, atol=1e-300), axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        return (f"contract: weight {weight[idx][k]} != eval / pdf {ref[k]} "
                f"({int(bad.sum())} of {len(idx)})")
    return ""


def _direction_xy(wo, axis, angles, bounds):
    """(xy, bounds) of unit directions in the (cos theta, phi) (angles="cos") or (theta, phi)
    (angles="theta") parameterisation about ``axis``; default bounds: the whole sphere."""
    if angles == "cos":
        return directions_to_xy(wo, axis), bounds or ((-1.0, 1.0), (-math.pi, math.pi))
    if angles == "theta":
        return directions_to_theta_phi(wo, axis), bounds or ((-0.5 * math.pi, 0.5 * math.pi), (-math.pi, math.pi))
    raise ValueError(f"angles = {angles!r}: 'cos' or 'theta'")


def check_shading_model(sample, pdf, eval, p, frame, wi, *, axis=None, angles="cos", n=200_000, seed=1,
                        res=(40, 80), sub=6, bounds=None, alpha=0.01, n_tests=1, n_contract=2000,
                        rtol=1e-9) -> Chi2Result:
    """One model of the shading interface (numba functions ``sample``, ``pdf``, ``eval``) at one
    (p, frame, wi): n samples drawn in a numba loop; the sample contract on the first ``n_contract``
    successful samples (|wo| = 1, pdf(wo) == returned pdf and weight == eval(wo) / pdf, rtol); then
    the chi-square of the samples against ``pdf`` in (cos theta, phi) (angles="cos") or, for narrow
    fibre lobes, (theta, phi) (angles="theta") about ``axis`` (default: the frame, when it is a
    direction). Failed samples (pdf 0) count as attempts without a sample."""
    p = np.ascontiguousarray(p, np.float64)
    frame = np.ascontiguousarray(frame, np.float64)
    wi = np.ascontiguousarray(wi, np.float64)
    axis = frame if axis is None else np.asarray(axis, float)
    wo, weight, q = shading_draw(sample, p, frame, wi, int(n), int(seed))
    ok = q > 0.0
    msg = _contract(wo, weight, q, ok, lambda W: shading_pdf_many(pdf, p, frame, wi, W),
                    lambda W: shading_eval_many(eval, p, frame, wi, W), n_contract, rtol)
    if msg:
        return Chi2Result(False, 0.0, math.inf, 0, alpha, float("nan"), msg)
    xy, bounds = _direction_xy(wo[ok], axis, angles, bounds)
    u, v, w = frame_from_axis(axis)
    def pdf_xy(x, y):
        return shading_pdf_xy(pdf, p, frame, wi, x, y, u, v, w, angles == "theta")

    return chi2_test(xy, pdf_xy, bounds, res=res, sub=sub, alpha=alpha, n_tests=n_tests,
                     n_total=None if ok.all() else int(n))


# ------------------------------------------------------------------------------------------------
# adapter: the light interface of stages.render.lights
#     light_sample(lights, k, env, marg, cond, u1, u2) -> (w, r, g, b, pdf, delta)   r, g, b = radiance from w
#     light_pdf(lights, k, env, marg, cond, w) -> pdf ;  light_eval(...) -> (r, g, b)
@njit
def light_draw(lights, k, env, marg, cond, n, seed):
    """n samples of light k with (u1, u2) = uniform(seed, i, 0 / 1): (w (n, 3), values (n, 4) = r, g, b, pdf,
    delta (n,))."""
    out = np.empty((n, 3))
    vals = np.empty((n, 4))
    delta = np.empty(n, np.bool_)
    for i in range(n):
        w, r, g, b, pdf, dl = light_sample(lights, k, env, marg, cond, uniform(seed, i, 0), uniform(seed, i, 1))
        out[i, 0] = w[0]
        out[i, 1] = w[1]
        out[i, 2] = w[2]
        vals[i, 0] = r
        vals[i, 1] = g
        vals[i, 2] = b
        vals[i, 3] = pdf
        delta[i] = dl
    return out, vals, delta


@njit
def light_pdf_many(lights, k, env, marg, cond, W):
    out = np.empty(W.shape[0])
    for i in range(W.shape[0]):
        out[i] = light_pdf(lights, k, env, marg, cond, W[i])
    return out


@njit
def light_eval_many(lights, k, env, marg, cond, W):
    out = np.empty((W.shape[0], 3))
    for i in range(W.shape[0]):
        r, g, b = light_eval(lights, k, env, marg, cond, W[i])
        out[i, 0] = r
        out[i, 1] = g
        out[i, 2] = b
    return out


def latlong_to_directions(u, v):
    """The lat-long orientation of ``stages.render.lights``: (u, v) -> (sin phi sin theta, cos phi sin theta,
    cos theta), phi = 2 pi u, theta = pi v; arrays of any shape -> (..., 3)."""
    t = np.asarray(v) * math.pi
    ph = np.asarray(u) * 2.0 * math.pi
    return np.stack([np.sin(ph) * np.sin(t), np.cos(ph) * np.sin(t), np.cos(t)], -1)


def directions_to_latlong(W):
    th = np.arccos(np.clip(W[:, 2], -1.0, 1.0))
    ph = np.mod(np.arctan2(W[:, 0], W[:, 1]), 2.0 * math.pi)
    return np.stack([ph / (2.0 * math.pi), th / math.pi], -1)


def check_light(lights, k, env, marg, cond, *, angles="cos", axis=(0.0, 0.0, 1.0), n=200_000, seed=5,
                res=(100, 40), sub=6, alpha=0.01, n_tests=1, n_contract=2000, rtol=1e-12) -> Chi2Result:
    """Light k of a packed light table: n samples drawn in a numba loop; the sample contract on the first
    ``n_contract`` (not a delta light, |w| = 1, returned radiance == light_eval(w), returned pdf ==
    light_pdf(w), rtol); then the chi-square of the samples against light_pdf in (cos theta, phi) about
    ``axis`` (angles="cos") or in the lat-long (u, v) of the envmap (angles="latlong", density
    pdf 2 pi^2 sin theta; use bins aligned to pixels: the density is constant per pixel). Samples with
    pdf 0 count as attempts without a sample."""
    if angles not in ("cos", "latlong"):
        raise ValueError(f"angles = {angles!r}: 'cos' or 'latlong'")
    lights = np.ascontiguousarray(lights, np.float64)
    W, vals, delta = light_draw(lights, k, env, marg, cond, int(n), int(seed))
    def pdf_dirs(D):
        return light_pdf_many(lights, k, env, marg, cond, np.ascontiguousarray(D))

    if delta.any():
        return Chi2Result(False, 0.0, math.inf, 0, alpha, float("nan"), "a delta light has no density to test")
    ok = vals[:, 3] > 0.0
    idx = np.flatnonzero(ok)[:n_contract]
    Wc = np.ascontiguousarray(W[idx])
    msg = ""
    err = np.abs(np.linalg.norm(Wc, axis=1) - 1.0).max() if len(idx) else 0.0
    if len(idx) == 0:
        msg = "no sample succeeded"
    elif err > 1e-9:
        msg = f"contract: sampled directions are not unit (|1 - |w|| up to {err:.3g})"
    elif not np.allclose(vals[idx, 3], pdf_dirs(Wc), rtol=rtol, atol=0.0):
        msg = "contract: the returned pdf differs from light_pdf at the sample"
    elif not np.allclose(vals[idx, :3], light_eval_many(lights, k, env, marg, cond, Wc), rtol=rtol, atol=0.0):
        msg = "contract: the returned radiance differs from light_eval at the sample"
    if msg:
        return Chi2Result(False, 0.0, math.inf, 0, alpha, float("nan"), msg)
    n_total = None if ok.all() else int(n)
    if angles == "latlong":
        def pdf_uv(u, v):
            return pdf_dirs(latlong_to_directions(u, v)) * 2.0 * math.pi ** 2 * np.sin(v * math.pi)

        return chi2_test(directions_to_latlong(W[ok]), pdf_uv, ((0.0, 1.0), (0.0, 1.0)), res=res, sub=sub,
                         alpha=alpha, n_tests=n_tests, n_total=n_total)
    xy, bounds = _direction_xy(W[ok], axis, "cos", None)
    return chi2_test(xy, lambda x, y: pdf_dirs(xy_to_directions(x, y, axis)), bounds, res=res, sub=sub,
                     alpha=alpha, n_tests=n_tests, n_total=n_total)
