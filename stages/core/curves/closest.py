"""Closest points on yarn curves and the grid of yarns near a point (seed 000 §5.1-§5.2).

closest_on_segment(cv, i, p)    (t, distance^2): global minimum over t in [0, 1], exact root
                                isolation of the quintic d/dt |P(t) - p|^2 (never a local minimum)
closest_point_on_curve(cv,c,p)  (s, distance^2) over all segments of curve c near p
nearest_segments_in_cell(cv, p) the grid cell's segment list (``grid_*`` fields of ``Curves``)
yarns_near(cv, p, r, out)       curves passing within r of p (grid over segment boxes)
"""
import math

import numpy as np
from numba import njit

from stages.core.sampling import NO_HIT

from .spline import segment_arclen_to, segment_coeffs


# ------------------------------------------------------------------------------------------------
# closest point: exact root isolation of the quintic derivative of the squared distance
@njit(cache=True, inline="always")
def _peval(cf, deg, t):
    r = cf[deg]
    for k in range(deg - 1, -1, -1):
        r = r * t + cf[k]
    return r


@njit(cache=True)
def _roots01(q, out):
    """Sorted roots in (0, 1) of the quintic q[0] + q[1] t + ... + q[5] t^5 (returns count).

    Each derivative's roots split [0, 1] into intervals where the next lower derivative is monotone,
    so each interval holds at most one root, found by safeguarded Newton: no root is missed."""
    D = np.zeros((5, 6))
    for k in range(6):
        D[0, k] = q[k]
    for lev in range(1, 5):
        for k in range(0, 6 - lev):
            D[lev, k] = D[lev - 1, k + 1] * (k + 1)
    roots = np.empty(8)
    nr = 0
    if D[4, 1] != 0.0:
        r = -D[4, 0] / D[4, 1]
        if 0.0 < r < 1.0:
            roots[0] = r
            nr = 1
    br = np.empty(8)
    for lev in range(3, -1, -1):
        deg = 5 - lev
        br[0] = 0.0
        for k in range(nr):
            br[k + 1] = roots[k]
        br[nr + 1] = 1.0
        nb = nr + 2
        nnew = 0
        for k in range(nb - 1):
            lo = br[k]
            hi = br[k + 1]
            flo = _peval(D[lev], deg, lo)
            fhi = _peval(D[lev], deg, hi)
            if flo == 0.0:
                if lo > 0.0 and (nnew == 0 or roots[nnew - 1] != lo):
                    out[nnew] = lo
                    nnew += 1
                continue
            if flo * fhi > 0.0 or fhi == 0.0:
                continue
            a = lo
            b = hi
            t = 0.5 * (a + b)
            for _ in range(60):
                f = _peval(D[lev], deg, t)
                if f == 0.0:
                    break
                if (f < 0.0) == (flo < 0.0):
                    a = t
                else:
                    b = t
                df = _peval(D[lev + 1], deg - 1, t) if lev < 4 else 0.0
                tn = t - f / df if df != 0.0 else 0.5 * (a + b)
                if not (a < tn < b):
                    tn = 0.5 * (a + b)
                if abs(tn - t) < 1e-15:
                    t = tn
                    break
                t = tn
            out[nnew] = t
            nnew += 1
        for k in range(nnew):
            roots[k] = out[k]
        nr = nnew
    for k in range(nr):
        out[k] = roots[k]
    return nr


@njit(cache=True)
def closest_on_segment(cv, i, p):
    """(t, squared distance) of the closest point of segment i to p; the global minimum over [0, 1]."""
    a, b, c, d = segment_coeffs(cv, i)
    e = d - p
    q = np.empty(6)  # (1/2) d/dt |P(t) - p|^2
    q[5] = 3.0 * np.dot(a, a)
    q[4] = 5.0 * np.dot(a, b)
    q[3] = 4.0 * np.dot(a, c) + 2.0 * np.dot(b, b)
    q[2] = 3.0 * np.dot(b, c) + 3.0 * np.dot(a, e)
    q[1] = np.dot(c, c) + 2.0 * np.dot(b, e)
    q[0] = np.dot(c, e)
    roots = np.empty(8)
    nr = _roots01(q, roots)
    best_t = 0.0
    best = np.dot(e, e)
    g1 = a + b + c + e
    d1 = np.dot(g1, g1)
    if d1 < best:
        best = d1
        best_t = 1.0
    for k in range(nr):
        t = roots[k]
        g = ((a * t + b) * t + c) * t + e
        dd = np.dot(g, g)
        if dd < best:
            best = dd
            best_t = t
    return best_t, best


