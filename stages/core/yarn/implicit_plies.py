"""Implicit plies of the BYSDF yarn model (seed 004 §3.3): which ply a ray inside a yarn tube meets first.

Yarn space as in ``stages.core.yarn.model``: the yarn axis is z (absolute arc length, the ply and
fibre phases use it), x along the curve's rotation-minimising normal, y along the binormal; the
yarn is taken as locally straight (the caller maps a world ray into yarn space with the frame at its
hit on the yarn tube).

The plies are the plies of the procedural model, so that they coincide with the fibres that
``loomlight realize`` builds for the same yarn type ``tp``:

  ply k      centre C_k(z) = ply_radius (cos phi_k, sin phi_k, 0) + (0, 0, z), phi_k = model.ply_angle
             (2 pi k / P + sgn_y 2 pi z / yarn_alpha); ply frame d_r = (cos phi_k, sin phi_k), d_t = z x d_r
  ply tube   the points whose offset (a, b) = ((x, y) - C_k) . (d_r, d_t) in the plane of constant z
             lies in the ellipse  (a / A_r)^2 + (b / A_t)^2 <= 1  with half axes A_r = e_short + r_f,
             A_t = e_long + r_f: the model ellipse the fibre centres fill (unit-disc radius <= rho_max
             R_max = 1) grown by the fibre radius r_f. It is the hull of the fibre surfaces up to the
             offset-curve slack of an ellipse (an ellipse grown by r along its axes lies inside the
             ellipse offset by r; the gap is below 2 % of r_f for the presets). Loops and hairs are
             flyaways, not ply surface.
  membership G_k(x, y, z) = (a / A_r)^2 + (b / A_t)^2 - 1 (negative inside), exact at every z: the tube
             is a twisted elliptic cylinder (the ellipse turns with the ply around the yarn axis).

``ply_envelope_radius(tp)`` = ply_radius + max(e_short, e_long) + r_f: a tube that holds every ply
(the yarn tube the caller's BVH intersects first). It is not tight; ``ply_reach_radius(tp)`` is the
exact largest distance of a ply point from the axis, max over t of |(ply_radius + A_r cos t, A_t sin t)|
(ply_radius + A_r unless A_t^2 - A_r^2 > ply_radius A_r; cotton1: 0.0216 against 0.0246 at radius 0.02).

``ply_hit(tp, o, d, u_max, tol, max_iter)`` -> ``PlyHit`` for the ray o + u d, u in [0, u_max] (o the
entry on the envelope, u_max its exit, finite; o and d length-3 arrays or tuples, d nonzero, not
necessarily unit). Only the part [u_lo, u_hi] of the chord within ply_reach_radius of the axis can
meet a ply. For each ply k:

1. The paper's iteration on the ray's elliptical cross-section (§3.3, Fig. 4). The ellipse plane
   contains the ray and w = normalize(z x d); its unit normal is n = d x w = (-d_z d_xy / |d_xy|,
   |d_xy|) (d unit). Starting from the circular cross-section at the entry (z_0 = o_z), take the ply
   centre there, C_k(z_i), and move along the yarn axis to where that centre meets the plane:
   z_{i+1} = z_i - h(z_i) / n_z with h(z) = n . (C_k(z) - o). That step is Newton's step on h with the
   helix's own motion left out; the paper calls its method Newtonian, and the full Newton step
   z_i - h / h' (h' = n_z + n_xy . C_k'(z)) converges quadratically where the plain step converges
   only linearly (rate q = |cot(ray, axis)| ply_radius 2 pi / yarn_alpha: it diverges for q > 1, rays
   within about 15 degrees of the axis for the presets), so the full step is taken wherever h' > 0, the
   paper's step elsewhere; a step that leaves the bracket of a crossing (a z with h < 0 below one with
   h > 0; initially o_z -+ |d_z| (ply_radius + |o_xy|) / |d_xy|, d unit) is replaced by the bracket's
   midpoint (safeguarded Newton). Stop when the centre moves less than ``tol`` ply radii (the smaller
   half axis A_min = min(A_r, A_t)) or after ``max_iter`` steps (3-10). Where q < 1 the helix crosses
   the plane once and the iteration converges (3-4 steps for most rays); nearer the axis it crosses it
   several times or the steps wander. A ray along the axis (|d_xy| < 1e-9 |d|) has no ellipse plane: the
   circular section at the entry is kept (0 steps).
2. The ray meets the ply tube near that centre: the straight elliptic cylinder along the helix
   tangent C_k'(z*) through C_k(z*) whose constant-z section is the model ellipse at z* (a quadratic
   in u), then up to 8 Newton steps on the exact G_k(o + u d) make the entry exact (the cylinder
   leaves out the ellipse's turn with z). Chosen over the cylinder alone because the ply tube is
   twisted: on uniformly random rays the cylinder's entry is off by a median 3-4 % of A_min and by
   14-22 % at the 90th percentile (cotton1, polyester1).
3. Certification. The helix's crossing of the ellipse plane is not always next to the first entry:
   near the axis the ply can reach the ray before its helix crosses the plane, and a ray can cross a ply
   twice; the iteration plus cylinder picks the wrong entry on about 3 % of uniformly random rays and on
   most rays within 10 degrees of the axis. So a march along [u_lo, u_hi] proves that no entry comes
   first: with K a bound of |G_k''| along the chord (below), G(a + h) >= G(a) + G'(a) h - K h^2 / 2,
   which stays above -GRAZE for h < h* = (G' + sqrt(G'^2 + 2 K (G + GRAZE))) / K, so the march steps by
   h* and never passes an entry deeper than GRAZE (1e-6 in G, about 5e-7 ply radii: shallower clips
   count as misses, which keeps the march from crawling along a ray that touches a ply tangentially).
   It stops in the certified neighbourhood (u_c - 2 |G'(u_c)| / K, u_c) of the iteration's entry u_c
   (G > 0 there), at u_hi (no entry), or converges quadratically on an earlier entry, which is then
   made exact by Newton (or, for a ray running along the surface within GRAZE, by bisection from the
   march's last point outside) and replaces u_c (``corrections`` counts such plies). After 256 steps
   (a ray crawling along a ply tangentially) the iteration's answer stands.
   K: in the ply's co-rotating frame q(u) = R(-phi_k) (x, y), |q'| <= V1 = |d_xy| + w Rp and
   |q''| <= V2 = w^2 Rp + 2 w |d_xy| with w = 2 pi |d_z| / yarn_alpha and Rp the larger distance of
   the chord's ends (u_lo, u_hi) from the axis, so |G''| <= K = 2 (V1^2 + (Rp + ply_radius) V2) / A_min^2.
   Result: the first entry, exact to 1e-10 ply radii along the ray where the ray crosses the surface
   at an angle; the brute-force march of the tests agrees on every ray but those grazing a ply within
   1e-5 ply radii.

The nearest ply entry wins. Every ply's own entry (steps 1-2) is found first; an entry they find is a
true one (G = 0, G' < 0), so only its being first is left to the march, and the march of every other
ply stops once it has passed the earliest entry known (that ply cannot come first). A ply whose
iteration found no entry is marched over the whole chord when ``plies_crossed`` is asked for
(``count=True``, the default), and only up to the earliest entry otherwise.

Queries for a renderer (same answers as ``ply_hit``, less work):
  ``ply_hit(..., count=False)``  the first hit without ``plies_crossed`` (-1): the shading point
  ``plies_crossed(tp, o, d, u_max, tol, max_iter)``  the count alone (Beer-Lambert along a chord); a ply
             with an entry of its own needs no march
  ``ply_blocks(tp, o, d, u_max, tol, max_iter)``  whether any ply is entered (shadow rays): the first
             entry found settles it; the march runs only where no iteration found one
  On 20,000 random rays of four presets all three agree with ``ply_hit`` bit for bit (tests).

Search (the last argument of the three queries and of ``ply_hit``): ``SEARCH_ITERATION`` (the paper's
iteration, steps 1-3, the default here) or ``SEARCH_MARCH`` (step 3 alone: every ply marched from
u_lo with no target, stopping at its first entry or at the earliest entry of a ply marched before it).
The march is what makes either search exact, and on its own it is cheaper: 5.4 steps per ply on
uniformly random rays (cotton1) to its first entry or the chord's end, against the iteration's 3-5
ellipse-plane steps plus 3-4 Newton steps before its (shorter) march; 0.78 against 1.44 us per first
hit on one core, and the march alone marches the plies nearest first (by G at u_lo, which it reuses), so
the first entry found cuts the others short (12.4 -> 8.9 membership evaluations per first hit): 0.66 us.
bysdf renders the demo 1.2x faster with it in ``near`` mode, 1.7x in ``far``, 1.8x in ``multiscale``
(0.5-0.7 % of the pixels differ from the iteration's images, the means by 1e-6). Both find the same
entries (within 1e-15 on 10,000 random rays); they can differ on a ray that starts on a ply's
surface within rounding of G = 0 (the own ply counted or not). ``bysdf`` uses the march unless
``--set ply_search=iteration``.

``PlyHit`` fields:
  hit            False: the ray passes through the yarn between the plies
  ply            the ply k hit (-1 without hit)
  u              ray parameter of the hit (u_max without hit)
  point          (x, y, z) of the hit (the exit o + u_max d without hit)
  tangent        the ply's tangent, the normalised helix derivative C_k'(z) = (-ply_radius phi' sin phi_k,
                 ply_radius phi' cos phi_k, 1), phi' = sgn_y 2 pi / yarn_alpha
  normal         the outward normal of the ply's cross-section ellipse at the hit (the gradient
                 (a / A_r^2, b / A_t^2) in the ply frame, which for a circle is the direction away from
                 the ply centre, as in the paper), orthogonalised against the tangent and normalised
  ply_angle      the hit's angle around the ply in the model's unit disc, atan2(b / e_long, a / e_short):
                 a fibre at unit-disc angle psi sits on the line from the ply centre through the hit, so
                 ply_angle - model.fiber_twist(z) is the fibre pattern's angle theta the fibre tables
                 (implicit_tables.fibre_lookup) are indexed by
  plies_crossed  how many plies the ray enters on [0, u_max] (each counted once)
  iterations     ellipse-plane steps of the hit ply (the largest over the plies without hit; 0 with
                 SEARCH_MARCH)
  converged      every ply's iteration met ``tol`` within ``max_iter`` (True with SEARCH_MARCH)
  corrections    plies whose first entry the certification moved (or found where the cylinder missed)
                 (diagnostic: how often the paper's iteration alone would have been wrong; a ply
                 whose march stopped at another ply's earlier entry is not looked at)
Degenerate rays (along the axis, grazing a ply, tangent to the envelope) return finite values.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from stages.core.geometry.stack import stack_array

from .model import E_LONG, E_SHORT, FIBER_RADIUS, PLY_NUM, PLY_RADIUS, TWO_PI, YARN_ALPHA, YARN_SGN, ply_frame

PlyHit = namedtuple("PlyHit", ["hit", "ply", "u", "point", "tangent", "normal", "ply_angle", "plies_crossed",
                               "iterations", "converged", "corrections"])

AXIAL_EPS = 1e-9       # |d_xy| / |d| below which a ray runs along the axis (no ellipse plane)
NEWTON_STEPS = 8       # exact refinement of the cylinder's entry
MARCH_STEPS = 256      # certified march (module doc, step 3)
GRAZE = 1e-6           # clips shallower than this (in G; about half of it in ply radii) count as misses
HIT_EPS = 1e-10        # entries are exact to HIT_EPS ply radii along the ray
PLY_MAX = 16           # plies a yarn type may have (per-ply scratch on the machine stack; bysdf refuses more)
SEARCH_ITERATION, SEARCH_MARCH = 0, 1   # how the queries find entries (module doc, "Search")
SEARCHES = ("iteration", "march")


@njit(cache=True)
def ply_half_axes(tp):
    """(A_r, A_t): the ply tube's half axes along d_r and d_t (model ellipse grown by the fibre radius)."""
    return tp[E_SHORT] + tp[FIBER_RADIUS], tp[E_LONG] + tp[FIBER_RADIUS]


