"""Fitting the cloth texture of seed 002: Lafortune lobes times a view lookup table, per texel and
mip level (Daubert et al. 2001, §5 and §5.1).

What it fits
------------
For every texel of a repeat, the acquired radiance samples r(l, v) (per unit irradiance, one per view v,
light l and colour channel) are fitted by the model of ``stages.core.btf`` (Eq. 1-2):

    r(l, v) ~ T(v) f_1(l, v),    f_1(l, v) = l_z (rho + sum_k [C_x,k l'_x v'_x + C_y,k l'_y v'_y + C_z,k l'_z v'_z]^N_k)

each channel on its own (rho, C_x, C_y, C_z, N and T(v) are per channel; l', v' in the texel frame
of the texel's average normal and tangent, l_z the light's pattern-space z). The fit minimises

    E = sum_v alpha(v) sum_l (r(l, v) - T(v) f_1(l, v))^2                                        (Eq. 3 over all views)

``alpha(v)`` is the fraction of the texel's rays that hit fibres from view v. A view with alpha = 0
is a hole: it carries no information about the texel, takes no part in the fit and gets T = 0. The
paper's alpha is boolean (0 or 1), and then E is its plain sum over the texel's non-hole views.
loomlight's alpha can be fractional (supersampling), so a view counts in proportion to its coverage;
this is what makes the mip grouping below exact. The samples are taken to be the mean radiance of the
rays that hit fibres, not premultiplied by alpha. That is how the renderer composites:
alpha T f_1 over what lies behind.

Algorithm (§5), per texel
-------------------------
1. **Scale.** Each channel's samples are divided by their largest magnitude s over the texel's
   non-hole views (s = 1 for an all-zero channel). The fit runs in these units, so its tolerances and
   damping do not depend on the data's scale. The result is converted back exactly:
   rho = s rho', C = s^(1/N) C', T unchanged.
2. **Initial guess** (the paper's "average gray BRDF with a moderate specular highlight and slightly
   anisotropic lobes", made concrete and scaled to the data). Let rho_d = <l_z | r> / <l_z | l_z> over
   the fitted samples, the best constant ("gray") BRDF, taken as 0 if negative. The start is:
   - rho = rho_d / 2;
   - lobe 1: (C_x, C_y, C_z) = (-1.22 c, -c, c), lobe 2 (K = 2): (-c, -1.22 c, c). These are
     mirror-like lobes, slightly anisotropic as in the paper.
   - N = ``N_START`` (4: a moderate highlight), and c = (rho_d / (2K))^(1/N), so that at normal
     incidence the lobes together add rho_d / 2;
   - T = 1 for every non-hole view ("all its entries set to white").
3. **Lobes.** Levenberg-Marquardt fits (rho, C_x, C_y, C_z, log N of every lobe: P = 1 + 4K
   parameters) to E with T fixed. Each iteration solves the damped normal equations
   (J^T W J + lambda D) delta = J^T W e by Cholesky. D is the diagonal of J^T W J, floored at 1e-12 of
   its largest entry. lambda starts at 1e-3. A step is kept only if E falls; lambda is then updated by
   Nielsen's rule from the ratio of the actual to the predicted decrease. A rejected step multiplies
   lambda by 2, 4, 8, ...
   Constraints:
   - rho >= 0 and N in [``N_MIN``, ``N_MAX``] (N is optimised as log N), by projection;
   - each lobe's peak, max(|C_x|, |C_y|, |C_z|)^N (an upper bound of the lobe over all directions,
     between the grid's too), is at most ``PEAK_MAX`` = 1000 times the texel's largest sample. The
     projection scales C towards 0. This keeps a sparse grid from hiding a spike between its
     directions, and keeps every value finite;
   - a parameter held at its bound with the gradient pushing it out is frozen for that iteration
     (active set).
   A trial whose lobe overflows (N log a > 700) or whose normal equations are not finite counts as
   rejected. The LM has converged when one of these holds:
   - a kept step lowers E by less than ``FTOL`` relative;
   - a kept step moves every parameter by less than ``XTOL`` relative;
   - E falls below 1e-30 of the data's energy (an exact fit);
   - lambda passes 1e16: no step lowers E, so the point is stationary to rounding.
   Otherwise it stops after ``max_iter`` trial steps, not converged. Every kept step lowers E, so the
   iterate it stops on is the best one seen.
4. **Table.** T(v) = <f(v) | r(v)> / <f(v) | f(v)> per view and channel over the lights (Eq. 4,
   ``table_entry``). It is 0 when <f | f> = 0, and |T| is clipped to ``T_MAX`` so that a view the lobes
   cannot reach stays finite.
5. **Alternate** steps 3 and 4 until the mean |T_new - T_old| over the texel's non-hole views and the 3
   channels falls below ``threshold`` (the paper's 0.1; the first round compares with T = 1), or until
   ``max_rounds`` rounds. Each round is one LM pass plus one table update. The joint error never
   rises: Eq. 4 is the exact minimiser over T, and LM keeps only steps that lower E.

``converged`` is True when the alternation met the threshold and the last round's LM converged in
every channel. ``rounds`` is the number of rounds used, and ``iterations`` the LM trial steps spent on
the texel (all channels and rounds, plus the fit without a table). ``rmse`` (per channel) is
sqrt(E / (L sum_v alpha(v))), in radiance units, of the final (rho, lobes, T); for boolean alpha it
is the plain RMS error over the non-hole views. ``rmse_no_table`` is the same data fitted by the lobes
alone with T = 1 (the paper's Fig. 5 comparison). That fit is round 1's LM (which has T = 1 too)
continued, if it has not converged, up to the same total budget of max_iter x max_rounds iterations.

The paper's threshold (0.1 on the mean absolute change of T) stops early. On synthetic noisy data
with a view-dependent colour shift, most texels stop after 1 round, and the error is 40-55 % above the
noise floor in the shifted channels. A threshold of 0.01 takes about 4 rounds and comes within 15 %
of the floor. The alternation converges linearly: reproducing a model to 1e-6 takes a
hundred or more rounds.

Degenerate data never yields NaN or inf:
- A texel without a non-hole view keeps rho = 0, C = 0, N = N_START, T = 0, rmse 0, 0 rounds.
- A zero channel fits exactly at the start.
- A channel whose conversion back to radiance units would leave the float32 range (|C| > 1e30, only
  possible for absurd data) falls back to the diffuse-only fit (rho = rho_d, C = 0, T by Eq. 4) and is
  flagged not converged.
Samples must be finite with |r| <= ``MAX_RADIANCE``; ``fit_btf`` raises ValueError otherwise.

Mip levels (§5.1)
-----------------
``group_level`` makes level l from level 0. Level-l texel (i, j) (row i, column j; res >> l a side)
groups the 2^l x 2^l level-0 texels [i 2^l, (i+1) 2^l) x [j 2^l, (j+1) 2^l):
- Every texel shares the pattern-space (l, v) grid, and the model gives one value per (l, v). So fitting
  the group's concatenated samples, each weighted by its texel's alpha(v), equals fitting their
  alpha-weighted mean with weight sum_t alpha_t(v) per view.
- ``group_level`` therefore returns the alpha-weighted mean of the samples (the plain mean where the
  group's alphas are equal, e.g. without holes; the plain mean where every alpha is 0), the mean alpha
  (the coverage of the coarser texel), and the normalised mean normal. The mean tangent is
  re-orthonormalised against that normal. If the mean tangent is parallel to the normal, the tangent
  is built as in the paper's §4: b perpendicular to n and to x, t = b x n.
- ``fit_levels`` fits levels 0 .. log2(res), one ``BtfFit`` per level, each with its error summary.

Parameters
----------
``fit_btf(samples (T, V, L, 3), alpha (T, V), view_dirs (V, 3), light_dirs (L, 3), frames (T, 2, 3),
lobes=2, threshold=0.1, max_rounds=10, max_iter=50) -> BtfFit``:
- T texels, flattened row-major from (res, res); directions are unit vectors in pattern space (upper
  hemisphere, ``hemisphere_grid``); frames hold the average normal and tangent per texel.
- K = ``lobes`` is 1 or 2.
- The result holds:
  - ``rho`` (T, 3) and ``lobes`` (T, K, 3, 4) [C_x, C_y, C_z, N];
  - ``table`` (T, V, 4) [T_r, T_g, T_b, alpha] (alpha copied from the input);
  - ``rmse`` and ``rmse_no_table`` (T, 3);
  - ``rounds``, ``converged`` and ``iterations`` (T,);
  - ``frames`` (T, 2, 3), the frames it was fitted with;
  - ``summary``, a ``FitSummary``: per channel, ``rmse`` and ``rmse_no_table`` pooled over all the
    fitted samples (sqrt(sum E / sum L alpha)) and the alpha-weighted ``mean_radiance``; also
    ``mean_rounds`` and ``converged_fraction``.
- ``fit_levels(samples (res, res, V, L, 3), alpha (res, res, V), frames (res, res, 2, 3), view_dirs,
  light_dirs, lobes, threshold, max_rounds, max_iter) -> [BtfFit]`` fits levels 0 .. log2(res). Each
  level's texels are flattened row-major (res >> l a side), and its ``frames`` are the grouped ones.
- ``predict_samples(rho, lobes, table, frames, view_dirs, light_dirs)`` gives the model's radiance in
  the samples' layout (residual pictures, tests).

The texels run on threads (``stages.core.threads``). Each texel's arithmetic is sequential and independent
of the others, so the bytes are the same at any thread count.

Cost
----
One LM trial step makes one pass over the texel's V x L samples per channel. It takes K logs and exps
per sample, writes the rows of J, and then forms the (1 + 4K)(2 + 4K) / 2 entries of J^T W J as
vectorised dot products over the samples (about 65 ns a sample for K = 2, of which 38 ns is the
error alone). Level 0 dominates: each coarser level has a quarter of the texels of the one below,
so all levels together cost 4/3 of level 0.

Measured on synthetic noisy data at the runner's defaults: the paper's 32 x 32 texels, 64 views x
64 lights, K = 2, 6 levels (1365 texels), threshold 0.1. It takes about 77 trial steps per texel
(all channels). That is 25 s on one thread and 17-21 s on two, on a 2-core machine shared with other
jobs. Threshold 0.01 takes 23 s on two threads. Compiling the kernels the first time takes 17-25 s.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.btf import LOBE_PARAMS, to_texel_frame
from stages.core.threads import chunk_kernel, for_chunks

N_START = 4.0          # initial lobe exponent: a moderate highlight (§5)
ANISO = 1.22           # C_x = 1.22 C_y (lobe 1), C_y = 1.22 C_x (lobe 2) at the start (§5)
N_MIN = 0.1            # bounds of the lobe exponent N
N_MAX = 1.0e4
PEAK_MAX = 1.0e3       # largest lobe peak max|C|^N, in units of the texel's largest sample
T_MAX = 1.0e6          # |T(v)| clip (keeps an unreachable view finite)
MAX_RADIANCE = 1.0e20  # largest accepted |sample|
C_MAX = 1.0e30         # largest |C| after conversion back to radiance units (float32-safe)
FTOL = 1.0e-10         # LM: relative decrease of E below which a kept step ends the fit
XTOL = 1.0e-12         # LM: relative step below which a kept step ends the fit
LAMBDA_START = 1.0e-3
LAMBDA_MAX = 1.0e16
EXP_LIMIT = 700.0      # N log a above this overflows: the trial is rejected

BtfFit = namedtuple("BtfFit", ["rho", "lobes", "table", "rmse", "rmse_no_table", "rounds", "converged",
                               "iterations", "frames", "summary"])
FitSummary = namedtuple("FitSummary", ["rmse", "rmse_no_table", "mean_radiance", "mean_rounds", "converged_fraction"])
BtfLevel = namedtuple("BtfLevel", ["samples", "alpha", "frames", "res"])


# ------------------------------------------------------------------------------------------------
# one channel of one texel: model, error and normal equations
@njit(cache=True, fastmath={"reassoc", "contract"})
def _dot(a, b, m):
    """sum_q a[q] b[q] over q < m (reassociated so it vectorises; the same order at any thread count)."""
    s = 0.0
    for q in range(m):
        s += a[q] * b[q]
    return s


@njit(cache=True)
def _channel_error(x, K, rs, wv, Tv, views, lp, vp, lz, jac, JTJ, g, Jb, eb, nexp):
    """E of parameters ``x`` (scaled units) with the table ``Tv`` fixed; with ``jac`` also J^T W J (upper
    triangle) into ``JTJ`` and J^T W e into ``g``. The rows sqrt(w) J and sqrt(w) e go to ``Jb`` (P, M)
    and ``eb`` (M,) first, then the products are dot products over the samples. Returns inf when a
    lobe overflows.
    15 parameters: the Levenberg-Marquardt residual of ``_fit_texel``: parameters, samples, weights, the table,
    directions, and the scratch for J^T W J and J^T W e that the iteration reuses."""
    P = 1 + LOBE_PARAMS * K
    L = rs.shape[1]
    for k in range(K):
        nexp[k] = math.exp(x[1 + LOBE_PARAMS * k + 3])
    err = 0.0
    m = 0
    for iv in range(views.shape[0]):
        v = views[iv]
        w = wv[v]
        sw = math.sqrt(w)
        tv = Tv[v]
        vx, vy, vz = vp[v, 0], vp[v, 1], vp[v, 2]
        for li in range(L):
            r = rs[v, li]
            sc = tv * lz[li]
            if sc == 0.0 or lz[li] <= 0.0:
                err += w * r * r                     # the model is 0 here: nothing to fit
                continue
            px = lp[li, 0] * vx
            py = lp[li, 1] * vy
            pz = lp[li, 2] * vz
            f = x[0]
            ss = sw * sc
            if jac:
                Jb[0, m] = ss
            for k in range(K):
                o = 1 + LOBE_PARAMS * k
                a = x[o] * px + x[o + 1] * py + x[o + 2] * pz
                if a > 1e-300:                       # a^N, 0 for a <= 0 (footnote 3)
                    n = nexp[k]
                    q = n * math.log(a)
                    if q > EXP_LIMIT:
                        return math.inf
                    val = math.exp(q)
                    f += val
                    if jac:
                        d = ss * n * val / a
                        Jb[o, m] = d * px
                        Jb[o + 1, m] = d * py
                        Jb[o + 2, m] = d * pz
                        Jb[o + 3, m] = ss * val * q  # d a^N / d log N
                elif jac:
                    Jb[o, m] = 0.0
                    Jb[o + 1, m] = 0.0
                    Jb[o + 2, m] = 0.0
                    Jb[o + 3, m] = 0.0
            e = r - sc * f
            err += w * e * e
            if jac:
                eb[m] = sw * e
            m += 1
    if jac:
        for i in range(P):
            g[i] = _dot(Jb[i], eb, m)
            for j in range(i, P):
                JTJ[i, j] = _dot(Jb[i], Jb[j], m)
    return err


@njit(cache=True)
def _solve_damped(JTJ, g, lam, fixed, M, delta):
    """delta from (J^T W J + lam D) delta = g, frozen parameters held at 0 (Cholesky, in ``M``).
    False when the matrix is not positive definite or not finite."""
    P = g.shape[0]
    dmax = 0.0
    for i in range(P):
        dmax = max(dmax, JTJ[i, i])
    floor = max(1e-12 * dmax, 1e-300)
    for i in range(P):
        for j in range(P):
            if fixed[i] or fixed[j]:
                M[i, j] = 1.0 if i == j else 0.0
            elif j >= i:
                M[i, j] = JTJ[i, j]
            else:
                M[i, j] = JTJ[j, i]
        if not fixed[i]:
            M[i, i] += lam * max(JTJ[i, i], floor)
        delta[i] = 0.0 if fixed[i] else g[i]
    for j in range(P):                               # Cholesky M = R^T R, R upper, in place
        s = M[j, j]
        for k in range(j):
            s -= M[k, j] * M[k, j]
        if not (s > 0.0) or not math.isfinite(s):
            return False
        s = math.sqrt(s)
        M[j, j] = s
        for i in range(j + 1, P):
            t = M[j, i]
            for k in range(j):
                t -= M[k, j] * M[k, i]
            M[j, i] = t / s
    for i in range(P):                               # R^T y = g
        t = delta[i]
        for k in range(i):
            t -= M[k, i] * delta[k]
        delta[i] = t / M[i, i]
    for i in range(P - 1, -1, -1):                   # R delta = y
        t = delta[i]
        for k in range(i + 1, P):
            t -= M[i, k] * delta[k]
        delta[i] = t / M[i, i]
    for i in range(P):
        if not math.isfinite(delta[i]):
            return False
    return True


@njit(cache=True)
def _project(x, K):
    """rho >= 0, log N within [log N_MIN, log N_MAX], each lobe's peak max|C|^N at most PEAK_MAX (C scaled
    down towards 0 when above)."""
    x[0] = max(x[0], 0.0)
    lo = math.log(N_MIN)
    hi = math.log(N_MAX)
    for k in range(K):
        o = 1 + LOBE_PARAMS * k
        x[o + 3] = min(max(x[o + 3], lo), hi)
        cmax = max(abs(x[o]), abs(x[o + 1]), abs(x[o + 2]))
        limit = math.exp(math.log(PEAK_MAX) / math.exp(x[o + 3]))
        if cmax > limit:
            f = limit / cmax
            x[o] *= f
            x[o + 1] *= f
            x[o + 2] *= f


@njit(cache=True)
def _levenberg_marquardt(x, K, rs, wv, Tv, views, lp, vp, lz, max_iter, energy):
    """Fit ``x`` in place (module doc, step 3). Returns (E, converged, iterations)."""
    P = 1 + LOBE_PARAMS * K
    JTJ = np.zeros((P, P))
    g = np.zeros(P)
    JTJt = np.zeros((P, P))
    gt = np.zeros(P)
    Jb = np.empty((P, views.shape[0] * rs.shape[1]))
    eb = np.empty(views.shape[0] * rs.shape[1])
    nexp = np.zeros(K)
    M = np.zeros((P, P))
    delta = np.zeros(P)
    xt = np.zeros(P)
    fixed = np.zeros(P, np.bool_)
    lo = math.log(N_MIN)
    hi = math.log(N_MAX)
    err = _channel_error(x, K, rs, wv, Tv, views, lp, vp, lz, True, JTJ, g, Jb, eb, nexp)
    if not _all_finite(err, JTJ, g):
        return err, False, 0
    tiny = 1e-30 * energy
    if err <= tiny:
        return err, True, 0
    lam = LAMBDA_START
    nu = 2.0
    it = 0
    while it < max_iter:
        for i in range(P):
            fixed[i] = False
        if x[0] <= 0.0 and g[0] <= 0.0:
            fixed[0] = True
        for k in range(K):
            o = 1 + LOBE_PARAMS * k + 3
            if (x[o] <= lo and g[o] <= 0.0) or (x[o] >= hi and g[o] >= 0.0):
                fixed[o] = True
        gmax = 0.0
        for i in range(P):
            if not fixed[i]:
                gmax = max(gmax, abs(g[i]))
        if gmax == 0.0:
            return err, True, it                     # stationary: nothing left to move
        if not _solve_damped(JTJ, g, lam, fixed, M, delta):
            lam *= nu
            nu *= 2.0
            if lam > LAMBDA_MAX:
                return err, True, it
            continue
        it += 1
        small = True
        for i in range(P):
            xt[i] = x[i] + delta[i]
            if abs(delta[i]) > XTOL * (abs(x[i]) + XTOL):
                small = False
        _project(xt, K)
        et = _channel_error(xt, K, rs, wv, Tv, views, lp, vp, lz, True, JTJt, gt, Jb, eb, nexp)
        if et < err and _all_finite(et, JTJt, gt):
            # gain ratio: actual over predicted decrease of the (projected) step, Nielsen's update of lam
            pred = 0.0                               # 2 d.g - d.JTJ.d of the linearised model
            for i in range(P):
                di = xt[i] - x[i]
                q = JTJ[i, i] * di
                for j in range(i + 1, P):
                    q += 2.0 * JTJ[i, j] * (xt[j] - x[j])
                pred += di * (2.0 * g[i] - q)
            drop = err - et
            rho_g = drop / pred if pred > 0.0 else 0.0
            for i in range(P):
                x[i] = xt[i]
                g[i] = gt[i]
                for j in range(P):
                    JTJ[i, j] = JTJt[i, j]
            err = et
            if err <= tiny or drop <= FTOL * (err + drop) or small:
                return err, True, it
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho_g - 1.0) ** 3)
            lam = max(lam, 1e-15)
            nu = 2.0
        else:
            if small:
                return err, True, it                 # no representable step lowers E
            lam *= nu
            nu *= 2.0
            if lam > LAMBDA_MAX:
                return err, True, it
    return err, False, it


@njit(cache=True)
def _all_finite(err, JTJ, g):
    if not math.isfinite(err):
        return False
    for i in range(g.shape[0]):
        if not math.isfinite(g[i]):
            return False
        for j in range(g.shape[0]):
            if not math.isfinite(JTJ[i, j]):
                return False
    return True


# ------------------------------------------------------------------------------------------------
# Eq. 4
@njit(cache=True)
def table_entry(f, r):
    """T(v) = <f | r> / <f | f> (Eq. 4): the least-squares solution of r = T f over the lights; 0 when
    <f | f> = 0; |T| clipped to ``T_MAX``."""
    ff = 0.0
    fr = 0.0
    for i in range(f.shape[0]):
        ff += f[i] * f[i]
        fr += f[i] * r[i]
    if not (ff > 0.0):
        return 0.0
    t = fr / ff
    if not math.isfinite(t):
        return 0.0
    return min(max(t, -T_MAX), T_MAX)


@njit(cache=True)
def _view_f1(x, K, lp, vp, lz, v, fbuf):
    """f_1(l, v) for every light l (Eq. 2) of the parameters ``x`` into ``fbuf``."""
    vx, vy, vz = vp[v, 0], vp[v, 1], vp[v, 2]
    for li in range(lz.shape[0]):
        if lz[li] <= 0.0:
            fbuf[li] = 0.0
            continue
        s = x[0]
        for k in range(K):
            o = 1 + LOBE_PARAMS * k
            a = x[o] * lp[li, 0] * vx + x[o + 1] * lp[li, 1] * vy + x[o + 2] * lp[li, 2] * vz
            if a > 1e-300:
                q = math.exp(x[o + 3]) * math.log(a)
                s += math.exp(min(q, EXP_LIMIT))
        fbuf[li] = lz[li] * s


@njit(cache=True)
def _table_update(x, K, rs, views, lp, vp, lz, Tv, fbuf):
    """T(v) of every non-hole view by Eq. 4 into ``Tv``."""
    for iv in range(views.shape[0]):
        v = views[iv]
        _view_f1(x, K, lp, vp, lz, v, fbuf)
        Tv[v] = table_entry(fbuf, rs[v])


# ------------------------------------------------------------------------------------------------
# one texel
@njit(cache=True)
def _initial_guess(K, rs, wv, views, lz, x):
    """The start of §5 scaled to the data (module doc, step 2); returns rho_d."""
    num = 0.0
    den = 0.0
    for iv in range(views.shape[0]):
        v = views[iv]
        for li in range(lz.shape[0]):
            if lz[li] > 0.0:
                num += wv[v] * lz[li] * rs[v, li]
                den += wv[v] * lz[li] * lz[li]
    rho_d = num / den if den > 0.0 else 0.0
    if not (rho_d > 0.0):
        rho_d = 0.0
    x[0] = 0.5 * rho_d
    c = (rho_d / (2.0 * K)) ** (1.0 / N_START) if rho_d > 0.0 else 0.0
    for k in range(K):
        o = 1 + LOBE_PARAMS * k
        if k % 2 == 0:
            x[o], x[o + 1] = -ANISO * c, -c
        else:
            x[o], x[o + 1] = -c, -ANISO * c
        x[o + 2] = c
        x[o + 3] = math.log(N_START)
    _project(x, K)
    return rho_d


@njit(cache=True)
def _diffuse_only(K, rho_d, x):
    x[0] = rho_d
    for k in range(K):
        o = 1 + LOBE_PARAMS * k
        x[o] = 0.0
        x[o + 1] = 0.0
        x[o + 2] = 0.0
        x[o + 3] = math.log(N_START)


@njit(cache=True)
def _to_radiance(x, K, s, rho_out, lobes_out, c):
    """Convert scaled parameters back (rho = s rho', C = s^(1/N) C'); False when out of range."""
    rho = s * x[0]
    if not (math.isfinite(rho) and abs(rho) <= C_MAX):
        return False
    ls = math.log(s)
    for k in range(K):
        o = 1 + LOBE_PARAMS * k
        n = min(max(math.exp(x[o + 3]), N_MIN), N_MAX)
        m = ls / n
        for j in range(3):
            if x[o + j] == 0.0:
                continue
            if m + math.log(abs(x[o + j])) > math.log(C_MAX):
                return False
    rho_out[c] = rho
    for k in range(K):
        o = 1 + LOBE_PARAMS * k
        n = min(max(math.exp(x[o + 3]), N_MIN), N_MAX)
        f = math.exp(ls / n)
        lobes_out[k, c, 0] = f * x[o]
        lobes_out[k, c, 1] = f * x[o + 1]
        lobes_out[k, c, 2] = f * x[o + 2]
        lobes_out[k, c, 3] = n
    return True


@njit(cache=True)
def _fit_texel(smp, alpha, frame, view_dirs, light_dirs, K, threshold, max_rounds, max_iter,
               rho_out, lobes_out, table_out, rmse_out, rmse_nt_out):
    """Fit one texel (module doc); returns (rounds, converged, LM iterations).
    14 parameters: one texel's samples, frame, directions and fit settings, and its five outputs."""
    V = smp.shape[0]
    L = smp.shape[1]
    P = 1 + LOBE_PARAMS * K
    nv = 0
    for v in range(V):
        if alpha[v] > 0.0:
            nv += 1
    views = np.empty(nv, np.int64)
    wsum = 0.0
    j = 0
    for v in range(V):
        table_out[v, 3] = alpha[v]
        for c in range(3):
            table_out[v, c] = 0.0
        if alpha[v] > 0.0:
            views[j] = v
            j += 1
            wsum += alpha[v]
    for c in range(3):
        rho_out[c] = 0.0
        rmse_out[c] = 0.0
        rmse_nt_out[c] = 0.0
        for k in range(K):
            lobes_out[k, c, 0] = 0.0
            lobes_out[k, c, 1] = 0.0
            lobes_out[k, c, 2] = 0.0
            lobes_out[k, c, 3] = N_START
    if nv == 0:
        return 0, True, 0
    lp = np.empty((L, 3))
    lz = np.empty(L)
    for li in range(L):
        a, b, n = to_texel_frame(frame, light_dirs[li, 0], light_dirs[li, 1], light_dirs[li, 2])
        lp[li, 0], lp[li, 1], lp[li, 2] = a, b, n
        lz[li] = light_dirs[li, 2]
    vp = np.empty((V, 3))
    for v in range(V):
        a, b, n = to_texel_frame(frame, view_dirs[v, 0], view_dirs[v, 1], view_dirs[v, 2])
        vp[v, 0], vp[v, 1], vp[v, 2] = a, b, n
    wv = alpha.astype(np.float64)
    rs = np.empty((3, V, L))
    scale = np.ones(3)
    energy = np.zeros(3)
    rho_d = np.zeros(3)
    X = np.zeros((3, P))
    Tv = np.zeros((3, V))
    Tn = np.zeros((3, V))
    fbuf = np.empty(L)
    for c in range(3):
        s = 0.0
        for iv in range(nv):
            for li in range(L):
                s = max(s, abs(smp[views[iv], li, c]))
        if s == 0.0:
            s = 1.0
        scale[c] = s
        for v in range(V):
            for li in range(L):
                rs[c, v, li] = smp[v, li, c] / s
        for iv in range(nv):
            v = views[iv]
            Tv[c, v] = 1.0
            for li in range(L):
                energy[c] += wv[v] * rs[c, v, li] * rs[c, v, li]
        rho_d[c] = _initial_guess(K, rs[c], wv, views, lz, X[c])

    # lobes and table, alternately (§5); round 1's LM (T = 1) is also the start of the fit without a table
    rounds = 0
    iters = 0
    met = False
    lm_ok = np.zeros(3, np.bool_)
    Xnt = np.zeros((3, P))
    e_nt = np.zeros(3)
    nt_ok = np.zeros(3, np.bool_)
    dummy_J = np.zeros((P, P))
    dummy_g = np.zeros(P)
    dummy_b = np.zeros((P, 1))
    dummy_e = np.zeros(1)
    nexp = np.zeros(K)
    while rounds < max_rounds:
        for c in range(3):
            e, ok, nit = _levenberg_marquardt(X[c], K, rs[c], wv, Tv[c], views, lp, vp, lz, max_iter, energy[c])
            lm_ok[c] = ok
            iters += nit
            if rounds == 0:
                Xnt[c] = X[c]
                e_nt[c] = e
                nt_ok[c] = ok
            _table_update(X[c], K, rs[c], views, lp, vp, lz, Tn[c], fbuf)
        diff = 0.0
        for c in range(3):
            for iv in range(nv):
                v = views[iv]
                diff += abs(Tn[c, v] - Tv[c, v])
                Tv[c, v] = Tn[c, v]
        rounds += 1
        if diff / (3.0 * nv) < threshold:
            met = True
            break

    # the lobes alone, T = 1 (Fig. 5's model without a table): round 1's LM continued to the same budget
    ones = np.zeros(V)
    for iv in range(nv):
        ones[views[iv]] = 1.0
    for c in range(3):
        if not nt_ok[c] and max_rounds > 1:
            e_nt[c], _, nit = _levenberg_marquardt(Xnt[c], K, rs[c], wv, ones, views, lp, vp, lz,
                                                   max_iter * (max_rounds - 1), energy[c])
            iters += nit
        e = e_nt[c] if math.isfinite(e_nt[c]) else energy[c]
        rmse_nt_out[c] = scale[c] * math.sqrt(max(e, 0.0) / (L * wsum))

    converged = met and lm_ok[0] and lm_ok[1] and lm_ok[2]

    for c in range(3):
        if not _to_radiance(X[c], K, scale[c], rho_out, lobes_out, c):
            _diffuse_only(K, rho_d[c], X[c])
            _table_update(X[c], K, rs[c], views, lp, vp, lz, Tv[c], fbuf)
            _to_radiance(X[c], K, scale[c], rho_out, lobes_out, c)
            converged = False
        e = _channel_error(X[c], K, rs[c], wv, Tv[c], views, lp, vp, lz, False, dummy_J, dummy_g, dummy_b, dummy_e,
                           nexp)
        if not math.isfinite(e):
            e = energy[c]
        rmse_out[c] = scale[c] * math.sqrt(max(e, 0.0) / (L * wsum))
        for iv in range(nv):
            table_out[views[iv], c] = Tv[c, views[iv]]
    return rounds, converged, iters


