"""Segment visibility functions (seed 001 §4.1): binary visibility images, their SSDFs, the PCA of the
SSDFs and sums of spherical Gaussians, for the fibre segments of one exemplar.

The SVF V_k(w) of segment k is 1 when the ray from its midpoint mu_k in direction w hits no fibre but
segment k's own, else 0 (§4.1); the ray starts where it leaves segment k's capsule, on the side facing
w (*Rays from a segment* in ``stages.precompute.periodic``: the procedural fibres overlap). It is traced
in the flat fabric made of the exemplar repeated without end (``stages.precompute.periodic``), in
exemplar space (z up).

Pixel grid (every function takes ``res_theta`` x ``res_phi``; the paper uses 128 x 128)
---------------------------------------------------------------------------------------
Pixel (r, c) is centred at theta = (r + 1/2) pi / res_theta (from +z), phi = (c + 1/2) 2 pi / res_phi,
direction (sin theta cos phi, sin theta sin phi, cos theta) (``pixel_direction``); its solid angle is
(cos(r pi/res_theta) - cos((r+1) pi/res_theta)) 2 pi/res_phi. Images are stored bit-packed, row-major
(r then c), in ``np.packbits`` order (pixel i = r res_phi + c is bit 7 - i % 8 of byte i // 8):
``(S, ceil(D / 8))`` uint8 with D = res_theta res_phi, 1 = visible.

1. Visibility images (chunk level): ``visibility_images(psc, k, z_lo, z_hi, mids, fibres, ...)``
   One ray per pixel centre from mu_k (from its capsule's surface: ``capsules``; ``max_dist`` counts
   from mu_k), skipping the segment's whole fibre (and its periodic copies),
   until it leaves the slab z_lo <= z <= z_hi or has run ``max_dist`` (default 32 max(W, H)); a ray
   that hits nothing there is visible. The answer is ``periodic_hit_outside(...).t == inf`` (identical bits
   in the tests) by an any-hit walk over whole exemplar periods through the same wrapped capsules (a hit is any capsule
   root in (0, L), wherever it lies), which first tries the capsule that blocked the previous pixel of
   the row and the one that blocked the pixel above (image coherence; pixels are visited in
   serpentine order). ``tests/precompute/test_svf.py`` compares it with ``periodic_hit_outside`` pixel by pixel.
   The walk reads only exemplar k's fibres, never the block map: ``psc`` may be ``periodic_scene(sc,
   k)`` or the tiling's ``ShellScene`` itself.

2. SSDF (chunk level): ``ssdf_images(packed, res_theta, res_phi)`` -> (S, D) float32.
   Metric: the true angle (great-circle distance, radians) between pixel centres. The renderer turns
   d_k into visibility as 1/2 [erf(sqrt(lam/2) d_k(xi)) + 1] (§5.2.2), whose width sqrt(2/lam) is an
   angle on the sphere, so d_k must be one too (a distance in (theta, phi) pixels would stretch it by
   1/sin theta near the poles). gamma(p) = angle from p's centre to the nearest centre of a pixel of
   the opposite value, found exactly: a row pass gives, per row and column, the column distance to the
   nearest 0 and nearest 1 of that row (phi wraps; two sweeps), so the nearest candidate of each row
   is known; among the rows, the nearest maximises the dot product p . q, which for a fixed column is
   linear in the target's (cos theta, sin theta): an upper convex hull of the rows' candidates per
   column, swept once as theta grows (``ssdf_of_image``), O(D) per image; the chord^2 of the chosen
   candidate is evaluated as 2 - 2 cos(theta - theta') + 4 sin theta sin theta' sin^2(dphi / 2).
   Value: d = +-max(gamma - delta/2, gamma/2), delta = pi / res_theta, + visible, - occluded; a fully
   visible image is +pi everywhere, a fully occluded one -pi. Why: the image's boundary runs between
   the centres of unlike neighbours; a pixel whose nearest unlike centre is the next row's (gamma =
   delta) is delta/2 from it, a farther pixel about gamma - delta/2, so |d| approximates the angular
   distance to the boundary (what the erf above wants); two unlike row neighbours both get +-delta/2,
   so the bilinear zero crossing lies midway between them; and |d| > 0 everywhere, so sign(d)
   reproduces the image exactly (at pixel centres). gamma/2 takes over where unlike centres are closer
   than delta (along the short rows near the poles, sin theta 2 pi / res_phi apart), keeping |d| > 0.
   Between unlike neighbours whose |d| differ (their nearest unlike pixels are not each other) the
   bilinear zero crossing moves towards the smaller |d|, always staying between the two centres.

3. PCA (global): ``ssdf_pca(packed, res_theta, res_phi, n_components=48, seed=0, ...)`` -> ``SsdfPca``
   (mean (D,) float32, basis (n, D) float32 with orthonormal rows, eigenvalues (n,) float64, the
   variance of the SSDFs per segment and the number of segments). Randomised subspace iteration on the
   covariance C = X_c^T X_c (Halko et al. 2011): Z_0 = orth(Omega), Omega (D, p) standard normals from
   ``stages.core.rng.normal(seed, d, 2 j)``, p = n + oversample (8); Z_{i+1} = orth(C Z_i) for
   ``power_iters`` (2) passes over the data; then Rayleigh-Ritz: eigh(Z^T C Z) (p x p, numpy) gives the
   basis rows (Z U)^T, each turned so its largest entry is positive. On 3000 segments of the demo's
   damask (128 x 128, 48 components) the RMS error is 1.085, 1.008, 1.0016 times the optimum (exact
   SVD) at 1, 2, 3 power iterations. Every pass streams the images in chunks (recomputing their SSDFs
   from the packed bits, cheap next to the products) or, with ``hold=True``, keeps the (u, D) float32
   SSDF matrix (``svf_memory_estimate`` gives the peak of either); both give the same bytes.
   Identical images are processed once (``unique_images``: distinct images in lexicographic order of
   their bytes, weighted by their counts): in the demo's damask about 60 % of the segments see
   nothing at all (half of all midpoints lie inside another fibre's capsule, whose ray "meets it on
   the way out"), so this more than halves the PCA and the projection.
   Determinism: every reduction is a numba loop with a fixed order (each output entry sums the
   distinct images in their order, in parallel only over output entries); tall matrices are
   orthonormalised by modified Gram-Schmidt (twice) in numba; only the p x p eigenproblem goes to
   LAPACK. The result is the same at any thread count, chunk size or order of the segments.
   ``ssdf_project(packed_chunk, res_theta, res_phi, mean, basis)`` (chunk level) -> (coeffs (s, n)
   float32, error partials (7,) float64); add the partials of all chunks (in chunk order) and pass them
   to ``pca_error_report`` for the RMS error, the RMS relative to the RMS of the SSDFs, the fraction of
   pixels whose reconstructed sign differs from the image, the same outside the one-pixel band along
   the image's boundary (pixels with an opposite 8-neighbour, phi wrapping), and the visible fraction.

4. Sums of SGs (chunk level): ``sg_fit(packed, seg_ids, res_theta, res_phi, n_sg=48, seed=0)`` ->
   (angle (S,) float32, weights (S, Q) float32). Axes xi_{k,q} = R_k xi'_q (``stages.core.sg.
   spherical_fibonacci_axes``: the paper's spherical Fibonacci points, upper hemisphere, turned about z),
   the angle of R_k = 2 pi uniform(seed, global segment id, SG_ANGLE_DIM) (rounded to float32 before the
   axes are built, so the stored angle rebuilds the same axes); w_{k,q} = total solid angle of the
   visible pixels whose centre is nearer xi_{k,q} than any other axis (largest dot product; ties to
   the lower q), so sum_q w_{k,q} is the visible solid angle.

5. Renderer helpers (``stages.core.svf``, where the renderer reads them): ``ssdf_reconstruct``, ``ssdf_at``,
   ``image_at``, ``ssdf_visible``, ``ssg_visibility``, and the pixel grid (``pixel_direction``, ``pixel_solid_angle``).

Chunking: everything per segment (1, 2, 4, projection) depends only on the segment (its midpoint,
fibre and global id), so a runner splits the segments into contiguous chunks computed independently;
the PCA is the one global step between the visibility images and the projection.
"""
import math
from collections import namedtuple

