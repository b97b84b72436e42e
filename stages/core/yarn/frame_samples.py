"""Sampled yarn frames and their chord grid: the lookups' fast, error-bounded stand-in for Eq. 7.

Derived when tables are loaded (``tables.derive_lookup_accel``), never stored: like the BVH of the
realized reference, they are an acceleration structure built from what is stored (the curves).

Frame samples. Per yarn, the rotation-minimising frame of seed 000 §5.1 is sampled (exact kernels
of stages/core/curves.py) at every spline knot and stored RMF sample (where the frame's derivative
may jump) and at equal arc-length steps no longer than ``delta`` between them: position, unit
tangent, normal, binormal, and per step the derivatives of normal and binormal at its two ends
(``FRAME_COLS`` float64 columns, below). Between samples the position is the cubic Hermite
interpolant of (position, tangent x step), and so are the normal and the binormal, of (N, N' x step)
and (B, B' x step): a frame moving along a curve turns as N' = -(N . T') T + w B and
B' = -(B . T') T - w N, with T' the curvature vector of the spline (one-sided at the step's ends,
which lie between breakpoints) and w the frame's twist rate (0 for a rotation-minimising frame, the
holonomy spread of a closed yarn otherwise). Between breakpoints the frame is smooth, so the
interpolation error is fourth order in the step (it was second order with linear normals, which
took ~10x the samples: 4.2 GB of them for a 1,000-yarn cloth).
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
  sample_all(cv, deltas, rho, yarns)       per-yarn samples (offsets, s, frames (M, FRAME_COLS)), errors
  frame_at(s_arr, fr, lo, hi, i, z)        (step, 12 scalars) interpolated frame at z (hint step i)
  chord_grid(...)                          the uniform grid of coarse-chord runs
  foot_point(...)                          p's foot point on yarn c near a coarse chord
"""
import math

import numpy as np
from numba import njit

from stages.core.curves.frames import curve_frame_at
from stages.core.curves.spline import acceleration_s, coeffs_s, last_at_or_below, locate, segment_t_at, velocity_s
from stages.core.threads import chunk_kernel, for_chunks

# fs_frame columns: position 0-2, unit tangent 3-5, normal 6-8, binormal 9-11; then, on the row of
# the step's first sample, N . T' and B . T' at its start (12, 13) and at its end (14, 15), and the
# twist rate w (16); the last sample of a yarn has no step (zeros)
FRAME_COLS = 17
EMPTY_BOUND = 1e300     # an empty box's lower corner (its upper one: minus it)


@njit(cache=True)
def _breakpoints(cv, c):
    """Sorted distinct arc lengths of yarn c where the frame may be only C0 in its derivative: the
    spline knots, the stored RMF samples (double reflection restarts there) and both ends."""
    return breakpoints_of(cv.offsets, cv.closed, cv.seg_arclen, cv.frame_offsets, cv.frame_s, cv.curve_length, c)


@njit(cache=True)
def breakpoints_of(offsets, closed, seg_arclen, frame_offsets, frame_s, curve_length, c):
    """_breakpoints from the curve arrays it reads (Curves' fields of those names)."""
    lo = offsets[c]
    nseg = offsets[c + 1] - lo - (0 if closed[c] else 1)
    f0 = frame_offsets[c]
    f1 = frame_offsets[c + 1]
    raw = np.empty(nseg + (f1 - f0) + 1)
    for i in range(nseg):
        raw[i] = seg_arclen[lo + i]
    for i in range(f0, f1):
        raw[nseg + i - f0] = frame_s[i]
    raw[-1] = curve_length[c]
    raw = np.sort(raw)
    out = np.empty(raw.shape[0])
    n = 0
    L = curve_length[c]
    tol = 1e-12 * (1.0 + L)
    for v in raw:
        if v < -tol or v > L + tol:
            continue
        if n == 0 or v - out[n - 1] > tol:
            out[n] = min(max(v, 0.0), L)
            n += 1
    return out[:n]


def sample_counts(offsets, closed, seg_arclen, frame_offsets, frame_s, curve_length, deltas):
    """The number of frame samples sample_all makes per yarn at steps ``deltas``, from the curve arrays
    alone (a memory estimate reads them without loading the curves). Yarns on threads."""
    counts = np.zeros(deltas.shape[0], np.int64)
    for_chunks(_count_from_arrays, deltas.shape[0], offsets, closed, seg_arclen, frame_offsets, frame_s, curve_length,
               deltas, counts)
    return counts


