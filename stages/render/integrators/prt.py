"""Precomputed light transport for fabrics (``--method prt``, seed 001 §5-§6, the CPU version).

Geometry: a shell-mapped tiling (``stages.core.shell``): an eye ray walks the shell to its first fibre
hit x on segment k of exemplar e (§5.1). The outgoing radiance is split (§5):

    L_o(x, w_o) = L_single + L_multi

Single scattering (§5.2), per light:
- directional (§5.2.1): E S(w_d, w_o) cos(theta_d) V_loc V_glo, with V_loc the sign of segment k's
  PCA-reconstructed SSDF at w_d (``stages.core.svf.ssdf_at``, bilinear) and V_glo a shadow ray from
  x_, the top-surface point of the shell above x (``stages.core.shell.top``), against the shell's
  boundary (the paper: the cloth as a macroscopic solid, other folds block) and the ground; here, where
  the IIRTF carries its exemplars' layer transmittance (``stages.precompute.layer``), each fold the
  shadow ray enters passes that share of the light, RGB, read at the ray's angle in the fold's flat
  space (translucent folds: the shadowed side of a drape is lit through the fold in front);
- SG, constant and environment lights, version (a) "mc" (§5.2.1 "Generalization"): the light is
  sampled into one direction w per light and camera sample (``light_sample``: an SG exactly) and
  shaded as a directional light of irradiance L(w) / p(w);
- SG lights, version (b) "analytic" (§5.2.2): P/M(lambda) times ``bcsdf_sg.sg_single_scatter`` (Eq. 2's
  Gamma with the sum-of-SGs product for lambda <= 100, the erf-smoothed SSDF at the axis for lambda
  >= 200, linear in lambda between), the SG's power scaled by V_glo of one shadow ray towards a
  direction sampled from the lobe (soft shadows by sampling the lobe against the shell).

Multiple scattering (§5.3): L_multi = c_S(theta_o) . (R_wo a_C^T c_L) V~_glo per channel, with c_L the SH
coefficients of the light's radiance in the exemplar's (flat) space (directional: E Y(w_d); SG: P times
the normalised SG's zonal expansion rotated to its axis, ``stages.core.sg``; mc lights: the sample's
E Y(w)), a_C the cell's transfer matrices (``seg_row``), R_wo the exact SH rotation into the w_o-space
of §4.3 (x = the fibre tangent, the view in the xy-plane; applied to c_S instead, as D(R_wo)^T c_S, by
``stages.core.sh.sh_rotate_rows`` through R_wo's Euler angles and ``quarter_turn``), c_S the
BCSDF's SH table at theta_o (``stages.core.shading.bcsdf_sh``), and V~_glo the global visibility
filtered by a 2D Gaussian of sigma_glo in the flat fabric's plane, estimated as the paper's CPU version
does: one shadow ray from the top surface above a point x' drawn from the Gaussian around x.
With ``ms_incidence`` (``ms_incidence=filtered``, the renderer's default; ``local`` is the paper's) the
light's flat direction for multiple scattering is also taken at x' (``_incidence_at_offset``: tilted by the
change of the top surface's normal from x to x'): a cell's transfer holds for light falling evenly around
it, and where the incidence changes fast across the cloth (a curved drape's terminator) the fibres carry
light sideways from where it falls steeply into where it grazes. On flat cloth it changes nothing.
Light from below the fabric's plane (in flat space): an IIRTF precomputed for light from above (the
paper's, §4.2) adds no multiple scattering for it, and V_glo is 0 for it (the shadow ray leaves through
the top surface). An IIRTF precomputed for light from both sides (``precompute iirtf --light-domain
sphere``, §4.2 "Extension to bottom and side fabric surfaces"; the field ``below``) adds its multiple
scattering too, and V_glo for light from below the shell's base starts from the base surface's point
below x (``stages.core.shell.top.base_point``): light that reaches the cloth from its underside and
crosses it (the hanging sides of a drape under a low light).

Directions: the SVF, the IIRTF and the SH tables live in exemplar (flat) space; a world direction v
is taken there by the linear part of the hit tetrahedron's world -> flat map (normalised). The
single-scattering BCSDF is evaluated in world space with the world tangent, as fiberpath does.

Random numbers: ``uniform(seed, index, dim)``: dims 0-1 place the sample in its pixel, then 6 per
light (2 light sample, 2 Gaussian offset, 2 lobe sample for the analytic SG's shadow).

``PrtIntegrator`` fields: see the namedtuple; ``terms`` bit 1 single, bit 2 multi (0: fibre hits stay
black, which times the eye rays alone); ``sg_mode`` 0 mc, 1 analytic; ``below`` True when the IIRTF
holds light from below (see above); ``layer_tau`` (K, 2, NB, 3) the exemplars' layer transmittance
(``stages.core.layer``), (0, 2, 1, 3) for an IIRTF without one.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit
from numba.extending import overload

from stages.core.dispatch import is_tuple_class
from stages.core.geometry.stack import stack_array, stack_vector3
from stages.core.layer import FROM_ABOVE, FROM_BELOW, tau_at
from stages.core.rng import uniform
from stages.core.sg import sg_sh_coefficients, spherical_fibonacci_axes
from stages.core.sh import sh_eval, sh_rotate_rows
from stages.core.shading.bcsdf_sg import sg_single_scatter
from stages.core.shading.bcsdf_sh import bcsdf_sh_lookup, omega_o_frame
from stages.core.shading.material import CTX_SIZE, material_eval_pdf, material_prepare
from stages.core.shell.top import base_point, top_point
from stages.core.shell.traversal import enter_shell, shell_intersect
from stages.core.svf import ssdf_at
from stages.render.ground import ground_intersect
from stages.render.integrator import PathSample, radiance
from stages.render.lights import SG, light_eval, light_sample_into

PrtIntegrator = namedtuple("PrtIntegrator", [
    "scene", "top", "mat_of_fiber", "mats", "lights", "ground", "has_ground", "ground_mat",
    "svf_row", "svf_mean", "svf_basis", "svf_coeffs", "svf_res", "sg_angle", "sg_weights", "lam_svf",
    "seg_row", "transfer", "order", "quarter_turn", "cs_table", "mat_cs",
    "flat_size", "sigma_glo", "terms", "sg_mode", "eps", "below", "layer_tau", "ms_incidence"])

SINGLE = 1
MULTI = 2
DIMS_PER_LIGHT = 6


@njit(cache=True)
def _to_flat(w2f, tet, v, out):
    x = w2f[tet, 0, 0] * v[0] + w2f[tet, 0, 1] * v[1] + w2f[tet, 0, 2] * v[2]
    y = w2f[tet, 1, 0] * v[0] + w2f[tet, 1, 1] * v[1] + w2f[tet, 1, 2] * v[2]
    z = w2f[tet, 2, 0] * v[0] + w2f[tet, 2, 1] * v[1] + w2f[tet, 2, 2] * v[2]
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        n = 1.0
    out[0] = x / n
    out[1] = y / n
    out[2] = z / n


@njit(cache=True)
def _flat_point(w2f, tet, p):
    return (w2f[tet, 0, 0] * p[0] + w2f[tet, 0, 1] * p[1] + w2f[tet, 0, 2] * p[2] + w2f[tet, 0, 3],
            w2f[tet, 1, 0] * p[0] + w2f[tet, 1, 1] * p[1] + w2f[tet, 1, 2] * p[2] + w2f[tet, 1, 3])


MAX_LAYERS = 8   # cloth layers a shadow ray crosses before its light counts as spent


@njit(cache=True)
def _exemplar_at(sc, X, Y):
    """The exemplar of the block holding the flat point (X, Y) (the block map wraps; -1: an empty block)."""
    i = int(math.floor(X / sc.block_size[0]))
    j = int(math.floor(Y / sc.block_size[1]))
    return sc.block_map[i % sc.block_map.shape[0], j % sc.block_map.shape[1]]


@njit(cache=True)
def _layer_transmittance(it, f, t, ox, oy, oz, w):
    """(r, g, b): the share of light that crosses the cloth layer a shadow ray from o along w enters through
    boundary face f at distance t: tau of the block's exemplar (``stages.precompute.layer``), on the side the
    light falls on (it travels along -w), interpolated in |cos theta| of w in the layer's flat space."""
    sc = it.scene
    tet = sc.btet[f]
    p = stack_vector3()
    p[0] = ox + t * w[0]
    p[1] = oy + t * w[1]
    p[2] = oz + t * w[2]
    X, Y = _flat_point(sc.w2f, tet, p)
    e = _exemplar_at(sc, X, Y)
    if e < 0:
        return 1.0, 1.0, 1.0
    lf = stack_vector3()
    _to_flat(sc.w2f, tet, w, lf)
    return tau_at(it.layer_tau[e], FROM_ABOVE if lf[2] > 0.0 else FROM_BELOW, abs(lf[2]))