@njit(cache=True)
def ply_envelope_radius(tp):
    """Radius of the tube around the yarn axis that holds every ply."""
    return tp[PLY_RADIUS] + max(tp[E_SHORT], tp[E_LONG]) + tp[FIBER_RADIUS]


@njit(cache=True)
def ply_reach_radius(tp):
    """Largest distance of a ply tube point from the yarn axis: max over t of
    |(ply_radius + A_r cos t, A_t sin t)|, at t = 0 unless A_t^2 - A_r^2 > ply_radius A_r."""
    ar, at = ply_half_axes(tp)
    rp = tp[PLY_RADIUS]
    q = at * at - ar * ar
    if q <= rp * ar:
        return rp + ar
    c = rp * ar / q
    return math.sqrt((rp + ar * c) ** 2 + at * at * (1.0 - c * c))


@njit(cache=True)
def ply_centre(tp, k, z):
    """(cx, cy, dcx, dcy, cos phi_k, sin phi_k): ply k's centre at z, its z-derivative and the ply frame."""
    cx, cy, ca, sa = ply_frame(tp, k, z)
    rp = tp[PLY_RADIUS]
    w = tp[YARN_SGN] * TWO_PI / tp[YARN_ALPHA]
    return cx, cy, -rp * w * sa, rp * w * ca, ca, sa


