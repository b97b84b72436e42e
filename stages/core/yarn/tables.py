"""The procedural tables' layout (seed 000 §4): ``Tables``, what is stored, what is derived at load.

``Tables`` is a namedtuple of flat arrays usable inside numba kernels. Its *stored* fields
(``STORED_FIELDS``) are built by the tables stage (``stages.procedural.tables``) and written to the
``tables`` artifact: the regular fibres' trajectories and azimuth bins (seed 000 §4.3, Fig. 7), the
per-yarn loop lists in z-bins (§4.4.1) and the hybrid hairs (§4.4.2). Its *derived* fields
(``DERIVED_FIELDS``: frame samples, coarse knots, chord grid, scan bounds, fringe occupancy, chord
gates) are rebuilt whenever tables are loaded (``stages.core.yarn.accel.derive_lookup_accel``) and
never stored.

Besides the layout, this module holds what both the tables build and the lookups
(``stages.core.yarn.lookup``) must compute the same way: the z window and yarn-space limit of a yarn
visit, the fringe cells' bits, a loop's fibre and cycle, the hair quad-tree's node seed, and the
byte counts of seed 000's Table 1.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.rng import hash_u64

from .frame_samples import FRAME_COLS
from .model import ALPHA, FIBER_NUM, S_MIG

Tables = namedtuple("Tables", [
    "tparams",          # (T, NPARAM) float64 packed yarn types (yarn_model indices)
    "type_K",           # (T,) cross-section distance / true distance bound
    "type_mz",          # (T,) yarn-space z margin of hair activity (>= fibre radius / g_min)
    "type_fib_off",     # (T+1,) int64: fibres of type t, ply k, fibre j at type_fib_off[t] + k N + j
    "fib_R", "fib_th", "fib_th0", "fib_rlo", "fib_rhi",   # float64 per fibre
    "type_nbins",       # (T,) int64 azimuth bins B_t
    "type_bin_off",     # (T+1,) int64: bin (t, k, b) at type_bin_off[t] + k B_t + b
    "bin_start",        # (nbins_total+1,) int64 CSR into bin_items
    "bin_items",        # int32 fibre index within the ply
    "yarn_type",        # (Y,) int32
    "yarn_seed",        # (Y,) int64 per-yarn random key
    "yarn_extent",      # (Y,) float64 radius bound of all fibre surfaces around the yarn axis
    "yarn_gmin",        # (Y,) float64 smallest axial stretch 1 - kappa rho of the yarn-space map
    "yarn_albedo",      # (Y, 3) float64
    "yarn_ply_off",     # (Y+1,) int64 slot g = yarn_ply_off[c] + k
    "hair_count",       # (S,) int64 hairs of slot g
    "hair_off",         # (S+1,) int64 hybrid: hair h of slot g at hair_off[g] + h
    "hair_z1", "hair_ze",   # float64 hybrid: pre-generated z extents
    "hair_r0", "hair_r1", "hair_th1", "hair_pe",   # float64 hybrid: pre-generated shape (model.hair_params)
    "hb_zoff",          # (S+1,) int64: breakpoints of slot g at hb_z[hb_zoff[g]:hb_zoff[g+1]]
    "hb_z",             # float64 breakpoints
    "hb_start",         # CSR over bins (bin (g, b) at hb_zoff[g] - g + b), into hb_items
    "hb_items",         # int32 hair index
    "hair_mode",        # (1,) int64: 0 hybrid, 1 realization-free
    "yarn_length",      # (Y,) float64 arc length of each yarn curve (yarn-space z range)
    "max_extent",       # (1,) float64 largest yarn_extent (candidate-yarn search radius)
    "fib_mask",         # (F,) uint64 bit b set when the fibre is listed in azimuth bin b (all set for > 64 bins)
    "lp_off",           # (S+1,) int64: loops (mutated migration cycles) of slot g at lp_off[g]:lp_off[g+1]
    "lp_fib", "lp_U",   # int32 fibre index within the ply, float64 the cycle's U_loop (ascending fibre, cycle)
    "lp_cyc",           # int32 the loop's migration cycle
    "lz_off",           # (S+1,) int64: loop z-bins of slot g are lz_off[g] .. lz_off[g+1]-1
    "lz_h",             # (S,) float64 z-bin width of slot g
    "lz_start",         # CSR over loop z-bins (global bin index), into lz_items
    "lz_items",         # int32 loop index within the slot (ascending)
    "type_pad",         # (T,) float64 slack (beyond the fibre radius) the azimuth bins' margin allows for
    "yarn_kappa",       # (Y,) float64 curvature bound of each yarn curve (x 1.25 margin)
    # ---- derived when loaded (derive_lookup_accel; never stored): frame samples and chord grid
    "fs_at",            # (Y,) int64: frame samples of yarn c at fs_at[c] .. fs_at[c] + fs_n[c] - 1 (frame_samples.py);
                        # -1 while they are not resident (frame_pool.py: a render pages them in as its rays reach c)
    "fs_n",             # (Y,) int64 number of frame samples of yarn c
    "fs_step",          # (Y,) float64 the step yarn c's frame samples are made at (frame_samples.sample_all)
    "fs_s",             # float64 arc length of each resident frame sample
    "fs_frame",         # (M, FRAME_COLS) float64 position, tangent, normal, binormal, step derivatives
    "fs_want",          # (Y,) uint8: set by a lookup that needed yarn c's frame samples while they were not resident
    "fs_miss",          # (1,) int64: lookups that found a needed yarn's frame samples not resident (frame_pool.py)
    "yarn_eps",         # (Y,) float64 bound of |Eq. 7 with sampled frames - Eq. 7| within the extent
    "kn_off",           # (Y+1,) int64: coarse knots of yarn c at kn_off[c]:kn_off[c+1]
    "kn_idx",           # int64 index of each coarse knot among its yarn's frame samples (0 .. fs_n[c] - 1)
    "kn_s",             # float64 arc length of each coarse knot
    "kn_pos",           # (K, 3) float64 position of each coarse knot
    "kn_sag",           # float64 sag bound of the coarse chord starting at each knot
    "fg_lo", "fg_cell", "fg_dims",   # (3,), (1,), (3,) chord grid geometry
    "fg_start",         # (cells+1,) int32 CSR into the runs
    "fg_yarn", "fg_a", "fg_b",       # runs: yarn, coarse chords [a, b) (int32 each)
    "ply_rr",           # (T, max plies, 2) float64 (min r_lo, max r_hi) over the ply's fibres (unit disc)
    "fib_v",            # (F,) float64 transverse speed bound of each fibre outside loop cycles
    "hair_box",         # (H, 4) float32 hybrid: each hair's z range and radius range (zlo, zhi, Rlo, Rhi),
                        # rounded outward
    "lz_rr",            # (loop z-bins, 2) float64 (min r_lo, max U_loop) over each loop z-bin's loops
    "type_rcore",       # (T,) float64 yarn-space radius beyond which no regular (non-loop) fibre is in reach
    "fo_off",           # (Y+1,) int64: fringe z-bins of yarn c at fo_off[c]:fo_off[c+1]
    "fo_geom",          # (Y, 2) float64 fringe z-bin width and shell width of yarn c
    "fo_bits",          # (fringe z-bins, 2 FO_WORDS) uint64 fringe occupancy of loops, then hairs (fringe_occupancy)
    "kn_rgate",         # (coarse knots,) float64 axis distance beyond which a visit near the chord finds nothing
])
DERIVED_FIELDS = ("fs_at", "fs_n", "fs_step", "fs_s", "fs_frame", "fs_want", "fs_miss", "yarn_eps", "kn_off",
                  "kn_idx", "kn_s", "kn_pos", "kn_sag", "fg_lo", "fg_cell",
                  "fg_dims", "fg_start", "fg_yarn", "fg_a", "fg_b", "ply_rr", "fib_v", "hair_box", "lz_rr",
                  "type_rcore", "fo_off", "fo_geom", "fo_bits", "kn_rgate")
STORED_FIELDS = tuple(f for f in Tables._fields if f not in DERIVED_FIELDS)
PAD_FRACTION = 0.05      # type_pad in fibre radii: the bins' slack for the sampled frames' error
FRAME_TOLERANCE = 0.01   # frame-sample error aimed at, in fibre radii (<= PAD_FRACTION / 3 keeps lookups binned)
FO_SECTORS = 32          # fringe occupancy: azimuth sectors around the yarn axis
FO_SHELLS = 8            # fringe occupancy: radial shells (the last one open-ended)
FO_WORDS = FO_SECTORS * FO_SHELLS // 64
FO_ZBIN_EXTENTS = 0.25   # fringe z-bin width in yarn extents


@njit(cache=True)
def hair_node_seed_nb(yarn_seed, k):
    return hash_u64(yarn_seed, k, 31)


def table_bytes(tab: Tables) -> dict:
    """Bytes of the tables by part: regular (fibre trajectories and bins), hair, loop (none)."""
    reg = sum(getattr(tab, n).nbytes for n in ("fib_R", "fib_th", "fib_th0", "fib_rlo", "fib_rhi", "fib_mask",
                                                "bin_start", "bin_items", "tparams", "type_K", "type_mz",
                                                "type_fib_off", "type_nbins", "type_bin_off"))
    hair = sum(getattr(tab, n).nbytes for n in ("hair_count", "hair_off", "hair_z1", "hair_ze", "hb_zoff",
                                                 "hb_z", "hb_start", "hb_items", "hair_r0", "hair_r1", "hair_th1",
                                                 "hair_pe"))
    loop = sum(getattr(tab, n).nbytes for n in ("lp_off", "lp_fib", "lp_U", "lp_cyc", "lz_off", "lz_h", "lz_start",
                                                 "lz_items"))
    yarn = sum(getattr(tab, n).nbytes for n in ("yarn_type", "yarn_seed", "yarn_extent", "yarn_gmin",
                                                 "yarn_albedo", "yarn_ply_off", "yarn_length", "max_extent",
                                                 "yarn_kappa", "hair_mode", "type_pad"))
    return {"regular": int(reg), "hair": int(hair), "loop": int(loop), "per_yarn": int(yarn)}


def accel_bytes(tab: Tables) -> int:
    """Bytes of the structures derived at load time (frame samples, coarse knots, chord grid)."""
    return int(sum(getattr(tab, n).nbytes for n in DERIVED_FIELDS))


def empty_accel(Y):
    z, zi = np.zeros(0), np.zeros(0, np.int64)
    return (np.full(Y, -1, np.int64), np.zeros(Y, np.int64), np.zeros(Y), z, np.zeros((0, FRAME_COLS)),
            np.zeros(Y, np.uint8), np.zeros(1, np.int64), np.zeros(Y), np.zeros(Y + 1, np.int64), zi, z,
            np.zeros((0, 3)), z,
            np.zeros(3), np.ones(1), np.ones(3, np.int64), np.zeros(2, np.int32), np.zeros(0, np.int32),
            np.zeros(0, np.int32), np.zeros(0, np.int32),
            np.zeros((0, 1, 2)), np.zeros(0), np.zeros((0, 4), np.float32), np.zeros((0, 2)), np.zeros(0),
            np.zeros(Y + 1, np.int64), np.ones((Y, 2)), np.zeros((0, 2 * FO_WORDS), np.uint64), np.zeros(0))


@njit(cache=True)
def fibre_row(tab, t, tp, k, j):
    """Row of regular fibre j of ply k in the fibre tables (fib_R, fib_th, ...) of yarn type t, tp its parameters."""
    return tab.type_fib_off[t] + k * int(tp[FIBER_NUM]) + j


@njit(cache=True)
def loop_fibre(tab, tp, c, k, e):
    """Loop e of ply k of yarn c (tp its type's parameters): (j its fibre's index in the ply, fi that
    fibre's row in the type's fibre tables, [z0, z1] the z range of its migration cycle lp_cyc[e],
    clipped to the yarn)."""
    j = tab.lp_fib[e]
    fi = fibre_row(tab, tab.yarn_type[c], tp, k, j)
    w = tp[S_MIG] * 2.0 * math.pi / tp[ALPHA]  # migration phase per unit z
    cyc = tab.lp_cyc[e]
    th0 = tab.fib_th0[fi]
    z0 = max(0.0, (2.0 * math.pi * cyc - math.pi - th0) / w)
    z1 = min(tab.yarn_length[c], (2.0 * math.pi * cyc + math.pi - th0) / w)
    return j, fi, z0, z1


@njit(cache=True, inline="always")
def yarn_space_limit(rf, w, eps, gmin):
    """Yarn-space distance within which a fibre point must lie to cover a point with tangential
    residual w (1.1 (r_f + w + 2 eps_c) / g_min; the lookups' hair and loop limit)."""
    return 1.1 * (rf + w + 2.0 * eps) / gmin


@njit(cache=True, inline="always")
def z_window(K, mz, rf, w, eps, gmin):
    """Half width of a yarn visit's z window: every fibre point within r_f of a point with tangential
    residual w lies within it of the foot point s (|z - s| <= yarn-space distance / g_min)."""
    return (max((1.0 + K) * (rf + w + eps), mz) + w + 2.0 * eps) / gmin


@njit(cache=True, inline="always")
def fringe_reach(rf, eps, gmin):
    """yarn_space_limit at the largest tangential residual a yarn visit goes on with (w < r_f + 2 eps_c)."""
    return yarn_space_limit(rf, rf + 2.0 * eps, eps, gmin)


@njit(cache=True, inline="always")
def fringe_window(K, mz, rf, eps, gmin):
    """z_window at the largest tangential residual a yarn visit goes on with (w < r_f + 2 eps_c)."""
    return z_window(K, mz, rf, rf + 2.0 * eps, eps, gmin)


@njit(cache=True, inline="always")
def fringe_bits(tab, c, s, x, y, rho):
    """(loop bit, hair bit) of the fringe cell of yarn-space point (x, y, s) in yarn c."""
    base = tab.fo_off[c]
    nb = tab.fo_off[c + 1] - base
    zb = min(max(int(s / tab.fo_geom[c, 0]), 0), nb - 1)
    sh = min(int(rho / tab.fo_geom[c, 1]), FO_SHELLS - 1)
    q = min(int((math.atan2(y, x) + math.pi) * (FO_SECTORS / (2.0 * math.pi))), FO_SECTORS - 1)
    idx = sh * FO_SECTORS + q
    w = idx >> 6
    b = np.uint64(idx & 63)
    one = np.uint64(1)
    return ((tab.fo_bits[base + zb, w] >> b) & one) != 0, ((tab.fo_bits[base + zb, FO_WORDS + w] >> b) & one) != 0
