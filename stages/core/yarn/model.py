"""The procedural yarn model of seed 000 §3.2 (after Zhao, Luan, Bala 2016), in yarn space.

Yarn space: the yarn axis is z (arc length of the yarn curve), the cross-section is (x, y);
seed 000 Eq. 7 maps it to fabric space with the rotation-minimising frame (x along n, y along b).

Parameters of one yarn type are packed in a float64 vector ``tp`` (indices below, names as in
``data/yarns/*.toml``; lengths already scaled to the target yarn radius, see pipeline/presets.py):

  plies      P plies; ply k's centre sits at radius ``ply_radius`` (= yarn_radius / 2; 0 for P = 1)
             at angle 2 pi k / P + sgn_y 2 pi z / yarn_alpha (sgn = -1 when *_clock_wise = 1)
  ply frame  d_r (yarn axis -> ply centre) and d_t (across); the ply cross-section is an ellipse
             with half axes ``e_short`` along d_r and ``e_long`` along d_t (footnote 1: compression)
  fibres     N per ply; fibre j has R_j from p(R) = (1-2 eps)((e - e^R)/(e - 1))^beta + eps by
             rejection (R = sqrt(u) R_max, Eq. 3), theta_j and theta0_j uniform in [0, 2 pi)
  position   unit-disc offset R(z) (cos psi, sin psi), psi = theta_j + sgn_f 2 pi z / alpha (Eq. 1),
             scaled by (e_short, e_long) in the ply frame and added to the ply centre
  migration  R(z) = R_j [rho_min + (rho_max - rho_min)/2 (cos(s 2 pi z / alpha + theta0_j) + 1)] (Eq. 2)
  loops      migration cycle c of a fibre spans phase s 2 pi z / alpha + theta0_j in [2 pi c - pi,
             2 pi c + pi); it is mutated with probability p = loop_density alpha / (N s) (so a ply gets
             loop_density per unit length on average, §4.4.1) when r1 ~ N(mu, sigma/2) exceeds 1.05
             times the fibre's distance from the ply centre at the cycle's maximum; the mutated cycle
             follows R(z) = rho_min R_j + (U_loop - rho_min R_j) w(z), w = (cos(phase) + 1)/2, with
             U_loop = rho_max R_j r1 / (that distance): continuous at the cycle ends (where R =
             rho_min R_j) and reaching the absolute distance r1 at the maximum.
  hairs      per ply round(hair_density L); hair h: (z1, ze) from the quad-tree of hair_free.py,
             r0, re, pe ~ N(mu, 0.75 sigma), theta1 uniform; Eq. 4 in the ply frame:
             R(t) = r0 + re t, theta(t) = theta1 + pe t, z(t) = z1 + ze t for t in [0, 1]
             (absolute lengths around the ply centre; r0 and r0 + re clamped at 0).
Every normal variate is clamped to +-3 standard deviations so that the model has hard bounds
(tables rely on them). All random numbers are counter-based (stages/core/rng.py): per type and
(ply, fibre) for the regular fibres, per (yarn, ply, fibre, cycle) for loops, per (yarn, ply,
hair) for hairs, so realization and lookups see the same fabric.
"""
import math

import numpy as np
from numba import njit

from stages.core.rng import hash_u64, normal, uniform

# indices into the packed parameter vector
PLY_NUM, FIBER_NUM, PLY_RADIUS, YARN_ALPHA, YARN_SGN, ALPHA, FIBER_SGN, E_LONG, E_SHORT = 0, 1, 2, 3, 4, 5, 6, 7, 8
EPSILON, BETA, R_MAX, RHO_MIN, RHO_MAX, S_MIG = 9, 10, 11, 12, 13, 14
HAIR_DENSITY, LOOP_DENSITY = 15, 16
ZE_MU, ZE_SIG, R0_MU, R0_SIG, RE_MU, RE_SIG, PE_MU, PE_SIG, R1_MU, R1_SIG = 17, 18, 19, 20, 21, 22, 23, 24, 25, 26
FIBER_RADIUS, ALB_R, ALB_G, ALB_B, DENSITY, ROUGHNESS = 27, 28, 29, 30, 31, 32
P_LOOP, USE_MIGRATION, USE_FLYAWAYS, YARN_RADIUS, U_MAX, HAIR_RMAX, SEED = 33, 34, 35, 36, 37, 38, 39
NPARAM = 40

# random-number streams (third hash key)
STREAM_FIBER, STREAM_LOOP, STREAM_HAIR, STREAM_TREE = 1, 2, 3, 4
TWO_PI = 2.0 * math.pi
CLAMP = 3.0


@njit(cache=True)
def clamped_normal(seed, index, dim):
    v = normal(seed, index, dim)
    return min(CLAMP, max(-CLAMP, v))


@njit(cache=True)
def key3(a, b, c):
    return hash_u64(a, b, c)


