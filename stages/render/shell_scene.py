"""A shell-mapped fibre scene for ray casting: ``ShellScene`` (stages.core.shell_traversal) from the
arrays of a ``tiling`` artifact (stage ``tile``).

``build_shell_scene(a)`` takes a mapping name -> array with the tiling artifact's arrays and builds
the boundary-face BVH and one SAH capsule BVH per exemplar (stages.core.bvh) over its wrapped fibre
pieces; node arrays of all exemplars are concatenated with ``ex_root[k]`` the root of exemplar k.
Both BVH builds are deterministic, so a scene rebuilt from the same artifact traces identically.
"""
import numpy as np

from stages.core.bvh import build_bvh_nodes, build_fiber_bvh
from stages.core.shell_traversal import ShellScene


def _f64(x):
    return np.ascontiguousarray(x, dtype=np.float64)


def build_shell_scene(a) -> ShellScene:
    tri = _f64(a["bnd_tri"])
    lo = tri.min(axis=1)
    hi = tri.max(axis=1)
    pad = 1e-9 * (np.abs(lo) + np.abs(hi)) + 1e-12
    bn = build_bvh_nodes(lo - pad, hi + pad)
    piece_ex = np.asarray(a["wrap_exemplar_pieces"], np.int64)
    W_off = np.asarray(a["wrap_offsets"], np.int64)
    W_pts = _f64(a["wrap_points"])
    W_rad = _f64(a["wrap_radius"])
    W_fib = np.asarray(a["wrap_fiber"], np.int64)
    W_seg0 = np.asarray(a["wrap_seg0"], np.int64)
    K = len(piece_ex) - 1
    pts, seg_a, seg_r, src, srcf = [], [], [], [], []
    nodes = {k: [] for k in ("lo", "hi", "left", "right", "start", "count")}
    prim = []
    roots = np.zeros(K, np.int64)
    p_off = s_off = n_off = 0
    for k in range(K):
        p0, p1 = piece_ex[k], piece_ex[k + 1]
        o = W_off[p0:p1 + 1]
        bvh, fso = build_fiber_bvh(W_pts[o[0]:o[-1]], o - o[0], W_rad[o[0]:o[-1]])
        pts.append(bvh.points)
        seg_a.append(bvh.seg_a + p_off)
        seg_r.append(bvh.seg_r)
        piece = bvh.seg_fiber.astype(np.int64) + p0
        local = np.arange(len(bvh.seg_a)) - fso[bvh.seg_fiber]
        src.append(W_seg0[piece] + local)
        srcf.append(W_fib[piece])
        roots[k] = n_off
        nodes["lo"].append(bvh.node_lo)
        nodes["hi"].append(bvh.node_hi)
        nodes["left"].append(np.where(bvh.node_left >= 0, bvh.node_left + n_off, -1))
        nodes["right"].append(np.where(bvh.node_right >= 0, bvh.node_right + n_off, -1))
        nodes["start"].append(bvh.node_start + len(np.concatenate(prim)) if prim else bvh.node_start)
        nodes["count"].append(bvh.node_count)
        prim.append(bvh.prim + s_off)
        p_off += len(bvh.points)
        s_off += len(bvh.seg_a)
        n_off += len(bvh.node_lo)
    cat = np.concatenate
    return ShellScene(
        _f64(a["planes"]), np.asarray(a["tet_neighbours"], np.int64), _f64(a["w2f"]), _f64(a["f2w"]),
        tri, np.asarray(a["bnd_tet"], np.int64), _f64(a["bnd_normal"]),
        bn[0], bn[1], bn[2].astype(np.int64), bn[3].astype(np.int64), bn[4], bn[5], bn[6],
        _f64(a["block_size"]), np.ascontiguousarray(a["block_map"], np.int32),
        np.ascontiguousarray(a["ex_nblocks"], np.int64),
        cat(pts), cat(seg_a), cat(seg_r), cat(src), cat(srcf).astype(np.int64),
        cat(nodes["lo"]), cat(nodes["hi"]), cat(nodes["left"]).astype(np.int64),
        cat(nodes["right"]).astype(np.int64), cat(nodes["start"]).astype(np.int64),
        cat(nodes["count"]).astype(np.int64), cat(prim).astype(np.int64), roots)


