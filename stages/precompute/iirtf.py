"""The indirect incoming radiance transfer function, IIRTF (seed 001 §4.2, used in §5.3.1).

What it is
----------
T(w0, w1, x) is the radiance arriving at a point x of the fabric from direction w1 (travelling
along -w1) due to a directional light of unit irradiance (on a plane perpendicular to it) arriving
from direction w0 (travelling along -w0), counting only light paths with at least one scattering
event on a fibre. It is computed on the flat fabric made of one exemplar repeated without end
(``stages.precompute.periodic``), light from above only (w0 in the upper hemisphere H+; T = 0 for
w0 below the horizon: the paper's, ``light_domain`` "hemisphere") or from both sides (w0 on the whole
sphere, ``light_domain`` "sphere": §4.2's "Extension to bottom and side fabric surfaces", light that
reaches the fabric from below and crosses it, as on the hanging sides of a drape under a low light;
below, read S^2 for H+ and 4pi for 2pi). Direct light is single scattering and is handled by the
renderer (SVF): a ray from x along w1 that meets no fibre contributes nothing.

Per cell C of an exemplar, T is averaged over the segments whose midpoints mu_k lie in C and
expanded in real orthonormal spherical harmonics of order L (``stages.core.sh.sh_eval``, index
j = l(l+1)+m, J = (L+1)^2 functions), one matrix per RGB channel:

    a_C[j0, j1] = 1/|C| sum_k  int_{H+} int_{S^2} T(w0, w1, mu_k) Y_j0(w0) Y_j1(w1) dw1 dw0      (§4.2)

Reconstruction: T(w0, w1, C) ~= sum_{j0, j1} a_C[j0, j1] Y_j0(w0) Y_j1(w1) (``iirtf_reconstruct``);
for a light with SH coefficients c_d[j0] (a directional light: c_d = Y(w_d)), the incoming indirect
radiance has coefficients c_T[j1] = sum_j0 a_C[j0, j1] c_d[j0], i.e. c_T = a_C^T c_d (§5.3.1 writes
A_C c_d with A_C = a_C^T).

Estimator (§4.2)
----------------
Per path: segment k uniform among the cell's segments, w1 uniform on the sphere (pdf 1/4pi), and a
one-path estimate u[j0] of the light integral int_{H+} T(w0, w1, mu_k) Y_j0(w0) dw0; the path's
estimate is x[j0, j1] = u[j0] Y_j1(w1) 4pi, a_C the mean over N paths and its standard error per
entry sqrt((sum x^2 - (sum x)^2 / N) / (N (N - 1))) (stored beside a_C). Two estimators of u
(``light_sampling``):

- "uniform" (the paper's, the default): w0 uniform on the upper hemisphere (pdf 1/2pi), one per path,
  u[j0] = T^(w0, w1, mu_k) Y_j0(w0) 2pi -- i.e. x = T^ Y_j0(w0) Y_j1(w1) 2pi 4pi.
- "mis": the same integral as a path tracer lit by the sky "radiance Y_j0 over the upper hemisphere":
  at every fibre vertex one light direction uniform on the upper hemisphere (next-event estimation)
  and the BCSDF-sampled continuation when it escapes upwards, combined by the power heuristic. Same
  expectation; far less variance for sharp lobes (a 1-degree R lobe is rarely met by a uniform w0).

T^ is one path-traced sample: the ray from mu_k along w1 (``stages.precompute.periodic.periodic_hit``)
skips k's whole fibre (the BCSDF integrates over the fibre's cross-section, ``stages.core.shading.bcsdf``
"Measure") and meets a capsule that contains mu_k at its way out, as fiberpath's rays meet a capsule
they start in (module doc of ``stages.precompute.periodic``, "Rays from a segment"); no fibre hit before it
leaves the slab: T^ = 0. At each fibre vertex y (wi = the direction back towards the previous vertex)
next-event estimation to the light -- the only estimator of a delta light -- adds
throughput * (S cos)(wi, w0) if the shadow ray from y along w0 (skipping y's fibre) leaves the slab
(or runs ``max_dist``, i.e. out of the side of a finite flat section) without meeting a fibre;
then the material is sampled for the next direction (throughput *= f cos / pdf), Russian roulette
from scattering event ``rr_depth`` on (survival min(0.95, max channel of the throughput)), and the
path continues to the next fibre hit; a path that leaves the slab adds nothing more ("mis": unless
it leaves upwards, see above). ``max_depth`` is the largest number of fibre vertices on a light path
(1: single scattering at y only).
Materials: rows of ``stages.core.shading.material`` through ``mat_of_fiber`` (global fibre id ->
row), as in the fiberpath renderer; a curve material (BCSDF) leaves from the hit point and skips its
fibre, an opaque one (Lambert) leaves just off the capsule surface and tests every fibre.

Random numbers: ``uniform(seed, key, dim)`` with key = cell id * 2^32 + path index (global cell id):
dim 0 picks the segment, 1-2 w0, 3-4 w1, then 6 per fibre vertex (lobe, direction, direction,
roulette, and "mis"'s light direction). So every cell's result depends only on (seed, cell id, its
inputs): identical bytes for any thread count and any split of the cells into chunks.

Mean free path (``mean_free_path``)
-----------------------------------
ell = the mean length of the path segments between two consecutive fibre scattering events, over
paths that enter exemplar k's slab from above at a uniform random (x, y) of the period with
direction -w0, w0 uniform on the upper hemisphere, and scatter at each fibre hit into a direction
sampled from the hit fibre's material (``material_sample``; the throughput is ignored: ell is a
property of the fibre arrangement as seen along the directions light takes). The entering segment
(from the top of the slab to the first hit) and the leaving one (to the slab's boundary) are not
between two scattering events and do not count; a path ends when it leaves the slab, after
``max_depth`` events, or when a ray runs ``max_dist``. ell = sum of lengths / number of segments, a
ratio estimator over independent paths; its standard error by the delta method,
SE = sqrt(sum_p (S_p - ell n_p)^2 / (N (N - 1))) / mean(n_p), with S_p, n_p path p's total length and
segment count. Keys: (seed, 2^62 + path index).

Cells (§4.2 "Choosing cell dimensions", ``build_cells``)
----------------------------------------------------------
Each exemplar block (block_size bw x bh) is cut into nx x ny cells and the slab [z_lo, z_hi]
(exemplar k's fibre bounds, ``exemplar_slabs``) into nz layers; per axis n is the whole number >= 1
whose cell side (side / n) is closest to the target length (cell_factor * ell; ties: fewer cells;
this is round(side / target) except near the half-way points, where round's choice can be farther).
Exemplar k's cells cover [0, W) x [0, H) x [z_lo, z_hi] in a grid NX x NY x NZ (NX = nblocks_x nx,
NY = nblocks_y ny, NZ = nz); the cell index is global over the tiling,

    cell = ex_cells[k] + (iz * NY + iy) * NX + ix          (x fastest, then y, then z)

A segment's cell is the cell of its midpoint wrapped into the period (``seg_cell``); cells with no
midpoint are empty and get a = 0 (and se = 0).

API (chunk-level: ``iirtf_chunk`` over any contiguous range of global cell ids; chunks are
independent, may run in other processes, and concatenate to the whole)
    exemplar_slabs(points, radius, offsets, ex_fibers) -> (K, 2) float64 z_lo, z_hi
    mean_free_path(sc, k, z_lo, z_hi, period, mat_of_fiber, mats, *, n_paths=20000, seed=0,
                   max_depth=64, max_dist=None) -> (ell, se, n_segments)
    cells_per_side(side, target) -> int (per axis)
    build_cells(points, offsets, ex_fibers, ex_period, ex_nblocks, block_size, slabs, target) -> Cells
    cell_box(cells, c) -> (k, lo (3,), hi (3,))
    iirtf_chunk(sc, cells, c0, c1, mat_of_fiber, mats, *, order=4, n_paths=50000, seed=0, max_depth=32,
                rr_depth=5, light_sampling="uniform", max_dist=None, light_domain="hemisphere")
                -> IIRTFChunk(a, se, rays)
    iirtf_reconstruct(a, w0, w1) -> (N, 3) float64
    transfer_projection(...)  the one-path estimator (njit), for kernels that need it
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.dispatch import runtime_value
from stages.core.rng import uniform
from stages.core.sampling import power_heuristic
from stages.core.sh import sh_eval
from stages.core.shading.material import CTX_SIZE, material_eval_pdf, material_prepare, material_sample
from stages.core.threads import chunk_kernel, for_chunks
from stages.precompute.periodic import (
    DIRECTION_DIMS,
    PathScratch,
    PeriodicPaths,
    light_reaches,
    periodic_hit,
    periodic_path,
    periodic_scene,
    periodic_vertex,
    register_tally,
)

MAX_ORDER = 8
TWO_PI = 2.0 * math.pi
FOUR_PI = 4.0 * math.pi
MFP_STREAM = 1 << 62
CELL_CHUNKS_PER_THREAD = 64   # cells cost from nothing to a full cell's paths: small runs balance the threads
MAX_DIST_PERIODS = 32.0  # default max_dist = 32 max(W, H), as the SVF's (stages.precompute.svf)

Cells = namedtuple("Cells", [
    "ex_cells", "ex_grid", "block_cells", "cell_size", "ex_slab", "ex_period",
    "seg_cell", "seg_mid", "seg_fibre", "cell_offsets", "cell_segments", "cell_count"])
Cells.__doc__ = """Cells of a tiling (module doc "Cells"). Per exemplar k: ``ex_cells`` (K+1,) int64 the
range of global cell ids, ``ex_grid`` (K, 3) int64 (NX, NY, NZ), ``block_cells`` (K, 3) int64 cells per
block (nx, ny, nz), ``cell_size`` (K, 3) float64 the cell's sides, ``ex_slab`` (K, 2) float64 (z_lo, z_hi),
``ex_period`` (K, 2) float64 (W, H). Per global segment id s (of fibre f, s = offsets[f] - f + i):
``seg_cell`` (S,) int64, ``seg_mid`` (S, 3) float64 the midpoint wrapped into the period, ``seg_fibre``
(S,) int64. Per cell: ``cell_offsets`` (C+1,) int64 CSR into ``cell_segments`` (S,) int64, the
segments of each cell in increasing id; ``cell_count`` (C,) int64 its number of segments (0: an empty
cell, a = 0; a cell's cost is n_paths paths if it is not empty, nothing otherwise)."""

IIRTFChunk = namedtuple("IIRTFChunk", ["a", "se", "rays"])
IIRTFChunk.__doc__ = """iirtf_chunk's result for cells c0..c1-1: ``a`` and ``se`` (c1-c0, 3, J, J) float64
indexed [cell - c0, channel, j0 (light direction w0), j1 (incoming direction w1)]; ``rays`` (c1-c0,)
int64 rays cast per cell."""


# ------------------------------------------------------------------------------------------------
# geometry helpers

def exemplar_slabs(points, radius, offsets, ex_fibers):
    """(K, 2) float64: exemplar k's slab z_lo = min(P_z - R), z_hi = max(P_z + R) over its fibres."""
    P = np.asarray(points, np.float64)
    R = np.asarray(radius, np.float64)
    O = np.asarray(offsets, np.int64)
    Fb = np.asarray(ex_fibers, np.int64)
    out = np.empty((len(Fb) - 1, 2))
    for k in range(len(Fb) - 1):
        a, b = O[Fb[k]], O[Fb[k + 1]]
        out[k, 0] = (P[a:b, 2] - R[a:b]).min()
        out[k, 1] = (P[a:b, 2] + R[a:b]).max()
    return out


def cells_per_side(side: float, target: float) -> int:
    """The number n >= 1 of cells along a side whose length side / n is closest to ``target``
    (ties: fewer cells)."""
    if not (side > 0.0 and target > 0.0 and math.isfinite(side / target)):
        raise ValueError(f"cells_per_side: side {side} and target {target} must be positive and finite")
    r = side / target
    lo = max(1, int(math.floor(r)))
    hi = lo + 1
    return lo if abs(side / lo - target) <= abs(side / hi - target) else hi


def build_cells(points, offsets, ex_fibers, ex_period, ex_nblocks, block_size, slabs, target) -> Cells:
    """Cells of every exemplar (module doc "Cells"); ``target`` the target cell length, a number or
    one per exemplar (cell_factor * ell_k)."""
    P = np.asarray(points, np.float64)
    O = np.asarray(offsets, np.int64)
    Fb = np.asarray(ex_fibers, np.int64)
    period = np.asarray(ex_period, np.float64).reshape(-1, 2)
    nblocks = np.asarray(ex_nblocks, np.int64).reshape(-1, 2)
    bs = np.asarray(block_size, np.float64)
    slabs = np.asarray(slabs, np.float64).reshape(-1, 2)
    K = len(Fb) - 1
    target = np.broadcast_to(np.asarray(target, np.float64), (K,))
    F = len(O) - 1
    nseg = O[1:] - O[:-1] - 1
    seg_fibre = np.repeat(np.arange(F, dtype=np.int64), nseg)
    first = O[seg_fibre] + (np.arange(len(seg_fibre)) - (O[:-1] - np.arange(F))[seg_fibre])
    mid = 0.5 * (P[first] + P[first + 1])
    ex_of_fibre = np.repeat(np.arange(K, dtype=np.int64), Fb[1:] - Fb[:-1])
    seg_ex = ex_of_fibre[seg_fibre]
    ex_grid = np.zeros((K, 3), np.int64)
    block_cells = np.zeros((K, 3), np.int64)
    cell_size = np.zeros((K, 3))
    ex_cells = np.zeros(K + 1, np.int64)
    seg_cell = np.empty(len(seg_fibre), np.int64)
    for k in range(K):
        thick = slabs[k, 1] - slabs[k, 0]
        n = (cells_per_side(bs[0], target[k]), cells_per_side(bs[1], target[k]), cells_per_side(thick, target[k]))
        block_cells[k] = n
        ex_grid[k] = (nblocks[k, 0] * n[0], nblocks[k, 1] * n[1], n[2])
        cell_size[k] = (bs[0] / n[0], bs[1] / n[1], thick / n[2])
        ex_cells[k + 1] = ex_cells[k] + int(np.prod(ex_grid[k]))
        sel = seg_ex == k
        W, H = period[k]
        x = mid[sel, 0] - W * np.floor(mid[sel, 0] / W)
        y = mid[sel, 1] - H * np.floor(mid[sel, 1] / H)
        mid[sel, 0] = x
        mid[sel, 1] = y
        NX, NY, NZ = ex_grid[k]
        ix = np.clip(np.floor(x / cell_size[k, 0]).astype(np.int64), 0, NX - 1)
        iy = np.clip(np.floor(y / cell_size[k, 1]).astype(np.int64), 0, NY - 1)
        iz = np.clip(np.floor((mid[sel, 2] - slabs[k, 0]) / cell_size[k, 2]).astype(np.int64), 0, NZ - 1)
        seg_cell[sel] = ex_cells[k] + (iz * NY + iy) * NX + ix
    C = int(ex_cells[-1])
    order = np.argsort(seg_cell, kind="stable").astype(np.int64)
    count = np.bincount(seg_cell, minlength=C).astype(np.int64)
    cell_offsets = np.zeros(C + 1, np.int64)
    np.cumsum(count, out=cell_offsets[1:])
    return Cells(ex_cells, ex_grid, block_cells, cell_size, slabs.copy(), period.copy(),
                 seg_cell, mid, seg_fibre, cell_offsets, order, count)


def cell_box(cells: Cells, c: int):
    """(exemplar k, (x0, y0, z0), (x1, y1, z1)): the box of global cell ``c`` in exemplar space."""
    k = int(np.searchsorted(cells.ex_cells, c, side="right") - 1)
    NX, NY, _ = cells.ex_grid[k]
    r = c - cells.ex_cells[k]
    ix, iy, iz = r % NX, (r // NX) % NY, r // (NX * NY)
    s = cells.cell_size[k]
    lo = np.array([ix * s[0], iy * s[1], cells.ex_slab[k, 0] + iz * s[2]])
    return k, lo, lo + s


# ------------------------------------------------------------------------------------------------
# the path tracer

IirtfLight = namedtuple("IirtfLight", ["u", "Y", "T", "w0", "order", "mis", "sphere"])
IirtfLight.__doc__ = """What one IIRTF path records (``transfer_projection``; a tally of ``periodic_path``): the
projection ``u`` (3, J) onto the SH basis of order ``order`` (``Y`` (J,) scratch for the basis), ``T`` (3,) the
transfer towards the fixed light direction ``w0`` of the paper's estimator (``mis`` False), or, with ``mis``,
a light direction drawn per vertex and the path's escapes, power heuristic; light from the whole sphere when
``sphere``, else from the upper hemisphere."""

P_LIGHT = 1.0 / TWO_PI   # the density of a light direction uniform on the upper hemisphere
P_LIGHT_SPHERE = 1.0 / FOUR_PI   # ... uniform on the whole sphere (light_domain "sphere")
LIGHT_DOMAINS = ("hemisphere", "sphere")


@njit(cache=True)
def light_density(sphere):
    """The density of a light direction drawn by ``draw_light_direction``: 1/2pi or (``sphere``) 1/4pi."""
    return P_LIGHT_SPHERE if sphere else P_LIGHT


@njit(cache=True)
def draw_light_direction(seed, key, dim, sphere, out):
    """A light direction uniform on the upper hemisphere (or, ``sphere``, the whole sphere) into ``out`` from
    the uniforms of dimensions ``dim`` (cos theta) and ``dim + 1`` (azimuth)."""
    z = uniform(seed, key, dim)
    if sphere:
        z = 1.0 - 2.0 * z
    r = math.sqrt(max(0.0, 1.0 - z * z))
    ph = TWO_PI * uniform(seed, key, dim + 1)
    out[0] = r * math.cos(ph)
    out[1] = r * math.sin(ph)
    out[2] = z


@njit(cache=True)
def _add_projection(u, Y, order, w, dx, dy, dz, c0, c1, c2):
    """u[ch, j] += c_ch w Y_j(d) for the SH basis of ``order`` (``Y`` scratch)."""
    sh_eval(order, dx, dy, dz, Y)
    for j in range((order + 1) * (order + 1)):
        y = w * Y[j]
        u[0, j] += c0 * y
        u[1, j] += c1 * y
        u[2, j] += c2 * y


@njit(cache=True)
def _iirtf_light_vertex(tally, paths, v, mat, nf, tp, seed, key, base):
    """``periodic.light_vertex`` for an IIRTF path: one light direction, ``w0`` or (``mis``) drawn uniform
    on the light's domain from dimensions base + DIRECTION_DIMS, + 1 (unit irradiance from there)."""
    wl = v.wl
    if tally.mis:
        draw_light_direction(seed, key, base + DIRECTION_DIMS, tally.sphere, wl)
    else:
        for k in range(3):
            wl[k] = tally.w0[k]
    f0, f1, f2, pf = material_eval_pdf(mat, v.ctx, v.t_tan, v.n, v.wi, wl)
    if f0 == 0.0 and f1 == 0.0 and f2 == 0.0:
        return 0
    if light_reaches(paths, v, nf):
        tp0, tp1, tp2 = tp
        if tally.mis:
            # the power heuristic over the light's density, folded into one division: power_heuristic(pl, pf) / pl
            pl = light_density(tally.sphere)
            w = pl / (pl * pl + pf * pf)
            _add_projection(tally.u, tally.Y, tally.order, w, wl[0], wl[1], wl[2], tp0 * f0, tp1 * f1, tp2 * f2)
        else:
            T = tally.T
            T[0] += tp0 * f0
            T[1] += tp1 * f1
            T[2] += tp2 * f2
    return 1


@njit(cache=True)
def _iirtf_escaped(tally, wo, tp, pdf):
    """``periodic.path_escaped`` for an IIRTF path: with ``mis``, the sky above (``sphere``: the sky all round)
    is the BCSDF-sampled light."""
    if tally.mis and (wo[2] > 0.0 or tally.sphere):
        tp0, tp1, tp2 = tp
        _add_projection(tally.u, tally.Y, tally.order, power_heuristic(pdf, light_density(tally.sphere)), wo[0],
                        wo[1], wo[2], tp0, tp1, tp2)


register_tally(IirtfLight, _iirtf_light_vertex, _iirtf_escaped)


@njit(cache=True)
def transfer_projection(paths, ox, oy, oz, ign0, w0, w1, order, mis, sphere, seed, key, dim0, Y, u):
    """One path's estimate u[ch, j0] of int_{H+} T(w0', w1, x) Y_j0(w0') dw0' (``sphere``: over S^2) at
    x = (ox, oy, oz), the ray from x along w1 skipping fibre ``ign0`` (module doc "Estimator"). ``mis`` False:
    the paper's, T(w0, w1, x) Y_j0(w0) 2 pi (4 pi) with NEE along the path's w0; True: light directions drawn
    per vertex and BCSDF-sampled escapes, power heuristic (``IirtfLight``; the path itself is
    ``periodic_path``'s). ``Y`` (J,) scratch, ``u`` (3, J) output (zeroed here). Random numbers (seed, key,
    dim0 + 6 per vertex). Returns the number of rays cast.
    15 parameters: the path's start (point, skipped fibre, w0, w1), the basis order, estimator and light
    domain, the random stream (seed, key, dim0) and two arrays; the fabric is one record (``PeriodicPaths``)."""
    J = (order + 1) * (order + 1)
    for ch in range(3):
        for j in range(J):
            u[ch, j] = 0.0
    h = periodic_hit(paths.scene, paths.z_lo, paths.z_hi, ox, oy, oz, w1[0], w1[1], w1[2], ign0, paths.max_dist)
    if math.isinf(h.t):
        return 1
    v = PathScratch(np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(CTX_SIZE))
    for k in range(3):
        v.wi[k] = -w1[k]
    T = np.zeros(3)
    rays = 1 + periodic_path(paths, IirtfLight(u, Y, T, w0, order, mis, sphere), v, h, seed, key, dim0,
                             DIRECTION_DIMS + 2)
    if not mis and (T[0] != 0.0 or T[1] != 0.0 or T[2] != 0.0):
        sh_eval(order, w0[0], w0[1], w0[2], Y)
        solid_angle = FOUR_PI if sphere else TWO_PI   # 1 / light_density, without its rounding
        for j in range(J):
            y = solid_angle * Y[j]
            u[0, j] = T[0] * y
            u[1, j] = T[1] * y
            u[2, j] = T[2] * y
    return rays


@chunk_kernel
def _iirtf_cells(paths, cell_offsets, cell_segments, seg_mid, seg_fibre, c0, c1, order, mis, sphere, n_paths, seed,
                 a_out, se_out, rays_out, i0, i1):
    """Cells c0 + i0 .. c0 + i1 - 1 into rows i0 .. i1 - 1 of the outputs (``for_chunks``).
    17 parameters: a ``for_chunks`` chunk kernel: the cells' CSR and segments, the estimator's settings, three
    output arrays and the chunk's range."""
    J = (order + 1) * (order + 1)
    S = np.empty((3, J, J))   # per chunk, zeroed per cell (as numba's parallel loop hoisted them)
    Q = np.empty((3, J, J))
    Y = np.empty(J)
    Y1 = np.empty(J)
    u = np.empty((3, J))
    w0 = np.empty(3)
    w1 = np.empty(3)
    for ci in range(i0, i1):
        c = c0 + ci
        s_beg = cell_offsets[c]
        ns = cell_offsets[c + 1] - s_beg
        if ns == 0:
            continue
        S[:] = 0.0
        Q[:] = 0.0
        rays = 0
        for p in range(n_paths):
            key = (c << 32) + p
            s = cell_segments[s_beg + min(int(uniform(seed, key, 0) * ns), ns - 1)]
            # w0 uniform on the light's domain (the paper's estimator: the upper hemisphere), w1 uniform on the sphere
            draw_light_direction(seed, key, 1, sphere, w0)
            z = 1.0 - 2.0 * uniform(seed, key, 3)
            r = math.sqrt(max(0.0, 1.0 - z * z))
            ph = TWO_PI * uniform(seed, key, 4)
            w1[0] = r * math.cos(ph)
            w1[1] = r * math.sin(ph)
            w1[2] = z
            rays += transfer_projection(paths, seg_mid[s, 0], seg_mid[s, 1], seg_mid[s, 2], seg_fibre[s], w0, w1,
                                        order, mis, sphere, seed, key, 5, Y, u)
            nz = False
            for ch in range(3):
                for j in range(J):
                    if u[ch, j] != 0.0:
                        nz = True
            if not nz:
                continue
            sh_eval(order, w1[0], w1[1], w1[2], Y1)
            for j1 in range(J):
                y1 = FOUR_PI * Y1[j1]
                for ch in range(3):
                    for j0 in range(J):
                        x = u[ch, j0] * y1
                        S[ch, j0, j1] += x
                        Q[ch, j0, j1] += x * x
        N = float(n_paths)
        for ch in range(3):
            for j0 in range(J):
                for j1 in range(J):
                    m = S[ch, j0, j1] / N
                    a_out[ci, ch, j0, j1] = m
                    if n_paths > 1:
                        v = (Q[ch, j0, j1] - S[ch, j0, j1] * m) / (N * (N - 1.0))
                        se_out[ci, ch, j0, j1] = math.sqrt(max(v, 0.0))
        rays_out[ci] = rays


def _max_dist(max_dist, period):
    return MAX_DIST_PERIODS * float(max(period)) if max_dist is None else float(max_dist)


def iirtf_chunk(sc, cells: Cells, c0: int, c1: int, mat_of_fiber, mats, *, order: int = 4, n_paths: int = 50_000,
                seed: int = 0, max_depth: int = 32, rr_depth: int = 5, light_sampling: str = "uniform",
                max_dist=None, light_domain: str = "hemisphere") -> IIRTFChunk:
    """a_C and its standard error for global cells c0 <= c < c1 (module doc), cells on threads.
    ``sc`` the tiling's ShellScene, ``mat_of_fiber`` (F,) int32 material row per global fibre id, ``mats``
    (NM, MAT_SIZE); ``order`` L in 0..8 (J = (L+1)^2); ``max_dist`` caps every ray (default 32 periods:
    a flat section 64 periods across); ``light_sampling`` "uniform" (the paper's estimator) or "mis"
    (module doc "Estimator"); ``light_domain`` "hemisphere" (the paper's: light from above) or "sphere"
    (from both sides). Any split of [0, C) into chunks gives the same bytes; threads
    take runs of cells (``CELL_CHUNKS_PER_THREAD`` per thread: cells cost from nothing to a full cell's paths)."""
    order = int(order)
    if not 0 <= order <= MAX_ORDER:
        raise ValueError(f"iirtf_chunk: SH order {order} outside 0..{MAX_ORDER}")
    if not 0 <= c0 <= c1 <= len(cells.cell_offsets) - 1:
        raise ValueError(f"iirtf_chunk: cell range [{c0}, {c1}) outside [0, {len(cells.cell_offsets) - 1})")
    if n_paths < 1 or max_depth < 1 or rr_depth < 1:
        raise ValueError("iirtf_chunk: n_paths, max_depth and rr_depth must be >= 1")
    if light_sampling not in ("uniform", "mis"):
        raise ValueError(f"iirtf_chunk: light_sampling {light_sampling!r} is neither 'uniform' nor 'mis'")
    if light_domain not in LIGHT_DOMAINS:
        raise ValueError(f"iirtf_chunk: light_domain {light_domain!r} is neither 'hemisphere' nor 'sphere'")
    J = (order + 1) ** 2
    a = np.zeros((c1 - c0, 3, J, J))
    se = np.zeros((c1 - c0, 3, J, J))
    rays = np.zeros(c1 - c0, np.int64)
    mof = np.ascontiguousarray(mat_of_fiber, np.int32)
    mats = np.ascontiguousarray(mats, np.float64)
    for k in range(len(cells.ex_cells) - 1):
        lo = max(c0, int(cells.ex_cells[k]))
        hi = min(c1, int(cells.ex_cells[k + 1]))
        if lo >= hi:
            continue
        W, H = (float(v) for v in cells.ex_period[k])
        z_lo, z_hi = (float(v) for v in cells.ex_slab[k])
        sl = slice(lo - c0, hi - c0)
        paths = PeriodicPaths(periodic_scene(sc, k), z_lo, z_hi, W, H, mof, mats, int(max_depth), int(rr_depth),
                              _max_dist(max_dist, (W, H)), 1e-7 * max(W, H))
        for_chunks(_iirtf_cells, hi - lo, paths, cells.cell_offsets, cells.cell_segments, cells.seg_mid,
                   cells.seg_fibre, lo, hi, order, light_sampling == "mis", light_domain == "sphere", int(n_paths),
                   int(seed), a[sl], se[sl], rays[sl], chunks_per_thread=CELL_CHUNKS_PER_THREAD)
    return IIRTFChunk(a, se, rays)


# ------------------------------------------------------------------------------------------------
# mean free path

@chunk_kernel
def _free_paths(sc, z_lo, z_hi, W, H, mat_of_fiber, mats, seed, max_depth, max_dist, eps, S, Nseg, p0, p1):
    """Free paths p0 .. p1 - 1 (``for_chunks``).
    15 parameters: a ``for_chunks`` chunk kernel: the periodic fabric's parts, the path settings, the output and
    the chunk's range."""
    for p in range(p0, p1):
        key = MFP_STREAM + p
        t_tan = np.empty(3)
        n = np.empty(3)
        so = np.empty(3)
        wi = np.empty(3)
        wo = np.empty(3)
        ctx = np.empty(CTX_SIZE)
        x = W * uniform(seed, key, 0)
        y = H * uniform(seed, key, 1)
        z = uniform(seed, key, 2)
        r = math.sqrt(max(0.0, 1.0 - z * z))
        ph = TWO_PI * uniform(seed, key, 3)
        wo[0] = -r * math.cos(ph)
        wo[1] = -r * math.sin(ph)
        wo[2] = -z
        h = periodic_hit(sc, z_lo, z_hi, x, y, z_hi, wo[0], wo[1], wo[2], runtime_value(-1), max_dist)
        total = 0.0
        count = 0
        depth = 0
        while not math.isinf(h.t) and depth < max_depth:
            depth += 1
            for k in range(3):
                wi[k] = -wo[k]
            row, nf = periodic_vertex(sc, mats, mat_of_fiber, h, W, H, eps, t_tan, n, so)
            mat = mats[row]
            material_prepare(mat, t_tan, n, wi, ctx)
            base = 4 + 3 * depth
            _s0, _s1, _s2, pf = material_sample(mat, ctx, t_tan, n, wi, uniform(seed, key, base),
                                                uniform(seed, key, base + 1), uniform(seed, key, base + 2), wo)
            if pf <= 0.0:
                break
            h = periodic_hit(sc, z_lo, z_hi, so[0], so[1], so[2], wo[0], wo[1], wo[2], nf, max_dist)
            if not math.isinf(h.t):
                total += h.t
                count += 1
        S[p] = total
        Nseg[p] = count


def mean_free_path(sc, k: int, z_lo: float, z_hi: float, period, mat_of_fiber, mats, *, n_paths: int = 20_000,
                   seed: int = 0, max_depth: int = 64, max_dist=None):
    """(ell, standard error, number of segments measured) of exemplar ``k`` (module doc "Mean free path")."""
    if n_paths < 2 or max_depth < 1:
        raise ValueError("mean_free_path: n_paths >= 2 and max_depth >= 1")
    W, H = (float(v) for v in period)
    S = np.zeros(n_paths)
    Nseg = np.zeros(n_paths, np.int64)
    for_chunks(_free_paths, n_paths, periodic_scene(sc, k), float(z_lo), float(z_hi), W, H,
               np.ascontiguousarray(mat_of_fiber, np.int32), np.ascontiguousarray(mats, np.float64), int(seed),
               int(max_depth), _max_dist(max_dist, (W, H)), 1e-7 * max(W, H), S, Nseg)
    total = int(Nseg.sum())
    if total == 0:
        return math.nan, math.nan, 0
    ell = float(S.sum() / total)
    nbar = total / n_paths
    d = S - ell * Nseg
    se = math.sqrt(float((d * d).sum()) / (n_paths * (n_paths - 1))) / nbar
    return ell, se, total


# ------------------------------------------------------------------------------------------------
# reconstruction

@njit(cache=True)
def _reconstruct(a, order, w0, w1, out):
    J = (order + 1) * (order + 1)
    Y0 = np.empty(J)
    Y1 = np.empty(J)
    for i in range(w0.shape[0]):
        sh_eval(order, w0[i, 0], w0[i, 1], w0[i, 2], Y0)
        sh_eval(order, w1[i, 0], w1[i, 1], w1[i, 2], Y1)
        for ch in range(3):
            s = 0.0
            for j0 in range(J):
                t = 0.0
                for j1 in range(J):
                    t += a[ch, j0, j1] * Y1[j1]
                s += Y0[j0] * t
            out[i, ch] = s


def iirtf_reconstruct(a, w0, w1):
    """T(w0, w1) ~= sum a[ch, j0, j1] Y_j0(w0) Y_j1(w1) per channel: ``a`` (3, J, J) one cell's matrices,
    ``w0``, ``w1`` (N, 3) or (3,) unit directions; returns (N, 3) float64."""
    a = np.ascontiguousarray(a, np.float64)
    J = a.shape[-1]
    order = int(round(math.sqrt(J))) - 1
    if a.shape != (3, J, J) or (order + 1) ** 2 != J:
        raise ValueError(f"iirtf_reconstruct: a has shape {a.shape}, expected (3, J, J) with J = (L+1)^2")
    w0 = np.ascontiguousarray(np.atleast_2d(w0), np.float64)
    w1 = np.ascontiguousarray(np.atleast_2d(w1), np.float64)
    if w0.shape != w1.shape or w0.shape[1] != 3:
        raise ValueError("iirtf_reconstruct: w0 and w1 must both be (N, 3)")
    out = np.empty((w0.shape[0], 3))
    _reconstruct(a, order, w0, w1, out)
    return out