@njit(cache=True)
def ray_membership(tp, k, ox, oy, oz, dx, dy, dz, u):
    """(G, dG/du, a, b) of ply k at the ray point o + u d: module doc, membership; (a, b) ply-frame offset."""
    ar, at = ply_half_axes(tp)
    x = ox + u * dx
    y = oy + u * dy
    _, _, c, s = ply_frame(tp, k, oz + u * dz)
    a = x * c + y * s - tp[PLY_RADIUS]
    b = -x * s + y * c
    wd = tp[YARN_SGN] * TWO_PI / tp[YARN_ALPHA] * dz
    da = dx * c + dy * s + wd * b
    db = -dx * s + dy * c - wd * (a + tp[PLY_RADIUS])
    G = (a / ar) ** 2 + (b / at) ** 2 - 1.0
    dG = 2.0 * (a * da / (ar * ar) + b * db / (at * at))
    return G, dG, a, b


@njit(cache=True)
def ellipse_plane_centre(tp, k, ox, oy, oz, dx, dy, dz, tol, max_iter):
    """(z*, iterations, converged): where ply k's centre helix meets the ray's ellipse plane (step 1)."""
    ar, at = ply_half_axes(tp)
    dn = math.sqrt(dx * dx + dy * dy + dz * dz)
    ux, uy, uz = dx / dn, dy / dn, dz / dn
    dxy = math.sqrt(ux * ux + uy * uy)
    if dxy < AXIAL_EPS:
        return oz, 0, True
    nx = -uz * ux / dxy
    ny = -uz * uy / dxy
    nz = dxy
    # bracket: |n_xy . (C_xy - o_xy)| <= |u_z| (ply_radius + |o_xy|), so h < 0 below oz - D and h > 0 above oz + D
    D = 1.001 * abs(uz) * (tp[PLY_RADIUS] + math.sqrt(ox * ox + oy * oy)) / nz + 1e-300
    lo = oz - D
    hi = oz + D
    z = oz
    cx, cy, dcx, dcy, _, _ = ply_centre(tp, k, z)
    lim = tol * min(ar, at)
    for it in range(max_iter):
        h = nx * (cx - ox) + ny * (cy - oy) + nz * (z - oz)
        if h < 0.0:
            lo = z
        elif h > 0.0:
            hi = z
        dh = nz + nx * dcx + ny * dcy
        if dh > 0.0:
            zn = z - h / dh          # Newton on the helix-plane crossing
        else:
            zn = z - h / nz          # the paper's step: move the centre along the axis onto the plane
        if not (lo < zn < hi):
            zn = 0.5 * (lo + hi)     # kept inside the bracket, which always holds a crossing
        cxn, cyn, dcx, dcy, _, _ = ply_centre(tp, k, zn)
        move = math.sqrt((cxn - cx) ** 2 + (cyn - cy) ** 2 + (zn - z) ** 2)
        z, cx, cy = zn, cxn, cyn
        if move < lim:
            return z, it + 1, True
    return z, max_iter, False