@chunk_kernel
def _fit_all(samples, alpha, frames, view_dirs, light_dirs, K, threshold, max_rounds, max_iter,
             rho, lobes, table, rmse, rmse_nt, rounds, converged, iterations, t0, t1):
    """Texels t0 .. t1 - 1 (``for_chunks``).
    19 parameters: a ``for_chunks`` chunk kernel: the fit's inputs and settings, its eight output arrays and the
    chunk's range."""
    for t in range(t0, t1):
        r, ok, n = _fit_texel(samples[t], alpha[t], frames[t], view_dirs, light_dirs, K, threshold, max_rounds,
                           max_iter, rho[t], lobes[t], table[t], rmse[t], rmse_nt[t])
        rounds[t] = r
        converged[t] = ok
        iterations[t] = n


def fit_btf(samples, alpha, view_dirs, light_dirs, frames, lobes=2, threshold=0.1, max_rounds=10,
            max_iter=50) -> BtfFit:
    """Fit every texel's lobes and lookup table (module doc). ``samples`` (T, V, L, 3), ``alpha`` (T, V),
    ``view_dirs`` (V, 3), ``light_dirs`` (L, 3), ``frames`` (T, 2, 3)."""
    samples = np.ascontiguousarray(samples, dtype=np.float64)
    alpha = np.ascontiguousarray(alpha, dtype=np.float64)
    view_dirs = np.ascontiguousarray(view_dirs, dtype=np.float64)
    light_dirs = np.ascontiguousarray(light_dirs, dtype=np.float64)
    frames = np.ascontiguousarray(frames, dtype=np.float64)
    if samples.ndim != 4 or samples.shape[3] != 3:
        raise ValueError(f"samples must be (T, V, L, 3), got {samples.shape}")
    T, V, L, _ = samples.shape
    if alpha.shape != (T, V):
        raise ValueError(f"alpha must be (T, V) = {(T, V)}, got {alpha.shape}")
    if view_dirs.shape != (V, 3) or light_dirs.shape != (L, 3):
        raise ValueError(f"view_dirs must be ({V}, 3) and light_dirs ({L}, 3), "
                         f"got {view_dirs.shape}, {light_dirs.shape}")
    if frames.shape != (T, 2, 3):
        raise ValueError(f"frames must be (T, 2, 3) = {(T, 2, 3)}, got {frames.shape}")
    if int(lobes) not in (1, 2):
        raise ValueError(f"lobes must be 1 or 2, got {lobes}")
    if not (threshold > 0.0 and math.isfinite(threshold)):
        raise ValueError(f"threshold must be a positive number, got {threshold}")
    if int(max_rounds) < 1 or int(max_iter) < 1:
        raise ValueError(f"max_rounds and max_iter must be >= 1, got {max_rounds}, {max_iter}")
    for name, arr in (("samples", samples), ("alpha", alpha), ("view_dirs", view_dirs),
                      ("light_dirs", light_dirs), ("frames", frames)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} holds NaN or inf")
    if samples.size and np.max(np.abs(samples)) > MAX_RADIANCE:
        raise ValueError(f"samples exceed {MAX_RADIANCE:g} in magnitude")
    if np.any(alpha < 0.0) or np.any(alpha > 1.0):
        raise ValueError("alpha must lie in [0, 1]")
    K = int(lobes)
    rho = np.zeros((T, 3))
    lob = np.zeros((T, K, 3, LOBE_PARAMS))
    table = np.zeros((T, V, 4))
    rmse = np.zeros((T, 3))
    rmse_nt = np.zeros((T, 3))
    rounds = np.zeros(T, np.int32)
    converged = np.zeros(T, np.bool_)
    iterations = np.zeros(T, np.int32)
    for_chunks(_fit_all, samples.shape[0], samples, alpha, frames, view_dirs, light_dirs, K, float(threshold),
               int(max_rounds), int(max_iter), rho, lob, table, rmse, rmse_nt, rounds, converged, iterations)
    return BtfFit(rho, lob, table, rmse, rmse_nt, rounds, converged, iterations, frames.copy(),
                  _summary(samples, alpha, rmse, rmse_nt, rounds, converged))


