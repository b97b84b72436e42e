"""Sampled yarn frames and their chord grid: the lookups' fast, error-bounded stand-in for Eq. 7.

Derived when tables are loaded (``tables.derive_lookup_accel``), never stored: like the BVH of the
realized reference, they are an acceleration structure built from what is stored (the curves).

Frame samples. Per yarn, the rotation-minimising frame of seed 000 §5.1 is sampled (exact kernels
of stages/core/curves.py) at every spline knot and stored RMF sample (where the frame's derivative
may jump) and at equal arc-length steps no longer than ``delta`` between them: position, unit
tangent, normal, binormal (float64). Between samples the position is the cubic Hermite
interpolant of (position, tangent x step) and the normal and binormal are interpolated linearly;
between breakpoints the frame is smooth, so the interpolation error is second order in the step.
``sample_error`` measures it at the midpoint of every step against the exact frame (position error
+ rho x frame error, rho the largest offset a fibre can have); the lookups use twice the largest
value plus the chord sag as the bound eps_c of |f_sampled(x, y, z) - f(x, y, z)| for
|(x, y)| <= rho, decide with the sampled frames whenever a distance is farther than eps_c from a
fibre radius, and fall back to the exact frames otherwise.

Chord grid. Every ``stride``-th sample of a yarn is a coarse knot; the coarse chord between two
knots carries its sag bound (largest distance of the fine samples between them from the chord,
plus the fine chords' sag). A uniform grid lists per cell, ascending by yarn then chord, the runs
of consecutive coarse chords of a yarn whose capsule (radius: the yarn's extent + eps_c + sag)
meets the cell. A point's candidate yarns are the yarns of its cell's runs; the nearest coarse
chord bounds its distance to the axis from below (chord distance - sag) and seeds a safeguarded
Newton iteration for the foot point on the Hermite curve.

Kernels:
  sample_all(cv, deltas, rho)              per-yarn samples (offsets, s, frames (M, 12)), errors
  frame_at(s_arr, fr, lo, hi, i, z)        (step, 12 scalars) interpolated frame at z (hint step i)
  chord_grid(...)                          the uniform grid of coarse-chord runs
  foot_point(...)                          p's foot point on yarn c near a coarse chord
"""
import math

import numpy as np
from numba import njit, prange

from stages.core.curves.frames import curve_frame_at


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
def _n_samples(bp, delta):
    n = 1
    for i in range(bp.shape[0] - 1):
        n += max(1, int(math.ceil((bp[i + 1] - bp[i]) / delta)))
    return n


@njit(cache=True)
def sample_yarn(cv, c, delta, s, fr):
    """Fill s (n,) and fr (n, 12) with the samples of yarn c: breakpoints and equal steps <= delta."""
    bp = _breakpoints(cv, c)
    k = 0
    for i in range(bp.shape[0] - 1):
        m = max(1, int(math.ceil((bp[i + 1] - bp[i]) / delta)))
        for q in range(m):
            s[k] = bp[i] + (bp[i + 1] - bp[i]) * q / m
            k += 1
    s[k] = bp[-1]
    for q in range(s.shape[0]):
        pos, t, nn, b = curve_frame_at(cv, c, s[q])
        for d in range(3):
            fr[q, d] = pos[d]
            fr[q, 3 + d] = t[d]
            fr[q, 6 + d] = nn[d]
            fr[q, 9 + d] = b[d]


@njit(cache=True, inline="always")
def _interp(s_arr, fr, i, z):
    """Interpolated frame on step [i, i+1] at z as 12 scalars (pos, tangent, normal, binormal)."""
    s0 = s_arr[i]
    h = s_arr[i + 1] - s0
    u = (z - s0) / h if h > 0.0 else 0.0
    u2 = u * u
    u3 = u2 * u
    h00 = 2.0 * u3 - 3.0 * u2 + 1.0
    h10 = (u3 - 2.0 * u2 + u) * h
    h01 = -2.0 * u3 + 3.0 * u2
    h11 = (u3 - u2) * h
    d00 = (6.0 * u2 - 6.0 * u) / h if h > 0.0 else 0.0
    d10 = 3.0 * u2 - 4.0 * u + 1.0
    d01 = -d00
    d11 = 3.0 * u2 - 2.0 * u
    a = fr[i]
    b = fr[i + 1]
    v = 1.0 - u
    return (h00 * a[0] + h10 * a[3] + h01 * b[0] + h11 * b[3],
            h00 * a[1] + h10 * a[4] + h01 * b[1] + h11 * b[4],
            h00 * a[2] + h10 * a[5] + h01 * b[2] + h11 * b[5],
            d00 * a[0] + d10 * a[3] + d01 * b[0] + d11 * b[3],
            d00 * a[1] + d10 * a[4] + d01 * b[1] + d11 * b[4],
            d00 * a[2] + d10 * a[5] + d01 * b[2] + d11 * b[5],
            v * a[6] + u * b[6], v * a[7] + u * b[7], v * a[8] + u * b[8],
            v * a[9] + u * b[9], v * a[10] + u * b[10], v * a[11] + u * b[11])