# ------------------------------------------------------------------------------------------------
# Path tracing a shell-mapped scene: the fiberpath estimator (stages.render.fiberpath: NEE with one
# sample per light + BSDF sampling, power heuristic, Russian roulette, same random dimensions), with
# the geometry queries of stages.core.shell_traversal instead of a flat fibre BVH. Materials are
# fiberpath's packed rows (BCSDF via the public stages.core.bcsdf eval / pdf / sample, Lambert),
# indexed by exemplar fibre id; the shading frame (tangent, normal) comes back from the shell map.
# Once fiberpath's trace_path takes its geometry queries as arguments, this copy can go.
import math  # noqa: E402

from numba import njit, prange  # noqa: E402

from stages.core.rng import uniform  # noqa: E402
from stages.core.shell_traversal import shell_trace  # noqa: E402

from .camera import camera_ray  # noqa: E402
from .fiber_lambert import lambert_eval, lambert_pdf, lambert_sample  # noqa: E402
from stages.core import bcsdf as B  # noqa: E402

from .fiberpath import MAT_BCSDF, MAT_LAMBERT  # noqa: E402
from .ground import ground_intersect  # noqa: E402
from .lights import light_eval, light_pdf, light_sample  # noqa: E402


@njit(cache=True)
def _mat_eval(mats, m, kind, t, n, wi, wo):
    if kind == MAT_BCSDF:
        return B.bcsdf_eval(mats[m, 1:11], t, wi, wo)
    return lambert_eval(n, mats[m, 11:14], wo)


@njit(cache=True)
def _mat_pdf(mats, m, kind, t, n, wi, wo):
    if kind == MAT_BCSDF:
        return B.bcsdf_pdf(mats[m, 1:11], t, wi, wo)
    return lambert_pdf(n, wo)


@njit(cache=True)
def _mat_sample(mats, m, kind, t, n, wi, u0, u1, u2):
    if kind == MAT_BCSDF:
        return B.bcsdf_sample(mats[m, 1:11], t, wi, u0, u1, u2)
    return lambert_sample(n, mats[m, 11:14], u1, u2)


