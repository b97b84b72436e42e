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
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats


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