@njit(cache=True)
def global_visibility(it, u, v, w):
    """V_glo (r, g, b): the light that reaches the top-surface point above (u, v) from direction w (world).
    0 unless w is above the top surface's tangent plane (with ``it.below``, light from below the plane is
    seen from the base surface's point below (u, v) instead, the ray leaving downwards; module doc); the
    shadow ray then crosses the other folds of the cloth, each layer passing the share of the light its
    exemplar's transmittance gives (``it.layer_tau``; without one, the paper's opaque shell: any layer
    blocks), and the ground blocks it."""
    ok, x, y, z, nx, ny, nz = top_point(it.top, u, v)
    if not ok:
        return 1.0, 1.0, 1.0
    side = 1.0
    if w[0] * nx + w[1] * ny + w[2] * nz <= 0.0:
        if not it.below:
            return 0.0, 0.0, 0.0
        ok, x, y, z, nx, ny, nz = base_point(it.top, u, v)
        side = -1.0
    ox = x + side * it.eps * nx
    oy = y + side * it.eps * ny
    oz = z + side * it.eps * nz
    v0 = 1.0
    v1 = 1.0
    v2 = 1.0
    tmin = it.eps
    for layer in range(MAX_LAYERS + 1):
        t, f = enter_shell(it.scene, ox, oy, oz, w[0], w[1], w[2], tmin, np.inf)
        if f < 0:
            break
        if it.layer_tau.shape[0] == 0 or layer == MAX_LAYERS:
            return 0.0, 0.0, 0.0
        a0, a1, a2 = _layer_transmittance(it, f, t, ox, oy, oz, w)
        v0 *= a0
        v1 *= a1
        v2 *= a2
        tmin = t + it.eps
    if ground_intersect(it.ground, it.has_ground, oz, w[2], it.eps) < np.inf:
        return 0.0, 0.0, 0.0
    return v0, v1, v2


