"""Two of issue 24's routes to a faster fibre BVH, measured on realized fibres before anyone builds them:
spatial splits (SBVH) and ray streams sorted by direction. Prints JSON. Not run by tests or
``bench/run.py`` (it takes about a minute; ``bench_mitsuba.py`` holds the speed comparison itself).

    python bench/bvh_routes.py [--fibers out/bench_bysdf/fibers.zarr] [--scene data/scenes/demo.toml]

(``make bench`` leaves the demo swatch's fibres in ``out/bench_bysdf/``; ``loomlight realize`` makes others.)

1. **Capsule shape.** Segment length over diameter, and each capsule's box volume over its own volume
   against the same capsule's if it lay along an axis (the tightest an axis-aligned box gets).
2. **Spatial splits** (Stich et al. 2009). For internal nodes of loomlight's binned-SAH tree, sampled in
   three size classes: the SAH cost of the object split the build chose (its two children,
   sum of area x count over the parent's area) against the best binned spatial split (15 planes per
   axis; a capsule goes to every side it reaches, with its box clipped to that side: the part of the
   segment within r of the side, grown by r, cut at the plane). Reported: how often the spatial split
   is cheaper, the median ratio, and the mean cost ratio the SBVH rule (take the cheaper) would give.
3. **Ray order.** The camera's first fibre hits at 128 x 96 x 16 become bounce rays with uniform random
   directions (a fibre's scattering is broad); one thread walks them nearest-hit in the order a path
   tracer makes them (pixel by pixel), in random order, by origin alone (Morton order), sorted by
   direction octant then origin, and by 64 direction bins then origin. Sorting is what ray-stream tracers do to share node visits
   between rays; loomlight's traversal takes one ray at a time.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LOOMLIGHT_NUMBA_CACHE_ROOT", str(ROOT / ".numba_cache"))
import stages  # noqa: E402,F401  (NUMBA_CACHE_DIR before numba loads)

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from stages.core.geometry.surface import surface_hit  # noqa: E402
from stages.core.rng import uniform  # noqa: E402
from stages.render.camera import camera_ray  # noqa: E402

PLANES = 16   # spatial split bins per axis (15 planes)


def _area(lo, hi):
    e = np.maximum(hi - lo, 0.0)
    return 2.0 * (e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0])


def capsule_shape(a, b, r) -> dict:
    L = np.linalg.norm(b - a, axis=1)
    vcap = np.pi * r ** 2 * L + 4.0 / 3.0 * np.pi * r ** 3
    vbox = np.prod(np.maximum(a, b) - np.minimum(a, b) + 2.0 * r[:, None], axis=1)
    valigned = (L + 2.0 * r) * (2.0 * r) ** 2
    return {"length_over_diameter_median": float(np.median(L / (2 * r))),
            "length_over_diameter_p10_p90": np.percentile(L / (2 * r), [10, 90]).tolist(),
            "box_over_capsule_volume_median": float(np.median(vbox / vcap)),
            "box_over_capsule_volume_if_axis_aligned_median": float(np.median(valigned / vcap))}


def _clipped(a, b, r, ax, x0, x1):
    """Boxes of the capsules' parts with coordinate ``ax`` in [x0, x1], and which capsules reach it."""
    da = b[:, ax] - a[:, ax]
    inside = (a[:, ax] >= x0 - r) & (a[:, ax] <= x1 + r)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (x0 - r - a[:, ax]) / da
        t1 = (x1 + r - a[:, ax]) / da
    tl = np.clip(np.where(da != 0, np.minimum(t0, t1), np.where(inside, 0.0, 2.0)), 0.0, 1.0)
    th = np.clip(np.where(da != 0, np.maximum(t0, t1), np.where(inside, 1.0, -1.0)), 0.0, 1.0)
    pa = a + tl[:, None] * (b - a)
    pb = a + th[:, None] * (b - a)
    lo = np.minimum(pa, pb) - r[:, None]
    hi = np.maximum(pa, pb) + r[:, None]
    lo[:, ax] = np.maximum(lo[:, ax], x0)
    hi[:, ax] = np.minimum(hi[:, ax], x1)
    return lo, hi, (th >= tl) & (hi[:, ax] >= lo[:, ax])