@njit(cache=True)
def local_tube_entry(tp, k, ox, oy, oz, dx, dy, dz, zs, u_max):
    """Entry u of the ray into the straight elliptic cylinder along ply k's helix tangent at z* (step 2),
    clamped to [0, u_max]; -1 where it misses on [0, u_max]."""
    ar, at = ply_half_axes(tp)
    cx, cy, tx, ty, c, s = ply_centre(tp, k, zs)
    q0x = ox - cx - (oz - zs) * tx
    q0y = oy - cy - (oz - zs) * ty
    q1x = dx - dz * tx
    q1y = dy - dz * ty
    a0 = (q0x * c + q0y * s) / ar
    b0 = (-q0x * s + q0y * c) / at
    a1 = (q1x * c + q1y * s) / ar
    b1 = (-q1x * s + q1y * c) / at
    A = a1 * a1 + b1 * b1
    B = a0 * a1 + b0 * b1
    C = a0 * a0 + b0 * b0 - 1.0
    if A < 1e-300:
        return 0.0 if C <= 0.0 else -1.0
    disc = B * B - A * C
    if disc < 0.0:
        return -1.0
    sq = math.sqrt(disc)
    ue = (-B - sq) / A
    ux = (-B + sq) / A
    if ux < 0.0 or ue > u_max:
        return -1.0
    return max(ue, 0.0)