MAX_SH_ORDER = 8                  # the IIRTF's largest SH order (precompute iirtf --order)
MAX_SH_J = (MAX_SH_ORDER + 1) ** 2
MAX_SH_J3 = 3 * MAX_SH_J


@njit(cache=True, _nrt=False)
def _hit_sh_frame(it, m, tf, vf, W):
    """What multiple scattering needs of the hit alone, once per hit for all its lights: W[c] =
    D(R_wo)^T c_S(theta_o)[c] = D(R_wo^T) c_S[c], the BCSDF's SH coefficients of channel c for material m
    (``bcsdf_sh_lookup``) carried from the frame of the view and the fibre (``omega_o_frame``) into
    flat space, so that c_S . (R_wo c_T) = W[c] . c_T (``sh_rotate_rows``, without building D)."""
    R = stack_array(9, np.float64).reshape((3, 3))
    Rt = stack_array(9, np.float64).reshape((3, 3))
    theta_v = omega_o_frame(tf, vf, R)
    for i in range(3):
        for j in range(3):
            Rt[i, j] = R[j, i]
    cs = stack_array(MAX_SH_J3, np.float64).reshape((MAX_SH_J, 3))
    bcsdf_sh_lookup(it.cs_table[it.mat_cs[m]], theta_v, it.order, cs)
    C = stack_array(MAX_SH_J3, np.float64).reshape((3, MAX_SH_J))
    J = (it.order + 1) * (it.order + 1)
    for c in range(3):
        for j in range(J):
            C[c, j] = cs[j, c]
    sh_rotate_rows(it.order, Rt, it.quarter_turn, C, W)