@chunk_kernel
def _count_from_arrays(offsets, closed, seg_arclen, frame_offsets, frame_s, curve_length, deltas, counts, c0, c1):
    for c in range(c0, c1):
        counts[c] = _n_samples(breakpoints_of(offsets, closed, seg_arclen, frame_offsets, frame_s, curve_length, c),
                               deltas[c])


@njit(cache=True)
def _n_samples(bp, delta):
    n = 1
    for i in range(bp.shape[0] - 1):
        n += max(1, int(math.ceil((bp[i + 1] - bp[i]) / delta)))
    return n


@njit(cache=True)
def _curvature_vector(cv, j, s):
    """T' = dT/ds of the spline at arc length s within segment j (one-sided at its ends):
    (P'' - (P'' . T) T) / |P'|^2 in the segment's parameter t."""
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = coeffs_s(cv, j)
    t = segment_t_at(cv, j, s - cv.seg_arclen[j])
    vx, vy, vz = velocity_s(ax, ay, az, bx, by, bz, cx, cy, cz, t)
    qx, qy, qz = acceleration_s(ax, ay, az, bx, by, bz, t)
    v2 = vx * vx + vy * vy + vz * vz
    if v2 <= 0.0:
        return 0.0, 0.0, 0.0
    nv = math.sqrt(v2)
    tx, ty, tz = vx / nv, vy / nv, vz / nv
    f = qx * tx + qy * ty + qz * tz
    return (qx - f * tx) / v2, (qy - f * ty) / v2, (qz - f * tz) / v2


@njit(cache=True)
def sample_yarn(cv, c, delta, s, fr):
    """Fill s (n,) and fr (n, FRAME_COLS) with the samples of yarn c: breakpoints and equal steps <=
    delta, each step with its frame derivatives (module doc)."""
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
        for d in range(12, FRAME_COLS):
            fr[q, d] = 0.0
    w = -cv.frame_twist[c] / cv.curve_length[c]  # stages.core.curves.frames: rotation -tw s / L about T
    for q in range(s.shape[0] - 1):
        j, _ = locate(cv, c, 0.5 * (s[q] + s[q + 1]))  # the segment holding the step (no knot inside)
        for e in range(2):
            kx, ky, kz = _curvature_vector(cv, j, s[q + e])
            r = q + e
            fr[q, 12 + 2 * e] = fr[r, 6] * kx + fr[r, 7] * ky + fr[r, 8] * kz
            fr[q, 13 + 2 * e] = fr[r, 9] * kx + fr[r, 10] * ky + fr[r, 11] * kz
        fr[q, 16] = w


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
    w = a[16]
    # N' = -(N . T') T + w B and B' = -(B . T') T - w N at both ends (module doc)
    na, ba, nb, bb = a[12], a[13], a[14], a[15]
    return (h00 * a[0] + h10 * a[3] + h01 * b[0] + h11 * b[3],
            h00 * a[1] + h10 * a[4] + h01 * b[1] + h11 * b[4],
            h00 * a[2] + h10 * a[5] + h01 * b[2] + h11 * b[5],
            d00 * a[0] + d10 * a[3] + d01 * b[0] + d11 * b[3],
            d00 * a[1] + d10 * a[4] + d01 * b[1] + d11 * b[4],
            d00 * a[2] + d10 * a[5] + d01 * b[2] + d11 * b[5],
            h00 * a[6] + h10 * (w * a[9] - na * a[3]) + h01 * b[6] + h11 * (w * b[9] - nb * b[3]),
            h00 * a[7] + h10 * (w * a[10] - na * a[4]) + h01 * b[7] + h11 * (w * b[10] - nb * b[4]),
            h00 * a[8] + h10 * (w * a[11] - na * a[5]) + h01 * b[8] + h11 * (w * b[11] - nb * b[5]),
            h00 * a[9] - h10 * (w * a[6] + ba * a[3]) + h01 * b[9] - h11 * (w * b[6] + bb * b[3]),
            h00 * a[10] - h10 * (w * a[7] + ba * a[4]) + h01 * b[10] - h11 * (w * b[7] + bb * b[4]),
            h00 * a[11] - h10 * (w * a[8] + ba * a[5]) + h01 * b[11] - h11 * (w * b[8] + bb * b[5]))


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
    return last_at_or_below(s_arr, a, b, z)


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


