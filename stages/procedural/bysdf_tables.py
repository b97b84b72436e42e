"""Building the BYSDF yarn model's 1D tables (seed 004 §3.4 and the self-shadowing terms of §4.1) from the
procedural yarn model: 2D ray casting in cross-sections. The layout and the render-time lookups are
``stages.core.yarn.implicit_tables`` (``ImplicitTables``); the ply tube is that of
``stages.core.yarn.implicit_plies`` (half axes A_r = e_short + r_f, A_t = e_long + r_f).

Fibre tables (``fibre_table_of``), M of them, each a distinct arrangement of one ply's fibre centres in
the ply frame (``fibre_arrangement``): table m holds the model's regular fibres (model.regular_xy's
positions, loops left out: they are flyaways, not ply surface) of ply (m mod P) of the yarn type's
sample (``model.sample_regular_fibers(tp, type_key)``; with the key of the tables stage,
``stages.procedural.tables.type_key(seed, t)``, these are the fibres realize builds) at the height
z_m = (m / M) alpha / s_i, so the M tables spread over one migration period; without migration
(every height alike) tables m >= P draw their own sample (key hash(type_key, TABLE_STREAM, m // P)).
Sample i of a table is the fibre pattern's angle theta_i = 2 pi i / NA: at z_m a fibre at unit-disc
angle psi = theta + fiber_twist(z_m) lies on the line from the ply centre along (e_short cos psi,
e_long sin psi). A 2D ray along that line, from outside the ply tube towards the centre, meets the
first fibre circle (radius r_f; ``cast_circles``) at the outermost visible fibre j:
  normal angle   the signed angle from the ply tube's normal at the line's boundary point (the ellipse
                 gradient) to the fibre circle's normal at the hit
  phase          (j + 0.5) / N (-1 where the line meets no fibre)
  fibre shadow   ``open_fraction_circles``: of n_rays directions spread evenly (midpoints) over the half
                 circle around the fibre's normal at the hit, the fraction that leave without meeting
                 another fibre circle; remapped s (1 - thr) + thr (reference default thr = 0.5)
Ply shadowing (``ply_shadow_table``): the yarn cross-section at z = 0 with the P plies as their
ellipses (ply k at ply_radius (cos 2 pi k / P, sin 2 pi k / P), axes along d_r, d_t); for NA angles
over one period 2 pi / P from ply 0's angle, a 2D ray from outside the envelope towards the yarn axis
meets the first ply (``cast_ellipses``); at that point, the fraction of the outward half circle (about
the ellipse's normal) that no other ply blocks, remapped with thr (reference default 0.6). All
plies turn together with z, so the angle is measured from ply 0's angle at the query's z.

``build_implicit_tables(tp, type_key, n_tables=4, n_angles=256, n_rays=256, fibre_threshold=0.5,
ply_threshold=0.6, switch_length=None, blend_fraction=0.2)`` -> ``ImplicitTables``. The default switch
length is the migration period over M, alpha / (s_i M), the spacing of the tables' heights: the lookup
then changes arrangement about as often as the model's fibres migrate; blend_length = blend_fraction
switch_length. Everything is deterministic (counter-based random numbers only).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.rng import hash_u64
from stages.core.yarn.implicit_plies import ply_envelope_radius, ply_half_axes
from stages.core.yarn.implicit_tables import FIBRE_FIELDS, FIBRE_NORMAL_ANGLE, FIBRE_PHASE, FIBRE_SHADOW, ImplicitTables
from stages.core.yarn.model import (
    ALPHA,
    E_LONG,
    E_SHORT,
    FIBER_RADIUS,
    PLY_NUM,
    PLY_RADIUS,
    S_MIG,
    TWO_PI,
    USE_FLYAWAYS,
    USE_MIGRATION,
    fiber_twist,
    fiber_unit_radius,
    fibre_counts,
    sample_regular_fibers,
)

TABLE_STREAM = 0x7AB1E   # second hash key of a table's own fibre sample (no migration)
NUDGE = 1e-9             # a hit moves this far (in fibre / ply radii) back along its line before shadow rays start


@njit(cache=True)
def fibre_arrangement(tp, type_key, m, M):
    """(x, y, twist): ply-frame centres (along d_r, d_t) of fibre table m's N fibres and the fibre twist
    at its height (module doc)."""
    P, N = fibre_counts(tp)
    migrate = tp[USE_MIGRATION] != 0.0
    key = np.uint64(type_key)
    if not migrate and m >= P:
        key = hash_u64(type_key, TABLE_STREAM, m // P)
    R, th, th0 = sample_regular_fibers(tp, key)
    k = m % P
    z = m / M * tp[ALPHA] / tp[S_MIG] if migrate else 0.0
    regular = tp.copy()
    regular[USE_FLYAWAYS] = 0.0   # no loops: regular migration only
    twist = fiber_twist(tp, z)
    x = np.empty(N)
    y = np.empty(N)
    for j in range(N):
        U, _ = fiber_unit_radius(regular, 0, k, j, R[k, j], th[k, j], th0[k, j], z)
        psi = th[k, j] + twist
        x[j] = U * math.cos(psi) * tp[E_SHORT]
        y[j] = U * math.sin(psi) * tp[E_LONG]
    return x, y, twist


@njit(cache=True)
def entry_t(A, B, C):
    """Where a 2D ray s + t d (t > 0) enters a conic whose inside is A t^2 + 2 B t + C < 0 (A > 0): the smaller
    root, 0 where s is inside, inf where the ray misses it or it lies behind."""
    disc = B * B - A * C
    if disc < 0.0:
        return math.inf
    sq = math.sqrt(disc)
    t = (-B - sq) / A
    if t <= 0.0:
        if (-B + sq) / A <= 0.0:
            return math.inf
        t = 0.0
    return t


Circles = namedtuple("Circles", ["cx", "cy", "r"])
Circles.__doc__ = """Circles of one radius r about the centres (cx, cy) (arrays): fibres in a ply's cross-section."""
Ellipses = namedtuple("Ellipses", ["cx", "cy", "ca", "sa", "ar", "at"])
Ellipses.__doc__ = """Ellipses about the centres (cx, cy), half axes ar along (ca, sa) and at across (arrays ca, sa):
plies in a yarn's cross-section."""