import numba
import numpy as np
from numba import njit, prange

from stages.core.geometry.bvh import direction_signs, leaf_range, push_children_sorted
from stages.core.geometry.capsule import INSIDE, capsule_intersect, point_segment_dist2
from stages.core.geometry.slab import safe_inverse
from stages.core.geometry.stack import stack_array
from stages.core.rng import normal, uniform
from stages.core.sg import spherical_fibonacci_axes
from stages.core.svf import pixel_direction, pixel_solid_angle
from stages.precompute.periodic import ray_start, slab_length

MAX_DIST_PERIODS = 32.0     # default max_dist = 32 max(W, H)
SG_ANGLE_DIM = 0x5356       # rng dimension of the per-segment SG rotation angle ("SV")
STACK = 256

ExemplarSegments = namedtuple("ExemplarSegments", ["ids", "fibre", "mids", "capsules", "z_lo", "z_hi", "period"])
ExemplarSegments.__doc__ = """Segments of one exemplar: global ids (S,) int64, fibre (S,) int64 (global fibre id),
midpoints (S, 3) float64, capsules (S, 7) float64 (end points a, b and radius: the mean of the two
point radii, as the BVH's), the slab z_lo, z_hi and the period (W, H)."""

SsdfPca = namedtuple("SsdfPca", ["mean", "basis", "eigenvalues", "variance", "segments"])
SsdfPca.__doc__ = """ssdf_pca's result: mean (D,) float32, basis (n, D) float32 (orthonormal rows),
eigenvalues (n,) float64 (variance per segment along each row), variance (total variance per segment,
float), segments (S)."""


# ------------------------------------------------------------------------------------------------ pixels
def packed_bytes(res_theta: int, res_phi: int) -> int:
    """Bytes of one bit-packed image."""
    return (res_theta * res_phi + 7) // 8


def unpack_images(packed, res_theta: int, res_phi: int):
    """(S, res_theta, res_phi) uint8 0/1 from bit-packed images."""
    D = res_theta * res_phi
    return np.unpackbits(np.asarray(packed, np.uint8), axis=1, count=D).reshape(-1, res_theta, res_phi)


def pack_images(images):
    """Bit-packed (S, ceil(D/8)) uint8 from (S, res_theta, res_phi) 0/1 images."""
    a = np.asarray(images, np.uint8)
    return np.packbits(a.reshape(a.shape[0], -1) != 0, axis=1)


@njit(cache=True)
def _unpack_into(packed, s, img):
    """Image s of ``packed`` into the flat uint8 array ``img`` (length D)."""
    for i in range(img.shape[0]):
        img[i] = (packed[s, i >> 3] >> (7 - (i & 7))) & 1