@njit(cache=True, inline="always")
def _segment_box_dist2(cv, i, p):
    """Squared distance from p to the box of segment i's Bezier control points (a lower bound).
    Inlined into its callers (it runs over every segment of a grid cell): as a separate call taking
    the Curves tuple it cost ~20x its arithmetic."""
    c = cv.seg_curve[i]
    j = i + 1
    if j == cv.offsets[c + 1]:
        j = cv.offsets[c]
    d2 = 0.0
    for k in range(3):
        b0 = cv.points[i, k]
        b3 = cv.points[j, k]
        b1 = b0 + cv.tangents[i, k] / 3.0
        b2 = b3 - cv.tangents[j, k] / 3.0
        lo = min(min(b0, b1), min(b2, b3))
        hi = max(max(b0, b1), max(b2, b3))
        if p[k] < lo:
            d2 += (lo - p[k]) ** 2
        elif p[k] > hi:
            d2 += (p[k] - hi) ** 2
    return d2


@njit(cache=True)
def _grid_cell_of(cv, p):
    cell = cv.grid_cell[0]
    idx = 0
    stride = 1
    for k in range(3):
        g = int(math.floor((p[k] - cv.grid_lo[k]) / cell))
        if g < 0 or g >= cv.grid_dims[k]:
            return -1
        idx += g * stride
        stride *= cv.grid_dims[k]
    return idx


@njit(cache=True)
def nearest_segments_in_cell(cv, p):
    """(start, end) into grid_items of the segments whose padded boxes overlap p's cell."""
    cell = _grid_cell_of(cv, p)
    if cell < 0:
        return 0, 0
    return cv.grid_cell_start[cell], cv.grid_cell_start[cell + 1]


@njit(cache=True)
def _closer_on_segment(cv, i, p, best, best_i, best_t):
    """(squared distance, segment, t) of the closest point to p found so far, ``best`` at ``best_i``, ``best_t``,
    or of segment i's closest point where that is nearer (its box first: no nearer point, no test)."""
    if _segment_box_dist2(cv, i, p) >= best:
        return best, best_i, best_t
    t, d2 = closest_on_segment(cv, i, p)
    if d2 < best:
        return d2, i, t
    return best, best_i, best_t


@njit(cache=True)
def closest_point_on_curve(cv, c, p):
    """(s, squared distance) of the closest point of curve c to p: the global minimum.

    The grid's candidate segments in p's cell cover every point within the curve's pad (yarn radius
    + δ); when the best candidate is farther than that pad, all segments of the curve are searched
    (with box pruning), so the answer is exact everywhere."""
    best = NO_HIT
    best_i = -1
    best_t = 0.0
    start, end = nearest_segments_in_cell(cv, p)
    for k in range(start, end):
        i = cv.grid_items[k]
        if cv.seg_curve[i] != c:
            continue
        best, best_i, best_t = _closer_on_segment(cv, i, p, best, best_i, best_t)
    if best > cv.grid_pad[c] * cv.grid_pad[c]:
        lo = cv.offsets[c]
        nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
        for i in range(lo, lo + nseg):
            best, best_i, best_t = _closer_on_segment(cv, i, p, best, best_i, best_t)
    s = cv.seg_arclen[best_i] + segment_arclen_to(cv, best_i, best_t)
    return s, best


@njit(cache=True)
def yarns_near(cv, p, r, out):
    """Write into ``out`` the distinct curves that pass within r of p; exact for r up to each
    curve's grid pad (yarn radius + δ by default); returns how many."""
    start, end = nearest_segments_in_cell(cv, p)
    n = 0
    r2 = r * r
    for k in range(start, end):
        i = cv.grid_items[k]
        c = cv.seg_curve[i]
        dup = False
        for m in range(n):
            if out[m] == c:
                dup = True
                break
        if dup:
            continue
        if _segment_box_dist2(cv, i, p) > r2:
            continue
        t, d2 = closest_on_segment(cv, i, p)
        if d2 <= r2 and n < out.shape[0]:
            out[n] = c
            n += 1
    return n