def conic_coefficients(conics, k, qx, qy, dx, dy):
    """(A, B, C) of ``entry_t`` for conic k and the 2D ray s + t d, q = s - conic k's centre; numba-only (answered
    per class, ``stages.core.dispatch``)."""
    raise TypeError("conic_coefficients is only callable from numba-compiled code")


@overload(conic_coefficients)
def _circle_coefficients(conics, k, qx, qy, dx, dy):
    if is_tuple_class(conics, Circles):
        def impl(conics, k, qx, qy, dx, dy):
            r = conics.r
            return 1.0, qx * dx + qy * dy, qx * qx + qy * qy - r * r
        return impl


@overload(conic_coefficients)
def _ellipse_coefficients(conics, k, qx, qy, dx, dy):
    if is_tuple_class(conics, Ellipses):
        def impl(conics, k, qx, qy, dx, dy):
            ca = conics.ca[k]
            sa = conics.sa[k]
            p0 = (qx * ca + qy * sa) / conics.ar
            q0 = (-qx * sa + qy * ca) / conics.at
            p1 = (dx * ca + dy * sa) / conics.ar
            q1 = (-dx * sa + dy * ca) / conics.at
            return p1 * p1 + q1 * q1, p0 * p1 + q0 * q1, p0 * p0 + q0 * q0 - 1.0
        return impl


