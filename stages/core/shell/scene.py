"""A shell-mapped fibre scene for ray casting: ``ShellScene`` (stages.core.shell.traversal) from the
arrays of a ``tiling`` artifact (stage ``tile``).

``build_shell_scene(a)`` takes a mapping name -> array with the tiling artifact's arrays and builds
the boundary-face BVH and one SAH capsule BVH per exemplar (stages.core.geometry.bvh) over its wrapped fibre
pieces; node arrays of all exemplars are concatenated with ``ex_root[k]`` the root of exemplar k (and
their 4-wide forms, ``fw_box`` / ``fw_child``, with ``ex_wide_root[k]``).
Both BVH builds are deterministic, so a scene rebuilt from the same artifact traces identically.
"""
import numpy as np

from stages.core.geometry.bvh import build_bvh_nodes, build_fiber_bvh, cache_aligned
from stages.core.geometry.wide_walk import LEAF_CODE
from stages.core.shell.traversal import ShellScene


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
    wide_box, wide_child = [], []
    roots = np.zeros(K, np.int64)
    wide_roots = np.zeros(K, np.int64)
    p_off = s_off = n_off = w_off = 0
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
        # 4-wide nodes: inner references shift by the wide nodes before, leaf ranges by the prims before
        ch = bvh.wide_child
        leaf = -1 - np.where(ch < 0, ch, -1)
        wide_child.append(np.where(ch >= 0, ch + w_off,
                                   -1 - ((leaf // LEAF_CODE + s_off) * LEAF_CODE + leaf % LEAF_CODE)))
        wide_box.append(bvh.wide_box)
        wide_roots[k] = w_off
        p_off += len(bvh.points)
        s_off += len(bvh.seg_a)
        n_off += len(bvh.node_lo)
        w_off += len(bvh.wide_box)
    cat = np.concatenate
    return ShellScene(
        _f64(a["planes"]), np.asarray(a["tet_neighbours"], np.int64), _f64(a["w2f"]), _f64(a["f2w"]),
        tri, np.asarray(a["bnd_tet"], np.int64), _f64(a["bnd_normal"]),
        bn[0], bn[1], bn[2].astype(np.int64), bn[3].astype(np.int64), bn[4], bn[5], bn[6],
        _f64(a["block_size"]), np.ascontiguousarray(a["block_map"], np.int32),
        np.ascontiguousarray(a["ex_nblocks"], np.int64),
        cat(pts), cat(seg_a), cat(seg_r), cat(src), cat(srcf).astype(np.int64),
        cat(nodes["lo"]).astype(np.float64), cat(nodes["hi"]).astype(np.float64), cat(nodes["left"]).astype(np.int64),
        cat(nodes["right"]).astype(np.int64), cat(nodes["start"]).astype(np.int64),
        cat(nodes["count"]).astype(np.int64), cat(prim).astype(np.int64), roots,
        cache_aligned(cat(wide_box)), cache_aligned(cat(wide_child).astype(np.int64)), wide_roots)