def sample_all(cv, deltas, rho, yarns=None, errors=True, into=None):
    """Frame samples of the yarns ``yarns`` (default every yarn; yarns on threads: ``stages.core.threads``) at
    steps ``deltas`` and error radii ``rho`` (both indexed by yarn): (offsets (n+1,), s (M,), frames
    (M, FRAME_COLS), measured errors (n,)), the k-th listed yarn's samples at offsets[k]:offsets[k+1].
    ``errors`` False: the errors are not measured (zeros; measuring takes the exact frames at every step).
    ``into`` (s, frames, base): written into those arrays from row ``base`` on instead (offsets then count
    from base; nothing else allocated: a frame pool's page-in)."""
    yarns = np.arange(deltas.shape[0], dtype=np.int64) if yarns is None else np.asarray(yarns, np.int64)
    n = yarns.shape[0]
    counts = np.zeros(n, np.int64)
    for_chunks(_count_samples, n, cv, yarns, deltas, counts)
    off = np.zeros(n + 1, np.int64)
    off[1:] = np.cumsum(counts)
    if into is None:
        s_all = np.empty(off[n])
        fr_all = np.empty((off[n], FRAME_COLS))
    else:
        s_all, fr_all, base = into
        off += int(base)
        if off[n] > s_all.shape[0]:
            raise ValueError("sample_all: the samples do not fit the arrays given")
    err = np.zeros(n)
    for_chunks(_sample_yarns, n, cv, yarns, deltas, np.asarray(rho, np.float64), off, s_all, fr_all, err,
               bool(errors))
    return off, s_all, fr_all, err


@chunk_kernel
def _count_samples(cv, yarns, deltas, counts, k0, k1):
    for k in range(k0, k1):
        c = yarns[k]
        counts[k] = _n_samples(_breakpoints(cv, c), deltas[c])


@chunk_kernel
def _sample_yarns(cv, yarns, deltas, rho, off, s_all, fr_all, err, errors, k0, k1):
    for k in range(k0, k1):
        c = yarns[k]
        sample_yarn(cv, c, deltas[c], s_all[off[k]:off[k + 1]], fr_all[off[k]:off[k + 1]])
        if errors:
            err[k] = sample_error(cv, c, s_all, fr_all, rho[c], off[k], off[k + 1])


# ------------------------------------------------------------------------------------------------
# coarse chords and their grid
@njit(cache=True)
def coarse_knots(s_arr, fr, fs_off, stride):
    """The coarse knots of the yarns whose samples are s_arr / fr[fs_off[k]:fs_off[k+1]]: (knot offsets
    (n+1,), each knot's index among its yarn's samples (K,), its arc length (K,), its position (K, 3), the
    sag (K,) of the chord starting at it; the last knot of a yarn has sag 0). A chord's sag bounds the
    distance of the Hermite curve between its knots from the chord: largest distance of the fine samples
    from it + the largest fine sag."""
    Y = fs_off.shape[0] - 1
    koff = np.zeros(Y + 1, np.int64)
    for c in range(Y):
        n = fs_off[c + 1] - fs_off[c]
        koff[c + 1] = koff[c] + (n - 1 + stride - 1) // stride + 1
    kidx = np.empty(koff[Y], np.int64)
    ks = np.empty(koff[Y])
    kpos = np.empty((koff[Y], 3))
    sag = np.zeros(koff[Y])
    for c in range(Y):
        lo = fs_off[c]
        hi = fs_off[c + 1]
        q = koff[c]
        i = lo
        while True:
            kidx[q] = i - lo
            ks[q] = s_arr[i]
            kpos[q, 0] = fr[i, 0]
            kpos[q, 1] = fr[i, 1]
            kpos[q, 2] = fr[i, 2]
            q += 1
            if i == hi - 1:
                break
            i = min(i + stride, hi - 1)
        for q in range(koff[c], koff[c + 1] - 1):
            a = lo + kidx[q]
            b = lo + kidx[q + 1]
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
    return koff, kidx, ks, kpos, sag