@njit(cache=True, inline="always")
def _hermite_second(s_arr, fr, i, z):
    """Second derivative P'' of the Hermite position interpolant on step [i, i+1] at z."""
    s0 = s_arr[i]
    h = s_arr[i + 1] - s0
    if h <= 0.0:
        return 0.0, 0.0, 0.0
    u = (z - s0) / h
    e00 = (12.0 * u - 6.0) / (h * h)
    e10 = (6.0 * u - 4.0) / h
    e11 = (6.0 * u - 2.0) / h
    a = fr[i]
    b = fr[i + 1]
    return (e00 * (a[0] - b[0]) + e10 * a[3] + e11 * b[3], e00 * (a[1] - b[1]) + e10 * a[4] + e11 * b[4],
            e00 * (a[2] - b[2]) + e10 * a[5] + e11 * b[5])


@njit(cache=True, inline="always")
def locate_step(s_arr, lo, hi, i, z):
    """Step index in [lo, hi - 2] whose interval holds z (clamped), walking from the hint i when it
    is close, else by bisection."""
    if i < lo or i > hi - 2:
        i = lo
    if s_arr[i] <= z and (i == hi - 2 or z < s_arr[i + 1]):
        return i
    if i + 2 <= hi - 2 and s_arr[i + 1] <= z < s_arr[i + 2]:
        return i + 1
    if i - 1 >= lo and s_arr[i - 1] <= z < s_arr[i]:
        return i - 1
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


@njit(cache=True, inline="always")
def frame_at(s_arr, fr, lo, hi, i, z):
    """(step, frame) at arc length z of the yarn whose samples are lo..hi-1; i a hint step."""
    j = locate_step(s_arr, lo, hi, i, z)
    return j, _interp(s_arr, fr, j, z)


@njit(cache=True, inline="always")
def eq7(f, x, y):
    """Eq. 7 with an interpolated frame f: fabric-space point of yarn-space (x, y) in f's cross-section."""
    return (f[0] + x * f[6] + y * f[9], f[1] + x * f[7] + y * f[10], f[2] + x * f[8] + y * f[11])


@njit(cache=True)
def sample_error(cv, c, s_arr, fr, rho, lo, hi):
    """Largest |pos_s - pos| + rho max(|n_s - n|, |b_s - b|) at the midpoint of every step of
    samples lo..hi-1 (where the second-order interpolation errors peak)."""
    worst = 0.0
    for i in range(lo, hi - 1):
        z = 0.5 * (s_arr[i] + s_arr[i + 1])
        f = _interp(s_arr, fr, i, z)
        pos, t, nn, b = curve_frame_at(cv, c, z)
        ep = math.sqrt((f[0] - pos[0]) ** 2 + (f[1] - pos[1]) ** 2 + (f[2] - pos[2]) ** 2)
        en = math.sqrt((f[6] - nn[0]) ** 2 + (f[7] - nn[1]) ** 2 + (f[8] - nn[2]) ** 2)
        eb = math.sqrt((f[9] - b[0]) ** 2 + (f[10] - b[1]) ** 2 + (f[11] - b[2]) ** 2)
        e = ep + rho * max(en, eb)
        if e > worst:
            worst = e
    return worst


@njit(cache=True, parallel=True)
def sample_all(cv, deltas, rho):
    """Frame samples of every yarn (prange over yarns): (offsets (Y+1,), s (M,), frames (M, 12),
    measured errors (Y,))."""
    Y = deltas.shape[0]
    counts = np.zeros(Y, np.int64)
    for c in prange(Y):
        counts[c] = _n_samples(_breakpoints(cv, c), deltas[c])
    off = np.zeros(Y + 1, np.int64)
    for c in range(Y):
        off[c + 1] = off[c] + counts[c]
    s_all = np.empty(off[Y])
    fr_all = np.empty((off[Y], 12))
    err = np.zeros(Y)
    for c in prange(Y):
        sample_yarn(cv, c, deltas[c], s_all[off[c]:off[c + 1]], fr_all[off[c]:off[c + 1]])
        err[c] = sample_error(cv, c, s_all, fr_all, rho[c], off[c], off[c + 1])
    return off, s_all, fr_all, err


