"""The ray-tracing kernel under fiberpath against the one under Mitsuba 3, on the same rays and curves (issue 24).

fiberpath traces realized fibres with Embree 4.4.0 (``libembree4`` from the ``embreex`` wheel,
``stages.core.geometry.embree``); Mitsuba 3.9.1's ``llvm`` variants trace its ``linearcurve`` with the
Embree 3.13.4 bundled in the ``mitsuba`` wheel (``mitsuba/libembree3.so``, its C API in the C++
namespace ``mitsuba``, so its symbols are mangled). Most of a fiberpath render is Embree's
(``perf``: ~3/4 of the render threads' samples), so the two kernels' speed per ray bounds what
fiberpath's own code can do against Mitsuba. This bench measures that speed alone:

- *The same curves*: both scenes take loomlight's segment rows (``segment_rows``: a round linear
  curve per capsule, two float4 vertices of its own, stride 32) as their vertex buffer, with the
  same index buffer; both build Embree's default BVH for round curves (``BVH8<curve8v>``, the OBB
  hair builder, on AVX-512 here).
- *The same rays*, in the order a path tracer makes them (``record_rays``): per pixel sample a camera
  ray; where it meets a fibre (loomlight's answer), a cosine-weighted bounce ray and an independent
  cosine-weighted shadow ray from fiberpath's Lambertian spawn point (the hit moved 1e-3 r + eps off
  the surface, ``tmin`` eps); where the bounce meets a fibre, a second bounce and shadow ray alike.
  Camera and bounce rays go to ``rtcIntersect1``, shadow rays to ``rtcOccluded1``, one ray per call
  (float32 rays, no filter: what fiberpath's Lambertian vertices ask), on one thread.
- *Timings*: ``ROUNDS`` rounds, each tracing every ray class with Embree 4 and then Embree 3
  (interleaved against the machine's drift); the ratio is the median over rounds of Embree 3's time
  over Embree 4's (< 1: Mitsuba's kernel faster). Builds are timed too, one thread: ``EmbreeScene``
  from the fibres (its segment rows included) and Embree 3's commit of those rows.
- *Answers*: the fraction of camera rays whose nearest segment is the same in both, and of the rest those
  where one kernel reports the other's chain neighbour (a near-tie at a joint, in float32). Embree 3 is built
  here with back-face culling for curves (its ``verbose`` features say ``backfacecullingcurves``): a ray that
  starts inside a capsule does not meet its way out (``inside_rays``: from segments' axis midpoints across the
  axis, as far as the capsule's radius; Embree 4 meets a surface on all of them, Embree 3 only where another
  fibre begins that close), so bounce rays from inside overlapping fibres differ by more; camera rays start
  outside every fibre.

Runs inside ``bench_mitsuba`` (only when Mitsuba 3 is installed); never part of loomlight's renderer.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import os
import re
import subprocess
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

from stages.core.geometry.embree import embree_surface_hit, peek, poke, scratch_address, write_ray  # noqa: E402
from stages.core.rng import uniform  # noqa: E402  (after sys.path and stages set-up)
from stages.core.shading.lambert import cosine_direction  # noqa: E402  (after sys.path and stages set-up)
from stages.render.camera import CAM_HEIGHT, CAM_WIDTH, camera_ray  # noqa: E402  (after sys.path and stages set-up)

ROUNDS = 5
SPP = 32          # camera samples per pixel recorded
CAMERA, BOUNCE, SHADOW = 0, 1, 2
CLASSES = ("camera", "bounce", "shadow")
INVALID_ID = 0xFFFFFFFF


def embree3_library() -> Path:
    """The Embree 3 bundled with Mitsuba 3 (``mitsuba/libembree3.so``); FileNotFoundError without it."""
    import importlib.util

    spec = importlib.util.find_spec("mitsuba")
    if spec is None or spec.origin is None:
        raise FileNotFoundError("the mitsuba package is not installed")
    path = Path(spec.origin).parent / "libembree3.so"
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    return path


def _mangled_names(path: Path) -> dict:
    """Embree 3's C API names -> their symbols in Mitsuba's copy (``mitsuba::rtcNewDevice(char const*)``
    is ``_ZN7mitsuba12rtcNewDeviceEPKc``), read from the library's dynamic symbol table."""
    out = subprocess.run(["nm", "-D", "--defined-only", str(path)], capture_output=True, text=True, check=True).stdout
    names = {}
    for line in out.splitlines():
        sym = line.split()[-1]
        m = re.match(r"_ZN7mitsuba(\d+)", sym)
        if m:
            names[sym[m.end():m.end() + int(m.group(1))]] = sym
    return names