def _summary(samples, alpha, rmse, rmse_nt, rounds, converged) -> FitSummary:
    """Errors pooled over all texels' fitted samples: sqrt(sum E / sum L alpha) per channel; the
    alpha-weighted mean radiance per channel; mean rounds; fraction converged."""
    w = alpha.sum(axis=1) * samples.shape[2]                              # weight of each texel's E
    W = max(float(w.sum()), 1e-300)
    rm = np.sqrt((w[:, None] * rmse ** 2).sum(axis=0) / W)
    rmn = np.sqrt((w[:, None] * rmse_nt ** 2).sum(axis=0) / W)
    mean_r = np.einsum("tv,tvlc->c", alpha, samples) / W
    n = max(len(rounds), 1)
    return FitSummary(rm, rmn, mean_r, float(rounds.sum()) / n, float(converged.sum()) / n)


# ------------------------------------------------------------------------------------------------
# predictions (residual pictures, tests)
@chunk_kernel
def _predict(rho, lobes, table, frames, view_dirs, light_dirs, out, t0, t1):
    for t in range(t0, t1):
        for v in range(view_dirs.shape[0]):
            vx, vy, vz = view_dirs[v, 0], view_dirs[v, 1], view_dirs[v, 2]
            bx, by, bz = to_texel_frame(frames[t], vx, vy, vz)
            for li in range(light_dirs.shape[0]):
                lz = light_dirs[li, 2]
                if lz <= 0.0:
                    for c in range(3):
                        out[t, v, li, c] = 0.0
                    continue
                ax, ay, az = to_texel_frame(frames[t], light_dirs[li, 0], light_dirs[li, 1], lz)
                for c in range(3):
                    s = rho[t, c]
                    for k in range(lobes.shape[1]):
                        a = lobes[t, k, c, 0] * ax * bx + lobes[t, k, c, 1] * ay * by + lobes[t, k, c, 2] * az * bz
                        if a > 0.0:
                            s += a ** lobes[t, k, c, 3]
                    out[t, v, li, c] = table[t, v, c] * lz * s


