"""Yarn-curve processing for the ingest stage (seed 000 §5.1, §5.2).

From control points to everything ``stages.core.curves`` queries:
- ``catmull_rom_tangents``: uniform Catmull-Rom tangents m_k = (p_{k+1} - p_{k-1}) / 2 (one-sided
  at the ends of open curves), so the cubic Hermite spline interpolates the points and is C1;
- ``arc_lengths``: per-segment lengths (Gauss-Legendre) and cumulative arc length;
- ``rotation_minimising_frames``: normals sampled along each curve by the double reflection method,
  starting from the component of +z (fabric up; a placed fabric's rotated up) normal to the first
  tangent; closed curves record
  their holonomy (``frame_twist``) so queries can spread it evenly;
- ``yarn_delta``: δ_i, the smallest radius such that spheres of radius δ_i around the control points
  cover the curve, from each segment's Bezier box contained in the two end spheres (§5.2, Fig. 9);
- ``build_grid``: a uniform grid listing the segments whose Bezier box, grown by a pad, touches
  each cell ("which yarns pass within r of p" for r up to the pad).
"""
import math

import numpy as np
from numba import njit

from stages.core.curves.frames import double_reflection
from stages.core.curves.spline import (
    Curves,
    arclen_coeffs,
    cross3,
    curve_point_at,
    normalize3,
    segment_coeffs,
    segment_deriv,
)

UP_PARALLEL = 0.99   # |up . tangent| above which a curve's first normal starts from the second axis instead


@njit(cache=True)
def catmull_rom_tangents(points, offsets, closed):
    tangents = np.zeros_like(points)
    for c in range(offsets.shape[0] - 1):
        lo = offsets[c]
        n = offsets[c + 1] - lo
        for k in range(n):
            if closed[c]:
                prev = lo + (k - 1) % n
                nxt = lo + (k + 1) % n
                tangents[lo + k] = 0.5 * (points[nxt] - points[prev])
            elif k == 0:
                tangents[lo] = points[lo + 1] - points[lo]
            elif k == n - 1:
                tangents[lo + k] = points[lo + k] - points[lo + k - 1]
            else:
                tangents[lo + k] = 0.5 * (points[lo + k + 1] - points[lo + k - 1])
    return tangents


def seg_curve_of(offsets):
    n = int(offsets[-1])
    counts = np.diff(offsets)
    return np.repeat(np.arange(len(counts), dtype=np.int32), counts)[:n]


def partial_curves(points, tangents, offsets, closed):
    """A ``Curves`` with the spline arrays only (frames and grid empty) for the builders below."""
    z1 = np.zeros(1)
    return Curves(points, tangents, offsets, closed, seg_curve_of(offsets), np.zeros(len(points)),
                  np.zeros(len(points)), np.zeros(len(offsets) - 1), z1, np.zeros(len(offsets), np.int64),
                  np.zeros((1, 3)), np.zeros(len(offsets) - 1), np.zeros(len(offsets) - 1),
                  np.zeros(len(offsets) - 1), np.zeros(3), np.ones(1), np.ones(3, np.int64),
                  np.zeros(2, np.int64), np.zeros(1, np.int32), np.zeros(len(offsets) - 1))


@njit(cache=True)
def _nseg(cv, c):
    return cv.offsets[c + 1] - cv.offsets[c] - (0 if cv.closed[c] else 1)


@njit(cache=True)
def arc_lengths(cv):
    """(seg_length, seg_arclen, curve_length)."""
    n = cv.points.shape[0]
    C = cv.offsets.shape[0] - 1
    seg_length = np.zeros(n)
    seg_arclen = np.zeros(n)
    curve_length = np.zeros(C)
    for c in range(C):
        lo = cv.offsets[c]
        acc = 0.0
        for i in range(lo, lo + _nseg(cv, c)):
            a, b, cc, d = segment_coeffs(cv, i)
            seg_arclen[i] = acc
            seg_length[i] = arclen_coeffs(a, b, cc, 0.0, 1.0)
            acc += seg_length[i]
        if not cv.closed[c]:
            seg_arclen[lo + _nseg(cv, c)] = acc
        curve_length[c] = acc
    return seg_length, seg_arclen, curve_length