class Embree3:
    """Mitsuba's Embree 3 loaded through ctypes (and into numba's symbol table for ``rtcIntersect1`` /
    ``rtcOccluded1``), with the few API calls a scene build needs."""

    def __init__(self):
        import llvmlite.binding as llvm

        path = embree3_library()
        self.names = _mangled_names(path)
        self.lib = ctypes.CDLL(str(path))
        llvm.load_library_permanently(str(path))
        vp, c_int, c_uint, c_size = ctypes.c_void_p, ctypes.c_int, ctypes.c_uint, ctypes.c_size_t
        self.fn = {}
        for name, res, args in (("rtcNewDevice", vp, [ctypes.c_char_p]), ("rtcReleaseDevice", None, [vp]),
                                ("rtcGetDeviceError", c_int, [vp]), ("rtcNewScene", vp, [vp]),
                                ("rtcCommitScene", None, [vp]), ("rtcReleaseScene", None, [vp]),
                                ("rtcNewGeometry", vp, [vp, c_int]),
                                ("rtcSetSharedGeometryBuffer", None,
                                 [vp, c_int, c_uint, c_int, vp, c_size, c_size, c_size]),
                                ("rtcCommitGeometry", None, [vp]), ("rtcAttachGeometry", c_uint, [vp, vp]),
                                ("rtcReleaseGeometry", None, [vp])):
            f = getattr(self.lib, self.names[name])
            f.restype, f.argtypes = res, args
            self.fn[name] = f
        self.intersect1 = self.names["rtcIntersect1"]
        self.occluded1 = self.names["rtcOccluded1"]

    def curve_scene(self, rows_address, n_segments):
        """(device, scene, index buffer, build seconds): loomlight's segment rows (at ``rows_address``,
        ``EmbreeFibers.rows``) as round linear curves."""
        from stages.core.geometry.embree import (
            BUFFER_INDEX,
            BUFFER_VERTEX,
            FORMAT_FLOAT4,
            FORMAT_UINT,
            GEOMETRY_ROUND_LINEAR_CURVE,
            VERTEX_STRIDE,
        )

        f = self.fn
        dev = f["rtcNewDevice"](b"threads=1")
        scene = f["rtcNewScene"](dev)
        geom = f["rtcNewGeometry"](dev, GEOMETRY_ROUND_LINEAR_CURVE)
        index = np.arange(0, 2 * n_segments, 2, dtype=np.uint32)
        f["rtcSetSharedGeometryBuffer"](geom, BUFFER_VERTEX, 0, FORMAT_FLOAT4, rows_address, 0, VERTEX_STRIDE,
                                        2 * n_segments)
        f["rtcSetSharedGeometryBuffer"](geom, BUFFER_INDEX, 0, FORMAT_UINT, index.ctypes.data, 0, 4, n_segments)
        f["rtcCommitGeometry"](geom)
        f["rtcAttachGeometry"](scene, geom)
        f["rtcReleaseGeometry"](geom)
        t = time.perf_counter()
        f["rtcCommitScene"](scene)
        build_s = time.perf_counter() - t
        if f["rtcGetDeviceError"](dev):
            raise RuntimeError("Embree 3: building the curve scene failed")
        return dev, scene, index, build_s

    def release(self, dev, scene):
        self.fn["rtcReleaseScene"](scene)
        self.fn["rtcReleaseDevice"](dev)


