"""Sampled yarn frames: a fast, error-bounded stand-in for Eq. 7 used to pre-classify lookups.

Per yarn, the rotation-minimising frame of seed 000 §5.1 is sampled (exact kernels of
stages/core/curves.py) at every spline knot and stored RMF sample (where the frame's derivative
may jump) and at equal arc-length steps no longer than ``delta`` between them: position, unit
tangent, normal, binormal (float32). Between samples the position is the cubic Hermite
interpolant of (position, tangent x step) and the normal and binormal are interpolated linearly;
between breakpoints the frame is smooth, so the interpolation error is second order in the step. ``sample_error`` measures it at the three
inner quarter points of every step against the exact frame (position error + rho x frame error,
rho the largest offset a fibre can have) and the lookups use twice the largest value, plus float32
rounding, as the bound eps_c of |f_sampled(x, y, z) - f(x, y, z)| (Eq. 7) for |(x, y)| <= rho.

The lookups decide with these frames whenever a fibre's distance is farther than eps_c from its
radius and fall back to the exact frames otherwise, so their answers stay those of Eq. 7.

Kernels:
  sample_yarn(cv, c, delta)              (s (n,), frames (n, 12): pos, t, n, b) for yarn c
  sample_error(cv, c, s, frames, rho)    largest measured |sampled - exact| over the steps
  sampled_frame(s_arr, fr, lo, hi, z)    interpolated (pos, t, n, b) at arc length z (samples lo..hi-1)
  project_on_samples(...)                closest chord point of samples [a, b] to p: (s, distance^2)
"""
import math

import numpy as np
from numba import njit, prange

from stages.core.curves import curve_frame_at


@njit(cache=True)
def _breakpoints(cv, c):
    """Sorted distinct arc lengths of yarn c where the frame may be only C0 in its derivative: the
    spline knots, the stored RMF samples (double reflection restarts there) and both ends."""
    lo = cv.offsets[c]
    nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
    f0 = cv.frame_offsets[c]
    f1 = cv.frame_offsets[c + 1]
    raw = np.empty(nseg + (f1 - f0) + 1)
    for i in range(nseg):
        raw[i] = cv.seg_arclen[lo + i]
    for i in range(f0, f1):
        raw[nseg + i - f0] = cv.frame_s[i]
    raw[-1] = cv.curve_length[c]
    raw = np.sort(raw)
    out = np.empty(raw.shape[0])
    n = 0
    L = cv.curve_length[c]
    tol = 1e-12 * (1.0 + L)
    for v in raw:
        if v < -tol or v > L + tol:
            continue
        if n == 0 or v - out[n - 1] > tol:
            out[n] = min(max(v, 0.0), L)
            n += 1
    return out[:n]


@njit(cache=True)
def sample_yarn(cv, c, delta):
    """Samples of yarn c at its breakpoints and at equal steps <= delta between them; also the index
    of each spline segment's first sample (relative to the yarn's first sample)."""
    bp = _breakpoints(cv, c)
    n = 1
    for i in range(bp.shape[0] - 1):
        n += max(1, int(math.ceil((bp[i + 1] - bp[i]) / delta)))
    s = np.empty(n)
    k = 0
    for i in range(bp.shape[0] - 1):
        m = max(1, int(math.ceil((bp[i + 1] - bp[i]) / delta)))
        for q in range(m):
            s[k] = bp[i] + (bp[i + 1] - bp[i]) * q / m
            k += 1
    s[k] = bp[-1]
    lo = cv.offsets[c]
    nseg = cv.offsets[c + 1] - lo - (0 if cv.closed[c] else 1)
    seg_first = np.empty(nseg, np.int64)
    j = 0
    for i in range(nseg):
        knot = cv.seg_arclen[lo + i]
        while j + 1 < n and s[j + 1] <= knot + 1e-12 * (1.0 + bp[-1]):
            j += 1
        seg_first[i] = j
    fr = np.empty((n, 12), np.float32)
    for q in range(n):
        pos, t, nn, b = curve_frame_at(cv, c, s[q])
        for d in range(3):
            fr[q, d] = pos[d]
            fr[q, 3 + d] = t[d]
            fr[q, 6 + d] = nn[d]
            fr[q, 9 + d] = b[d]
    return s, fr, seg_first