# ------------------------------------------------------------------------------------------------
# coarse chords and their grid
@njit(cache=True)
def coarse_knots(s_arr, fr, fs_off, stride):
    """(knot offsets (Y+1,), knot sample index (K,), sag (K,) of the chord starting at each knot; the
    last knot of a yarn has sag 0). A chord's sag bounds the distance of the Hermite curve between
    its knots from the chord: largest distance of the fine samples from it + the largest fine sag."""
    Y = fs_off.shape[0] - 1
    koff = np.zeros(Y + 1, np.int64)
    for c in range(Y):
        n = fs_off[c + 1] - fs_off[c]
        koff[c + 1] = koff[c] + (n - 1 + stride - 1) // stride + 1
    kidx = np.empty(koff[Y], np.int64)
    sag = np.zeros(koff[Y])
    for c in range(Y):
        lo = fs_off[c]
        hi = fs_off[c + 1]
        q = koff[c]
        i = lo
        while True:
            kidx[q] = i
            q += 1
            if i == hi - 1:
                break
            i = min(i + stride, hi - 1)
        for q in range(koff[c], koff[c + 1] - 1):
            a = kidx[q]
            b = kidx[q + 1]
            ax, ay, az = fr[a, 0], fr[a, 1], fr[a, 2]
            ux, uy, uz = fr[b, 0] - ax, fr[b, 1] - ay, fr[b, 2] - az
            uu = ux * ux + uy * uy + uz * uz
            worst = 0.0
            fine = 0.0
            for j in range(a, b + 1):
                wx, wy, wz = fr[j, 0] - ax, fr[j, 1] - ay, fr[j, 2] - az
                t = (wx * ux + wy * uy + wz * uz) / uu if uu > 0.0 else 0.0
                t = min(max(t, 0.0), 1.0)
                dx, dy, dz = wx - t * ux, wy - t * uy, wz - t * uz
                worst = max(worst, math.sqrt(dx * dx + dy * dy + dz * dz))
                if j < b:  # fine sag: the turn of the tangent over a step bounds kappa h
                    h = s_arr[j + 1] - s_arr[j]
                    cx = fr[j, 3] - fr[j + 1, 3]
                    cy = fr[j, 4] - fr[j + 1, 4]
                    cz = fr[j, 5] - fr[j + 1, 5]
                    fine = max(fine, h * math.sqrt(cx * cx + cy * cy + cz * cz) / 4.0)
            sag[q] = 1.05 * worst + 2.0 * fine
    return koff, kidx, sag


@njit(cache=True, inline="always")
def _cell_range(lo, cell, dims, a, b, r, d):
    v0 = min(a, b) - r
    v1 = max(a, b) + r
    i0 = max(int(math.floor((v0 - lo[d]) / cell)), 0)
    i1 = min(int(math.floor((v1 - lo[d]) / cell)), dims[d] - 1)
    return i0, i1


