"""The BYSDF yarn model's precomputed 1D tables (seed 004 §3.4 and the self-shadowing of §4.1): layout
and render-time lookups.

Built once per yarn type by ``stages.procedural.bysdf_tables.build_implicit_tables`` from the procedural
yarn model (``stages.core.yarn.model``); read at a ply hit of ``stages.core.yarn.implicit_plies``.

``ImplicitTables`` (a namedtuple usable inside kernels):
  fibre_table      (M, NA, 3) float64: M fibre tables (distinct fibre arrangements of the ply cross-section,
                   migration §3.4), NA samples each over the fibre pattern's angle theta in [0, 2 pi)
                   (sample i at theta = 2 pi i / NA); per sample, at index
                   FIBRE_NORMAL_ANGLE  the signed angle (radians, counter-clockwise from d_r towards d_t)
                                       from the ply boundary's normal to the normal of the outermost fibre
                                       that a line from the boundary towards the ply centre meets
                   FIBRE_PHASE         (j + 0.5) / N for that fibre j of the arrangement's N: a per-fibre key
                                       for random variation; -1 where the line meets no fibre
                   FIBRE_SHADOW        fibre shadowing: the fraction of the outward half circle of 2D
                                       directions at the fibre's hit that no other fibre blocks, remapped
                                       s (1 - thr) + thr (thr = fibre_threshold)
  ply_shadow       (NP,) float64: ply shadowing over one period 2 pi / P of the angle around the yarn
                   measured from ply 0's angle (sample i at 2 pi i / (NP P)): the fraction of the outward
                   half circle at the outermost ply point on that radius (plies as their ellipses, no
                   fibres) that no other ply blocks, remapped with ply_threshold
  n_tables, n_angles, n_ply_angles     M, NA, NP (int)
  switch_length    the z length after which a ply switches (randomly) to another fibre table
  blend_length     the z length over which two tables blend linearly around each switch
  fibre_threshold, ply_threshold       the remap thresholds the tables were built with (recorded)

Lookups:
``fibre_lookup(tables, tp, yarn_key, k, angle_around_ply, z)`` -> (normal_angle, phase, fibre_shadow):
  angle_around_ply is ``PlyHit.ply_angle`` (the unit-disc angle psi of the model); the fibre pattern turns
  with the model's fibre twist, so the table coordinate is u = frac((psi - model.fiber_twist(z)) / 2 pi),
  linearly interpolated (normal angle and shadowing; the phase is a key, taken from the nearer sample).
  Migration: along z the ply's table changes every ``switch_length`` (cycle c = floor((z + o_k) /
  switch_length), o_k = switch_length uniform(yarn_key, k, OFFSET_DIM) staggers the plies' switches) to
  table floor(M uniform(yarn_key, k, c)) (stages.core.rng: counter-based, the same for every query);
  within blend_length / 2 of a switch the two tables blend linearly (weight 1/2 at the switch), so the
  values are continuous in z; the phase comes from the heavier table.
``ply_shadow_lookup(tables, tp, angle_around_yarn, z)``: the ply shadowing at the yarn-space polar angle
  atan2(y, x) of a ply hit, u = frac((angle - model.ply_angle(tp, 0, z)) P / 2 pi), linear.
``fibre_frame(tp, k, z, psi, ply_tangent, ply_normal, normal_angle)`` -> (fibre tangent, fibre normal),
  each a 3-tuple, orthonormal (k, z, psi: the hit's ply, height and ply_angle; ply_tangent, ply_normal:
  PlyHit's, orthonormal):
  normal   the ply normal rotated about the ply tangent by normal_angle (Rodrigues)
  tangent  the direction of the model's outer fibre through the hit: d/dz of
           model.ply_to_yarn(tp, k, z, U e_short cos psi(z), U e_long sin psi(z)) at unit-disc radius
           U = rho_max R_max with psi(z) turning by the fibre twist; in the ply frame that is the helix
           tangent plus (a' - phi' b) d_r + (b' + phi' a) d_t, phi' = sgn_y 2 pi / yarn_alpha the ply
           frame's turn and (a', b') = U psi' (-e_short sin psi, e_long cos psi), psi' = sgn_f 2 pi / alpha
           the fibre twist. Its angle to the ply tangent is the fibres' helix angle about the ply axis
           including the ply frame's own turn, which the fibre twist alone, atan(2 pi r / alpha), leaves
           out: every preset's plies and fibres turn opposite ways, and the tilt at ply hits of random
           rays is a median 2-6 degrees (cotton1 4.5, silk1 2.1, rayon1 6.1) where atan(2 pi r / alpha)
           at r = sqrt(e_short e_long) gives 17-22; then made orthogonal to the normal.
"""
import math
from collections import namedtuple

from numba import njit

from stages.core.rng import uniform

from .model import (
    ALPHA,
    E_LONG,
    E_SHORT,
    FIBER_SGN,
    PLY_NUM,
    R_MAX,
    RHO_MAX,
    TWO_PI,
    YARN_ALPHA,
    YARN_SGN,
    fiber_twist,
    ply_angle,
    ply_frame,
)

ImplicitTables = namedtuple("ImplicitTables", [
    "fibre_table", "ply_shadow", "n_tables", "n_angles", "n_ply_angles", "switch_length", "blend_length",
    "fibre_threshold", "ply_threshold"])