# ------------------------------------------------------------------------------------------------ segments
def exemplar_segments(ex_points, ex_radius, ex_offsets, ex_fibers, ex_period, k: int) -> ExemplarSegments:
    """Segments of exemplar k of a tiling (arrays as in the tiling artifact): fibre f's segment i has
    global id ex_offsets[f] - f + i and joins points ex_offsets[f] + i, + i + 1."""
    O = np.asarray(ex_offsets, np.int64)
    P = np.asarray(ex_points, np.float64)
    R = np.asarray(ex_radius, np.float64)
    f0, f1 = int(ex_fibers[k]), int(ex_fibers[k + 1])
    n = np.diff(O[f0:f1 + 1])
    nseg = np.maximum(n - 1, 0)
    fibre = np.repeat(np.arange(f0, f1, dtype=np.int64), nseg)
    first = np.repeat(O[f0:f1] - np.arange(f0, f1), nseg)          # global id of each fibre's segment 0
    ids = np.arange(int(O[f0]) - f0, int(O[f1]) - f1, dtype=np.int64)
    a = ids - first + O[fibre]                                     # first point of each segment
    mids = 0.5 * (P[a] + P[a + 1])
    capsules = np.concatenate([P[a], P[a + 1], (0.5 * (R[a] + R[a + 1]))[:, None]], axis=1)
    zs, rs = P[O[f0]:O[f1], 2], R[O[f0]:O[f1]]
    W, H = (float(v) for v in ex_period[k])
    return ExemplarSegments(ids, fibre, mids, capsules, float((zs - rs).min()), float((zs + rs).max()), (W, H))