@njit(cache=True)
def record_rays(fibers, cam, eps, spp, seed):
    """Rays (origin, direction, tmin, tmax; n x 8) and their class (CAMERA / BOUNCE / SHADOW), in path order
    (module doc): camera rays, and up to two Lambertian vertices' bounce and shadow rays each."""
    W = int(cam[CAM_WIDTH])
    H = int(cam[CAM_HEIGHT])
    n_max = W * H * spp * 5
    rays = np.empty((n_max, 8))
    rays[:, 7] = np.inf
    kind = np.empty(n_max, np.int8)
    n = 0
    nrm = np.empty(3)
    for pix in range(W * H):
        row = pix // W
        col = pix % W
        for s in range(spp):
            key = pix * spp + s
            o, d = camera_ray(cam, row, col, uniform(seed, key, 0), uniform(seed, key, 1))
            ox, oy, oz, dx, dy, dz = o[0], o[1], o[2], d[0], d[1], d[2]
            tmin = 0.0
            for depth in range(3):
                rays[n, 0] = ox
                rays[n, 1] = oy
                rays[n, 2] = oz
                rays[n, 3] = dx
                rays[n, 4] = dy
                rays[n, 5] = dz
                rays[n, 6] = tmin
                kind[n] = CAMERA if depth == 0 else BOUNCE
                n += 1
                h = embree_surface_hit(fibers, ox, oy, oz, dx, dy, dz, tmin, np.inf, -1, -1, 0)
                if h.prim < 0 or depth == 2:
                    break
                nrm[0] = h.nx
                nrm[1] = h.ny
                nrm[2] = h.nz
                if nrm[0] * dx + nrm[1] * dy + nrm[2] * dz > 0.0:
                    nrm[0] = -nrm[0]
                    nrm[1] = -nrm[1]
                    nrm[2] = -nrm[2]
                off = 1e-3 * h.radius + eps
                ox = ox + h.t * dx + off * nrm[0]
                oy = oy + h.t * dy + off * nrm[1]
                oz = oz + h.t * dz + off * nrm[2]
                tmin = eps
                sx, sy, sz = cosine_direction(nrm, uniform(seed, key, 2 + 4 * depth), uniform(seed, key, 3 + 4 * depth))
                rays[n, 0] = ox
                rays[n, 1] = oy
                rays[n, 2] = oz
                rays[n, 3] = sx
                rays[n, 4] = sy
                rays[n, 5] = sz
                rays[n, 6] = tmin
                kind[n] = SHADOW
                n += 1
                dx, dy, dz = cosine_direction(nrm, uniform(seed, key, 4 + 4 * depth), uniform(seed, key, 5 + 4 * depth))
    return rays[:n], kind[:n]


def inside_rays(points, seg_a, seg_r, n=1000, seed=3):
    """Rays (n x 8) from the axis midpoints of n segments (of nonzero length, spread over the scene)
    across the axis, with tmax just beyond the capsule's radius: each starts inside its own capsule, so
    a kernel that reports ways out meets a surface on every one."""
    rng = np.random.default_rng(seed)
    a = points[seg_a]
    e = points[seg_a + 1] - a
    ok = np.flatnonzero(np.einsum("ij,ij->i", e, e) > 0.0)
    segs = np.sort(rng.choice(ok, size=min(n, len(ok)), replace=False))
    axis = e[segs] / np.linalg.norm(e[segs], axis=1, keepdims=True)
    across = np.cross(axis, rng.normal(size=axis.shape))
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    rays = np.zeros((len(segs), 8))
    rays[:, :3] = a[segs] + 0.5 * e[segs]
    rays[:, 3:6] = across
    rays[:, 7] = seg_r[segs] * (1.0 + 1e-3)
    return rays


def _tracer(intersect_symbol: str, occluded_symbol: str, embree3: bool):
    """A numba loop tracing every ray of class ``which`` with one kernel, one call per ray; returns the
    primIDs it met (INVALID_ID: none; for shadow rays 1 = occluded, 0 = not)."""
    intersect1 = types.ExternalFunction(intersect_symbol, types.void(types.intp, types.intp, types.intp))
    occluded1 = types.ExternalFunction(occluded_symbol, types.void(types.intp, types.intp, types.intp))
    inv = np.uint32(INVALID_ID)

    @njit
    def trace(handle, rays, kind, which, out):
        base = scratch_address()
        ctx = base + 144
        m = 0
        for i in range(rays.shape[0]):
            if kind[i] != which:
                continue
            write_ray(base, rays[i, 0], rays[i, 1], rays[i, 2], rays[i, 3], rays[i, 4], rays[i, 5], rays[i, 6],
                      rays[i, 7])
            if embree3:   # RTCIntersectContext: flags (incoherent) 0, filter 8, instID 16
                poke(ctx, np.uint32(0))
                poke(ctx + 8, np.int64(0))
                poke(ctx + 16, inv)
            if which == SHADOW:
                if embree3:
                    occluded1(handle, ctx, base)
                else:
                    occluded1(handle, base, 0)
                out[m] = np.uint32(1) if peek(base + 32, np.float32) == -np.inf else np.uint32(0)
            else:
                if embree3:
                    intersect1(handle, ctx, base)
                else:
                    intersect1(handle, base, 0)
                out[m] = peek(base + 68, np.uint32) if peek(base + 72, np.uint32) != inv else inv
            m += 1
        return m
    return trace


