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
3. **Ray order.** The camera's first fibre hits at 128 x 96 x 16 become bounce rays, 1e-4 off the surface in
   cosine-distributed directions about the normal (a diffuse bounce); one thread walks them nearest-hit in the
   order a path tracer makes them (pixel by pixel), in random order, by origin alone (Morton order), sorted by
   direction octant then origin, and by 64 direction bins then origin. Sorting is what ray-stream tracers do
   to share node visits between rays; loomlight's traversal takes one ray at a time.
4. **A library: Embree 4.** The ``embreex`` wheel on PyPI (now one of loomlight's dependencies: fiberpath's
   default tracer, ``stages.core.geometry.embree``, came out of this probe) carries a whole ``libembree4``,
   though its Python API only builds triangle meshes. The same fibres go in as Embree round linear curves (a
   vertex and radius per fibre point, a segment per capsule), and a numba loop calls ``rtcIntersect1`` through
   ctypes one ray at a time, beside the same loop over loomlight's ``surface_hit``, on the camera rays and the
   bounce rays above (no segments skipped; both also compute the hit's normal, as a path tracer must).
   Reported: both build times, ns per ray, hit counts and the summed hit distances. The hits differ only where
   Embree's float32 curve test differs from loomlight's float64 capsule test (near-ties at joints, grazing
   rays; the vertices here are shared at joints, where Embree interpolates the points' radii, as
   ``stages.core.geometry.embree`` does not). (numba cannot cache a kernel that calls a ctypes function: these
   two compile every run.) Skipped with the reason when ``embreex`` is missing.
5. **The same, end to end.** One Lambertian path tracer (unit sky, albedo 0.75, max depth 16, cosine
   sampling, 64 x 48 @ 16 spp, one thread) written twice, identical but for the traversal: loomlight's
   ``surface_hit`` (the normal from the capsule's axis) or ``rtcIntersect1`` (Embree's geometric normal).
   Reported: both times, rays and mean radiances (they differ where the hits do, see 4).
6. **Packets.** fiberpath's own Embree scene (``stages.core.geometry.embree``: a curve segment per
   capsule) traced one ray per ``rtcIntersect1`` call against 16 consecutive rays per ``rtcIntersect16``
   call (the packet API Mitsuba's vectorised wavefront uses), camera and bounce rays in pixel order, one
   thread: ns per ray, hits and summed distances of each; and fiberpath's whole query on the same rays
   (``embree_intersect``: ``rtcIntersect1``, then the float64 re-intersection of the hit and its chain
   neighbour), whose cost over the bare call (``fiberpath_over_single``) is what the float64 answer costs.
7. **Point queries** (the realized volpath source: ``realized_medium.covering_segment``, the segment of
   the lowest-index fibre whose capsule holds a point, walked in loomlight's 4-wide tree). Embree's
   ``rtcPointQuery`` on fiberpath's curve scene (reported: how many times it calls back, which is never:
   Embree 4 does not visit curve primitives in point queries, embree issue 480), and on a user geometry
   of the same capsules (a bounds callback per capsule; the point-query callback keeps the lowest fibre,
   as ``covering_segment`` does), against ``covering_segment_arrays`` on 300,000 points near fibres
   (within about a radius of a random segment) and 300,000 uniform in the fibres' box, one thread:
   ns per query, the answers that agree, and both builds.
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

# isort: split

import numpy as np  # noqa: E402  (after sys.path and stages set-up)
from numba import njit, types  # noqa: E402  (after sys.path and stages set-up)

from stages.core.geometry.embree import embree_intersect  # noqa: E402  (after sys.path and stages set-up)
from stages.core.geometry.surface import Skip, surface_hit  # noqa: E402  (after sys.path and stages set-up)
from stages.core.geometry.wide_walk import Ray  # noqa: E402  (after sys.path and stages set-up)
from stages.core.rng import uniform  # noqa: E402  (after sys.path and stages set-up)
from stages.render.camera import camera_ray  # noqa: E402  (after sys.path and stages set-up)
from stages.render.media.realized_medium import covering_segment_arrays  # noqa: E402  (after sys.path and stages set-up)

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
def _cosine_direction(n, u1, u2, out):
    """Cosine-weighted direction about the unit normal n (Malley)."""
    if abs(n[0]) > 0.5:
        t0, t1, t2 = -n[1], n[0], 0.0
    else:
        t0, t1, t2 = 0.0, -n[2], n[1]
    tl = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0 /= tl
    t1 /= tl
    t2 /= tl
    b0, b1, b2 = n[1] * t2 - n[2] * t1, n[2] * t0 - n[0] * t2, n[0] * t1 - n[1] * t0
    r = np.sqrt(u1)
    x, y, z = r * np.cos(2.0 * np.pi * u2), r * np.sin(2.0 * np.pi * u2), np.sqrt(max(0.0, 1.0 - u1))
    out[0] = x * t0 + y * b0 + z * n[0]
    out[1] = x * t1 + y * b1 + z * n[1]
    out[2] = x * t2 + y * b2 + z * n[2]


@njit(cache=True)
def _capsule_normal(G, prim, o, d, t, n):
    """Unit normal of segment ``prim``'s capsule at o + t d (from its axis), faced against d."""
    a = G.seg_a[prim]
    w = 0.0
    ab2 = 0.0
    for k in range(3):
        ab = G.points[a + 1, k] - G.points[a, k]
        w += (o[k] + t * d[k] - G.points[a, k]) * ab
        ab2 += ab * ab
    w = min(1.0, max(0.0, w / max(ab2, 1e-300)))
    nl = 0.0
    for k in range(3):
        n[k] = o[k] + t * d[k] - (G.points[a, k] + w * (G.points[a + 1, k] - G.points[a, k]))
        nl += n[k] * n[k]
    flip = -1.0 if n[0] * d[0] + n[1] * d[1] + n[2] * d[2] > 0.0 else 1.0
    for k in range(3):
        n[k] *= flip / np.sqrt(nl)


@njit(cache=True)
def _camera_rays(cam, W, H, spp, O, D):
    """The camera's rays, pixel by pixel and sample by sample (the tile loop's jitter)."""
    for row in range(H):
        for col in range(W):
            for s in range(spp):
                idx = (row * W + col) * spp + s
                o, d = camera_ray(cam, row, col, uniform(0, idx, 0), uniform(0, idx, 1))
                for k in range(3):
                    O[idx, k] = o[k]
                    D[idx, k] = d[k]


@njit(cache=True)
def _bounce_rays(G, Oc, Dc, eps, win, O, D, F, S):
    """First fibre hits of the camera rays (Oc, Dc), each leaving 1e-4 off the surface in a
    cosine-distributed direction about the normal (a diffuse bounce): (count)."""
    n = 0
    o = np.empty(3)
    d = np.empty(3)
    nrm = np.empty(3)
    dn = np.empty(3)
    for idx in range(Oc.shape[0]):
        for k in range(3):
            o[k] = Oc[idx, k]
            d[k] = Dc[idx, k]
        h = surface_hit(G, -1, Ray(o[0], o[1], o[2], d[0], d[1], d[2]), eps, np.inf, Skip(-1, -1, win))
        if h.prim < 0:
            continue
        _capsule_normal(G, h.prim, o, d, h.t, nrm)
        _cosine_direction(nrm, uniform(1, idx, 0), uniform(1, idx, 1), dn)
        for k in range(3):
            O[n, k] = o[k] + h.t * d[k] + 1e-4 * nrm[k]
            D[n, k] = dn[k]
        F[n] = h.fiber
        S[n] = h.prim
        n += 1
    return n


@njit(cache=True)
def _walk(G, O, D, F, S, order, eps, win):
    acc = 0.0
    for i in order:
        h = surface_hit(G, -1, Ray(O[i, 0], O[i, 1], O[i, 2], D[i, 0], D[i, 1], D[i, 2]), eps, np.inf,
                        Skip(F[i], S[i], win))
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
    from pipeline.runners.render import RenderRequest, resolve_options
    from pipeline.scene import load_scene

    scene = load_scene(scene_path)
    # loomlight's own BVH: the walk measured here
    opts = resolve_options(scene, method("fiberpath"),
                           RenderRequest(width=W, height=H, spp=spp, fibers=str(fibers), extra={"accel": "bvh"}))
    setup = film_setup(scene, opts)
    G, it = setup.integ.scene, setup.integ
    N = W * H * spp
    O, D = np.zeros((N, 3)), np.zeros((N, 3))
    F, S = np.zeros(N, np.int64), np.zeros(N, np.int64)
    Oc, Dc = np.zeros((N, 3)), np.zeros((N, 3))
    _camera_rays(setup.cam, W, H, spp, Oc, Dc)
    n = _bounce_rays(G, Oc, Dc, it.eps, it.ign_window, O, D, F, S)
    O, D, F, S = O[:n], D[:n], F[:n], S[:n]
    octant = ((D[:, 0] > 0) * 4 + (D[:, 1] > 0) * 2 + (D[:, 2] > 0)).astype(np.int64)
    zb = np.clip(((D[:, 2] + 1.0) * 4.0).astype(np.int64), 0, 7)
    pb = np.clip(((np.arctan2(D[:, 1], D[:, 0]) + np.pi) / (2 * np.pi) * 8.0).astype(np.int64), 0, 7)
    t0 = time.perf_counter()
    by_octant = np.lexsort((_morton(O), octant))
    sort_s = time.perf_counter() - t0
    orders = {"pixel": np.arange(n), "random": np.random.default_rng(0).permutation(n),
              "origin": np.argsort(_morton(O)), "octant_then_origin": by_octant,
              "direction64_then_origin": np.lexsort((_morton(O), zb * 8 + pb))}
    _walk(G, O, D, F, S, orders["pixel"][:16], it.eps, it.ign_window)   # compile (or load) apart
    best = {}
    for _ in range(repeats):
        for k, order in orders.items():
            t0 = time.perf_counter()
            _walk(G, O, D, F, S, order, it.eps, it.ign_window)
            best[k] = min(best.get(k, np.inf), time.perf_counter() - t0)
    res = {"bounce_rays": int(n), "threads": 1, "sort_s_octant_then_origin": sort_s,
           **{f"{k}_s": v for k, v in best.items()},
           **{f"{k}_ns_per_ray": v / n * 1e9 for k, v in best.items()},
           **{f"{k}_over_pixel": v / best["pixel"] for k, v in best.items()}}
    # the library comparison's rays: the camera's, and the bounce rays (already 1e-4 off the surface)
    rays = {"camera": (Oc, Dc), "bounce": (O, D)}
    return res, rays, G, it.ign_window


def _embree():
    """ctypes bindings of the libembree4 inside the embreex wheel: (library, rtcIntersect1 taking addresses)."""
    import ctypes
    import glob

    import embreex

    libs = glob.glob(os.path.join(os.path.dirname(embreex.__file__), os.pardir, "embreex.libs", "libembree4*"))
    if not libs:
        raise ImportError("the embreex wheel carries no libembree4")
    E = ctypes.CDLL(libs[0])
    vp, c_int, c_uint, c_size = ctypes.c_void_p, ctypes.c_int, ctypes.c_uint, ctypes.c_size_t
    for name, res, args in (("rtcNewDevice", vp, [ctypes.c_char_p]), ("rtcNewScene", vp, [vp]),
                            ("rtcNewGeometry", vp, [vp, c_int]),
                            ("rtcSetNewGeometryBuffer", vp, [vp, c_int, c_uint, c_int, c_size, c_size]),
                            ("rtcCommitGeometry", None, [vp]), ("rtcAttachGeometry", c_uint, [vp, vp]),
                            ("rtcReleaseGeometry", None, [vp]), ("rtcCommitScene", None, [vp]),
                            ("rtcGetDeviceError", c_int, [vp]), ("rtcReleaseScene", None, [vp]),
                            ("rtcReleaseDevice", None, [vp])):
        fn = getattr(E, name)
        fn.restype, fn.argtypes = res, args
    # pointers as size_t, so that numba can pass array addresses
    return E, ctypes.CFUNCTYPE(None, c_size, c_size, c_size)(("rtcIntersect1", E))


ROUND_LINEAR_CURVE, BUFFER_INDEX, BUFFER_VERTEX, FORMAT_UINT, FORMAT_FLOAT4 = 16, 0, 1, 0x5001, 0x9004
NO_HIT = 0xFFFFFFFF


def _embree_scene(E, bvh):
    """(device, committed scene) of the fibres as one geometry of Embree round linear curves, one thread."""
    import ctypes

    P, rad = bvh.points, np.zeros(len(bvh.points))
    rad[bvh.seg_a] = bvh.seg_r      # a segment's radius at its first point (loomlight capsules: one radius each)
    rad[bvh.seg_a + 1] = np.maximum(rad[bvh.seg_a + 1], bvh.seg_r)
    dev = E.rtcNewDevice(b"threads=1")
    scene = E.rtcNewScene(dev)
    geom = E.rtcNewGeometry(dev, ROUND_LINEAR_CURVE)
    nv, ns = len(P), len(bvh.seg_a)
    vb = E.rtcSetNewGeometryBuffer(geom, BUFFER_VERTEX, 0, FORMAT_FLOAT4, 16, nv)
    V = np.ctypeslib.as_array((ctypes.c_float * (4 * nv)).from_address(vb)).reshape(nv, 4)
    V[:, :3] = P
    V[:, 3] = rad
    ib = E.rtcSetNewGeometryBuffer(geom, BUFFER_INDEX, 0, FORMAT_UINT, 4, ns)
    np.ctypeslib.as_array((ctypes.c_uint32 * ns).from_address(ib))[:] = bvh.seg_a.astype(np.uint32)
    E.rtcCommitGeometry(geom)
    E.rtcAttachGeometry(scene, geom)
    E.rtcReleaseGeometry(geom)
    E.rtcCommitScene(scene)
    return dev, scene


ALBEDO, DEPTH = 0.75, 16   # the Lambertian path tracer: bench_mitsuba's fibre albedo and depth


@njit(cache=True)
def _path_step(o, d, n, t, u1, u2):
    """Move the path to its hit, 1e-4 off along the unit normal n (faced to the ray), and draw its next
    direction."""
    for k in range(3):
        o[k] = o[k] + t * d[k] + 1e-4 * n[k]
    _cosine_direction(n, u1, u2, d)


def _path_tracer(nearest):
    """A Lambertian path tracer under a unit sky whose traversal is ``nearest(scene, o, d, n)`` (the hit
    distance, inf on a miss, and the unit normal faced to the ray in n): (mean radiance, rays)."""
    @njit
    def path(scene, cam, W, H, spp):
        total, rays = 0.0, 0
        n = np.empty(3)
        for row in range(H):
            for col in range(W):
                for s in range(spp):
                    idx = (row * W + col) * spp + s
                    o, d = camera_ray(cam, row, col, uniform(0, idx, 0), uniform(0, idx, 1))
                    tp = 1.0
                    for depth in range(DEPTH + 1):
                        t = nearest(scene, o, d, n)
                        rays += 1
                        if t == np.inf:
                            total += tp
                            break
                        if depth == DEPTH:
                            break
                        _path_step(o, d, n, t, uniform(2, idx, 2 * depth), uniform(2, idx, 2 * depth + 1))
                        tp *= ALBEDO
        return total / (W * H * spp), rays
    return path


@njit(cache=True)
def _nearest_loomlight(scene, o, d, n):
    """``_path_tracer``'s traversal on loomlight's BVH; scene = (FiberBVH, ignore window)."""
    G, win = scene
    h = surface_hit(G, -1, Ray(o[0], o[1], o[2], d[0], d[1], d[2]), 0.0, np.inf, Skip(-1, -1, win))
    if h.prim < 0:
        return np.inf
    _capsule_normal(G, h.prim, o, d, h.t, n)
    return h.t


def _embree_nearest(intersect1):
    @njit
    def nearest(scene, o, d, n):
        """``_path_tracer``'s traversal through rtcIntersect1; scene = (Embree scene, RTCRayHit float32[32])."""
        handle, rayhit = scene
        u = rayhit.view(np.uint32)
        for k in range(3):
            rayhit[k] = o[k]
            rayhit[4 + k] = d[k]
        rayhit[3] = 0.0
        rayhit[7] = 0.0
        rayhit[8] = np.inf
        u[9] = NO_HIT
        u[10] = 0
        u[11] = 0
        u[18] = NO_HIT
        u[19] = NO_HIT
        intersect1(handle, rayhit.ctypes.data, 0)
        if u[18] == NO_HIT:
            return np.inf
        nl = np.sqrt(float(rayhit[12]) ** 2 + float(rayhit[13]) ** 2 + float(rayhit[14]) ** 2)
        flip = -1.0 if rayhit[12] * d[0] + rayhit[13] * d[1] + rayhit[14] * d[2] > 0.0 else 1.0
        for k in range(3):
            n[k] = flip * rayhit[12 + k] / nl
        return float(rayhit[8])
    return nearest


def _walker(nearest):
    """Nearest hits of rays (O, D) through ``nearest`` (``_path_tracer``'s traversal, normal included):
    (summed hit distance, hits)."""
    @njit
    def walk(scene, O, D):
        acc = 0.0
        hits = 0
        o = np.empty(3)
        d = np.empty(3)
        n = np.empty(3)
        for i in range(O.shape[0]):
            for k in range(3):
                o[k] = O[i, k]
                d[k] = D[i, k]
            t = nearest(scene, o, d, n)
            if t < np.inf:
                acc += t
                hits += 1
        return acc, hits
    return walk


def embree_path_tracer(bvh, G, win, scene_path, W=64, H=48, spp=16, repeats=3) -> dict:
    """One Lambertian path tracer (unit sky, albedo 0.75, max depth 16, one thread), its traversal swapped."""
    from pipeline.scene import camera_array, load_scene

    cam = camera_array(load_scene(scene_path).camera, W, H)
    try:
        E, intersect1 = _embree()
    except ImportError as e:
        return {"skipped": f"embreex not installed or unusable ({e}); pip install embreex"}
    dev, scene = _embree_scene(E, bvh)
    tracers = {"loomlight": (_path_tracer(_nearest_loomlight), (G, win)),
               "embree": (_path_tracer(_embree_nearest(intersect1)), (scene, np.zeros(32, np.float32)))}
    for path, arg in tracers.values():
        path(arg, cam, 2, 2, 1)   # compile apart
    best = {}
    for _ in range(repeats):
        for name, (path, arg) in tracers.items():
            t0 = time.perf_counter()
            mean, rays = path(arg, cam, W, H, spp)
            dt = time.perf_counter() - t0
            if dt < best.get(name, (np.inf,))[0]:
                best[name] = (dt, mean, rays)
    E.rtcReleaseScene(scene)
    E.rtcReleaseDevice(dev)
    return {"image": f"{W}x{H} @ {spp} spp, one thread", **{f"{k}_s": v[0] for k, v in best.items()},
            **{f"{k}_mean": v[1] for k, v in best.items()}, **{f"{k}_rays": v[2] for k, v in best.items()},
            "loomlight_over_embree": best["loomlight"][0] / best["embree"][0]}


def embree_library(bvh, G, win, rays: dict, repeats=3) -> dict:
    """Embree 4 (from embreex) against loomlight's BVH on the same fibres and rays, one thread each."""
    try:
        E, intersect1 = _embree()
    except ImportError as e:
        return {"skipped": f"embreex not installed or unusable ({e}); pip install embreex"}
    t0 = time.perf_counter()
    dev, scene = _embree_scene(E, bvh)
    build_s = time.perf_counter() - t0
    out = {"embree_build_s_1_thread": build_s, "embree_error": int(E.rtcGetDeviceError(dev)), "threads": 1}
    walkers = {"loomlight": (_walker(_nearest_loomlight), (G, win)),
               "embree": (_walker(_embree_nearest(intersect1)), (scene, np.zeros(32, np.float32)))}
    for name, (O, D) in rays.items():
        best = {}
        for _ in range(repeats + 1):   # the first round compiles (or loads)
            for key, (walk, arg) in walkers.items():
                t0 = time.perf_counter()
                r = walk(arg, O, D)
                best[key] = (min(best.get(key, (np.inf,))[0], time.perf_counter() - t0), r[0], r[1])
        (te, se, he), (tl, sl, hl) = best["embree"], best["loomlight"]
        out[name] = {"rays": int(len(O)), "embree_ns_per_ray": te / len(O) * 1e9,
                     "loomlight_ns_per_ray": tl / len(O) * 1e9, "loomlight_over_embree": tl / te,
                     "embree_hits": int(he), "loomlight_hits": int(hl),
                     "embree_sum_t": float(se), "loomlight_sum_t": float(sl)}
    E.rtcReleaseScene(scene)
    E.rtcReleaseDevice(dev)
    return out


_intersect1 = types.ExternalFunction("rtcIntersect1", types.void(types.intp, types.intp, types.intp))
_intersect16 = types.ExternalFunction("rtcIntersect16", types.void(types.intp, types.intp, types.intp, types.intp))
PACKET = 16


@njit(cache=True)
def _single_rays(handle, O, D, buf):
    """rtcIntersect1 per ray (``buf``: float32[32], 16-byte aligned, one RTCRayHit): (hits, summed t)."""
    u = buf.view(np.uint32)
    hits, acc = 0, 0.0
    for i in range(O.shape[0]):
        for k in range(3):
            buf[k] = O[i, k]
            buf[4 + k] = D[i, k]
        buf[3] = 0.0
        buf[7] = 0.0
        buf[8] = np.inf
        u[9] = 0xFFFFFFFF
        u[10] = 0
        u[11] = 0
        u[18] = 0xFFFFFFFF
        _intersect1(handle, buf.ctypes.data, 0)
        if u[18] != 0xFFFFFFFF:
            hits += 1
            acc += buf[8]
    return hits, acc


@njit(cache=True)
def _packet_rays(handle, O, D, buf, valid):
    """rtcIntersect16 on runs of 16 consecutive rays (``buf``: float32[16 * 24], 64-byte aligned, one
    RTCRayHit16: each field 16 wide; ``valid`` int32[16], 64-byte aligned): (hits, summed t)."""
    u = buf.view(np.uint32)
    hits, acc = 0, 0.0
    n = O.shape[0]
    for p0 in range(0, n, PACKET):
        m = min(PACKET, n - p0)
        for j in range(PACKET):
            valid[j] = -1 if j < m else 0
            i = p0 + min(j, m - 1)
            for k in range(3):
                buf[k * PACKET + j] = O[i, k]
                buf[(4 + k) * PACKET + j] = D[i, k]
            buf[3 * PACKET + j] = 0.0
            buf[7 * PACKET + j] = 0.0
            buf[8 * PACKET + j] = np.inf
            u[9 * PACKET + j] = 0xFFFFFFFF
            u[10 * PACKET + j] = 0
            u[11 * PACKET + j] = 0
            u[18 * PACKET + j] = 0xFFFFFFFF
        _intersect16(valid.ctypes.data, handle, buf.ctypes.data, 0)
        for j in range(m):
            if u[18 * PACKET + j] != 0xFFFFFFFF:
                hits += 1
                acc += buf[8 * PACKET + j]
    return hits, acc


@njit(cache=True, _nrt=False)
def _fiberpath_rays(fibers, O, D):
    """fiberpath's own Embree query per ray (``embree_intersect``: rtcIntersect1, then the hit and its chain
    neighbour re-intersected in float64): (hits, summed t)."""
    hits, acc = 0, 0.0
    for i in range(O.shape[0]):
        t, s = embree_intersect(fibers, O[i, 0], O[i, 1], O[i, 2], D[i, 0], D[i, 1], D[i, 2], 0.0, np.inf, -1, -1, 0)
        if s >= 0:
            hits += 1
            acc += t
    return hits, acc


def _aligned(n, dtype, align=64):
    raw = np.zeros(n * np.dtype(dtype).itemsize + align, np.uint8)
    off = (-raw.ctypes.data) % align
    return raw[off:off + n * np.dtype(dtype).itemsize].view(dtype)


def embree_packets(points, fiber_offsets, point_radius, rays: dict, repeats=3) -> dict:
    """Embree's packet API against one ray at a time, on fiberpath's own Embree scene
    (``stages.core.geometry.embree``) and the camera and bounce rays in the order a path tracer makes
    them (pixel by pixel), one thread: would tracing 16 rays per call, as Mitsuba's vectorised
    wavefront does, pay?"""
    from stages.core.geometry.embree import EmbreeScene, EmbreeUnavailable

    try:
        es = EmbreeScene(points, fiber_offsets, point_radius, 1)
    except EmbreeUnavailable as e:
        return {"skipped": str(e)}
    out = {"threads": 1, "packet": PACKET}
    one, pkt, valid = _aligned(32, np.float32, 16), _aligned(PACKET * 24, np.float32), _aligned(PACKET, np.int32)
    with es:
        h = int(es.fibers.handle)
        for name, (O, D) in rays.items():
            best = {}
            for _ in range(repeats + 1):   # the first round compiles (or loads)
                for key, fn, args in (("single", _single_rays, (h, O, D, one)),
                                      ("packet16", _packet_rays, (h, O, D, pkt, valid)),
                                      ("fiberpath", _fiberpath_rays, (es.fibers, O, D))):
                    t0 = time.perf_counter()
                    r = fn(*args)
                    best[key] = (min(best.get(key, (np.inf,))[0], time.perf_counter() - t0), r)
            out[name] = {"rays": int(len(O)), **{f"{k}_ns_per_ray": v[0] / len(O) * 1e9 for k, v in best.items()},
                         "single_over_packet16": best["single"][0] / best["packet16"][0],
                         "fiberpath_over_single": best["fiberpath"][0] / best["single"][0],
                         **{f"{k}_hits": int(v[1][0]) for k, v in best.items()},
                         **{f"{k}_sum_t": float(v[1][1]) for k, v in best.items()}}
    return out


def _point_query_kernels():
    """(covering callback, capsule bounds callback, the query loop), compiled on first use. The query's
    user block: x, y, z (float64) at 0, 8, 16, the best segment and its fibre (int64) at 24 and 32, the
    rows' address at 40 and a count of callbacks at 48; segments are read from fiberpath's Embree rows
    (``stages.core.geometry.embree``: float32 points, float64 radius, fibre)."""
    from numba import cfunc

    from stages.core.geometry import embree as E
    from stages.core.geometry.capsule import point_segment_dist2

    peek, poke = E.peek, E.poke

    @cfunc(types.boolean(types.intp))
    def covering(args):   # RTCPointQueryFunctionArguments: userPtr 8, primID 16
        user = peek(args + 8, np.int64)
        poke(user + 48, peek(user + 48, np.int64) + 1)
        s = np.int64(peek(args + 16, np.uint32))
        row = peek(user + 40, np.int64) + E.ROW_BYTES * s
        f = np.int64(peek(row + E.ROW_FIBER, np.int32))
        best = peek(user + 24, np.int64)
        best_f = peek(user + 32, np.int64)
        if f > best_f or (f == best_f and s > best):
            return False
        r = peek(row + E.ROW_R, np.float64)
        a, b = row + E.ROW_A, row + E.ROW_B
        if point_segment_dist2(peek(user, np.float64), peek(user + 8, np.float64), peek(user + 16, np.float64),
                               float(peek(a, np.float32)), float(peek(a + 4, np.float32)),
                               float(peek(a + 8, np.float32)), float(peek(b, np.float32)),
                               float(peek(b + 4, np.float32)), float(peek(b + 8, np.float32))) < r * r:
            poke(user + 24, s)
            poke(user + 32, f)
        return False

    @cfunc(types.void(types.intp))
    def bounds(args):   # RTCBoundsFunctionArguments: geometryUserPtr 0, primID 8, bounds_o 16
        row = peek(args, np.int64) + E.ROW_BYTES * np.int64(peek(args + 8, np.uint32))
        out = peek(args + 16, np.int64)
        r = peek(row + E.ROW_R, np.float64)
        for k in range(3):
            a = float(peek(row + E.ROW_A + 4 * k, np.float32))
            b = float(peek(row + E.ROW_B + 4 * k, np.float32))
            lo = np.float32(min(a, b) - r)
            hi = np.float32(max(a, b) + r)
            if float(lo) > min(a, b) - r:
                lo = np.nextafter(lo, np.float32(-np.inf))
            if float(hi) < max(a, b) + r:
                hi = np.nextafter(hi, np.float32(np.inf))
            poke(out + 4 * k, lo)
            poke(out + 16 + 4 * k, hi)

    point_query = types.ExternalFunction("rtcPointQuery", types.void(types.intp, types.intp, types.intp, types.intp,
                                                                      types.intp))

    @njit(_nrt=False)
    def run(handle, rows, callback, X, out):
        calls = 0
        for j in range(X.shape[0]):
            q = E.scratch_address()    # RTCPointQuery at 0 (x, y, z, time, radius), the user block at 32
            ctx = E.scratch_address()  # RTCPointQueryContext: no instance (instStackSize 0, instID[0] invalid)
            poke(q, np.float32(X[j, 0]))
            poke(q + 4, np.float32(X[j, 1]))
            poke(q + 8, np.float32(X[j, 2]))
            poke(q + 12, np.float32(0.0))
            poke(q + 16, np.float32(0.0))
            u = q + 32
            poke(u, X[j, 0])
            poke(u + 8, X[j, 1])
            poke(u + 16, X[j, 2])
            poke(u + 24, np.int64(-1))
            poke(u + 32, np.int64(1 << 62))
            poke(u + 40, rows)
            poke(u + 48, np.int64(0))
            for k in range(0, 176, 8):
                poke(ctx + k, np.int64(0))
            poke(ctx + 128, np.uint32(E.INVALID_ID))
            point_query(handle, q, ctx, callback, u)
            out[j] = peek(u + 24, np.int64)
            calls += peek(u + 48, np.int64)
        return calls

    return covering, bounds, run


@njit(_nrt=False)
def _covering_bvh(box, child, prims, seg_fiber, X, out):
    for j in range(X.shape[0]):
        out[j] = covering_segment_arrays(box, child, prims, seg_fiber, X[j, 0], X[j, 1], X[j, 2], -1, seg_fiber[:0])


def point_queries(points, fiber_offsets, point_radius, bvh, n=300_000, repeats=3) -> dict:
    """Embree's point queries (on the curves, and on a user geometry of the capsules) against loomlight's
    ``covering_segment_arrays``, one thread (module doc, 7)."""
    import ctypes

    from stages.core.geometry import embree as E

    try:
        es = E.EmbreeScene(points, fiber_offsets, point_radius, 1)
    except E.EmbreeUnavailable as e:
        return {"skipped": str(e)}
    lib = E.load_embree()
    vp = ctypes.c_void_p
    for name, argt in (("rtcSetGeometryUserPrimitiveCount", [vp, ctypes.c_uint]),
                       ("rtcSetGeometryBoundsFunction", [vp, vp, vp]), ("rtcSetGeometryUserData", [vp, vp])):
        getattr(lib, name).restype, getattr(lib, name).argtypes = None, argt
    covering, bounds, run = _point_query_kernels()
    rng = np.random.default_rng(0)
    s = rng.integers(0, len(bvh.seg_a), n)
    a, b = bvh.points[bvh.seg_a[s]], bvh.points[bvh.seg_a[s] + 1]
    near = a + rng.random((n, 1)) * (b - a) + rng.normal(size=(n, 3)) * bvh.seg_r[s][:, None]
    lo, hi = bvh.points.min(0), bvh.points.max(0)
    sets = {"near_fibres": near, "uniform_in_box": lo + rng.random((n, 3)) * (hi - lo)}
    out = {"threads": 1, "points": n}
    with es:
        rows = es.fibers.rows
        got = np.empty(n, np.int64)
        out["curve_scene_callbacks"] = int(run(es.fibers.handle, rows, covering.address, near, got))
        t0 = time.perf_counter()
        device = lib.rtcNewDevice(b"threads=1")
        scene = lib.rtcNewScene(device)
        geom = lib.rtcNewGeometry(device, 120)   # RTC_GEOMETRY_TYPE_USER
        lib.rtcSetGeometryUserPrimitiveCount(geom, len(bvh.seg_a))
        lib.rtcSetGeometryUserData(geom, vp(int(rows)))
        lib.rtcSetGeometryBoundsFunction(geom, vp(bounds.address), vp(int(rows)))
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(scene, geom)
        lib.rtcReleaseGeometry(geom)
        lib.rtcCommitScene(scene)
        out["user_geometry_build_s"] = time.perf_counter() - t0
        try:
            for name, X in sets.items():
                mine, theirs = np.empty(n, np.int64), np.empty(n, np.int64)
                best = {}
                for _ in range(repeats + 1):   # the first round compiles
                    for key, fn, args in (("embree_user_geometry", run, (np.int64(scene), rows, covering.address, X,
                                                                         theirs)),
                                          ("loomlight", _covering_bvh, (bvh.wide_box, bvh.wide_child, bvh.prims,
                                                                        bvh.seg_fiber, X, mine))):
                        t0 = time.perf_counter()
                        fn(*args)
                        best[key] = min(best.get(key, np.inf), time.perf_counter() - t0)
                out[name] = {"covered": float((mine >= 0).mean()), "agree": int((mine == theirs).sum()),
                             **{f"{k}_ns_per_query": v / n * 1e9 for k, v in best.items()},
                             "loomlight_over_embree": best["loomlight"] / best["embree_user_geometry"]}
        finally:
            lib.rtcReleaseScene(scene)
            lib.rtcReleaseDevice(device)
    return out


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
           "capsule_shape": capsule_shape(A, B, bvh.seg_r), "spatial_splits": spatial_splits(bvh)}
    res["ray_order"], rays, G, win = ray_order(args.scene, args.fibers)
    res["embree"] = embree_library(bvh, G, win, rays)
    res["embree_path_tracer"] = embree_path_tracer(bvh, G, win, args.scene)
    res["embree_packets"] = embree_packets(f.points, f.fiber_offsets, f.point_radius, rays)
    res["point_queries"] = point_queries(f.points, f.fiber_offsets, f.point_radius, bvh)
    print(json.dumps(res, indent=2))
    return res


if __name__ == "__main__":
    main()