@njit(cache=True)
def cross_section_density(tp, R):
    """Eq. 3, unnormalised."""
    e = math.e
    eps = tp[EPSILON]
    base = (e - math.exp(R / tp[R_MAX])) / (e - 1.0)
    return (1.0 - 2.0 * eps) * max(base, 0.0) ** tp[BETA] + eps


@njit(cache=True)
def fibre_counts(tp):
    """(P, N): the plies of a yarn of type tp and the regular fibres of each ply."""
    return int(tp[PLY_NUM]), int(tp[FIBER_NUM])


@njit(cache=True)
def sample_regular_fibers(tp, type_key):
    """(R, theta, theta0) arrays of shape (P, N): rejection sampling of Eq. 3, uniform angles."""
    P, N = fibre_counts(tp)
    R = np.empty((P, N))
    th = np.empty((P, N))
    th0 = np.empty((P, N))
    pmax = max(cross_section_density(tp, 0.0), cross_section_density(tp, tp[R_MAX]))
    for k in range(P):
        for j in range(N):
            idx = key3(type_key, k, j)
            trial = 0
            while True:
                r = math.sqrt(uniform(idx, trial, 0)) * tp[R_MAX]
                if uniform(idx, trial, 1) * pmax <= cross_section_density(tp, r) or trial > 10000:
                    break
                trial += 1
            R[k, j] = r
            th[k, j] = TWO_PI * uniform(idx, 0, 2)
            th0[k, j] = TWO_PI * uniform(idx, 0, 3)
    return R, th, th0


@njit(cache=True)
def ply_angle(tp, k, z):
    P = tp[PLY_NUM]
    return TWO_PI * k / P + tp[YARN_SGN] * TWO_PI * z / tp[YARN_ALPHA]


@njit(cache=True)
def ply_frame(tp, k, z):
    """(cx, cy, drx, dry): ply centre and the unit radial direction d_r (d_t = (-dry, drx))."""
    a = ply_angle(tp, k, z)
    ca = math.cos(a)
    sa = math.sin(a)
    rp = tp[PLY_RADIUS]
    return rp * ca, rp * sa, ca, sa


@njit(cache=True)
def fiber_twist(tp, z):
    return tp[FIBER_SGN] * TWO_PI * z / tp[ALPHA]


@njit(cache=True)
def migration_phase(tp, theta0, z):
    return tp[S_MIG] * TWO_PI * z / tp[ALPHA] + theta0


@njit(cache=True)
def cycle_of(phase):
    return int(math.floor((phase + math.pi) / TWO_PI))


@njit(cache=True)
def loop_unit_radius(tp, yarn_seed, k, j, Rj, th, th0, c):
    """U_loop of migration cycle c of fibre (k, j) in a yarn, or -1 where the cycle is not mutated."""
    if tp[USE_FLYAWAYS] == 0.0 or tp[P_LOOP] <= 0.0 or tp[USE_MIGRATION] == 0.0:
        return -1.0
    idx = key3(yarn_seed, k * 1000003 + j, c + (1 << 30))
    if uniform(idx, STREAM_LOOP, 0) >= tp[P_LOOP]:
        return -1.0
    r1 = tp[R1_MU] + tp[R1_SIG] * clamped_normal(idx, STREAM_LOOP, 1)
    zmax = (TWO_PI * c - th0) * tp[ALPHA] / (tp[S_MIG] * TWO_PI)
    psi = th + fiber_twist(tp, zmax)
    Rm = tp[RHO_MAX] * Rj
    u = Rm * math.cos(psi) * tp[E_SHORT]
    v = Rm * math.sin(psi) * tp[E_LONG]
    dist = math.sqrt(u * u + v * v)
    if r1 <= 1.05 * dist or dist <= 0.0:
        return -1.0
    return Rm * r1 / dist


@njit(cache=True)
def fiber_unit_radius(tp, yarn_seed, k, j, Rj, th, th0, z):
    """(R(z) on the unit disc, kind): kind 1 regular, 2 inside a mutated (loop) cycle."""
    if tp[USE_MIGRATION] == 0.0:
        return Rj, 1
    ph = migration_phase(tp, th0, z)
    w = 0.5 * (math.cos(ph) + 1.0)
    lo = tp[RHO_MIN] * Rj
    c = cycle_of(ph)
    U = loop_unit_radius(tp, yarn_seed, k, j, Rj, th, th0, c)
    if U > 0.0:
        return lo + (U - lo) * w, 2
    return lo + (tp[RHO_MAX] - tp[RHO_MIN]) * Rj * w, 1


@njit(cache=True)
def ply_to_yarn(tp, k, z, a, b):
    """Yarn-space (x, y) of the ply-frame offset (a along d_r, b along d_t) of ply k at z."""
    cx, cy, drx, dry = ply_frame(tp, k, z)
    return cx + a * drx - b * dry, cy + a * dry + b * drx


