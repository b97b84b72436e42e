"""Shading points on a yarn: implicit plies and fibres at one or several azimuthal offsets (seed 004 §3.3-3.4, §4.2).

A ray that enters a yarn's envelope tube is described in yarn space (``stages.core.yarn.tubes``):
entry point ``o`` on the envelope of radius R, direction ``d``, ``u_max`` the length inside. Its
*azimuthal offset* is h = (o . w) / R in [-1, 1], w = normalize(z x d) the direction across the
yarn as the ray sees it: h = 0 meets the axis, |h| = 1 grazes the silhouette. The ray at another
offset h' is the same ray moved by (h' - h) R w.

``near_point(yt, o, d, u_max)``: the implicit ply hit (``stages.core.yarn.implicit_plies.ply_hit``), the
visible fibre's frame from the fibre tables (normal perturbation, fibre tangent tilt) and the
shadowing S = S_ply S_fibre (``stages.core.yarn.implicit_tables``). No ply hit: ``hit`` False -- the
ray passes on through the yarn.

``offset_points(yt, key, o, d, h0, h_lo, h_hi, K, jitter, ...)``: K near points at offsets h_k
stratified uniformly in h over [h_lo, h_hi], the stratum's position ``jitter`` in [0, 1) shared by all
k. (Uniform in h, the measure a pixel covers a yarn with, so ``far`` is the mean of ``near`` over a
pixel spanning the yarn; the reference implementation spaces them uniformly in asin(h).) ``far`` mode
uses h over [-1, 1] and shades the mean of the K near BYSDFs (seed 004 Eq. 6); ``multiscale`` uses the
pixel's footprint and aggregates the geometry (``aggregate``: seed 004 Eq. 8-9): the normal and
tangent are the weighted means of the K fibre frames with weights exp(-falloff |x_k - x_0| / R) (x_0:
the point of the ray's own offset), the shadowing their weighted mean, and the specular roughness is
widened by (h_hi - h_lo) / 10.

Nothing here allocates: points and frames are 3-tuples (``ShadingPoint``'s x, t, n too), and
``offset_points`` fills the caller's arrays, so ``stages.render.integrators.bysdf`` calls these without reference
counting.

``YarnType`` holds what the kernels need of one yarn type: ``tp`` (the packed procedural yarn model,
``stages.core.yarn.model``), its tables, the envelope radius, the ply iteration's tolerance and
iteration cap, and the ply search (the paper's iteration or the march alone; same entries).
"""
import math
from collections import namedtuple

from numba import njit

from stages.core.yarn.implicit_plies import ply_hit
from stages.core.yarn.implicit_tables import (
    fibre_frame,
    fibre_lookup,
    ply_shadow_lookup,
)
from stages.core.yarn.tubes import cylinder_span

# one yarn type: tp (NPARAM,), tables (ImplicitTables), envelope radius, ply tolerance, ply iterations, ply search
# (stages.core.yarn.implicit_plies.SEARCH_ITERATION or SEARCH_MARCH)
YarnType = namedtuple("YarnType", ["tp", "tables", "radius", "tol", "max_iter", "search"])

# shading point in yarn space: hit (bool), x (3) the ply hit, t (3) fibre tangent, n (3) fibre normal,
# shadow S_ply S_fibre, ply the ply index
ShadingPoint = namedtuple("ShadingPoint", ["hit", "x", "t", "n", "shadow", "ply"])


@njit(cache=True)
def across(d):
    """w = normalize(z x d): the direction across the yarn as the ray sees it ((1, 0, 0) along the axis)."""
    wx = -d[1]
    wy = d[0]
    L = math.sqrt(wx * wx + wy * wy)
    if L < 1e-12:
        return 1.0, 0.0
    return wx / L, wy / L


@njit(cache=True)
def offset_of(o, d, R):
    """The azimuthal offset h in [-1, 1] of the yarn-space ray (o, d)."""
    wx, wy = across(d)
    return min(1.0, max(-1.0, (o[0] * wx + o[1] * wy) / R))