# fields of a fibre-table sample (last axis of ImplicitTables.fibre_table)
FIBRE_NORMAL_ANGLE, FIBRE_PHASE, FIBRE_SHADOW = 0, 1, 2
FIBRE_FIELDS = 3
OFFSET_DIM = 1 << 62    # rng dimension of a ply's switch offset (no switch cycle reaches it)


@njit(cache=True)
def periodic_sample(n, u):
    """(i0, i1, f): the two samples of a periodic table of n samples around u (in units of the period)."""
    x = (u - math.floor(u)) * n
    i0 = int(math.floor(x))
    f = x - i0
    i0 = i0 % n
    return i0, (i0 + 1) % n, f


@njit(cache=True)
def switch_table(tables, yarn_key, k, c):
    """The fibre table of ply k in switch cycle c."""
    M = tables.n_tables
    return min(int(uniform(yarn_key, k, c) * M), M - 1)


@njit(cache=True)
def table_blend(tables, yarn_key, k, z):
    """(m0, m1, w1): ply k's fibre tables at z and the weight of m1 (0 away from a switch)."""
    L = tables.switch_length
    zz = z + L * uniform(yarn_key, k, OFFSET_DIM)
    c = int(math.floor(zz / L))
    t = zz - c * L
    hb = 0.5 * tables.blend_length
    if t < hb:
        return switch_table(tables, yarn_key, k, c - 1), switch_table(tables, yarn_key, k, c), 0.5 + 0.5 * t / hb
    m = switch_table(tables, yarn_key, k, c)
    if t > L - hb:
        return m, switch_table(tables, yarn_key, k, c + 1), 0.5 * (t - (L - hb)) / hb
    return m, m, 0.0


@njit(cache=True)
def fibre_lookup(tables, tp, yarn_key, k, angle_around_ply, z):
    """(normal_angle, phase, fibre_shadow) of ply k at its unit-disc angle psi and height z (module doc)."""
    u = (angle_around_ply - fiber_twist(tp, z)) / TWO_PI
    i0, i1, f = periodic_sample(tables.n_angles, u)
    m0, m1, w1 = table_blend(tables, yarn_key, k, z)
    T = tables.fibre_table
    a0 = (1.0 - f) * T[m0, i0, FIBRE_NORMAL_ANGLE] + f * T[m0, i1, FIBRE_NORMAL_ANGLE]
    a1 = (1.0 - f) * T[m1, i0, FIBRE_NORMAL_ANGLE] + f * T[m1, i1, FIBRE_NORMAL_ANGLE]
    s0 = (1.0 - f) * T[m0, i0, FIBRE_SHADOW] + f * T[m0, i1, FIBRE_SHADOW]
    s1 = (1.0 - f) * T[m1, i0, FIBRE_SHADOW] + f * T[m1, i1, FIBRE_SHADOW]
    mp = m1 if w1 >= 0.5 else m0
    ip = i1 if f >= 0.5 else i0
    return (1.0 - w1) * a0 + w1 * a1, T[mp, ip, FIBRE_PHASE], (1.0 - w1) * s0 + w1 * s1


@njit(cache=True)
def ply_shadow_lookup(tables, tp, angle_around_yarn, z):
    """Ply shadowing at the yarn-space polar angle of a ply hit at height z (module doc)."""
    P = tp[PLY_NUM]
    u = (angle_around_yarn - ply_angle(tp, 0, z)) * P / TWO_PI
    i0, i1, f = periodic_sample(tables.n_ply_angles, u)
    return (1.0 - f) * tables.ply_shadow[i0] + f * tables.ply_shadow[i1]


@njit(cache=True)
def fibre_frame(tp, k, z, psi, ply_tangent, ply_normal, normal_angle):
    """(fibre tangent, fibre normal) at a ply hit (module doc); 3-tuples, orthonormal."""
    tx, ty, tz = ply_tangent[0], ply_tangent[1], ply_tangent[2]
    nx, ny, nz = ply_normal[0], ply_normal[1], ply_normal[2]
    # Rodrigues: the ply normal (orthogonal to the tangent) rotated about the tangent
    c = math.cos(normal_angle)
    s = math.sin(normal_angle)
    bx = ty * nz - tz * ny
    by = tz * nx - tx * nz
    bz = tx * ny - ty * nx
    fnx, fny, fnz = c * nx + s * bx, c * ny + s * by, c * nz + s * bz
    fn = math.sqrt(fnx * fnx + fny * fny + fnz * fnz)
    fnx, fny, fnz = fnx / fn, fny / fn, fnz / fn
    # the model's outer fibre through the hit, d/dz
    cx, cy, drx, dry = ply_frame(tp, k, z)
    wy = tp[YARN_SGN] * TWO_PI / tp[YARN_ALPHA]
    wf = tp[FIBER_SGN] * TWO_PI / tp[ALPHA]
    U = tp[RHO_MAX] * tp[R_MAX]
    a = U * tp[E_SHORT] * math.cos(psi)
    b = U * tp[E_LONG] * math.sin(psi)
    da = -U * tp[E_SHORT] * math.sin(psi) * wf - wy * b
    db = U * tp[E_LONG] * math.cos(psi) * wf + wy * a
    vx = -wy * cy + da * drx - db * dry
    vy = wy * cx + da * dry + db * drx
    vz = 1.0
    dot = vx * fnx + vy * fny + vz * fnz
    vx, vy, vz = vx - dot * fnx, vy - dot * fny, vz - dot * fnz
    vn = math.sqrt(vx * vx + vy * vy + vz * vz)
    return (vx / vn, vy / vn, vz / vn), (fnx, fny, fnz)