@njit(cache=True)
def first_entered(conics, sx, sy, dx, dy, skip):
    """(k, t): the first of the conics (``Circles`` or ``Ellipses``; conic ``skip`` left out) that the 2D ray
    s + t d (t > 0) enters, and t; (-1, inf) where it meets none."""
    best = math.inf
    bk = -1
    for k in range(conics.cx.shape[0]):
        if k == skip:
            continue
        A, B, C = conic_coefficients(conics, k, sx - conics.cx[k], sy - conics.cy[k], dx, dy)
        t = entry_t(A, B, C)
        if t < best:
            best = t
            bk = k
    return bk, best


@njit(cache=True)
def cast_circles(cx, cy, r, sx, sy, dx, dy, skip):
    """(j, t): the first circle (centres cx, cy, radius r; circle ``skip`` left out) that the 2D ray
    s + t d (t > 0, d unit) enters, and t; (-1, inf) where it meets none."""
    return first_entered(Circles(cx, cy, r), sx, sy, dx, dy, skip)


@njit(cache=True)
def half_circle_direction(q, n_rays, nx, ny):
    """Direction q of n_rays spread evenly (midpoints) over the half circle about the unit vector (nx, ny)."""
    beta = -0.5 * math.pi + math.pi * (q + 0.5) / n_rays
    cb = math.cos(beta)
    sb = math.sin(beta)
    return cb * nx - sb * ny, sb * nx + cb * ny


@njit(cache=True)
def open_fraction_circles(cx, cy, r, hx, hy, nx, ny, skip, n_rays):
    """Fraction of n_rays directions over the half circle about (nx, ny) from h that meet no circle
    other than ``skip``."""
    free = 0
    for q in range(n_rays):
        dx, dy = half_circle_direction(q, n_rays, nx, ny)
        j, _ = cast_circles(cx, cy, r, hx, hy, dx, dy, skip)
        if j < 0:
            free += 1
    return free / n_rays


@njit(cache=True)
def fibre_table_of(tp, x, y, twist, NA, n_rays, thr):
    """(NA, FIBRE_FIELDS) fibre table of the arrangement (x, y) (ply frame) whose pattern is turned by
    ``twist`` (module doc); fibre radius, ply ellipse and tube from tp."""
    r = tp[FIBER_RADIUS]
    ar, at = ply_half_axes(tp)
    N = x.shape[0]
    out = np.empty((NA, FIBRE_FIELDS))
    for i in range(NA):
        psi = TWO_PI * i / NA + twist
        ex = tp[E_SHORT] * math.cos(psi)
        ey = tp[E_LONG] * math.sin(psi)
        en = math.sqrt(ex * ex + ey * ey)
        ex, ey = ex / en, ey / en
        tb = 1.0 / math.sqrt((ex / ar) ** 2 + (ey / at) ** 2)   # the ply tube's boundary on the line
        gx = tb * ex / (ar * ar)
        gy = tb * ey / (at * at)
        gn = math.sqrt(gx * gx + gy * gy)
        gx, gy = gx / gn, gy / gn
        ts = tb + 2.0 * r
        j, t = cast_circles(x, y, r, ts * ex, ts * ey, -ex, -ey, -1)
        if j < 0:
            out[i, FIBRE_NORMAL_ANGLE] = 0.0
            out[i, FIBRE_PHASE] = -1.0
            out[i, FIBRE_SHADOW] = 1.0
            continue
        th = ts - t + NUDGE * r     # the hit, nudged back along the line: outside every circle
        hx = th * ex
        hy = th * ey
        fx = (hx - x[j]) / r
        fy = (hy - y[j]) / r
        fn = math.sqrt(fx * fx + fy * fy)
        fx, fy = fx / fn, fy / fn
        out[i, FIBRE_NORMAL_ANGLE] = math.atan2(gx * fy - gy * fx, gx * fx + gy * fy)
        out[i, FIBRE_PHASE] = (j + 0.5) / N
        s = open_fraction_circles(x, y, r, hx, hy, fx, fy, j, n_rays)
        out[i, FIBRE_SHADOW] = s * (1.0 - thr) + thr
    return out