@njit(cache=True)
def near_point(yt, yarn_key, o, d, u_max):
    """``ShadingPoint`` of the yarn-space ray o + u d, u in [0, u_max], through yarn type ``yt``."""
    ph = ply_hit(yt.tp, o, d, u_max, yt.tol, yt.max_iter, False, yt.search)
    if not ph.hit:
        zero = (0.0, 0.0, 0.0)
        x = (o[0] + u_max * d[0], o[1] + u_max * d[1], o[2] + u_max * d[2])
        return ShadingPoint(False, x, zero, zero, 1.0, -1)
    x = ph.point
    normal_angle, _, s_fibre = fibre_lookup(yt.tables, yt.tp, yarn_key, ph.ply, ph.ply_angle, x[2])
    s_ply = ply_shadow_lookup(yt.tables, yt.tp, math.atan2(x[1], x[0]), x[2])
    ft, fn = fibre_frame(yt.tp, ph.ply, x[2], ph.ply_angle, ph.tangent, ph.normal, normal_angle)
    return ShadingPoint(True, x, ft, fn, s_ply * s_fibre, ph.ply)


@njit(cache=True)
def shifted_entry(o, d, R, dh):
    """(o', u_max') of the ray moved across the yarn by dh R (its entry on the envelope, a 3-tuple, and
    length inside); u_max' < 0 when the moved ray misses the envelope."""
    wx, wy = across(d)
    q = (o[0] + dh * R * wx, o[1] + dh * R * wy, float(o[2]))
    u0, u1 = cylinder_span(q, d, R)
    if u1 <= u0 or not math.isfinite(u0) or not math.isfinite(u1):
        return q, -1.0
    return (q[0] + u0 * d[0], q[1] + u0 * d[1], q[2] + u0 * d[2]), u1 - u0


@njit(cache=True)
def offset_h(h_lo, h_hi, K, k, jitter):
    """Offset k of K stratified uniformly in h over [h_lo, h_hi] (a pixel covers a yarn uniformly in h)."""
    return h_lo + (k + jitter) / K * (h_hi - h_lo)


@njit(cache=True)
def offset_points(yt, yarn_key, o, d, h0, h_lo, h_hi, K, jitter, xs, ts, ns, shadow, hit):
    """K near points at offsets h_k in [h_lo, h_hi] (``offset_h``) of the ray (o, d) whose own offset
    is h0; fills xs, ts, ns (K, 3), shadow (K,), hit (K,) and returns the number of ply hits.
    14 parameters: the yarn (type, key), the ray and its offset, the offsets' range and jitter, and five output
    arrays."""
    R = yt.radius
    nh = 0
    for k in range(K):
        hk = offset_h(h_lo, h_hi, K, k, jitter)
        q, um = shifted_entry(o, d, R, hk - h0)
        hit[k] = False
        shadow[k] = 0.0
        if um <= 0.0:
            continue
        sp = near_point(yt, yarn_key, q, d, um)
        if not sp.hit:
            continue
        hit[k] = True
        nh += 1
        shadow[k] = sp.shadow
        for c in range(3):
            xs[k, c] = sp.x[c]
            ts[k, c] = sp.t[c]
            ns[k, c] = sp.n[c]
    return nh


@njit(cache=True)
def aggregate(x0, xs, ts, ns, shadow, hit, K, R, falloff):
    """Multiscale geometry (seed 004 Eq. 8-9): (t, n, shadow), t and n 3-tuples, as the means of the K
    points' fibre frames and shadowing weighted by exp(-falloff |x_k - x0| / R); n orthonormalised
    against t."""
    t0 = t1 = t2 = 0.0
    n0 = n1 = n2 = 0.0
    s = 0.0
    wsum = 0.0
    for k in range(K):
        if not hit[k]:
            continue
        dx = xs[k, 0] - x0[0]
        dy = xs[k, 1] - x0[1]
        dz = xs[k, 2] - x0[2]
        w = math.exp(-falloff * math.sqrt(dx * dx + dy * dy + dz * dz) / R)
        wsum += w
        s += w * shadow[k]
        t0 += w * ts[k, 0]
        t1 += w * ts[k, 1]
        t2 += w * ts[k, 2]
        n0 += w * ns[k, 0]
        n1 += w * ns[k, 1]
        n2 += w * ns[k, 2]
    if wsum <= 0.0:
        return (t0, t1, t2), (n0, n1, n2), 0.0
    tl = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0 /= tl
    t1 /= tl
    t2 /= tl
    dn = n0 * t0 + n1 * t1 + n2 * t2
    n0 -= dn * t0
    n1 -= dn * t1
    n2 -= dn * t2
    nl = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    return (t0, t1, t2), (n0 / nl, n1 / nl, n2 / nl), s / wsum