@njit(cache=True)
def trace_path_shell(cam, sc, mat_of_fiber, mats, lights, env, marg, cond, ground, has_ground,
                     row, col, key, seed, max_depth, rr_depth, ign_window, eps, counters):
    """Radiance (r, g, b) and first-hit distance of one camera sample (see stages.render.fiberpath)."""
    u = uniform(seed, key, 0)
    v = uniform(seed, key, 1)
    o, d = camera_ray(cam, row, col, u, v)
    nl = lights.shape[0]
    dims_per_bounce = 4 + 2 * nl
    tp0 = tp1 = tp2 = 1.0
    L0 = L1 = L2 = 0.0
    first_t = 0.0
    ign_f = -1
    ign_s = -1
    cell = -1
    pdf_prev = 0.0
    n = np.zeros(3)
    wi = np.empty(3)
    p = np.empty(3)
    so = np.empty(3)
    depth = 0
    while True:
        t_hit, tet, s, fib, k, bi, bj, hp, t_tan, nrm, fl, rad = shell_trace(
            sc, cell, o[0], o[1], o[2], d[0], d[1], d[2], eps, np.inf, ign_f, ign_s, ign_window)
        counters[0] += 1
        tg = ground_intersect(ground, has_ground, o[2], d[2], eps)
        if tg < t_hit:
            t_hit = tg
            s = -2
        if s == -1:
            for kk in range(nl):
                lr, lg, lb = light_eval(lights, kk, env, marg, cond, d)
                if lr == 0.0 and lg == 0.0 and lb == 0.0:
                    continue
                w = 1.0
                if depth > 0:
                    pl = light_pdf(lights, kk, env, marg, cond, d)
                    w = pdf_prev * pdf_prev / (pdf_prev * pdf_prev + pl * pl)
                L0 += tp0 * lr * w
                L1 += tp1 * lg * w
                L2 += tp2 * lb * w
            break
        if depth == 0:
            first_t = t_hit
        if depth >= max_depth:
            break
        for c in range(3):
            p[c] = o[c] + t_hit * d[c]
            wi[c] = -d[c]
        if s >= 0:
            m = mat_of_fiber[fib]
            kind = int(mats[m, 0])
            n[0], n[1], n[2] = nrm[0], nrm[1], nrm[2]
            if kind == MAT_BCSDF:
                nf = fib
                ns = s
                for c in range(3):
                    so[c] = p[c]
            else:
                nf = -1
                ns = -1
                off = 1e-3 * rad + eps  # as fiberpath: a Lambertian vertex's rays start just off the surface
                for c in range(3):
                    so[c] = p[c] + off * n[c]
            galb = 0
            next_cell = tet
        else:
            m = -1
            kind = MAT_LAMBERT
            n[0] = 0.0; n[1] = 0.0; n[2] = 1.0 if d[2] < 0.0 else -1.0
            nf = -1
            ns = -1
            for c in range(3):
                so[c] = p[c] + eps * n[c]
            galb = 1
            next_cell = -1
        base = 2 + depth * dims_per_bounce
        for kk in range(nl):
            wl, lr, lg, lb, pl, delta = light_sample(lights, kk, env, marg, cond,
                                                     uniform(seed, key, base + 4 + 2 * kk),
                                                     uniform(seed, key, base + 5 + 2 * kk))
            if pl <= 0.0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
                continue
            if galb == 1:
                f0, f1, f2 = lambert_eval(n, ground[1:4], wl)
                pf = lambert_pdf(n, wl)
            else:
                f0, f1, f2 = _mat_eval(mats, m, kind, t_tan, n, wi, wl)
                pf = _mat_pdf(mats, m, kind, t_tan, n, wi, wl)
            if f0 == 0.0 and f1 == 0.0 and f2 == 0.0:
                continue
            counters[0] += 1
            ts = shell_trace(sc, next_cell, so[0], so[1], so[2], wl[0], wl[1], wl[2], eps, np.inf, nf, ns, ign_window)[0]
            if ts < np.inf:
                continue
            if ground_intersect(ground, has_ground, so[2], wl[2], eps) < np.inf:
                continue
            w = 1.0 if delta else pl * pl / (pl * pl + pf * pf) / pl
            L0 += tp0 * f0 * lr * w
            L1 += tp1 * f1 * lg * w
            L2 += tp2 * f2 * lb * w
        u0 = uniform(seed, key, base + 0)
        u1 = uniform(seed, key, base + 1)
        u2 = uniform(seed, key, base + 2)
        if galb == 1:
            wo, w0, w1, w2, pf = lambert_sample(n, ground[1:4], u1, u2)
        else:
            wo, w0, w1, w2, pf = _mat_sample(mats, m, kind, t_tan, n, wi, u0, u1, u2)
        if pf <= 0.0:
            break
        tp0 *= w0
        tp1 *= w1
        tp2 *= w2
        depth += 1
        if depth >= rr_depth:
            q = min(0.95, max(tp0, max(tp1, tp2)))
            if uniform(seed, key, base + 3) >= q:
                break
            tp0 /= q
            tp1 /= q
            tp2 /= q
        pdf_prev = pf
        for c in range(3):
            o[c] = so[c]
            d[c] = wo[c]
        ign_f = nf
        ign_s = ns
        cell = next_cell
    return L0, L1, L2, first_t


@njit(cache=True, parallel=True)
def render_tiles_shell(cam, sc, mat_of_fiber, mats, lights, env, marg, cond, ground, has_ground,
                       tiles, t_begin, t_end, spp, seed, max_depth, rr_depth, ign_window, eps,
                       film_sum, film_sq, hits, depth_sum, tile_rays):
    """``stages.render.fiberpath.render_tiles`` for a ShellScene."""
    W = int(cam[13])
    for ti in prange(t_begin, t_end):
        r0, c0, r1, c1 = tiles[ti, 0], tiles[ti, 1], tiles[ti, 2], tiles[ti, 3]
        counters = np.zeros(1, np.int64)
        for row in range(r0, r1):
            for col in range(c0, c1):
                for s in range(spp):
                    key = (row * W + col) * spp + s
                    r, g, b, ft = trace_path_shell(cam, sc, mat_of_fiber, mats, lights, env, marg, cond, ground,
                                                   has_ground, row, col, key, seed, max_depth, rr_depth,
                                                   ign_window, eps, counters)
                    film_sum[row, col, 0] += r
                    film_sum[row, col, 1] += g
                    film_sum[row, col, 2] += b
                    film_sq[row, col, 0] += r * r
                    film_sq[row, col, 1] += g * g
                    film_sq[row, col, 2] += b * b
                    if ft > 0.0:
                        hits[row, col] += 1.0
                        depth_sum[row, col] += ft
        tile_rays[ti] = counters[0]