@njit(cache=True)
def exact_entry(tp, k, ox, oy, oz, dx, dy, dz, u0, u_max, eps_u):
    """Newton on the exact membership from u0: (u, -G'(u)) of an entry (G = 0, G' < 0), or (-1, 0)."""
    u = u0
    G, dG, _, _ = ray_membership(tp, k, ox, oy, oz, dx, dy, dz, u)
    if G <= 0.0 and u <= 0.0:
        return 0.0, -dG
    for _ in range(NEWTON_STEPS):
        if dG >= 0.0:
            return -1.0, 0.0
        un = min(max(u - G / dG, 0.0), u_max)
        step = abs(un - u)
        u = un
        G, dG, _, _ = ray_membership(tp, k, ox, oy, oz, dx, dy, dz, u)
        if step < eps_u:
            break
    if dG < 0.0 and abs(G) < 1e-9:
        return u, -dG
    if G <= 0.0 and u <= 0.0:
        return 0.0, -dG
    return -1.0, 0.0


@njit(cache=True)
def certified_first_entry(tp, k, ox, oy, oz, dx, dy, dz, u_lo, u_hi, u_c, slope_c, K, eps_u, u_stop,
                          G0=math.nan, dG0=math.nan):
    """(u, status): the first entry of the ray into ply k on [u_lo, u_hi] (step 3; no ply point lies
    outside it) at least GRAZE deep. u_c: the iteration's entry (-1: none) with slope_c = -G'(u_c).
    status 0: the march confirmed u_c (or no entry), 1: it found an earlier entry (or one where there
    was none), 2: it ran out of steps (u_c kept). u_stop: the march also ends (status 0, u_c returned)
    once it has proved that no entry lies before u_stop (an entry of another ply already known: this
    ply cannot come first); math.inf to march to u_c's neighbourhood or u_hi. (G0, dG0): G and G' at
    u_lo when the caller has them (``ray_membership``), else NaN.
    17 parameters: the ply, the ray and the state of ``ply_hit``'s root finder (bracket, iterate, slope, Lipschitz
    bound, tolerances), which it keeps as scalars across steps."""
    target = u_c - 2.0 * slope_c / K if u_c >= 0.0 else math.inf
    target = min(target, u_stop)
    a = u_lo
    if G0 == G0:
        G, dG = G0, dG0
    else:
        G, dG, _, _ = ray_membership(tp, k, ox, oy, oz, dx, dy, dz, a)
    if G <= 0.0:
        return a, 0 if (u_c >= 0.0 and abs(a - u_c) <= 1e3 * eps_u) else 1
    a_out = a    # the last march point outside the ply
    for _ in range(MARCH_STEPS):
        if a >= target:
            return u_c, 0
        Gt = G + GRAZE
        h = (dG + math.sqrt(dG * dG + 2.0 * K * Gt)) / K
        a = a + h
        if a >= u_hi:
            return (u_c, 0) if u_c >= 0.0 else (-1.0, 0)
        G, dG, _, _ = ray_membership(tp, k, ox, oy, oz, dx, dy, dz, a)
        if G > 0.0:
            a_out = a
        if G <= -0.5 * GRAZE or h < eps_u:
            # at (or just short of) the depth GRAZE inside an entry: back onto G = 0, by Newton, else by
            # bisection from the last point outside (a ray running along the surface within GRAZE)
            u, _ = exact_entry(tp, k, ox, oy, oz, dx, dy, dz, a, u_hi, eps_u)
            if u < 0.0:
                u = a
                if G <= 0.0:
                    lo = a_out
                    for _ in range(200):
                        if u - lo <= eps_u:
                            break
                        mid = 0.5 * (lo + u)
                        Gm, _, _, _ = ray_membership(tp, k, ox, oy, oz, dx, dy, dz, mid)
                        if Gm > 0.0:
                            lo = mid
                        else:
                            u = mid
            if u_c >= 0.0 and abs(u - u_c) <= 1e3 * eps_u:
                return u_c, 0
            return u, 1
    return u_c, 2