@njit(cache=True)
def _interp(s_arr, fr, i, z):
    """Interpolated (pos, t, n, b) on step [i, i+1] at z."""
    s0 = s_arr[i]
    h = s_arr[i + 1] - s0
    u = (z - s0) / h if h > 0.0 else 0.0
    u2 = u * u
    u3 = u2 * u
    h00 = 2 * u3 - 3 * u2 + 1
    h10 = u3 - 2 * u2 + u
    h01 = -2 * u3 + 3 * u2
    h11 = u3 - u2
    d00 = 6 * u2 - 6 * u
    d10 = 3 * u2 - 4 * u + 1
    d01 = -6 * u2 + 6 * u
    d11 = 3 * u2 - 2 * u
    pos = np.empty(3)
    tan = np.empty(3)
    nn = np.empty(3)
    bb = np.empty(3)
    for d in range(3):
        p0 = np.float64(fr[i, d])
        p1 = np.float64(fr[i + 1, d])
        m0 = np.float64(fr[i, 3 + d]) * h
        m1 = np.float64(fr[i + 1, 3 + d]) * h
        pos[d] = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
        tan[d] = (d00 * p0 + d10 * m0 + d01 * p1 + d11 * m1) / h if h > 0.0 else np.float64(fr[i, 3 + d])
        nn[d] = (1 - u) * np.float64(fr[i, 6 + d]) + u * np.float64(fr[i + 1, 6 + d])
        bb[d] = (1 - u) * np.float64(fr[i, 9 + d]) + u * np.float64(fr[i + 1, 9 + d])
    return pos, tan, nn, bb


@njit(cache=True)
def locate_sample(s_arr, lo, hi, z):
    """Step index i in [lo, hi - 2] with s_arr[i] <= z (clamped)."""
    a = lo
    b = hi - 2
    if z <= s_arr[a]:
        return a
    if z >= s_arr[b]:
        return b
    while a < b:
        m = (a + b + 1) // 2
        if s_arr[m] <= z:
            a = m
        else:
            b = m - 1
    return a


@njit(cache=True)
def sampled_frame(s_arr, fr, lo, hi, z):
    i = locate_sample(s_arr, lo, hi, z)
    return _interp(s_arr, fr, i, z)


@njit(cache=True)
def sample_error(cv, c, s_arr, fr, rho, lo=0, hi=-1):
    """Largest |pos_s - pos| + rho max(|n_s - n|, |b_s - b|) at the midpoint of every step of
    samples lo..hi-1 (where the second-order interpolation errors peak)."""
    if hi < 0:
        hi = s_arr.shape[0]
    worst = 0.0
    for i in range(lo, hi - 1):
        z = 0.5 * (s_arr[i] + s_arr[i + 1])
        pa, ta, na, ba = _interp(s_arr, fr, i, z)
        pos, t, nn, b = curve_frame_at(cv, c, z)
        ep = math.sqrt(np.sum((pa - pos) ** 2))
        en = math.sqrt(np.sum((na - nn) ** 2))
        eb = math.sqrt(np.sum((ba - b) ** 2))
        e = ep + rho * max(en, eb)
        if e > worst:
            worst = e
    return worst


@njit(cache=True)
def _n_samples(bp, delta):
    n = 1
    for i in range(bp.shape[0] - 1):
        n += max(1, int(math.ceil((bp[i + 1] - bp[i]) / delta)))
    return n


@njit(cache=True, parallel=True)
def sample_all(cv, deltas, rho):
    """Frame samples of every yarn (prange over yarns): (offsets (Y+1,), s, frames, seg_first (per
    spline segment, global sample index of its first sample; -1 for unused slots), errors (Y,))."""
    Y = deltas.shape[0]
    counts = np.zeros(Y, np.int64)
    for c in prange(Y):
        counts[c] = _n_samples(_breakpoints(cv, c), deltas[c])
    off = np.zeros(Y + 1, np.int64)
    for c in range(Y):
        off[c + 1] = off[c] + counts[c]
    s_all = np.empty(off[Y])
    fr_all = np.empty((off[Y], 12), np.float32)
    seg_first = np.full(cv.points.shape[0], -1, np.int64)
    err = np.zeros(Y)
    for c in prange(Y):
        s, fr, first = sample_yarn(cv, c, deltas[c])
        base = off[c]
        for q in range(s.shape[0]):
            s_all[base + q] = s[q]
            for d in range(12):
                fr_all[base + q, d] = fr[q, d]
        lo = cv.offsets[c]
        for i in range(first.shape[0]):
            seg_first[lo + i] = base + first[i]
        err[c] = sample_error(cv, c, s, fr, rho[c])
    return off, s_all, fr_all, seg_first, err