def predict_samples(rho, lobes, table, frames, view_dirs, light_dirs) -> np.ndarray:
    """The model's radiance T(v) f_1(l, v) (Eq. 1-2) at every texel, view, light and channel:
    (T, V, L, 3), the layout of ``fit_btf``'s samples. ``table`` (T, V, >= 3)."""
    rho = np.ascontiguousarray(rho, dtype=np.float64)
    lobes = np.ascontiguousarray(lobes, dtype=np.float64)
    table = np.ascontiguousarray(table, dtype=np.float64)
    frames = np.ascontiguousarray(frames, dtype=np.float64)
    view_dirs = np.ascontiguousarray(view_dirs, dtype=np.float64)
    light_dirs = np.ascontiguousarray(light_dirs, dtype=np.float64)
    out = np.empty((rho.shape[0], view_dirs.shape[0], light_dirs.shape[0], 3))
    for_chunks(_predict, rho.shape[0], rho, lobes, table, frames, view_dirs, light_dirs, out)
    return out


# ------------------------------------------------------------------------------------------------
# mip levels (§5.1)
def _frame_of(normal, tangent):
    """Unit normal and the tangent re-orthonormalised against it (module doc); (..., 2, 3)."""
    n = np.array(normal, dtype=np.float64)
    ln = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(ln > 1e-12, n / np.where(ln > 1e-12, ln, 1.0), np.array([0.0, 0.0, 1.0]))
    t = np.array(tangent, dtype=np.float64)
    t = t - np.sum(t * n, axis=-1, keepdims=True) * n
    lt = np.linalg.norm(t, axis=-1, keepdims=True)
    # §4's tangent: b perpendicular to n and x, t = b x n (x = (1, 0, 0)); n parallel to x: use y
    x = np.broadcast_to(np.array([1.0, 0.0, 0.0]), n.shape)
    b = np.cross(n, x)
    lb = np.linalg.norm(b, axis=-1, keepdims=True)
    b = np.where(lb > 1e-6, b, np.cross(n, np.array([0.0, 1.0, 0.0])))
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    t_fb = np.cross(b, n)
    t = np.where(lt > 1e-9, t / np.where(lt > 1e-9, lt, 1.0), t_fb)
    return np.stack([n, t], axis=-2)