@njit(cache=True)
def ply_chord(tp, ox, oy, oz, dx, dy, dz):
    """(u_lo, u_hi, |d_xy|, eps_u): the part [u_lo, u_hi] of the ray within ply_reach_radius of the axis
    (u_hi < u_lo: none; unclipped: the callers clip it to [0, u_max]) and the entry tolerance eps_u
    (HIT_EPS ply radii) along the ray."""
    ar, at = ply_half_axes(tp)
    amin = min(ar, at)
    dn = math.sqrt(dx * dx + dy * dy + dz * dz)
    dxy = math.sqrt(dx * dx + dy * dy)
    eps_u = HIT_EPS * amin / dn
    reach = ply_reach_radius(tp)
    u_lo = -math.inf
    u_hi = math.inf
    oo = ox * ox + oy * oy
    if dxy < AXIAL_EPS * dn:
        if oo > reach * reach:
            u_hi = -math.inf
    else:
        qa = dx * dx + dy * dy
        qb = ox * dx + oy * dy
        disc = qb * qb - qa * (oo - reach * reach)
        if disc < 0.0:
            u_hi = -math.inf
        else:
            sq = math.sqrt(disc)
            u_lo = (-qb - sq) / qa
            u_hi = (-qb + sq) / qa
    return u_lo, u_hi, dxy, eps_u


@njit(cache=True)
def ray_chord(tp, o, d, u_max):
    """(ox, oy, oz, dx, dy, dz, u_lo, u_hi, |d_xy|, eps_u): the ray as floats and the part of [0, u_max]
    within the plies' reach (``ply_chord``, clipped; u_hi < u_lo: none)."""
    ox, oy, oz = float(o[0]), float(o[1]), float(o[2])
    dx, dy, dz = float(d[0]), float(d[1]), float(d[2])
    u_lo, u_hi, dxy, eps_u = ply_chord(tp, ox, oy, oz, dx, dy, dz)
    return ox, oy, oz, dx, dy, dz, max(u_lo, 0.0), min(u_hi, u_max), dxy, eps_u


@njit(cache=True)
def march_bound(tp, ox, oy, oz, dx, dy, dz, dxy, u_lo, u_hi):
    """K, the bound of |G''| along [u_lo, u_hi] (module doc, step 3)."""
    ar, at = ply_half_axes(tp)
    amin = min(ar, at)
    rp = max(math.sqrt((ox + u_lo * dx) ** 2 + (oy + u_lo * dy) ** 2),
             math.sqrt((ox + u_hi * dx) ** 2 + (oy + u_hi * dy) ** 2))
    w = TWO_PI / tp[YARN_ALPHA] * abs(dz)
    v1 = dxy + w * rp
    v2 = w * w * rp + 2.0 * w * dxy
    return max(2.0 * (v1 * v1 + (rp + tp[PLY_RADIUS]) * v2) / (amin * amin), 1e-300)


@njit(cache=True)
def ply_candidate(tp, k, ox, oy, oz, dx, dy, dz, u_max, tol, max_iter, eps_u):
    """(u_c, slope, iterations, converged): ply k's entry found by the ellipse-plane iteration, the local
    cylinder and Newton on the exact membership (steps 1-2; u_c = -1: none), slope = -G'(u_c). An entry
    found here is a true entry (G = 0, G' < 0); only that it is the first is left to the march."""
    zs, its, conv = ellipse_plane_centre(tp, k, ox, oy, oz, dx, dy, dz, tol, max_iter)
    uc = local_tube_entry(tp, k, ox, oy, oz, dx, dy, dz, zs, u_max)
    slope = 0.0
    if uc >= 0.0:
        uc, slope = exact_entry(tp, k, ox, oy, oz, dx, dy, dz, uc, u_max, eps_u)
    return uc, slope, its, conv