def spatial_splits(bvh, samples=(600, 600, 200), seed=0) -> list[dict]:
    A, B, R = bvh.points[bvh.seg_a], bvh.points[bvh.seg_a + 1], bvh.seg_r
    nlo, nhi = bvh.node_lo.astype(np.float64), bvh.node_hi.astype(np.float64)
    left, right, start, count, prim = bvh.node_left, bvh.node_right, bvh.node_start, bvh.node_count, bvh.prim
    rng = np.random.default_rng(seed)
    internal = np.flatnonzero(left >= 0)
    out = []
    for (lo_n, hi_n), n_pick in zip(((16, 64), (64, 1024), (1024, 1 << 62)), samples):
        cand = internal[(count[internal] >= lo_n) & (count[internal] < hi_n)]
        ratios, overlap = [], []
        for node in rng.choice(cand, size=min(n_pick, len(cand)), replace=False):
            p = prim[start[node]:start[node] + count[node]]
            a, b, r = A[p], B[p], R[p]
            parent = _area(nlo[node], nhi[node])
            L, Rn = left[node], right[node]
            obj = (_area(nlo[L], nhi[L]) * count[L] + _area(nlo[Rn], nhi[Rn]) * count[Rn]) / parent
            overlap.append(_area(np.maximum(nlo[L], nlo[Rn]), np.minimum(nhi[L], nhi[Rn])) / parent)
            best = np.inf
            for ax in range(3):
                x0, x1 = nlo[node, ax], nhi[node, ax]
                for k in range(1, PLANES):
                    xs = x0 + (x1 - x0) * k / PLANES
                    l1, h1, t1 = _clipped(a, b, r, ax, x0, xs)
                    l2, h2, t2 = _clipped(a, b, r, ax, xs, x1)
                    if not t1.any() or not t2.any():
                        continue
                    c = (_area(l1[t1].min(0), h1[t1].max(0)) * t1.sum()
                         + _area(l2[t2].min(0), h2[t2].max(0)) * t2.sum()) / parent
                    best = min(best, c)
            ratios.append(best / obj)
        ratios = np.asarray(ratios)
        out.append({"node_segments": [lo_n, hi_n if hi_n < 1 << 62 else None], "nodes": int(len(cand)),
                    "sampled": int(len(ratios)), "children_overlap_area_over_parent": float(np.mean(overlap)),
                    "spatial_cheaper_fraction": float((ratios < 1.0).mean()),
                    "spatial_over_object_median": float(np.median(ratios)),
                    "sbvh_over_object_mean": float(np.minimum(ratios, 1.0).mean())})
    return out


@njit(cache=True)
def _bounce_rays(G, cam, W, H, spp, eps, win, O, D, F, S):
    """First fibre hits of the camera's rays, each with a uniform random direction: (count)."""
    n = 0
    for row in range(H):
        for col in range(W):
            for s in range(spp):
                idx = (row * W + col) * spp + s
                o, d = camera_ray(cam, row, col, uniform(0, idx, 0), uniform(0, idx, 1))
                h = surface_hit(G, -1, o[0], o[1], o[2], d[0], d[1], d[2], eps, np.inf, -1, -1, win)
                if h.prim < 0:
                    continue
                for k in range(3):
                    O[n, k] = o[k] + h.t * d[k]
                z = 1.0 - 2.0 * uniform(1, idx, 0)
                phi = 2.0 * np.pi * uniform(1, idx, 1)
                sr = np.sqrt(max(0.0, 1.0 - z * z))
                D[n, 0] = sr * np.cos(phi)
                D[n, 1] = sr * np.sin(phi)
                D[n, 2] = z
                F[n] = h.fiber
                S[n] = h.prim
                n += 1
    return n