@njit(cache=True)
def regular_xy(tp, yarn_seed, k, j, Rj, th, th0, z):
    """Yarn-space (x, y, kind) of regular fibre (k, j) at z (loops included)."""
    U, kind = fiber_unit_radius(tp, yarn_seed, k, j, Rj, th, th0, z)
    psi = th + fiber_twist(tp, z)
    a = U * math.cos(psi) * tp[E_SHORT]
    b = U * math.sin(psi) * tp[E_LONG]
    x, y = ply_to_yarn(tp, k, z, a, b)
    return x, y, kind


@njit(cache=True)
def hair_params(tp, yarn_seed, k, h):
    """(r0, r1, theta1, pe) of hair h of ply k: start and end radius, start azimuth, azimuth extent."""
    idx = key3(yarn_seed, k, h)
    r0 = tp[R0_MU] + tp[R0_SIG] * clamped_normal(idx, STREAM_HAIR, 0)
    re = tp[RE_MU] + tp[RE_SIG] * clamped_normal(idx, STREAM_HAIR, 2)
    pe = tp[PE_MU] + tp[PE_SIG] * clamped_normal(idx, STREAM_HAIR, 4)
    th1 = TWO_PI * uniform(idx, STREAM_HAIR, 6)
    return max(r0, 0.0), max(r0 + re, 0.0), th1, pe


@njit(cache=True)
def hair_point(tp, k, r0, r1, th1, pe, z1, ze, t):
    """Yarn-space (x, y, z) of a hair at t in [0, 1] (Eq. 4 in the ply frame)."""
    z = z1 + ze * t
    R = r0 + (r1 - r0) * t
    a = R * math.cos(th1 + pe * t)
    b = R * math.sin(th1 + pe * t)
    x, y = ply_to_yarn(tp, k, z, a, b)
    return x, y, z


def loop_bound(tp) -> float:
    """Largest unit-disc radius a fibre can reach (loops included): U_loop <= r1_max / e_short."""
    r1max = tp[R1_MU] + CLAMP * tp[R1_SIG]
    ub = tp[RHO_MAX] * tp[R_MAX]
    if tp[USE_FLYAWAYS] and tp[P_LOOP] > 0 and tp[USE_MIGRATION]:
        ub = max(ub, r1max / tp[E_SHORT])
    return float(ub)


def hair_radius_bound(tp) -> float:
    """Largest distance of a hair point from its ply centre."""
    r0 = max(tp[R0_MU] + CLAMP * tp[R0_SIG], 0.0)
    re = tp[RE_MU] + CLAMP * tp[RE_SIG]
    return float(max(r0, r0 + re, 0.0))


@njit(cache=True)
def transverse_speed(tp, u_hi, u_lo):
    """Upper bound of |d(x, y)/dz| in yarn space of a fibre whose unit-disc radius stays in
    [u_lo, u_hi]: the ply centre's turn, the offset's turn (ply and fibre twist) and migration."""
    w_y = 2.0 * math.pi / tp[YARN_ALPHA]
    w_f = 2.0 * math.pi / tp[ALPHA]
    e = max(tp[E_SHORT], tp[E_LONG])
    mig = 0.5 * (u_hi - u_lo) * tp[S_MIG] * w_f * e if tp[USE_MIGRATION] != 0.0 else 0.0
    return w_y * tp[PLY_RADIUS] + (w_y + w_f) * u_hi * e + mig


@njit(cache=True)
def reach_factor(v, gmin):
    """K: a fibre point within fabric distance D of p lies within K D of p in the cross-section at
    p's foot point s. Eq. 7 with rotation-minimising frames has the yarn-space metric
    dx^2 + dy^2 + g^2 dz^2 (g = 1 - kappa . (x, y) >= g_min), so a path of length D moves the
    cross-section by a and z by b with a^2 + g_min^2 b^2 <= D^2; the fibre moves by at most v b
    across the cross-section (v its transverse speed), so d <= a + v b <= sqrt(1 + v^2 / g_min^2) D
    (Cauchy-Schwarz). 5 % margin for the curvature estimate."""
    q = v / gmin
    return 1.05 * math.sqrt(1.0 + q * q)


@njit(cache=True)
def transverse_speed_bound(tp):
    """Upper bound of |d(x, y)/dz| of any regular or loop fibre in yarn space."""
    return transverse_speed(tp, tp[U_MAX], 0.0)


@njit(cache=True)
def hair_speed_bound(tp, r0, r1, pe, ze):
    """Upper bound of the yarn-space speed |d(x, y, z)/dt| of a hair (Eq. 4 in the rotating ply frame)."""
    rm = max(r0, r1) + tp[PLY_RADIUS]
    return abs(ze) * (1.0 + rm * TWO_PI / tp[YARN_ALPHA]) + abs(r1 - r0) + max(r0, r1) * abs(pe)


def extent_bound(tp) -> float:
    """Largest distance from the yarn axis any fibre surface reaches."""
    core = tp[PLY_RADIUS] + tp[U_MAX] * tp[E_LONG]
    hair = tp[PLY_RADIUS] + tp[HAIR_RMAX] if tp[USE_FLYAWAYS] else 0.0
    return float(max(core, hair) + tp[FIBER_RADIUS])