@njit(cache=True)
def order_by_membership(tp, ox, oy, oz, dx, dy, dz, u_lo, order, g0, dg0):
    """G and G' of every ply at u_lo into g0, dg0, and the plies by increasing G into ``order`` (the ply
    the ray starts nearest first: marched first, its entry cuts the others' marches short)."""
    P = int(tp[PLY_NUM])
    for k in range(P):
        G, dG, _, _ = ray_membership(tp, k, ox, oy, oz, dx, dy, dz, u_lo)
        g0[k] = G
        dg0[k] = dG
        i = k
        while i > 0 and g0[order[i - 1]] > G:
            order[i] = order[i - 1]
            i -= 1
        order[i] = k


@njit(cache=True)
def ply_hit(tp, o, d, u_max, tol, max_iter, count=True, search=SEARCH_ITERATION):
    """The first ply the ray o + u d (u in [0, u_max]) meets inside the yarn: a ``PlyHit`` (module doc).
    count=False leaves out ``plies_crossed`` (-1): plies without an entry of their own are then marched
    only as far as the first entry found, which a caller that shades the first hit is all it needs.
    search: SEARCH_ITERATION (steps 1-3) or SEARCH_MARCH (step 3 alone; module doc, "Search")."""
    u_max = float(u_max)
    P = int(tp[PLY_NUM])
    ar, at = ply_half_axes(tp)
    ox, oy, oz, dx, dy, dz, u_lo, u_hi, dxy, eps_u = ray_chord(tp, o, d, u_max)
    best_u = math.inf
    best_k = -1
    max_it = 0
    crossed = 0
    converged = True
    corrections = 0
    if u_hi >= u_lo:
        K = march_bound(tp, ox, oy, oz, dx, dy, dz, dxy, u_lo, u_hi)
        cand_u = stack_array(PLY_MAX, np.float64)
        cand_s = stack_array(PLY_MAX, np.float64)
        cand_it = stack_array(PLY_MAX, np.int64)
        order = stack_array(PLY_MAX, np.int64)
        g0 = stack_array(PLY_MAX, np.float64)
        dg0 = stack_array(PLY_MAX, np.float64)
        for k in range(P):   # every ply's own entry first: the earliest bounds the others' marches
            if search == SEARCH_MARCH:
                uc, slope, its, conv = -1.0, 0.0, 0, True
            else:
                uc, slope, its, conv = ply_candidate(tp, k, ox, oy, oz, dx, dy, dz, u_max, tol, max_iter, eps_u)
            converged = converged and conv
            max_it = max(max_it, its)
            cand_u[k] = uc
            cand_s[k] = slope
            cand_it[k] = its
            order[k] = k
            g0[k] = math.nan
            dg0[k] = math.nan
            if uc >= 0.0 and uc < best_u:
                best_u = uc
                best_k = k
        if search == SEARCH_MARCH:
            order_by_membership(tp, ox, oy, oz, dx, dy, dz, u_lo, order, g0, dg0)
        for i in range(P):
            k = order[i]
            uc = cand_u[k]
            if k == best_k or (count and uc < 0.0):
                stop = math.inf
            else:
                stop = best_u
            u, status = certified_first_entry(tp, k, ox, oy, oz, dx, dy, dz, u_lo, u_hi, uc, cand_s[k], K, eps_u,
                                              stop, g0[k], dg0[k])
            if status == 1:
                corrections += 1
            if u >= 0.0 and u <= u_max:
                crossed += 1
                # ties (a ray starting inside two overlapping plies, u = 0): the lower ply index, whatever the order
                if u < best_u or (u == best_u and k < best_k) or (k == best_k and u <= best_u):
                    best_u = u
                    best_k = k
    if not count:
        crossed = -1
    if best_k < 0:
        ex = ox + u_max * dx
        ey = oy + u_max * dy
        ez = oz + u_max * dz
        zero = (0.0, 0.0, 0.0)
        return PlyHit(False, -1, u_max, (ex, ey, ez), zero, zero, 0.0, crossed, max_it, converged, corrections)
    best_it = cand_it[best_k]
    u = best_u
    px = ox + u * dx
    py = oy + u * dy
    pz = oz + u * dz
    _, _, a, b = ray_membership(tp, best_k, ox, oy, oz, dx, dy, dz, u)
    _, _, tx, ty, c, s = ply_centre(tp, best_k, pz)
    tn = math.sqrt(tx * tx + ty * ty + 1.0)
    tx, ty, tz = tx / tn, ty / tn, 1.0 / tn
    ga = a / (ar * ar)
    gb = b / (at * at)
    nx = ga * c - gb * s
    ny = ga * s + gb * c
    dot = nx * tx + ny * ty
    nx, ny, nz = nx - dot * tx, ny - dot * ty, -dot * tz
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nn > 0.0:
        nx, ny, nz = nx / nn, ny / nn, nz / nn
    else:  # the hit at the ply centre (a ray starting inside): the ply frame's d_r
        nx, ny, nz = c, s, 0.0
    psi = math.atan2(b / tp[E_LONG], a / tp[E_SHORT])
    return PlyHit(True, best_k, u, (px, py, pz), (tx, ty, tz), (nx, ny, nz), psi, crossed, best_it, converged,
                  corrections)