@njit(cache=True)
def rotation_minimising_frames(cv, samples_per_segment, frame_axes):
    """(frame_s, frame_offsets, frame_normal, frame_twist) by double reflection along each curve; curve c's
    first normal is its up axis ``frame_axes[c, 0]`` made normal to the tangent (``frame_axes[c, 1]`` where the
    tangent is within ``UP_PARALLEL`` of the up axis)."""
    C = cv.offsets.shape[0] - 1
    counts = np.zeros(C + 1, np.int64)
    for c in range(C):
        counts[c + 1] = counts[c] + _nseg(cv, c) * samples_per_segment + 1
    M = counts[C]
    frame_s = np.zeros(M)
    frame_normal = np.zeros((M, 3))
    twist = np.zeros(C)
    for c in range(C):
        lo = cv.offsets[c]
        k = counts[c]
        x_prev = cv.points[lo].copy()
        t_prev = normalize3(segment_deriv(cv, lo, 0.0))
        up = frame_axes[c, 0].copy()
        if abs(np.dot(up, t_prev)) > UP_PARALLEL:
            up = frame_axes[c, 1].copy()
        n0 = normalize3(up - np.dot(up, t_prev) * t_prev)
        r = n0.copy()
        frame_s[k] = 0.0
        frame_normal[k] = r
        k += 1
        for i in range(lo, lo + _nseg(cv, c)):
            a, b, cc, d = segment_coeffs(cv, i)
            for q in range(1, samples_per_segment + 1):
                t = q / samples_per_segment
                x = ((a * t + b) * t + cc) * t + d
                tan = normalize3((3.0 * a * t + 2.0 * b) * t + cc)
                r = double_reflection(x_prev, t_prev, r, x, tan)
                frame_s[k] = cv.seg_arclen[i] + arclen_coeffs(a, b, cc, 0.0, t)
                frame_normal[k] = r
                x_prev = x
                t_prev = tan
                k += 1
        if cv.closed[c]:
            t0 = normalize3(segment_deriv(cv, lo, 0.0))
            twist[c] = math.atan2(np.dot(cross3(n0, r), t0), np.dot(n0, r))
    return frame_s, counts, frame_normal, twist


@njit(cache=True)
def _segment_box(cv, i):
    j = i + 1
    c = cv.seg_curve[i]
    if j == cv.offsets[c + 1]:
        j = cv.offsets[c]
    lo = np.empty(3)
    hi = np.empty(3)
    for k in range(3):
        b0 = cv.points[i, k]
        b3 = cv.points[j, k]
        b1 = b0 + cv.tangents[i, k] / 3.0
        b2 = b3 - cv.tangents[j, k] / 3.0
        lo[k] = min(min(b0, b1), min(b2, b3))
        hi[k] = max(max(b0, b1), max(b2, b3))
    return lo, hi, i, j


@njit(cache=True)
def yarn_delta(cv):
    """δ_i per curve (seed 000 §5.2): each segment's Bezier box lies in the union of the spheres of
    radius δ around its two end points. The farthest point of box ∩ {closer to p0} from p0 is a
    vertex of that polytope: a box corner or where a box edge crosses the bisector plane."""
    C = cv.offsets.shape[0] - 1
    delta = np.zeros(C)
    cand = np.empty((8 + 12, 3))
    for c in range(C):
        dmax = 0.0
        for i in range(cv.offsets[c], cv.offsets[c] + _nseg(cv, c)):
            lo, hi, i0, j0 = _segment_box(cv, i)
            p0 = cv.points[i0]
            p1 = cv.points[j0]
            nc = 0
            for m in range(8):
                cand[nc, 0] = hi[0] if (m & 1) else lo[0]
                cand[nc, 1] = hi[1] if (m & 2) else lo[1]
                cand[nc, 2] = hi[2] if (m & 4) else lo[2]
                nc += 1
            w = p1 - p0
            mid = 0.5 * (p0 + p1)
            for ax in range(3):  # 12 edges: 4 parallel to each axis
                for m in range(4):
                    a0 = np.empty(3)
                    o1 = (ax + 1) % 3
                    o2 = (ax + 2) % 3
                    a0[o1] = hi[o1] if (m & 1) else lo[o1]
                    a0[o2] = hi[o2] if (m & 2) else lo[o2]
                    a0[ax] = lo[ax]
                    if w[ax] == 0.0:
                        continue
                    # (x - mid) . w = 0 along the edge x = a0 + u e_ax
                    u = -np.dot(a0 - mid, w) / w[ax]
                    if 0.0 <= u <= hi[ax] - lo[ax]:
                        cand[nc] = a0
                        cand[nc, ax] = lo[ax] + u
                        nc += 1
            for m in range(nc):
                x = cand[m]
                d0 = math.sqrt(np.sum((x - p0) ** 2))
                d1 = math.sqrt(np.sum((x - p1) ** 2))
                d = min(d0, d1)
                if d > dmax:
                    dmax = d
        delta[c] = dmax
    return delta


@njit(cache=True)
def _grid_count(cv, lo_g, cell, dims, pad, counts, fill, items, cursor):
    for c in range(cv.offsets.shape[0] - 1):
        for i in range(cv.offsets[c], cv.offsets[c] + _nseg(cv, c)):
            blo, bhi, i0, j0 = _segment_box(cv, i)
            g0 = np.empty(3, np.int64)
            g1 = np.empty(3, np.int64)
            for k in range(3):
                g0[k] = max(0, int(math.floor((blo[k] - pad[c] - lo_g[k]) / cell)))
                g1[k] = min(dims[k] - 1, int(math.floor((bhi[k] + pad[c] - lo_g[k]) / cell)))
            for gz in range(g0[2], g1[2] + 1):
                for gy in range(g0[1], g1[1] + 1):
                    for gx in range(g0[0], g1[0] + 1):
                        idx = gx + dims[0] * (gy + dims[1] * gz)
                        if fill:
                            items[cursor[idx]] = i
                            cursor[idx] += 1
                        else:
                            counts[idx + 1] += 1