@njit(cache=True, _nrt=False)
def _multi_scatter(it, row, lf, lam, E0, E1, E2, W):
    """(r, g, b) = c_S(theta_o) . (R_wo a_C^T c_L[c]) = W[c] . (a_C^T c_L[c]) per channel: multiple
    scattering of a light of power (E0, E1, E2) from the flat direction lf, a directional light (lam <= 0:
    c_L = Y(lf)) or an SG lobe of sharpness lam (c_L its SH coefficients); W from ``_hit_sh_frame``.
    a_C^T c_L is summed row by row of a_C (contiguous, so the compiler vectorises it). Its SH work arrays
    live on the machine stack (orders up to MAX_SH_ORDER), so it runs without reference counting like
    the estimator around it."""
    L = it.order
    J = (L + 1) * (L + 1)
    Ysh = stack_array(MAX_SH_J, np.float64)
    if lam > 0.0:
        sg_sh_coefficients(lf, lam, L, Ysh)
    else:
        sh_eval(L, lf[0], lf[1], lf[2], Ysh)
    cT = stack_array(MAX_SH_J, np.float64)
    a = it.transfer
    r0 = 0.0
    r1 = 0.0
    r2 = 0.0
    for c in range(3):
        E = E0 if c == 0 else (E1 if c == 1 else E2)
        for j1 in range(J):
            cT[j1] = 0.0
        for j0 in range(J):   # c_T = a_C^T c_L
            y = E * Ysh[j0]
            for j1 in range(J):
                cT[j1] += a[row, c, j0, j1] * y
        acc = 0.0
        for j1 in range(J):
            acc += W[c, j1] * cT[j1]
        if c == 0:
            r0 = acc
        elif c == 1:
            r1 = acc
        else:
            r2 = acc
    return r0, r1, r2


@njit(cache=True, _nrt=True)
def _single_scatter_sg(it, e, srow, lf, mat, tf, vf, lam):
    """(r, g, b): single scattering from a unit-power SG lobe (axis lf in flat space, sharpness lam) at
    segment row srow of exemplar e (``sg_single_scatter`` with the segment's SSDF and SG fit)."""
    dk = ssdf_at(it.svf_mean[e], it.svf_basis[e], it.svf_coeffs[srow], it.svf_res[0], it.svf_res[1], lf)
    axes = spherical_fibonacci_axes(it.sg_weights.shape[1], float(it.sg_angle[srow]))
    return sg_single_scatter(mat[1:11], tf, vf, lf, lam, dk, axes, it.sg_weights[srow].astype(np.float64),
                             it.lam_svf)