# ------------------------------------------------------------------------------------------------ 1. visibility
# The hot helpers take arrays, never the ShellScene: passing the namedtuple of ~30 arrays to a call
# costs ~0.5 us (reference counts of every array), twenty times a capsule test.
@njit(cache=True, inline="always")
def _piece_hit(P, seg_a, seg_r, s, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Does the ray from the midpoint (origin already shifted into the capsule's period) enter wrapped
    capsule s beyond tmin before tmax? A capsule that contains the origin lets it through
    (``stages.precompute.periodic``: rays from a midpoint)."""
    a = seg_a[s]
    r = seg_r[s]
    if point_segment_dist2(ox, oy, oz, P[a, 0], P[a, 1], P[a, 2],
                           P[a + 1, 0], P[a + 1, 1], P[a + 1, 2]) < INSIDE * r * r:
        return False
    t = capsule_intersect(ox, oy, oz, dx, dy, dz, P[a, 0], P[a, 1], P[a, 2],
                          P[a + 1, 0], P[a + 1, 1], P[a + 1, 2], seg_r[s], tmin)
    return t < tmax


@njit(cache=True, inline="always")
def _any_hit_period(P, seg_a, seg_r, srcfib, box, child, prim, root,
                    ox, oy, oz, dx, dy, dz, ix, iy, iz, tmin, tmax, ign_fiber, stack):
    """Any wrapped capsule (not of ign_fiber) hit in (tmin, tmax) by the ray in one period: its index or -1.
    Walks the exemplar's 4-wide nodes (``stages.core.geometry.bvh``), children nearer first."""
    sx, sy, sz = direction_signs(ix, iy, iz)
    stack_t = stack_array(STACK, np.float64)
    stack[0] = root
    sp = 1
    while sp > 0:
        sp -= 1
        ref = stack[sp]
        if ref < 0:
            j0, n = leaf_range(ref)
            for j in range(j0, j0 + n):
                s = prim[j]
                if srcfib[s] == ign_fiber:
                    continue
                if _piece_hit(P, seg_a, seg_r, s, ox, oy, oz, dx, dy, dz, tmin, tmax):
                    return s
            continue
        sp = push_children_sorted(box, child, ref, ox, oy, oz, ix, iy, iz, sx, sy, sz, tmin, tmax, stack, stack_t, sp)
    return -1


@njit(cache=True, inline="always")
def _periodic_any_hit(P, seg_a, seg_r, srcfib, box, child, prim, root,
                      bw, bh, nx, ny, ox, oy, oz, dx, dy, dz, L, ign_fiber, stack):
    ci = int(math.floor(ox / bw)) // nx
    cj = int(math.floor(oy / bh)) // ny
    if dx > 0.0:
        stx, tmx, tdx = 1, ((ci + 1) * nx * bw - ox) / dx, nx * bw / dx
    elif dx < 0.0:
        stx, tmx, tdx = -1, (ci * nx * bw - ox) / dx, -nx * bw / dx
    else:
        stx, tmx, tdx = 0, np.inf, np.inf
    if dy > 0.0:
        sty, tmy, tdy = 1, ((cj + 1) * ny * bh - oy) / dy, ny * bh / dy
    elif dy < 0.0:
        sty, tmy, tdy = -1, (cj * ny * bh - oy) / dy, -ny * bh / dy
    else:
        sty, tmy, tdy = 0, np.inf, np.inf
    ix, iy, iz = safe_inverse(dx), safe_inverse(dy), safe_inverse(dz)
    s = 0.0
    while s < L:
        s1 = min(tmx, tmy, L)
        if s1 > s:
            shx = (ci * nx) * bw
            shy = (cj * ny) * bh
            p = _any_hit_period(P, seg_a, seg_r, srcfib, box, child, prim, root,
                                ox - shx, oy - shy, oz, dx, dy, dz, ix, iy, iz, s, s1, ign_fiber, stack)
            if p >= 0:
                return p, ci, cj
            s = s1
        if tmx < tmy:
            ci += stx
            tmx += tdx
        else:
            cj += sty
            tmy += tdy
        if tmx == np.inf and tmy == np.inf:
            break
    return -1, 0, 0


@njit(cache=True)
def periodic_any_hit(sc, k, ox, oy, oz, dx, dy, dz, L, ign_fiber, stack):
    """(piece, ci, cj): a wrapped capsule of exemplar k (not of fibre ign_fiber) that the ray o + t d,
    0 < t < L, hits in the exemplar repeated without end, found in period (ci, cj) (shift
    (ci nx bw, cj ny bh)); piece = -1 when none. Hit or not agrees with ``periodic_hit_outside`` (a walk over
    whole periods instead of blocks: the same capsules, the same roots)."""
    return _periodic_any_hit(sc.points, sc.seg_a, sc.seg_r, sc.seg_srcfiber, sc.fw_box, sc.fw_child, sc.fprim,
                             sc.ex_wide_root[k],
                             sc.block_size[0], sc.block_size[1], sc.ex_nblocks[k, 0], sc.ex_nblocks[k, 1],
                             ox, oy, oz, dx, dy, dz, L, ign_fiber, stack)


@njit(cache=True)
def _direction_table(res_theta, res_phi):
    dirs = np.empty((res_theta, res_phi, 3))
    for r in range(res_theta):
        for c in range(res_phi):
            x, y, z = pixel_direction(r, c, res_theta, res_phi)
            dirs[r, c, 0] = x
            dirs[r, c, 1] = y
            dirs[r, c, 2] = z
    return dirs


@njit(cache=True)
def segment_image(sc, k, z_lo, z_hi, mx, my, mz, capsule, fibre, dirs, max_dist, out, stack, col_cache):
    """Bit-packed visibility image of segment midpoint m (skipping fibre ``fibre``; rays start on the
    surface of ``capsule``, see ``ray_start``) into ``out`` (bytes); ``dirs`` from _direction_table;
    scratch: ``stack`` (STACK,) int64, ``col_cache`` (res_phi, 3) int64."""
    P, seg_a, seg_r, srcfib = sc.points, sc.seg_a, sc.seg_r, sc.seg_srcfiber
    box, child, prim = sc.fw_box, sc.fw_child, sc.fprim
    root = sc.ex_wide_root[k]
    bw = sc.block_size[0]
    bh = sc.block_size[1]
    nx = sc.ex_nblocks[k, 0]
    ny = sc.ex_nblocks[k, 1]
    R = dirs.shape[0]
    C = dirs.shape[1]
    out[:] = 0
    col_cache[:, 0] = -1
    pp, pi, pj = -1, 0, 0
    for r in range(R):
        for cc in range(C):
            c = cc if r % 2 == 0 else C - 1 - cc
            dx = dirs[r, c, 0]
            dy = dirs[r, c, 1]
            dz = dirs[r, c, 2]
            ox, oy, oz, t_start = ray_start(mx, my, mz, capsule, dx, dy, dz)
            L = slab_length(oz, dz, z_lo, z_hi, max_dist - t_start)
            visible = True
            if L > 0.0:
                blocked = False
                # the capsule that blocked the previous pixel, then the one that blocked the pixel above
                if pp >= 0 and _piece_hit(P, seg_a, seg_r, pp, ox - (pi * nx) * bw, oy - (pj * ny) * bh, oz,
                                          dx, dy, dz, 0.0, L):
                    blocked = True
                else:
                    q = col_cache[c, 0]
                    qi = col_cache[c, 1]
                    qj = col_cache[c, 2]
                    if q >= 0 and not (q == pp and qi == pi and qj == pj) and \
                            _piece_hit(P, seg_a, seg_r, q, ox - (qi * nx) * bw, oy - (qj * ny) * bh, oz,
                                       dx, dy, dz, 0.0, L):
                        blocked = True
                        pp, pi, pj = q, qi, qj
                    else:
                        q, qi, qj = _periodic_any_hit(P, seg_a, seg_r, srcfib, box, child, prim, root, bw, bh, nx,
                                                      ny, ox, oy, oz, dx, dy, dz, L, fibre, stack)
                        if q >= 0:
                            blocked = True
                            pp, pi, pj = q, qi, qj
                if blocked:
                    visible = False
                    col_cache[c, 0] = pp
                    col_cache[c, 1] = pi
                    col_cache[c, 2] = pj
            if visible:
                i = r * C + c
                out[i >> 3] |= np.uint8(1 << (7 - (i & 7)))


@njit(cache=True, parallel=True)
def _visibility_kernel(sc, k, z_lo, z_hi, mids, capsules, fibres, dirs, max_dist, out):
    C = dirs.shape[1]
    for s in prange(mids.shape[0]):
        stack = np.empty(STACK, np.int64)
        col_cache = np.empty((C, 3), np.int64)
        segment_image(sc, k, z_lo, z_hi, mids[s, 0], mids[s, 1], mids[s, 2], capsules[s], fibres[s], dirs,
                      max_dist, out[s], stack, col_cache)


def default_max_dist(psc, k: int) -> float:
    """32 max(W, H) of exemplar k."""
    W = float(psc.ex_nblocks[k, 0] * psc.block_size[0])
    H = float(psc.ex_nblocks[k, 1] * psc.block_size[1])
    return MAX_DIST_PERIODS * max(W, H)


def visibility_images(psc, k: int, z_lo: float, z_hi: float, mids, fibres, res_theta: int = 128,
                      res_phi: int = 128, max_dist: float | None = None, capsules=None):
    """Chunk level. Bit-packed visibility images (S, ceil(D/8)) uint8 of the points ``mids`` (S, 3)
    (segment midpoints, exemplar space), each skipping its fibre ``fibres`` (S,) (global fibre ids; -1
    skips nothing), in exemplar k repeated without end; ``psc`` is the tiling's ``ShellScene`` or its
    ``periodic_scene(sc, k)`` (only exemplar k's fibres are read). With ``capsules`` (S, 7: the
    segments' ``ExemplarSegments.capsules``) each ray starts where it leaves its segment's capsule
    (module doc, 1.), without them at the point itself. ``max_dist`` counts from the point. S * D
    rays; segments are taken one at a time by the threads."""
    mids = np.ascontiguousarray(mids, np.float64).reshape(-1, 3)
    fibres = np.ascontiguousarray(fibres, np.int64).reshape(-1)
    if capsules is None:
        capsules = np.zeros((mids.shape[0], 7))
    capsules = np.ascontiguousarray(capsules, np.float64).reshape(-1, 7)
    if max_dist is None:
        max_dist = default_max_dist(psc, k)
    out = np.zeros((mids.shape[0], packed_bytes(res_theta, res_phi)), np.uint8)
    if mids.shape[0]:
        dirs = _direction_table(res_theta, res_phi)
        with numba.parallel_chunksize(1):
            _visibility_kernel(psc, int(k), float(z_lo), float(z_hi), mids, capsules, fibres, dirs, float(max_dist),
                               out)
    return out


# ------------------------------------------------------------------------------------------------ 2. SSDF
@njit(cache=True)
def _ssdf_tables(res_theta, res_phi):
    """(sin theta, cos theta per row, 2 - 2 cos(k delta) per row offset k, sin^2(k pi / res_phi) per
    column offset k)."""
    d = math.pi / res_theta
    st = np.empty(res_theta)
    ct = np.empty(res_theta)
    dth = np.empty(res_theta)
    for r in range(res_theta):
        st[r] = math.sin((r + 0.5) * d)
        ct[r] = math.cos((r + 0.5) * d)
        dth[r] = 2.0 - 2.0 * math.cos(r * d)
    s2 = np.empty(res_phi // 2 + 1)
    for c in range(s2.shape[0]):
        v = math.sin(c * math.pi / res_phi)
        s2[c] = v * v
    return st, ct, dth, s2


@njit(cache=True)
def _row_distances(img, R, C, near):
    """near[v, r, c] = column distance (phi wraps) from (r, c) to the nearest pixel of value v in row r;
    -1 when the row has none."""
    for r in range(R):
        base = r * C
        for v in range(2):
            last = -1
            for c in range(C):
                if img[base + c] == v:
                    last = c
            if last < 0:
                for c in range(C):
                    near[v, r, c] = -1
                continue
            last -= C
            for c in range(C):          # forward sweep: distance to the nearest v at or before c
                if img[base + c] == v:
                    last = c
                near[v, r, c] = c - last
            nxt = -1
            for c in range(C):
                if img[base + c] == v:
                    nxt = c
                    break
            nxt += C
            for c in range(C - 1, -1, -1):   # backward sweep
                if img[base + c] == v:
                    nxt = c
                if nxt - c < near[v, r, c]:
                    near[v, r, c] = nxt - c


@njit(cache=True)
def ssdf_of_image(img, R, C, tabs, near, out):
    """SSDF (module doc) of the flat 0/1 image ``img`` (R*C,) into ``out`` (R*C,); ``tabs`` from
    _ssdf_tables; scratch ``near`` (2, R, C) int32.

    For a pixel p of row r and a source row r' whose nearest pixel of the wanted value (in |dphi|, the
    row pass) is k columns away, p . q = cos th cos th' + sin th (sin th' cos(2 pi k / C)): for a fixed
    column, linear in p's (cos th, sin th) with the row's point (cos th', sin th' cos dphi'). The
    nearest q maximises p . q, so it is on the upper convex hull of the rows' points, and as th grows
    the maximiser moves along that hull one way: per column and value one hull (monotone chain, rows in
    order) and one sweep, O(R) each. The chosen row's chord^2 is then evaluated accurately as
    2 - 2 cos(th - th') + 4 sin th sin th' sin^2(dphi / 2)."""
    st, ct, dth, s2 = tabs
    D = R * C
    n1 = 0
    for i in range(D):
        n1 += img[i]
    if n1 == 0 or n1 == D:
        v = math.pi if n1 == D else -math.pi
        for i in range(D):
            out[i] = v
        return
    _row_distances(img, R, C, near)
    half = 0.5 * math.pi / R
    hull = np.empty(R, np.int64)
    hx = np.empty(R)
    hy = np.empty(R)
    for o in range(2):              # the value looked for; targets are the pixels of value 1 - o
        v = 1 - o
        for c in range(C):
            # upper hull of the rows holding o, taken right to left (cos th' decreasing): left turns only
            H = 0
            for r2 in range(R):
                kk = near[o, r2, c]
                if kk < 0:
                    continue
                x = ct[r2]
                y = st[r2] * (1.0 - 2.0 * s2[kk])
                while H >= 2 and (hx[H - 1] - hx[H - 2]) * (y - hy[H - 2]) - \
                        (hy[H - 1] - hy[H - 2]) * (x - hx[H - 2]) <= 0.0:
                    H -= 1
                hull[H] = r2
                hx[H] = x
                hy[H] = y
                H += 1
            h = 0
            for r in range(R):
                ux = ct[r]
                uy = st[r]
                while h + 1 < H and ux * hx[h + 1] + uy * hy[h + 1] >= ux * hx[h] + uy * hy[h]:
                    h += 1
                i = r * C + c
                if img[i] != v:
                    continue
                r2 = hull[h]
                ch = dth[abs(r - r2)] + 4.0 * st[r] * st[r2] * s2[near[o, r2, c]]
                g = 2.0 * math.asin(min(1.0, 0.5 * math.sqrt(ch)))
                m = max(g - half, 0.5 * g)
                out[i] = m if v == 1 else -m


@njit(cache=True, parallel=True)
def _ssdf_kernel(packed, R, C, out):
    tabs = _ssdf_tables(R, C)
    D = R * C
    for s in prange(packed.shape[0]):
        img = np.empty(D, np.uint8)
        near = np.empty((2, R, C), np.int32)
        buf = np.empty(D)
        _unpack_into(packed, s, img)
        ssdf_of_image(img, R, C, tabs, near, buf)
        for i in range(D):
            out[s, i] = buf[i]


def ssdf_images(packed, res_theta: int, res_phi: int):
    """Chunk level. SSDFs (S, D) float32 of bit-packed images (module doc: angle in radians, + visible)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    out = np.empty((packed.shape[0], res_theta * res_phi), np.float32)
    if packed.shape[0]:
        with numba.parallel_chunksize(1):
            _ssdf_kernel(packed, res_theta, res_phi, out)
    return out


# ------------------------------------------------------------------------------------------------ 3. PCA
BLOCK = 32


@njit(cache=True, parallel=True)
def _acc_mean(X, m, acc):
    """acc[d] += m[s] X[s, d], s ascending."""
    S, D = X.shape
    nb = (D + BLOCK - 1) // BLOCK
    for b in prange(nb):
        d0 = b * BLOCK
        d1 = min(D, d0 + BLOCK)
        for s in range(S):
            for d in range(d0, d1):
                acc[d] += m[s] * X[s, d]


@njit(cache=True, parallel=True)
def _times_z(X, mean, Z, W):
    """W[s, :] = (X[s] - mean) Z  (Z (D, p)), d ascending."""
    S, D = X.shape
    p = Z.shape[1]
    for s in prange(S):
        acc = np.zeros(p)
        for d in range(D):
            x = X[s, d] - mean[d]
            for j in range(p):
                acc[j] += x * Z[d, j]
        for j in range(p):
            W[s, j] = acc[j]


@njit(cache=True, parallel=True)
def _acc_xtw(X, m, mean, W, Y, sq):
    """Y[d, :] += m[s] (X[s, d] - mean[d]) W[s, :] and sq[d] += m[s] (X[s, d] - mean[d])^2, s ascending."""
    S, D = X.shape
    p = W.shape[1]
    nb = (D + BLOCK - 1) // BLOCK
    for b in prange(nb):
        d0 = b * BLOCK
        d1 = min(D, d0 + BLOCK)
        for s in range(S):
            for d in range(d0, d1):
                x = X[s, d] - mean[d]
                mx = m[s] * x
                sq[d] += mx * x
                for j in range(p):
                    Y[d, j] += mx * W[s, j]


@njit(cache=True)
def _acc_gram(W, m, G):
    """G[i, j] += m[s] W[s, i] W[s, j], s ascending."""
    S, p = W.shape
    for s in range(S):
        for i in range(p):
            w = m[s] * W[s, i]
            for j in range(p):
                G[i, j] += w * W[s, j]


@njit(cache=True)
def _orthonormalise(Zt, seed, salt):
    """Rows of Zt (p, D) orthonormalised in place by modified Gram-Schmidt, twice; a row that vanishes
    (rank deficiency) is replaced by normals from rng (seed, salt + row, ...) and orthonormalised again."""
    p, D = Zt.shape
    for j in range(p):
        for attempt in range(4):
            n0 = 0.0
            for d in range(D):
                n0 += Zt[j, d] * Zt[j, d]
            n0 = math.sqrt(n0)
            for _rep in range(2):
                for i in range(j):
                    rr = 0.0
                    for d in range(D):
                        rr += Zt[i, d] * Zt[j, d]
                    for d in range(D):
                        Zt[j, d] -= rr * Zt[i, d]
            nn = 0.0
            for d in range(D):
                nn += Zt[j, d] * Zt[j, d]
            nn = math.sqrt(nn)
            if nn > 1e-10 * n0 and nn > 0.0:
                for d in range(D):
                    Zt[j, d] /= nn
                break
            for d in range(D):
                Zt[j, d] = normal(seed, salt + 1000003 * (attempt + 1) + j, 2 * d)


@njit(cache=True)
def _omega(seed, D, p, out):
    """out (p, D): standard normals normal(seed, d, 2 j)."""
    for d in range(D):
        for j in range(p):
            out[j, d] = normal(seed, d, 2 * j)


@njit(cache=True)
def _basis_rows(Zt, U, out):
    """out[k, d] = sum_j Zt[j, d] U[j, k], j ascending."""
    p, D = Zt.shape
    n = out.shape[0]
    for k in range(n):
        for d in range(D):
            acc = 0.0
            for j in range(p):
                acc += Zt[j, d] * U[j, k]
            out[k, d] = acc


def svf_memory_estimate(S: int, res_theta: int, res_phi: int, n_components: int, *, hold: bool = True,
                        chunk: int = 1024, oversample: int = 8, threads: int | None = None) -> int:
    """Peak bytes of the global PCA step (``ssdf_pca``) for S segments, with ``hold`` the (S, D) float32
    SSDF matrix in memory, else streamed in chunks of ``chunk`` images; includes the packed images
    and the outputs (mean, basis, coefficients). Worst case: every image distinct."""
    D = int(res_theta) * int(res_phi)
    p = int(n_components) + int(oversample)
    threads = threads or numba.get_num_threads()
    rows = S if hold else min(int(chunk), S)
    packed = S * packed_bytes(res_theta, res_phi)
    dense = rows * D * 4
    vectors = 3 * D * p * 8 + min(int(chunk), S) * p * 8 + 4 * p * p * 8 + 2 * D * 8
    outputs = S * n_components * 4 + n_components * D * 4 + D * 4
    scratch = threads * (D * (1 + 8 + 8) + 8 * res_theta * res_phi)
    return int(packed + dense + vectors + outputs + scratch)


def _chunks(S, chunk):
    return [(a, min(S, a + chunk)) for a in range(0, S, chunk)]


def unique_images(packed):
    """(unique rows (u, B) in lexicographic order of their bytes, inverse (S,) int64, counts (u,) int64)
    of bit-packed images: identical images have identical SSDFs (the damask's fully occluded segments
    are about 60 % of them), so the PCA and the projection work on distinct images only. A lexsort on
    big-endian 64-bit words (np.unique(axis=0) sorts 2 kB void records ~70x slower)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    S, B = packed.shape
    if S == 0:
        return packed, np.zeros(0, np.int64), np.zeros(0, np.int64)
    pad = (-B) % 8
    words = np.ascontiguousarray(np.pad(packed, ((0, 0), (0, pad))) if pad else packed).view(">u8")
    order = np.lexsort(words.T[::-1])
    ws = words[order]
    new = np.ones(S, bool)
    new[1:] = np.any(ws[1:] != ws[:-1], axis=1)
    group = np.cumsum(new) - 1
    inverse = np.empty(S, np.int64)
    inverse[order] = group
    return np.ascontiguousarray(packed[order[new]]), inverse, np.bincount(group).astype(np.int64)


def ssdf_pca(packed, res_theta: int, res_phi: int, n_components: int = 48, seed: int = 0,
             oversample: int = 8, power_iters: int = 2, chunk: int = 1024, hold: bool = False) -> SsdfPca:
    """Global. PCA of the SSDFs of all segments of an exemplar (module doc) from their bit-packed
    images (S, ceil(D/8)). Distinct images are processed once, weighted by their count, in
    lexicographic order of their bytes. The bytes depend neither on ``chunk``, ``hold``, the order of
    the segments nor the thread count."""
    packed = np.ascontiguousarray(packed, np.uint8)
    S = packed.shape[0]
    D = res_theta * res_phi
    if S < 1:
        raise ValueError("ssdf_pca needs at least one segment")
    n = int(n_components)
    if not 1 <= n <= D:
        raise ValueError(f"n_components must be in 1..{D}, got {n}")
    p = min(D, n + int(oversample))
    uniq, _, counts = unique_images(packed)
    m = counts.astype(np.float64)
    parts = _chunks(len(uniq), max(1, int(chunk)))
    X_all = ssdf_images(uniq, res_theta, res_phi) if hold else None

    def blocks():
        for a, b in parts:
            yield (X_all[a:b] if hold else ssdf_images(uniq[a:b], res_theta, res_phi)), m[a:b]

    acc = np.zeros(D)
    for X, mb in blocks():
        _acc_mean(X, mb, acc)
    mean = acc / S
    Zt = np.empty((p, D))
    _omega(int(seed), D, p, Zt)
    _orthonormalise(Zt, int(seed), 1 << 40)
    sq = np.zeros(D)
    for it in range(max(0, int(power_iters))):
        Z = np.ascontiguousarray(Zt.T)
        Y = np.zeros((D, p))
        sq[:] = 0.0
        for X, mb in blocks():
            W = np.empty((X.shape[0], p))
            _times_z(X, mean, Z, W)
            _acc_xtw(X, mb, mean, W, Y, sq)
        Zt = np.ascontiguousarray(Y.T)
        _orthonormalise(Zt, int(seed), (it + 2) << 40)
    Z = np.ascontiguousarray(Zt.T)
    G = np.zeros((p, p))
    if power_iters <= 0:
        sq[:] = 0.0
    for X, mb in blocks():
        W = np.empty((X.shape[0], p))
        _times_z(X, mean, Z, W)
        _acc_gram(W, mb, G)
        if power_iters <= 0:
            _acc_xtw(X, mb, mean, W, np.zeros((D, p)), sq)
    evals, U = np.linalg.eigh(G)
    order = np.argsort(-evals, kind="stable")[:n]
    U = np.ascontiguousarray(U[:, order])
    basis = np.empty((n, D))
    _basis_rows(Zt, U, basis)
    big = np.argmax(np.abs(basis), axis=1)
    basis *= np.where(basis[np.arange(n), big] < 0.0, -1.0, 1.0)[:, None]
    variance = float(sq.sum()) / S
    return SsdfPca(mean.astype(np.float32), basis.astype(np.float32),
                   np.maximum(evals[order], 0.0) / S, variance, S)


@njit(cache=True, parallel=True)
def _project_kernel(packed, R, C, mean, basis, basis_t, coeffs, parts):
    """Per segment: SSDF, coefficients (float32), and error partials of the reconstruction from the
    float32 coefficients: [err^2, ssdf^2, pixels, sign wrong, sign wrong outside band, pixels outside
    band, visible pixels]. basis_t = basis.T (D, n): the loops run along contiguous memory with one
    accumulator per output entry (sums in d, resp. j, ascending, as ``ssdf_reconstruct``)."""
    tabs = _ssdf_tables(R, C)
    D = R * C
    n = basis.shape[0]
    for s in prange(packed.shape[0]):
        img = np.empty(D, np.uint8)
        near = np.empty((2, R, C), np.int32)
        buf = np.empty(D)
        _unpack_into(packed, s, img)
        ssdf_of_image(img, R, C, tabs, near, buf)
        x = np.empty(D)
        for d in range(D):
            x[d] = np.float32(buf[d])          # the SSDF as the PCA saw it
        acc = np.zeros(n)
        for d in range(D):
            xc = x[d] - mean[d]
            for j in range(n):
                acc[j] += xc * basis_t[d, j]
        c32 = np.empty(n)
        for j in range(n):
            c32[j] = np.float32(acc[j])
            coeffs[s, j] = c32[j]
        y = np.empty(D)
        for d in range(D):
            y[d] = np.float64(mean[d])
        for j in range(n):
            cj = c32[j]
            for d in range(D):
                y[d] += cj * basis[j, d]
        e2 = 0.0
        x2 = 0.0
        wrong = 0.0
        wrong_out = 0.0
        outside = 0.0
        vis = 0.0
        for r in range(R):
            for c in range(C):
                i = r * C + c
                e = y[i] - x[i]
                e2 += e * e
                x2 += x[i] * x[i]
                v = img[i]
                vis += v
                band = False
                for a in range(-1, 2):
                    rr = r + a
                    if rr < 0 or rr >= R:
                        continue
                    for b in range(-1, 2):
                        cc = (c + b) % C
                        if img[rr * C + cc] != v:
                            band = True
                if not band:
                    outside += 1.0
                if (y[i] > 0.0) != (v == 1):
                    wrong += 1.0
                    if not band:
                        wrong_out += 1.0
        parts[s, 0] = e2
        parts[s, 1] = x2
        parts[s, 2] = D
        parts[s, 3] = wrong
        parts[s, 4] = wrong_out
        parts[s, 5] = outside
        parts[s, 6] = vis


N_PARTIALS = 7


def ssdf_project(packed, res_theta: int, res_phi: int, mean, basis):
    """Chunk level. (coeffs (s, n) float32, error partials (7,) float64) of the segments' SSDFs on the
    PCA (mean, basis as stored, float32). Add the partials of all chunks in chunk order and pass the
    sum to ``pca_error_report``. Each row depends only on the segment's image (distinct images are
    computed once)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    mean = np.ascontiguousarray(mean, np.float32)
    basis = np.ascontiguousarray(basis, np.float32)
    S = packed.shape[0]
    n = basis.shape[0]
    if S == 0:
        return np.zeros((0, n), np.float32), np.zeros(N_PARTIALS)
    uniq, inv, _ = unique_images(packed)
    cu = np.zeros((len(uniq), n), np.float32)
    pu = np.zeros((len(uniq), N_PARTIALS))
    with numba.parallel_chunksize(1):
        _project_kernel(uniq, res_theta, res_phi, mean, basis, np.ascontiguousarray(basis.T), cu, pu)
    parts = pu[inv]
    total = np.zeros(N_PARTIALS)
    for s in range(S):          # ascending, whatever the threads
        total += parts[s]
    return cu[inv], total


def pca_error_report(partials) -> dict:
    """From summed ``ssdf_project`` partials: rms_error (radians, over all pixels and segments),
    rel_error (rms_error / RMS of the SSDFs), sign_error (fraction of pixels whose reconstructed sign
    differs from the image), sign_error_outside_band (the same among pixels with no opposite
    8-neighbour), visible_fraction."""
    e2, x2, npx, wrong, wrong_out, outside, vis = (float(v) for v in partials)
    npx = max(npx, 1.0)
    rms = math.sqrt(e2 / npx)
    return {"rms_error": rms,
            "rel_error": rms / math.sqrt(x2 / npx) if x2 > 0 else 0.0,
            "sign_error": wrong / npx,
            "sign_error_outside_band": wrong_out / outside if outside > 0 else 0.0,
            "visible_fraction": vis / npx}


# ------------------------------------------------------------------------------------------------ 4. sums of SGs
@njit(cache=True)
def sg_angle(seed, segment_id):
    """Rotation angle about z of segment ``segment_id``'s SG axes, as stored (float32)."""
    return np.float32(2.0 * math.pi * uniform(seed, segment_id, SG_ANGLE_DIM))


@njit(cache=True, parallel=True)
def _sg_kernel(packed, seg_ids, seed, R, C, Q, angles, weights):
    D = R * C
    dirs = _direction_table(R, C)
    omega = np.empty(R)
    for r in range(R):
        omega[r] = pixel_solid_angle(r, R, C)
    for s in prange(packed.shape[0]):
        a = sg_angle(seed, seg_ids[s])
        angles[s] = a
        axes = spherical_fibonacci_axes(Q, np.float64(a))
        w = np.zeros(Q)
        for i in range(D):
            if (packed[s, i >> 3] >> (7 - (i & 7))) & 1:
                r = i // C
                c = i - r * C
                x = dirs[r, c, 0]
                y = dirs[r, c, 1]
                z = dirs[r, c, 2]
                bq = 0
                bd = -np.inf
                for q in range(Q):
                    dt = x * axes[q, 0] + y * axes[q, 1] + z * axes[q, 2]
                    if dt > bd:
                        bd = dt
                        bq = q
                w[bq] += omega[r]
        for q in range(Q):
            weights[s, q] = w[q]


def sg_fit(packed, seg_ids, res_theta: int, res_phi: int, n_sg: int = 48, seed: int = 0):
    """Chunk level. (angle (S,) float32, weights (S, Q) float32): each segment's sum-of-SGs visibility
    (module doc); ``seg_ids`` (S,) the global segment ids (they key the random rotation)."""
    packed = np.ascontiguousarray(packed, np.uint8)
    seg_ids = np.ascontiguousarray(seg_ids, np.int64).reshape(-1)
    S = packed.shape[0]
    angles = np.zeros(S, np.float32)
    weights = np.zeros((S, int(n_sg)), np.float32)
    if S:
        _sg_kernel(packed, seg_ids, int(seed), res_theta, res_phi, int(n_sg), angles, weights)
    return angles, weights


def sg_axes(angle, n_sg: int = 48):
    """(Q, 3) axes of a segment with stored rotation ``angle`` (float32)."""
    return spherical_fibonacci_axes(int(n_sg), float(np.float32(angle)))