@njit(cache=True)
def chord_grid(fr, koff, kidx, sag, radius, cell):
    """Uniform grid over the coarse chords' capsules (radius[c] + sag): (lo (3,), cell, dims (3,),
    cell_start (cells+1,), run_yarn, run_a, run_b) -- per cell the runs [run_a, run_b) of coarse
    chord indices (global knot numbering), ascending by yarn then chord."""
    Y = koff.shape[0] - 1
    lo = np.full(3, 1e300)
    hi = np.full(3, -1e300)
    for c in range(Y):
        for q in range(koff[c], koff[c + 1]):
            i = kidx[q]
            for d in range(3):
                lo[d] = min(lo[d], fr[i, d] - radius[c] - sag[q])
                hi[d] = max(hi[d], fr[i, d] + radius[c] + sag[q])
    if Y == 0 or koff[Y] == 0:
        lo[:] = 0.0
        hi[:] = 1.0
    dims = np.empty(3, np.int64)
    for d in range(3):
        dims[d] = max(1, int(math.ceil((hi[d] - lo[d]) / cell)))
    ncell = dims[0] * dims[1] * dims[2]
    count = np.zeros(ncell + 1, np.int64)
    for pass_ in range(2):
        if pass_ == 1:
            for i in range(ncell):
                count[i + 1] += count[i]
            pairs = np.empty(count[ncell], np.int64)
            cursor = count[:-1].copy()
        for c in range(Y):
            for q in range(koff[c], koff[c + 1] - 1):
                a = kidx[q]
                b = kidx[q + 1]
                r = radius[c] + sag[q]
                x0, x1 = _cell_range(lo, cell, dims, fr[a, 0], fr[b, 0], r, 0)
                y0, y1 = _cell_range(lo, cell, dims, fr[a, 1], fr[b, 1], r, 1)
                z0, z1 = _cell_range(lo, cell, dims, fr[a, 2], fr[b, 2], r, 2)
                for iz in range(z0, z1 + 1):
                    for iy in range(y0, y1 + 1):
                        for ix in range(x0, x1 + 1):
                            g = (iz * dims[1] + iy) * dims[0] + ix
                            if pass_ == 0:
                                count[g + 1] += 1
                            else:
                                pairs[cursor[g]] = q
                                cursor[g] += 1
    # pairs of each cell are ascending in q (chords were visited in order), so runs are contiguous q
    nrun = 0
    for g in range(ncell):
        for t in range(count[g], count[g + 1]):
            if t == count[g] or pairs[t] != pairs[t - 1] + 1 or _yarn_of(koff, pairs[t]) != _yarn_of(koff, pairs[t - 1]):
                nrun += 1
    start = np.zeros(ncell + 1, np.int64)
    ryarn = np.empty(nrun, np.int32)
    ra = np.empty(nrun, np.int64)
    rb = np.empty(nrun, np.int64)
    k = 0
    for g in range(ncell):
        for t in range(count[g], count[g + 1]):
            q = pairs[t]
            c = _yarn_of(koff, q)
            if t == count[g] or q != pairs[t - 1] + 1 or c != ryarn[k - 1]:
                ryarn[k] = c
                ra[k] = q
                k += 1
            rb[k - 1] = q + 1
        start[g + 1] = k
    return lo, cell, dims, start, ryarn, ra, rb


@njit(cache=True, inline="always")
def _yarn_of(koff, q):
    a = 0
    b = koff.shape[0] - 2
    while a < b:
        m = (a + b + 1) // 2
        if koff[m] <= q:
            a = m
        else:
            b = m - 1
    return a


@njit(cache=True, inline="always")
def chord_lower_bound(fr, kidx, sag, q, px, py, pz):
    """(distance from p to coarse chord q minus its sag: a lower bound of p's distance to the curve
    between the chord's knots, chord parameter t in [0, 1])."""
    a = kidx[q]
    b = kidx[q + 1]
    ax, ay, az = fr[a, 0], fr[a, 1], fr[a, 2]
    ux, uy, uz = fr[b, 0] - ax, fr[b, 1] - ay, fr[b, 2] - az
    wx, wy, wz = px - ax, py - ay, pz - az
    uu = ux * ux + uy * uy + uz * uz
    t = (wx * ux + wy * uy + wz * uz) / uu if uu > 0.0 else 0.0
    t = min(max(t, 0.0), 1.0)
    dx, dy, dz = wx - t * ux, wy - t * uy, wz - t * uz
    return math.sqrt(dx * dx + dy * dy + dz * dz) - sag[q], t


@njit(cache=True)
def foot_point(s_arr, fr, lo, hi, i, s0, sa, sb, px, py, pz, tol):
    """(s, step, squared distance) of p's foot point on the Hermite curve of samples lo..hi-1
    (samples s_arr[lo] <= sa and s_arr[hi - 1] >= sb: the steps are searched there only; i a
    hint step): Newton on g(s) = (P(s) - p) . P'(s) from s0, safeguarded by bisection on the
    bracket [sa, sb], until the next step is below tol; returns the last evaluated s (the lookups
    account for the tangential residual it leaves)."""
    s = min(max(s0, sa), sb)
    a = sa
    b = sb
    rx = ry = rz = 0.0
    for it in range(40):
        i, f = frame_at(s_arr, fr, lo, hi, i, s)
        rx, ry, rz = f[0] - px, f[1] - py, f[2] - pz
        g = rx * f[3] + ry * f[4] + rz * f[5]
        if g > 0.0:
            b = s
        else:
            a = s
        # g'(s) = |P'|^2 + (P - p) . P'' with P'' of the Hermite cubic (Newton converges quadratically)
        kx, ky, kz = _hermite_second(s_arr, fr, i, s)
        gp = f[3] * f[3] + f[4] * f[4] + f[5] * f[5] + rx * kx + ry * ky + rz * kz
        sn = s - g / gp if gp > 0.0 else 0.5 * (a + b)
        if not (a < sn < b):
            sn = 0.5 * (a + b)
        if abs(sn - s) <= tol or b - a <= tol:
            break  # s is within tol of the foot point: keep the evaluated s (no extra evaluation)
        s = sn
    return s, i, rx * rx + ry * ry + rz * rz