def group_level(samples, alpha, frames, res, level) -> BtfLevel:
    """Level ``level`` of the mip pyramid from the level-0 data (module doc, §5.1): ``samples`` (res, res,
    V, L, 3) or (res^2, V, L, 3), ``alpha`` (res, res, V) or (res^2, V), ``frames`` (res, res, 2, 3) or
    (res^2, 2, 3). Returns a ``BtfLevel`` of flattened (row-major) arrays for ``fit_btf``."""
    res = int(res)
    level = int(level)
    if res < 1 or res & (res - 1):
        raise ValueError(f"res must be a power of two, got {res}")
    if level < 0 or (1 << level) > res:
        raise ValueError(f"level must lie in 0..log2(res) = 0..{res.bit_length() - 1}, got {level}")
    smp = np.asarray(samples)
    V, L = smp.shape[-3], smp.shape[-2]
    smp = smp.reshape(res, res, V, L, 3)
    a = np.asarray(alpha, dtype=np.float64).reshape(res, res, V)
    fr = np.asarray(frames, dtype=np.float64).reshape(res, res, 2, 3)
    f = 1 << level
    rl = res // f
    if f == 1:
        return BtfLevel(np.ascontiguousarray(smp.reshape(res * res, V, L, 3), dtype=np.float64),
                        a.reshape(res * res, V).copy(), fr.reshape(res * res, 2, 3).copy(), res)
    wsum = np.zeros((rl, rl, V))
    num = np.zeros((rl, rl, V, L, 3))
    plain = np.zeros((rl, rl, V, L, 3))
    for di in range(f):                              # fixed order: the same bytes on any machine state
        for dj in range(f):
            part = smp[di::f, dj::f].astype(np.float64)
            w = a[di::f, dj::f]
            wsum += w
            num += part * w[..., None, None]
            plain += part
    plain /= f * f
    safe = np.where(wsum > 0.0, wsum, 1.0)[..., None, None]
    mean = np.where((wsum > 0.0)[..., None, None], num / safe, plain)
    fr5 = fr.reshape(rl, f, rl, f, 2, 3).mean(axis=(1, 3))
    frames_l = _frame_of(fr5[..., 0, :], fr5[..., 1, :])
    return BtfLevel(np.ascontiguousarray(mean.reshape(rl * rl, V, L, 3)), (wsum / (f * f)).reshape(rl * rl, V),
                    np.ascontiguousarray(frames_l.reshape(rl * rl, 2, 3)), rl)


def fit_levels(samples, alpha, frames, view_dirs, light_dirs, lobes=2, threshold=0.1, max_rounds=10,
               max_iter=50) -> list:
    """Fit mip levels 0 .. log2(res) (§5.1): ``samples`` (res, res, V, L, 3), ``alpha`` (res, res, V),
    ``frames`` (res, res, 2, 3). Returns a list of ``BtfFit``, one per level, flattened row-major with
    res >> l texels a side. Each holds the frames it was fitted with and its ``summary``: RMSE with and
    without the table pooled over the level's samples, mean radiance, mean rounds, fraction converged."""
    s = np.asarray(samples)
    if s.ndim != 5 or s.shape[0] != s.shape[1] or s.shape[4] != 3:
        raise ValueError(f"samples must be (res, res, V, L, 3), got {s.shape}")
    res = s.shape[0]
    if res < 1 or res & (res - 1):
        raise ValueError(f"res must be a power of two, got {res}")
    fits = []
    for level in range(res.bit_length()):
        grp = group_level(s, alpha, frames, res, level)
        fits.append(fit_btf(grp.samples, grp.alpha, view_dirs, light_dirs, grp.frames, lobes, threshold, max_rounds,
                            max_iter))
    return fits