def compare(f, camera: dict, W: int, H: int, eps: float, spp: int = SPP, rounds: int = ROUNDS) -> dict:
    """Both kernels on one case's fibres (``load_fibers``' answer) and camera rays (module doc): ns per ray
    of each class and kernel (medians over rounds), the ratio Embree 3 / Embree 4, builds, and answer
    agreement."""
    from pipeline.scene import camera_array
    from stages.core.geometry.embree import EmbreeScene

    e3 = Embree3()
    t = time.perf_counter()
    scene4 = EmbreeScene(f.points, f.fiber_offsets, f.point_radius, 1)
    build4 = time.perf_counter() - t
    scene3 = None
    try:
        dev3, scene3, index3, build3 = e3.curve_scene(int(scene4.fibers.rows), len(scene4.fibers.seg_a))
        rays, kind = record_rays(scene4.fibers, camera_array(camera, W, H), eps, spp, 7)
        trace4 = _tracer("rtcIntersect1", "rtcOccluded1", False)
        trace3 = _tracer(e3.intersect1, e3.occluded1, True)
        h4 = int(scene4.fibers.handle)
        h3 = int(scene3)
        out4 = np.empty(len(rays), np.uint32)
        out3 = np.empty(len(rays), np.uint32)
        for c in range(3):   # compile both tracers
            trace4(h4, rays[:1], kind[:1], c, out4)
            trace3(h3, rays[:1], kind[:1], c, out3)
        times = np.zeros((rounds, 3, 2))
        for r in range(rounds):
            for c in range(3):
                for k, (trace, h, out) in enumerate(((trace4, h4, out4), (trace3, h3, out3))):
                    t = time.perf_counter()
                    m = trace(h, rays, kind, c, out)
                    times[r, c, k] = (time.perf_counter() - t) / max(m, 1)
        counts = [int((kind == c).sum()) for c in range(3)]
        cam_n = counts[CAMERA]
        trace4(h4, rays, kind, CAMERA, out4)
        trace3(h3, rays, kind, CAMERA, out3)
        a = out4[:cam_n].astype(np.int64)
        b = out3[:cam_n].astype(np.int64)
        same_camera = float(np.mean(a == b)) if cam_n else 1.0
        # the rest: the chain neighbour (a near-tie at a joint, within float32) or a hit against a miss
        neighbour_camera = float(np.mean((a != b) & (a != INVALID_ID) & (b != INVALID_ID) & (np.abs(a - b) == 1))) \
            if cam_n else 0.0
        ins = inside_rays(scene4.fibers.points, scene4.fibers.seg_a, scene4.fibers.seg_r)
        ins_kind = np.full(len(ins), CAMERA, np.int8)
        exits = {}
        for name, trace, h, out in (("embree4", trace4, h4, out4), ("embree3", trace3, h3, out3)):
            trace(h, ins, ins_kind, CAMERA, out)
            exits[name] = float(np.mean(out[:len(ins)] != INVALID_ID))
    finally:
        if scene3 is not None:
            e3.release(dev3, scene3)
        scene4.close()
    med = np.median(times, axis=0) * 1e9
    ratio = np.median(times[:, :, 1] / times[:, :, 0], axis=0)
    allr = np.median((times[:, :, 1] * counts).sum(1) / (times[:, :, 0] * counts).sum(1))
    res = {"rays": dict(zip(CLASSES, counts)), "rounds": rounds, "threads": 1,
           "embree4_build_s": build4, "embree3_build_s": build3,
           "camera_same_segment": same_camera, "camera_chain_neighbour": neighbour_camera,
           "inside_rays_meeting_a_surface": exits,
           "all_rays_embree3_over_embree4": float(allr)}
    for c, name in enumerate(CLASSES):
        res[f"{name}_ns_per_ray"] = {"embree4": round(float(med[c, 0]), 1), "embree3": round(float(med[c, 1]), 1)}
        res[f"{name}_embree3_over_embree4"] = round(float(ratio[c]), 3)
    return res


def mitsuba_offset(points) -> float:
    """Mitsuba 3's ray offset at a surface point p, (1 + max |p_i|) x 1500 x 2^-24 (its RayEpsilon), taken at
    the fibres' largest coordinate: what the bench gives fiberpath's ``eps`` so both spawn rays alike."""
    return (1.0 + float(np.abs(points).max())) * 1500.0 * 2.0 ** -24


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("fibers", help="a fibers.zarr (loomlight realize)")
    ap.add_argument("scene", help="the scene whose camera makes the rays")
    ap.add_argument("--size", type=int, nargs=2, default=(96, 72), metavar=("W", "H"))
    args = ap.parse_args(argv)
    from pipeline.render_setup import load_fibers
    from pipeline.scene import load_scene

    f = load_fibers(args.fibers)
    res = compare(f, load_scene(args.scene).camera, *args.size, mitsuba_offset(f.points))
    print(json.dumps(res, indent=1))
    return res


if __name__ == "__main__":
    main()