@njit(cache=True)
def _walk(G, O, D, F, S, order, eps, win):
    acc = 0.0
    for i in order:
        h = surface_hit(G, -1, O[i, 0], O[i, 1], O[i, 2], D[i, 0], D[i, 1], D[i, 2], eps, np.inf, F[i], S[i], win)
        if h.prim >= 0:
            acc += h.t
    return acc


def _morton(P, bits=10):
    q = ((P - P.min(0)) / (np.ptp(P, 0).max() + 1e-30) * ((1 << bits) - 1)).astype(np.uint64)
    code = np.zeros(len(P), np.uint64)
    for b in range(bits):
        for k in range(3):
            code |= ((q[:, k] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + k)
    return code


def ray_order(scene_path, fibers, W=128, H=96, spp=16, repeats=3) -> dict:
    from pipeline.renderers import method
    from pipeline.renderers.fiberpath import film_setup
    from pipeline.runners.render import resolve_options
    from pipeline.scene import load_scene

    scene = load_scene(scene_path)
    opts = resolve_options(scene, method("fiberpath"), width=W, height=H, spp=spp, fibers=str(fibers), extra={})
    setup = film_setup(scene, opts)
    G, it = setup.integ.scene, setup.integ
    N = W * H * spp
    O, D = np.zeros((N, 3)), np.zeros((N, 3))
    F, S = np.zeros(N, np.int64), np.zeros(N, np.int64)
    n = _bounce_rays(G, setup.cam, W, H, spp, it.eps, it.ign_window, O, D, F, S)
    O, D, F, S = O[:n], D[:n], F[:n], S[:n]
    octant = ((D[:, 0] > 0) * 4 + (D[:, 1] > 0) * 2 + (D[:, 2] > 0)).astype(np.int64)
    zb = np.clip(((D[:, 2] + 1.0) * 4.0).astype(np.int64), 0, 7)
    pb = np.clip(((np.arctan2(D[:, 1], D[:, 0]) + np.pi) / (2 * np.pi) * 8.0).astype(np.int64), 0, 7)
    t0 = time.perf_counter()
    by_octant = np.lexsort((_morton(O), octant))
    sort_s = time.perf_counter() - t0
    orders = {"pixel": np.arange(n), "random": np.random.default_rng(0).permutation(n), "origin": np.argsort(_morton(O)),
              "octant_then_origin": by_octant, "direction64_then_origin": np.lexsort((_morton(O), zb * 8 + pb))}
    _walk(G, O, D, F, S, orders["pixel"][:16], it.eps, it.ign_window)   # compile (or load) apart
    best = {}
    for _ in range(repeats):
        for k, order in orders.items():
            t0 = time.perf_counter()
            _walk(G, O, D, F, S, order, it.eps, it.ign_window)
            best[k] = min(best.get(k, np.inf), time.perf_counter() - t0)
    return {"bounce_rays": int(n), "threads": 1, "sort_s_octant_then_origin": sort_s,
            **{f"{k}_s": v for k, v in best.items()},
            **{f"{k}_ns_per_ray": v / n * 1e9 for k, v in best.items()},
            **{f"{k}_over_pixel": v / best["pixel"] for k, v in best.items()}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fibers", default=str(ROOT / "out" / "bench_bysdf" / "fibers.zarr"))
    ap.add_argument("--scene", default=str(ROOT / "data" / "scenes" / "demo.toml"))
    args = ap.parse_args(argv)
    from pipeline.render_setup import load_fibers
    from stages.core.geometry.bvh import build_fiber_bvh

    f = load_fibers(args.fibers)
    bvh, _ = build_fiber_bvh(f.points, f.fiber_offsets, f.point_radius)
    A, B = bvh.points[bvh.seg_a], bvh.points[bvh.seg_a + 1]
    res = {"fibers": args.fibers, "segments": int(len(bvh.seg_a)), "binary_nodes": int(len(bvh.node_left)),
           "capsule_shape": capsule_shape(A, B, bvh.seg_r), "spatial_splits": spatial_splits(bvh),
           "ray_order": ray_order(args.scene, args.fibers)}
    print(json.dumps(res, indent=2))
    return res


if __name__ == "__main__":
    main()