@njit(cache=True)
def cast_ellipses(cx, cy, ca, sa, ar, at, sx, sy, dx, dy, skip):
    """(k, t): the first ellipse (centres cx, cy, axes ar along (ca, sa) and at across; ``skip`` left out)
    that the 2D ray s + t d (t > 0) enters, and t; (-1, inf) where it meets none."""
    return first_entered(Ellipses(cx, cy, ca, sa, ar, at), sx, sy, dx, dy, skip)


@njit(cache=True)
def ply_cross_section(tp):
    """(cx, cy, ca, sa): the P plies' centres and d_r at z = 0."""
    P = int(tp[PLY_NUM])
    cx = np.empty(P)
    cy = np.empty(P)
    ca = np.empty(P)
    sa = np.empty(P)
    for k in range(P):
        a = TWO_PI * k / P
        ca[k] = math.cos(a)
        sa[k] = math.sin(a)
        cx[k] = tp[PLY_RADIUS] * ca[k]
        cy[k] = tp[PLY_RADIUS] * sa[k]
    return cx, cy, ca, sa


@njit(cache=True)
def ply_shadow_table(tp, NA, n_rays, thr):
    """(NA,) ply shadowing over one period 2 pi / P of the angle around the yarn (module doc)."""
    P = int(tp[PLY_NUM])
    cx, cy, ca, sa = ply_cross_section(tp)
    ar, at = ply_half_axes(tp)
    rs = 1.01 * ply_envelope_radius(tp)
    out = np.empty(NA)
    for i in range(NA):
        phi = TWO_PI * i / (NA * P)
        ex = math.cos(phi)
        ey = math.sin(phi)
        k, t = cast_ellipses(cx, cy, ca, sa, ar, at, rs * ex, rs * ey, -ex, -ey, -1)
        if k < 0:
            out[i] = 1.0
            continue
        th = rs - t + NUDGE * min(ar, at)   # nudged back along the line: outside every ply (crevices)
        hx = th * ex
        hy = th * ey
        qa = ((hx - cx[k]) * ca[k] + (hy - cy[k]) * sa[k]) / (ar * ar)
        qb = (-(hx - cx[k]) * sa[k] + (hy - cy[k]) * ca[k]) / (at * at)
        nx = qa * ca[k] - qb * sa[k]
        ny = qa * sa[k] + qb * ca[k]
        nn = math.sqrt(nx * nx + ny * ny)
        nx, ny = nx / nn, ny / nn
        free = 0
        for q in range(n_rays):
            dx, dy = half_circle_direction(q, n_rays, nx, ny)
            kk, _ = cast_ellipses(cx, cy, ca, sa, ar, at, hx, hy, dx, dy, k)
            if kk < 0:
                free += 1
        out[i] = free / n_rays * (1.0 - thr) + thr
    return out


def build_implicit_tables(tp, type_key, n_tables=4, n_angles=256, n_rays=256, fibre_threshold=0.5,
                          ply_threshold=0.6, switch_length=None, blend_fraction=0.2) -> ImplicitTables:
    """The BYSDF tables of yarn type ``tp`` (module doc); type_key: the type's fibre-sample key."""
    tp = np.asarray(tp, np.float64)
    M = int(n_tables)
    NA = int(n_angles)
    fibre = np.empty((M, NA, FIBRE_FIELDS))
    for m in range(M):
        x, y, twist = fibre_arrangement(tp, np.uint64(type_key), m, M)
        fibre[m] = fibre_table_of(tp, x, y, twist, NA, int(n_rays), float(fibre_threshold))
    ply = ply_shadow_table(tp, NA, int(n_rays), float(ply_threshold))
    L = float(switch_length) if switch_length is not None else float(tp[ALPHA] / (tp[S_MIG] * M))
    return ImplicitTables(fibre, ply, M, NA, NA, L, float(blend_fraction) * L, float(fibre_threshold),
                          float(ply_threshold))