@njit(cache=True, _nrt=False)
def prt_radiance(it, o, d, seed, key):
    lights = it.lights.lights
    env = it.lights.env
    marg = it.lights.marginal
    cond = it.lights.conditional
    nl = lights.shape[0]
    h = shell_intersect(it.scene, o[0], o[1], o[2], d[0], d[1], d[2], np.inf)
    tg = ground_intersect(it.ground, it.has_ground, o[2], d[2], it.eps)
    L0 = 0.0
    L1 = 0.0
    L2 = 0.0
    rays = 1
    if tg < h.t:
        # the ground: Lambertian, lit directly, shadowed by the cloth's shell (a macroscopic object)
        wi = stack_vector3()
        n = stack_vector3()
        n[0] = 0.0
        n[1] = 0.0
        n[2] = 1.0 if d[2] < 0.0 else -1.0
        p = stack_vector3()
        for k in range(3):
            p[k] = o[k] + tg * d[k] + it.eps * n[k]
            wi[k] = -d[k]
        ctx = stack_array(CTX_SIZE, np.float64)
        wl = stack_vector3()
        material_prepare(it.ground_mat, n, n, wi, ctx)
        for k in range(nl):
            base = 2 + DIMS_PER_LIGHT * k
            lr, lg, lb, pl, delta = light_sample_into(lights, k, env, marg, cond, uniform(seed, key, base),
                                                      uniform(seed, key, base + 1), wl)
            if pl <= 0.0:
                continue
            f0, f1, f2, _pf = material_eval_pdf(it.ground_mat, ctx, n, n, wi, wl)
            rays += 1
            _t, fb = enter_shell(it.scene, p[0], p[1], p[2], wl[0], wl[1], wl[2], it.eps, np.inf)
            if fb >= 0:
                continue
            sc = 1.0 if delta else 1.0 / pl
            L0 += f0 * lr * sc
            L1 += f1 * lg * sc
            L2 += f2 * lb * sc
        return PathSample(L0, L1, L2, 1.0, tg, 0, rays)
    if h.segment < 0:
        for k in range(nl):
            lr, lg, lb = light_eval(lights, k, env, marg, cond, d)
            L0 += lr
            L1 += lg
            L2 += lb
        return PathSample(L0, L1, L2, 0.0, 0.0, 0, rays)
    # the hit: segment, material, frames in world and flat space, the point's (u, v)
    s = h.segment
    e = h.exemplar
    m = it.mat_of_fiber[h.fibre]
    mat = it.mats[m]
    t_w = stack_vector3()
    n_w = stack_vector3()
    wv = stack_vector3()
    for k in range(3):
        t_w[k] = h.tangent[k]
        n_w[k] = h.normal[k]
        wv[k] = -d[k]
    ctx = stack_array(CTX_SIZE, np.float64)
    material_prepare(mat, t_w, n_w, wv, ctx)
    w2f = it.scene.w2f
    tf = stack_vector3()
    vf = stack_vector3()
    lf = stack_vector3()
    wl = stack_vector3()
    _to_flat(w2f, h.tet, t_w, tf)
    _to_flat(w2f, h.tet, wv, vf)
    X, Y_ = _flat_point(w2f, h.tet, h.hit)
    u = X / it.flat_size[0]
    v = Y_ / it.flat_size[1]
    srow = it.svf_row[s]
    mrow = it.seg_row[s]
    R_res = it.svf_res[0]
    C_res = it.svf_res[1]
    axes_w = stack_vector3()
    W = stack_array(MAX_SH_J3, np.float64).reshape((3, MAX_SH_J))
    have_frame = False   # W, made when the first light needs it
    for k in range(nl):
        base = 2 + DIMS_PER_LIGHT * k
        typ = int(lights[k, 0])
        analytic = typ == SG and it.sg_mode == 1
        # --- single scattering ---
        if analytic:
            P0 = lights[k, 1]
            P1 = lights[k, 2]
            P2 = lights[k, 3]
            lam = lights[k, 7]
            for q in range(3):
                axes_w[q] = lights[k, 4 + q]
            # the lobe's global visibility: one shadow ray towards a direction sampled from it
            _lr, _lg, _lb, pl, _delta = light_sample_into(lights, k, env, marg, cond, uniform(seed, key, base + 4),
                                                          uniform(seed, key, base + 5), wl)
            vg0 = vg1 = vg2 = 0.0
            if it.terms & SINGLE and pl > 0.0:
                rays += 1
                vg0, vg1, vg2 = global_visibility(it, u, v, wl)
            if vg0 > 0.0 or vg1 > 0.0 or vg2 > 0.0:
                _to_flat(w2f, h.tet, axes_w, lf)
                g0, g1, g2 = _single_scatter_sg(it, e, srow, lf, mat, tf, vf, lam)
                L0 += P0 * g0 * vg0
                L1 += P1 * g1 * vg1
                L2 += P2 * g2 * vg2
            if it.terms & MULTI:
                _to_flat(w2f, h.tet, axes_w, lf)
                vt0 = vt1 = vt2 = 0.0
                if pl > 0.0:
                    u1, v1 = _gaussian_point(it, seed, key, base + 2, u, v)
                    vt0, vt1, vt2 = global_visibility(it, u1, v1, wl)
                rays += 1
                if vt0 > 0.0 or vt1 > 0.0 or vt2 > 0.0:
                    if not have_frame:
                        _hit_sh_frame(it, m, tf, vf, W)
                        have_frame = True
                    m0, m1, m2 = _multi_scatter(it, mrow, lf, lam, P0, P1, P2, W)
                    L0 += m0 * vt0
                    L1 += m1 * vt1
                    L2 += m2 * vt2
            continue
        lr, lg, lb, pl, delta = light_sample_into(lights, k, env, marg, cond, uniform(seed, key, base),
                                                  uniform(seed, key, base + 1), wl)
        if pl <= 0.0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
            continue
        sc = 1.0 if delta else 1.0 / pl
        E0 = lr * sc
        E1 = lg * sc
        E2 = lb * sc
        _to_flat(w2f, h.tet, wl, lf)
        if it.terms & SINGLE:
            f0, f1, f2, _pf = material_eval_pdf(mat, ctx, t_w, n_w, wv, wl)
            if f0 != 0.0 or f1 != 0.0 or f2 != 0.0:
                if ssdf_at(it.svf_mean[e], it.svf_basis[e], it.svf_coeffs[srow], R_res, C_res, lf) > 0.0:
                    rays += 1
                    vg0, vg1, vg2 = global_visibility(it, u, v, wl)
                    L0 += f0 * E0 * vg0
                    L1 += f1 * E1 * vg1
                    L2 += f2 * E2 * vg2
        if it.terms & MULTI and (lf[2] > 0.0 or it.below or it.ms_incidence):
            rays += 1
            u1, v1 = _gaussian_point(it, seed, key, base + 2, u, v)    # x' for V~_glo and the filtered incidence
            vt0, vt1, vt2 = global_visibility(it, u1, v1, wl)
            if it.ms_incidence:
                _incidence_at_offset(it, u, v, u1, v1, wl, lf)
            if (vt0 > 0.0 or vt1 > 0.0 or vt2 > 0.0) and (lf[2] > 0.0 or it.below):
                if not have_frame:
                    _hit_sh_frame(it, m, tf, vf, W)
                    have_frame = True
                m0, m1, m2 = _multi_scatter(it, mrow, lf, 0.0, E0, E1, E2, W)
                L0 += m0 * vt0
                L1 += m1 * vt1
                L2 += m2 * vt2
    return PathSample(L0, L1, L2, 1.0, h.t, 0, rays)