@njit(cache=True)
def plies_crossed(tp, o, d, u_max, tol, max_iter, search=SEARCH_ITERATION):
    """How many plies the ray o + u d (u in [0, u_max]) enters, each counted once: ``ply_hit``'s
    ``plies_crossed`` without its first hit (a ply whose own entry the iteration finds needs no march)."""
    u_max = float(u_max)
    ox, oy, oz, dx, dy, dz, u_lo, u_hi, dxy, eps_u = ray_chord(tp, o, d, u_max)
    if not (u_hi >= u_lo):
        return 0
    K = march_bound(tp, ox, oy, oz, dx, dy, dz, dxy, u_lo, u_hi)
    crossed = 0
    for k in range(int(tp[PLY_NUM])):
        uc = -1.0
        if search == SEARCH_ITERATION:
            uc, _, _, _ = ply_candidate(tp, k, ox, oy, oz, dx, dy, dz, u_max, tol, max_iter, eps_u)
        if uc < 0.0:
            uc, _ = certified_first_entry(tp, k, ox, oy, oz, dx, dy, dz, u_lo, u_hi, -1.0, 0.0, K, eps_u, math.inf)
        if uc >= 0.0 and uc <= u_max:
            crossed += 1
    return crossed


@njit(cache=True)
def ply_blocks(tp, o, d, u_max, tol, max_iter, search=SEARCH_ITERATION):
    """True when the ray o + u d (u in [0, u_max]) enters any ply (``ply_hit``'s ``hit``, for shadow rays):
    a ply entry the iteration finds settles it; the march runs only when none does."""
    u_max = float(u_max)
    ox, oy, oz, dx, dy, dz, u_lo, u_hi, dxy, eps_u = ray_chord(tp, o, d, u_max)
    if not (u_hi >= u_lo):
        return False
    P = int(tp[PLY_NUM])
    if search == SEARCH_ITERATION:
        for k in range(P):
            uc, _, _, _ = ply_candidate(tp, k, ox, oy, oz, dx, dy, dz, u_max, tol, max_iter, eps_u)
            if uc >= 0.0 and uc <= u_max:
                return True
    K = march_bound(tp, ox, oy, oz, dx, dy, dz, dxy, u_lo, u_hi)
    order = stack_array(PLY_MAX, np.int64)
    g0 = stack_array(PLY_MAX, np.float64)
    dg0 = stack_array(PLY_MAX, np.float64)
    order_by_membership(tp, ox, oy, oz, dx, dy, dz, u_lo, order, g0, dg0)
    for i in range(P):
        k = order[i]
        u, _ = certified_first_entry(tp, k, ox, oy, oz, dx, dy, dz, u_lo, u_hi, -1.0, 0.0, K, eps_u, math.inf,
                                     g0[k], dg0[k])
        if u >= 0.0 and u <= u_max:
            return True
    return False