def build_grid(cv, pad, max_cells=1 << 21):
    """Uniform grid over segment boxes grown by ``pad[c]`` (per curve). Returns
    (grid_lo, cell_size, dims, cell_start, items)."""
    pts = cv.points
    pmax = float(np.max(pad)) if len(pad) else 0.0
    lo = pts.min(axis=0) - np.abs(cv.tangents).max(axis=0) / 3.0 - pmax - 1e-9
    hi = pts.max(axis=0) + np.abs(cv.tangents).max(axis=0) / 3.0 + pmax + 1e-9
    ext = hi - lo
    seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    typical = float(np.median(seg_len)) if len(seg_len) else 1.0
    cell = max(2.0 * pmax, typical, 1e-9)
    while np.prod(np.ceil(ext / cell)) > max_cells:
        cell *= 1.25
    dims = np.maximum(1, np.ceil(ext / cell)).astype(np.int64)
    ncell = int(np.prod(dims))
    counts = np.zeros(ncell + 1, np.int64)
    dummy = np.zeros(1, np.int32)
    _grid_count(cv, lo, cell, dims, pad, counts, False, dummy, counts)
    start = np.cumsum(counts)
    items = np.zeros(int(start[-1]), np.int32)
    cursor = start[:-1].copy()
    _grid_count(cv, lo, cell, dims, pad, counts, True, items, cursor)
    return lo, float(cell), dims, start.astype(np.int64), items


def process_curves(points, offsets, closed, radius, frame_samples=4, grid_pad=None, frame_axes=None):
    """Everything ``Curves`` holds, from control points. Returns a dict of arrays (artifact layout).
    ``frame_axes`` (C, 2, 3): per curve the up axis its frames start from and the one used where the curve
    starts along it (``rotation_minimising_frames``); default z and x (a placed fabric's are rotated)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    offsets = np.ascontiguousarray(offsets, dtype=np.int64)
    closed = np.ascontiguousarray(closed, dtype=np.bool_)
    radius = np.ascontiguousarray(radius, dtype=np.float64)
    tangents = catmull_rom_tangents(points, offsets, closed)
    cv = partial_curves(points, tangents, offsets, closed)
    seg_length, seg_arclen, curve_length = arc_lengths(cv)
    cv = cv._replace(seg_length=seg_length, seg_arclen=seg_arclen, curve_length=curve_length)
    if frame_axes is None:
        frame_axes = np.broadcast_to(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), (len(offsets) - 1, 2, 3))
    frame_axes = np.ascontiguousarray(frame_axes, dtype=np.float64)
    frame_s, frame_offsets, frame_normal, twist = rotation_minimising_frames(cv, frame_samples, frame_axes)
    delta = yarn_delta(cv)
    pad = radius + delta if grid_pad is None else np.broadcast_to(np.asarray(grid_pad, float), radius.shape).copy()
    glo, gcell, gdims, gstart, gitems = build_grid(cv, pad)
    return {
        "tangents": tangents, "seg_curve": cv.seg_curve, "seg_length": seg_length, "seg_arclen": seg_arclen,
        "curve_length": curve_length, "frame_s": frame_s, "frame_offsets": frame_offsets,
        "frame_normal": frame_normal, "frame_twist": twist, "delta": delta,
        "grid_lo": glo, "grid_cell": np.array([gcell]), "grid_dims": gdims,
        "grid_cell_start": gstart, "grid_items": gitems, "grid_pad": pad,
    }


def curves_from_arrays(points, offsets, closed, radius, processed):
    """The ``Curves`` namedtuple from control points and ``process_curves`` output."""
    return Curves(
        np.ascontiguousarray(points, np.float64), np.ascontiguousarray(processed["tangents"], np.float64),
        np.ascontiguousarray(offsets, np.int64), np.ascontiguousarray(closed, np.bool_),
        np.ascontiguousarray(processed["seg_curve"], np.int32), processed["seg_length"], processed["seg_arclen"],
        processed["curve_length"], processed["frame_s"], np.ascontiguousarray(processed["frame_offsets"], np.int64),
        processed["frame_normal"], processed["frame_twist"], np.ascontiguousarray(radius, np.float64),
        processed["delta"], processed["grid_lo"], processed["grid_cell"],
        np.ascontiguousarray(processed["grid_dims"], np.int64), processed["grid_cell_start"],
        np.ascontiguousarray(processed["grid_items"], np.int32),
        np.ascontiguousarray(processed["grid_pad"], np.float64),
    )


@njit(cache=True)
def sample_curve_points(cv, c, n):
    """n points evenly spaced in arc length along curve c (pictures, brute-force references)."""
    out = np.empty((n, 3))
    L = cv.curve_length[c]
    for k in range(n):
        out[k] = curve_point_at(cv, c, L * k / (n - 1) if n > 1 else 0.0)
    return out