@njit(cache=True, inline="always")
def _cell_range(lo, cell, dims, a, b, r, d):
    v0 = min(a, b) - r
    v1 = max(a, b) + r
    i0 = max(int(math.floor((v0 - lo[d]) / cell)), 0)
    i1 = min(int(math.floor((v1 - lo[d]) / cell)), dims[d] - 1)
    return i0, i1


@njit(cache=True)
def chord_grid(kpos, koff, sag, radius, cell):
    """Uniform grid over the coarse chords' capsules (radius[c] + sag): (lo (3,), cell, dims (3,),
    cell_start (cells+1,), run_yarn, run_a, run_b) -- per cell the runs [run_a, run_b) of coarse
    chord indices (global knot numbering), ascending by yarn then chord."""
    Y = koff.shape[0] - 1
    lo = np.full(3, EMPTY_BOUND)     # the empty box, grown by every chord
    hi = np.full(3, -EMPTY_BOUND)
    for c in range(Y):
        for q in range(koff[c], koff[c + 1]):
            for d in range(3):
                lo[d] = min(lo[d], kpos[q, d] - radius[c] - sag[q])
                hi[d] = max(hi[d], kpos[q, d] + radius[c] + sag[q])
    if Y == 0 or koff[Y] == 0:
        lo[:] = 0.0
        hi[:] = 1.0
    dims = np.empty(3, np.int64)
    for d in range(3):
        dims[d] = max(1, int(math.ceil((hi[d] - lo[d]) / cell)))
    ncell = dims[0] * dims[1] * dims[2]
    # two passes over the chords in ascending order (yarn, then chord): a chord continues its cell's
    # last run when it follows that run's last chord (the last knot of a yarn starts no chord, so a
    # run never crosses yarns), else opens a run; pass 0 counts the runs per cell, pass 1 fills them.
    # Nothing per (chord, cell) pair is stored.
    start = np.zeros(ncell + 1, np.int64)
    last = np.empty(ncell, np.int64)
    cursor = np.empty(ncell, np.int64)
    ryarn = np.empty(0, np.int32)
    ra = np.empty(0, np.int32)      # coarse-chord numbers: int32 (a cloth of 10^9 chords would not fit in memory)
    rb = np.empty(0, np.int32)
    for pass_ in range(2):
        last[:] = -2
        if pass_ == 1:
            for g in range(ncell):
                start[g + 1] += start[g]
            cursor[:] = start[:-1]
            ryarn = np.empty(start[ncell], np.int32)
            ra = np.empty(start[ncell], np.int32)
            rb = np.empty(start[ncell], np.int32)
        for c in range(Y):
            for q in range(koff[c], koff[c + 1] - 1):
                r = radius[c] + sag[q]
                x0, x1 = _cell_range(lo, cell, dims, kpos[q, 0], kpos[q + 1, 0], r, 0)
                y0, y1 = _cell_range(lo, cell, dims, kpos[q, 1], kpos[q + 1, 1], r, 1)
                z0, z1 = _cell_range(lo, cell, dims, kpos[q, 2], kpos[q + 1, 2], r, 2)
                for iz in range(z0, z1 + 1):
                    for iy in range(y0, y1 + 1):
                        for ix in range(x0, x1 + 1):
                            g = (iz * dims[1] + iy) * dims[0] + ix
                            fresh = last[g] != q - 1
                            last[g] = q
                            if pass_ == 0:
                                if fresh:
                                    start[g + 1] += 1
                            elif fresh:
                                k = cursor[g]
                                ryarn[k] = c
                                ra[k] = q
                                rb[k] = q + 1
                                cursor[g] = k + 1
                            else:
                                rb[cursor[g] - 1] = q + 1
    if start[ncell] >= 2 ** 31:
        raise ValueError("chord grid: more than 2^31 runs")
    return lo, cell, dims, start.astype(np.int32), ryarn, ra, rb   # int32 offsets: half the bytes


@njit(cache=True, inline="always")
def chord_lower_bound(kpos, sag, q, px, py, pz):
    """(distance from p to coarse chord q (knot positions kpos) minus its sag: a lower bound of p's
    distance to the curve between the chord's knots, chord parameter t in [0, 1])."""
    ax, ay, az = kpos[q, 0], kpos[q, 1], kpos[q, 2]
    ux, uy, uz = kpos[q + 1, 0] - ax, kpos[q + 1, 1] - ay, kpos[q + 1, 2] - az
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
    for _it in range(40):
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