@njit(cache=True)
def _gaussian_point(it, seed, key, dim, u, v):
    """(u', v'): x' drawn from the 2D Gaussian of sigma_glo around (u, v) in the flat fabric's plane (Box-Muller
    from the uniforms of dimensions dim, dim + 1; (u, v) itself when sigma_glo is 0). V_glo at x' is the
    one-sample estimate of V~_glo (§5.3.2); with ``ms_incidence`` the light's incidence there too."""
    if it.sigma_glo <= 0.0:
        return u, v
    r = it.sigma_glo * math.sqrt(-2.0 * math.log(1.0 - uniform(seed, key, dim)))
    a = 2.0 * math.pi * uniform(seed, key, dim + 1)
    return u + r * math.cos(a) / it.flat_size[0], v + r * math.sin(a) / it.flat_size[1]


@njit(cache=True)
def _incidence_at_offset(it, u, v, u1, v1, w, lf):
    """``ms_incidence``: the light's flat direction ``lf`` tilted to the incidence it has at the Gaussian's point
    x' = (u1, v1) (``_gaussian_point``, the draw V~_glo is estimated at): its z moved by w . n(x') - w . n(x) of
    the top surface's normals, its azimuth kept; multiple scattering then gathers the light falling around x,
    not at x alone."""
    if it.sigma_glo <= 0.0:
        return
    ok0, _x, _y, _z, nx, ny, nz = top_point(it.top, u, v)
    ok1, _x, _y, _z, mx, my, mz = top_point(it.top, u1, v1)
    if not (ok0 and ok1):
        return
    dz = (w[0] * mx + w[1] * my + w[2] * mz) - (w[0] * nx + w[1] * ny + w[2] * nz)
    if dz == 0.0:
        return
    z = min(max(lf[2] + dz, -1.0), 1.0)
    h = math.sqrt(lf[0] * lf[0] + lf[1] * lf[1])
    s = math.sqrt(max(0.0, 1.0 - z * z))
    if h > 0.0:
        lf[0] *= s / h
        lf[1] *= s / h
    else:
        lf[0] = s
    lf[2] = z


# stages.render.tiles.tile_kernel: prt_radiance takes no references, so the tile loop need not either
PrtIntegrator.reference_free = True


@overload(radiance)
def _prt_radiance(integ, o, d, seed, index):
    if is_tuple_class(integ, PrtIntegrator):
        return lambda integ, o, d, seed, index: prt_radiance(integ, o, d, seed, index)