@njit(cache=True)
def _chord(s_arr, fr, i, p):
    """(s, distance^2) of p's closest point on the chord between samples i and i + 1."""
    ax = np.float64(fr[i, 0])
    ay = np.float64(fr[i, 1])
    az = np.float64(fr[i, 2])
    ux = np.float64(fr[i + 1, 0]) - ax
    uy = np.float64(fr[i + 1, 1]) - ay
    uz = np.float64(fr[i + 1, 2]) - az
    wx = p[0] - ax
    wy = p[1] - ay
    wz = p[2] - az
    uu = ux * ux + uy * uy + uz * uz
    t = (wx * ux + wy * uy + wz * uz) / uu if uu > 0.0 else 0.0
    t = min(max(t, 0.0), 1.0)
    dx = wx - t * ux
    dy = wy - t * uy
    dz = wz - t * uz
    return s_arr[i] + t * (s_arr[i + 1] - s_arr[i]), dx * dx + dy * dy + dz * dz


@njit(cache=True)
def project_local(s_arr, fr, a, b, p):
    """A local closest chord point of samples a..b to p: start at the chord nearest to p's projection
    on the line through samples a and b, walk to neighbouring chords while the distance drops.
    Within a yarn's extent of a curve that does not fold there (curvature x extent < 1) the foot
    point is unique, so the local minimum is the closest point."""
    if b - a <= 3:
        return project_on_samples(s_arr, fr, a, b, p)
    ux = np.float64(fr[b, 0]) - np.float64(fr[a, 0])
    uy = np.float64(fr[b, 1]) - np.float64(fr[a, 1])
    uz = np.float64(fr[b, 2]) - np.float64(fr[a, 2])
    uu = ux * ux + uy * uy + uz * uz
    u = 0.0
    if uu > 0.0:
        u = ((p[0] - fr[a, 0]) * ux + (p[1] - fr[a, 1]) * uy + (p[2] - fr[a, 2]) * uz) / uu
    j = min(max(a + int(u * (b - a)), a), b - 1)
    bs, best = _chord(s_arr, fr, j, p)
    while j > a:
        s2, d2 = _chord(s_arr, fr, j - 1, p)
        if d2 >= best:
            break
        best = d2
        bs = s2
        j -= 1
    while j < b - 1:
        s2, d2 = _chord(s_arr, fr, j + 1, p)
        if d2 >= best:
            break
        best = d2
        bs = s2
        j += 1
    return bs, best


@njit(cache=True)
def project_on_samples(s_arr, fr, a, b, p):
    """Closest point of the chords between samples a..b (inclusive) to p: (s, distance^2)."""
    best = 1e300
    bs = s_arr[a]
    for i in range(a, b):
        ax = np.float64(fr[i, 0])
        ay = np.float64(fr[i, 1])
        az = np.float64(fr[i, 2])
        ux = np.float64(fr[i + 1, 0]) - ax
        uy = np.float64(fr[i + 1, 1]) - ay
        uz = np.float64(fr[i + 1, 2]) - az
        wx = p[0] - ax
        wy = p[1] - ay
        wz = p[2] - az
        uu = ux * ux + uy * uy + uz * uz
        t = (wx * ux + wy * uy + wz * uz) / uu if uu > 0.0 else 0.0
        t = min(max(t, 0.0), 1.0)
        dx = wx - t * ux
        dy = wy - t * uy
        dz = wz - t * uz
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < best:
            best = d2
            bs = s_arr[i] + t * (s_arr[i + 1] - s_arr[i])
    return bs, best
