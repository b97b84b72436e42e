"""Realized fibres traced by Embree 4 (``EmbreeFibers``): the same capsule chains, another tracer.

Embree (Intel's ray-tracing kernels) intersects *round linear curves* -- cones between vertices with a
sphere at each, which for equal radii at both ends are exactly loomlight's capsules
(``stages.core.geometry.capsule``) -- through an 8-wide BVH walked with AVX2, about twice as fast per
ray as loomlight's own 4-wide tree on the realized demo swatch (``bench/bvh_routes.py``). The library
comes from the ``embreex`` wheel on PyPI (a complete ``libembree4`` in ``embreex.libs``; its Python API
is not used). Kernels call ``rtcIntersect1`` / ``rtcOccluded1`` directly (``types.ExternalFunction``,
the library loaded into LLVM's symbol table by ``load_embree``), so they cache like any other kernel
and take no reference counts (``_nrt=False``, like fiberpath's path tracer).

Use
---
``EmbreeScene(points, fiber_offsets, point_radius, threads)`` builds the Embree device and scene (one
geometry of round linear curves: a curve segment per capsule, in segment order, so Embree's ``primID``
is loomlight's segment index, each with two vertices of its own at the capsule's radius) and holds
them until ``close()`` (or the end of a ``with`` block); ``.fibers`` is the ``EmbreeFibers``
namedtuple the kernels take: ``handle`` (the RTCScene), ``filter`` (the address of ``window_filter``),
``rows`` (the address of the segment rows below), ``exact32`` (whether every point is a float32
value), and the segment arrays of ``stages.core.geometry.bvh`` (``points``, ``seg_a``, ``seg_r``,
``seg_fiber``, ``fiber_seg_offsets``). It answers the surface-scene queries ``surface_hit`` /
``surface_occluded`` (``stages.core.geometry.surface``) and ``embree_intersect`` /
``embree_occluded``, which have the signatures and results of ``bvh.intersect`` / ``bvh.occluded``.

*Segment rows* (``segment_rows``): Embree's vertex buffer is loomlight's, one 64-byte row (a cache
line) per segment: the two float4 vertices Embree reads (stride 32) and, in the gaps, the capsule's
float64 radius, its fibre and its first point. Embree has just read the hit segment's row, so the
float64 answer below reads the segment from cache; it missed on ``seg_a``, then ``points``, then
``seg_r`` and ``seg_fiber`` before, and those dependent misses were a quarter of the query's own
code in ``perf``. Realized fibres are stored as float32 (``fibers.zarr``), so their points *are*
Embree's vertices (``exact32``) and the answer is bit for bit what ``points`` give; other points
(float64 test fibres, transformed copies) are read from ``points``.

What is the same as loomlight's BVH, and what is not
----------------------------------------------------
- *Skipped segments* (a ray leaving a fibre skips its own fibre near the vertex): an argument filter
  (``window_filter``, a cached numba ``cfunc``) rejects candidate hits whose ``primID`` lies in the
  skipped range, which travels in the ray's query context. Rays that skip nothing run without it.
- *Hit distance*: Embree works in float32. The hit it reports is re-intersected in float64 with
  loomlight's capsule test, together with the chain neighbour at that end of the segment (Embree's
  cone test can put the hit on the next segment a few thousandths of a radius beyond where the two
  meet; their surfaces cross within r tan(bend / 2) of the joint): the nearer wins, ties to the lower
  index as in loomlight's BVH; the neighbour is tested only when the hit lies within 1.1 of its radius
  from its axis, or when it has length zero (Embree can miss such a sphere outright): farther out it
  cannot be the nearer but by Embree missing it, which the bench's rays never showed (at most 1.028 r
  on 0.4 M rays of the radius x 0.1 control). A float32 hit the float64 test does not confirm (a grazing ray, or one
  leaving a surface a few float32 steps off it) is looked past. So ``t``, the segment and the normal
  are loomlight's wherever Embree finds the same capsule.
- *A ray that starts inside a capsule* meets it where it leaves it, in Embree as in loomlight
  (``capsule.py``): Embree's round curves report the way out too (tested against brute force).
- *Where they differ*: rays within ~1e-3 rad of a segment's axis (Embree's cone test degenerates;
  a few in a thousand of such rays miss a capsule they pass inside), the float32 any-hit answer of
  ``embree_occluded`` for rays that start within a few float32 steps of a surface (0.03-0.17 % more
  occluded bounce rays on the realized demo fibres), and rays from inside a zero-length segment, which
  ``rtcOccluded1`` does not see leave. Images agree with the BVH's within noise
  (``tests/render/test_fiberpath.py``, ``bench/bench_mitsuba.py``).
- *Determinism*: the same bytes whatever the thread count (Embree's build is deterministic); Embree
  picks its SIMD width from the CPU, so another instruction set may break a float32 near-tie the
  other way.

Memory: the render's estimate (``pipeline.runners.render.VERTEX_BYTES`` per fibre vertex) covers
loomlight's BVH, the larger of the two (peak 545 MiB against Embree's 429-433 MiB on a demo render; 390 MiB
before the rows doubled Embree's vertex buffer from 32 to 64 bytes a segment).
"""
from __future__ import annotations

import ctypes
import glob
import importlib.util
import os
from collections import namedtuple

import numpy as np
from llvmlite import ir
from numba import cfunc, njit, types
from numba.extending import intrinsic

from stages.core.geometry.bvh import ignore_range, segments_from_fibers
from stages.core.geometry.capsule import capsule_intersect, point_segment_dist2
from stages.core.geometry.surface import answer_surface_queries, capsule_surface_hit, segment_surface_hit

EmbreeFibers = namedtuple("EmbreeFibers", ["handle", "filter", "rows", "exact32", "points", "seg_a", "seg_r",
                                           "seg_fiber", "fiber_seg_offsets"])

# Embree 4 API constants (rtcore_common.h, rtcore_geometry.h, rtcore_scene.h, rtcore_ray.h)
GEOMETRY_ROUND_LINEAR_CURVE = 16
BUFFER_INDEX, BUFFER_VERTEX = 0, 1
FORMAT_UINT, FORMAT_FLOAT4 = 0x5001, 0x9004
SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS = 1 << 3
QUERY_INVOKE_ARGUMENT_FILTER = 1 << 1
FEATURE_ALL = 0xFFFFFFFF
INVALID_ID = 0xFFFFFFFF
MAX_REQUERIES = 8   # float32 hits not confirmed in float64 that one query looks past
# the chain neighbour is re-intersected when s's hit lies within sqrt(NEIGHBOUR_GATE) r_k of its axis: Embree
# can miss the neighbour's near side a little outside it (up to 1.028 r_k seen at radius x 0.1)
NEIGHBOUR_GATE = 1.1 ** 2

# One 64-byte row per segment, 64-byte aligned (one cache line), shared with Embree as its vertex buffer
# (stride 32): Embree's two float4 vertices (x, y, z, float32 radius) at ROW_A and ROW_B, and in the gaps
# what the float64 answer needs: the capsule radius (float64) at ROW_R, the fibre (int32) at ROW_FIBER,
# the index of the first point (int64) at ROW_POINT. Embree has just read the hit segment's row, so the
# float64 answer reads it from cache instead of missing on four arrays.
ROW_BYTES, VERTEX_STRIDE = 64, 32
ROW_A, ROW_R, ROW_FIBER, ROW_B, ROW_POINT = 0, 16, 24, 32, 48

# Byte layout of the per-query scratch block (16-byte aligned, on the machine stack):
#   RTCRayHit at 0 (ray: org 0-8, tnear 12, dir 16-24, time 28, tfar 32, mask 36, id 40, flags 44;
#   hit: Ng 48-56, u 60, v 64, primID 68, geomID 72, instID 76 [instPrimID 80]),
#   RTCIntersectArguments / RTCOccludedArguments at ARGS (flags 0, feature_mask 4, context 8, filter 16,
#   intersect 24, minWidthDistanceFactor 32), and the query context at CTX (RTCRayQueryContext: instID 0
#   [instPrimID 4]; then loomlight's skipped segment range: lo at 16, hi at 24).
ARGS = 96
CTX = 144
CTX_LO, CTX_HI = 16, 24
SCRATCH_BYTES = 192


class EmbreeUnavailable(ImportError):
    """Embree 4 could not be found or loaded (the ``embreex`` wheel is missing or carries no libembree4)."""


_LIB = None


def library_path() -> str:
    """Path of the libembree4 shipped in the ``embreex`` wheel."""
    spec = importlib.util.find_spec("embreex")
    if spec is None or spec.origin is None:
        raise EmbreeUnavailable("Embree 4 needs the 'embreex' package (pip install embreex)")
    libs = sorted(glob.glob(os.path.join(os.path.dirname(spec.origin), os.pardir, "embreex.libs", "libembree4*")))
    if not libs:
        raise EmbreeUnavailable(f"the embreex package at {os.path.dirname(spec.origin)} carries no libembree4")
    return os.path.normpath(libs[0])


def load_embree():
    """The ctypes handle of libembree4, loaded once; its symbols become visible to numba's JIT linker."""
    global _LIB
    if _LIB is not None:
        return _LIB
    import llvmlite.binding as llvm

    path = library_path()
    try:
        lib = ctypes.CDLL(path)
        llvm.load_library_permanently(path)
    except OSError as e:
        raise EmbreeUnavailable(f"cannot load {path}: {e}") from None
    vp, c_int, c_uint, c_size, c_bool = ctypes.c_void_p, ctypes.c_int, ctypes.c_uint, ctypes.c_size_t, ctypes.c_bool
    for name, res, args in (("rtcNewDevice", vp, [ctypes.c_char_p]), ("rtcReleaseDevice", None, [vp]),
                            ("rtcGetDeviceError", c_int, [vp]),
                            ("rtcNewScene", vp, [vp]), ("rtcSetSceneFlags", None, [vp, c_int]),
                            ("rtcCommitScene", None, [vp]), ("rtcReleaseScene", None, [vp]),
                            ("rtcNewGeometry", vp, [vp, c_int]),
                            ("rtcSetNewGeometryBuffer", vp, [vp, c_int, c_uint, c_int, c_size, c_size]),
                            ("rtcSetSharedGeometryBuffer", None,
                             [vp, c_int, c_uint, c_int, vp, c_size, c_size, c_size]),
                            ("rtcSetGeometryEnableFilterFunctionFromArguments", None, [vp, c_bool]),
                            ("rtcCommitGeometry", None, [vp]), ("rtcAttachGeometry", c_uint, [vp, vp]),
                            ("rtcReleaseGeometry", None, [vp])):
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    _LIB = lib
    return lib


_ERRORS = {1: "unknown error", 2: "invalid argument", 3: "invalid operation", 4: "out of memory",
           5: "unsupported CPU", 6: "cancelled"}


class EmbreeScene:
    """An Embree device and a committed scene of realized fibres; ``.fibers`` is what kernels take."""

    def __init__(self, points, fiber_offsets, point_radius, threads: int = 1):
        lib = load_embree()
        points = np.ascontiguousarray(points, np.float64)
        fiber_offsets = np.ascontiguousarray(fiber_offsets, np.int64)
        point_radius = np.ascontiguousarray(point_radius, np.float64)
        seg_a, seg_r, seg_fiber, fso = segments_from_fibers(fiber_offsets, point_radius)
        if 2 * len(seg_a) >= INVALID_ID:
            raise ValueError(f"Embree indexes vertices with 32 bits ({len(seg_a)} segments)")
        self._lib = lib
        self._rows = None
        self.device = lib.rtcNewDevice(f"threads={max(1, int(threads))}".encode())
        if not self.device:
            raise EmbreeUnavailable("rtcNewDevice failed (unsupported CPU?)")
        self.scene = None
        try:
            self.scene = lib.rtcNewScene(self.device)
            lib.rtcSetSceneFlags(self.scene, SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS)
            if len(seg_a):
                geom = lib.rtcNewGeometry(self.device, GEOMETRY_ROUND_LINEAR_CURVE)
                # each segment gets two vertices of its own at its capsule radius (the mean of its points'
                # radii): on shared vertices Embree's cone would interpolate the points' radii instead
                ns = len(seg_a)
                self._rows = segment_rows(points, seg_a, seg_r, seg_fiber)
                lib.rtcSetSharedGeometryBuffer(geom, BUFFER_VERTEX, 0, FORMAT_FLOAT4, self._rows.ctypes.data, 0,
                                               VERTEX_STRIDE, 2 * ns)
                ib = lib.rtcSetNewGeometryBuffer(geom, BUFFER_INDEX, 0, FORMAT_UINT, 4, ns)
                self._check("allocating the curve buffers")
                np.ctypeslib.as_array((ctypes.c_uint32 * ns).from_address(ib))[:] = np.arange(0, 2 * ns, 2,
                                                                                               dtype=np.uint32)
                lib.rtcSetGeometryEnableFilterFunctionFromArguments(geom, True)
                lib.rtcCommitGeometry(geom)
                lib.rtcAttachGeometry(self.scene, geom)
                lib.rtcReleaseGeometry(geom)
            lib.rtcCommitScene(self.scene)
            self._check("building the scene")
        except BaseException:
            self.close()
            raise
        # float32 points (realized fibres are stored so) are Embree's vertices exactly: then the float64
        # answer takes them from the rows, otherwise from ``points``
        exact32 = bool(float32_exact(points))
        rows = np.int64(self._rows.ctypes.data if self._rows is not None else 0)
        self.fibers = EmbreeFibers(np.int64(self.scene), np.int64(window_filter.address), rows, exact32, points,
                                   seg_a, seg_r, seg_fiber, fso)

    def _check(self, what):
        err = self._lib.rtcGetDeviceError(self.device)
        if err:
            raise MemoryError(f"Embree: {what}: out of memory") if err == 4 else \
                RuntimeError(f"Embree: {what}: {_ERRORS.get(err, err)}")

    def close(self):
        """Release the scene, the device and then the rows Embree read (the kernels' ``fibers.handle`` and
        ``fibers.rows`` are dangling after this)."""
        if self.scene:
            self._lib.rtcReleaseScene(self.scene)
            self.scene = None
        if self.device:
            self._lib.rtcReleaseDevice(self.device)
            self.device = None
        self._rows = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def segment_rows(points, seg_a, seg_r, seg_fiber):
    """The segments' 64-byte rows (layout at ``ROW_BYTES``) in a 64-byte aligned uint8
    array, 16 bytes of padding after the last (Embree reads its vertices with 16-byte loads)."""
    ns = len(seg_a)
    raw = np.zeros(ns * ROW_BYTES + 16 + 64, np.uint8)
    skip = -raw.ctypes.data % 64
    rows = raw[skip:skip + ns * ROW_BYTES + 16]
    body = rows[:ns * ROW_BYTES]
    _fill_rows(body.view(np.float32).reshape(ns, ROW_BYTES // 4), body.view(np.float64).reshape(ns, ROW_BYTES // 8),
               body.view(np.int32).reshape(ns, ROW_BYTES // 4), body.view(np.int64).reshape(ns, ROW_BYTES // 8),
               points, seg_a, seg_r, seg_fiber)
    return rows


@njit(cache=True)
def _fill_rows(f32, f64, i32, i64, points, seg_a, seg_r, seg_fiber):
    """Write each segment's row through four typed views of the same bytes (no temporaries)."""
    for s in range(seg_a.shape[0]):
        i = seg_a[s]
        for k in range(3):
            f32[s, ROW_A // 4 + k] = points[i, k]
            f32[s, ROW_B // 4 + k] = points[i + 1, k]
        f32[s, ROW_A // 4 + 3] = seg_r[s]
        f32[s, ROW_B // 4 + 3] = seg_r[s]
        f64[s, ROW_R // 8] = seg_r[s]
        i32[s, ROW_FIBER // 4] = seg_fiber[s]
        i64[s, ROW_POINT // 8] = i


@njit(cache=True)
def float32_exact(x):
    """True when every value of the float64 array x is a float32 value (no temporaries)."""
    for v in x.ravel():
        if np.float64(np.float32(v)) != v:
            return False
    return True


# ------------------------------------------------------------------------------------------------
# raw memory: the scratch block on the machine stack, and loads / stores at byte addresses
@intrinsic
def scratch_address(typingctx):
    """The address (intp) of SCRATCH_BYTES bytes, 16-byte aligned, in the calling function's stack frame."""
    def codegen(context, builder, sig, args):
        from numba.core import cgutils

        ptr = cgutils.alloca_once(builder, ir.ArrayType(ir.IntType(8), SCRATCH_BYTES))
        ptr.align = 16
        return builder.ptrtoint(ptr, context.get_value_type(types.intp))
    return types.intp(), codegen


@intrinsic
def poke(typingctx, addr, value):
    """Store ``value`` (its own numba type) at byte address ``addr``."""
    def codegen(context, builder, sig, args):
        a, v = args
        ptr = builder.inttoptr(a, context.get_value_type(sig.args[1]).as_pointer())
        builder.store(v, ptr)
        return context.get_dummy_value()
    return types.void(addr, value), codegen


@intrinsic
def peek(typingctx, addr, dtype):
    """The value of type ``dtype`` (a numpy scalar type) at byte address ``addr``."""
    ty = dtype.dtype

    def codegen(context, builder, sig, args):
        ptr = builder.inttoptr(args[0], context.get_value_type(ty).as_pointer())
        return builder.load(ptr)
    return ty(addr, dtype), codegen


_rtc_intersect1 = types.ExternalFunction("rtcIntersect1", types.void(types.intp, types.intp, types.intp))
_rtc_occluded1 = types.ExternalFunction("rtcOccluded1", types.void(types.intp, types.intp, types.intp))


@cfunc(types.void(types.intp), cache=True)
def window_filter(args):
    """Embree argument filter: rejects candidate hits on the query's skipped segments [lo, hi], which
    travel in the query context (RTCFilterFunctionNArguments: valid 0, context 16, hit 32, N 40)."""
    valid = peek(args, np.int64)
    ctx = peek(args + 16, np.int64)
    hit = peek(args + 32, np.int64)
    n = peek(args + 40, np.uint32)
    lo = peek(ctx + CTX_LO, np.int64)
    hi = peek(ctx + CTX_HI, np.int64)
    for i in range(n):
        if peek(valid + 4 * i, np.int32) == 0:
            continue
        prim = np.int64(peek(hit + 4 * (5 * n + i), np.uint32))   # RTCHitN: primID is the 6th field, N wide
        if prim >= lo and prim <= hi:
            poke(valid + 4 * i, np.int32(0))


@njit(cache=True, inline="always")
def write_ray(base, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """The ray (float32) and an empty hit into the RTCRayHit at ``base`` (the same layout in Embree 3 and 4)."""
    poke(base + 0, np.float32(ox))
    poke(base + 4, np.float32(oy))
    poke(base + 8, np.float32(oz))
    poke(base + 12, np.float32(tmin))
    poke(base + 16, np.float32(dx))
    poke(base + 20, np.float32(dy))
    poke(base + 24, np.float32(dz))
    poke(base + 28, np.float32(0.0))
    poke(base + 32, np.float32(tmax))
    poke(base + 36, np.uint32(INVALID_ID))    # mask: every geometry
    poke(base + 40, np.uint32(0))
    poke(base + 44, np.uint32(0))
    poke(base + 72, np.uint32(INVALID_ID))    # geomID: no hit yet
    poke(base + 76, np.uint32(INVALID_ID))
    poke(base + 80, np.uint32(INVALID_ID))


@njit(cache=True, inline="always")
def _query(sc, base, ox, oy, oz, dx, dy, dz, tmin, tmax, lo, hi):
    """Fill the scratch block at ``base``: the ray, an empty hit, the arguments and the context."""
    write_ray(base, ox, oy, oz, dx, dy, dz, tmin, tmax)
    skips = lo <= hi
    poke(base + ARGS, np.uint32(QUERY_INVOKE_ARGUMENT_FILTER if skips else 0))
    poke(base + ARGS + 4, np.uint32(FEATURE_ALL))
    poke(base + ARGS + 8, base + CTX)
    poke(base + ARGS + 16, sc.filter if skips else np.int64(0))
    poke(base + ARGS + 24, np.int64(0))
    poke(base + ARGS + 32, np.float32(0.0))
    poke(base + CTX, np.uint32(INVALID_ID))
    poke(base + CTX + 4, np.uint32(INVALID_ID))
    poke(base + CTX + CTX_LO, np.int64(lo))
    poke(base + CTX + CTX_HI, np.int64(hi))


@njit(cache=True, inline="always")
def segment_capsule(sc, s):
    """(ax, ay, az, bx, by, bz, r, fibre) of segment s from its row: the points are Embree's
    float32 vertices where those are exact (``exact32``), else loomlight's float64 ``points``."""
    row = sc.rows + ROW_BYTES * s
    r = peek(row + ROW_R, np.float64)
    f = np.int64(peek(row + ROW_FIBER, np.int32))
    if sc.exact32:
        return (float(peek(row + ROW_A, np.float32)), float(peek(row + ROW_A + 4, np.float32)),
                float(peek(row + ROW_A + 8, np.float32)), float(peek(row + ROW_B, np.float32)),
                float(peek(row + ROW_B + 4, np.float32)), float(peek(row + ROW_B + 8, np.float32)), r, f)
    i = peek(row + ROW_POINT, np.int64)
    P = sc.points
    return P[i, 0], P[i, 1], P[i, 2], P[i + 1, 0], P[i + 1, 1], P[i + 1, 2], r, f


@njit(cache=True, _nrt=False, inline="always")
def embree_intersect(sc, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """Nearest hit (t, segment) with tmin < t < tmax; (inf, -1) when none (``bvh.intersect``'s contract)."""
    if sc.seg_a.shape[0] == 0:
        return np.inf, -1
    lo, hi = ignore_range(sc, ign_fiber, ign_seg, ign_window)
    base = scratch_address()
    tnear = tmin
    for _ in range(MAX_REQUERIES):
        _query(sc, base, ox, oy, oz, dx, dy, dz, tnear, tmax, lo, hi)
        _rtc_intersect1(sc.handle, base, base + ARGS)
        if peek(base + 72, np.uint32) == INVALID_ID:
            return np.inf, -1
        s = np.int64(peek(base + 68, np.uint32))
        ax, ay, az, bx, by, bz, r, f = segment_capsule(sc, s)
        t = capsule_intersect(ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, r, tmin)   # float64
        if t < tmax:
            # Embree's float32 cone test can put the hit on the next segment of the chain, a few
            # thousandths of a radius beyond where the two meet: the nearer of s and the neighbour k at
            # the hit's end of s wins (ties to the lower index, as in loomlight's BVH). Their surfaces
            # cross within r tan(bend / 2) of the joint, so the other neighbour is not a candidate, and
            # k can be the nearer only where s's hit lies in k or next to it (NEIGHBOUR_GATE). k's row
            # is the next cache line, so the gate costs no cache miss.
            px = ox + t * dx
            py = oy + t * dy
            pz = oz + t * dz
            ex = bx - ax
            ey = by - ay
            ez = bz - az
            along = (px - ax) * ex + (py - ay) * ey + (pz - az) * ez
            k = s - 1 if 2.0 * along < ex * ex + ey * ey + ez * ez else s + 1
            if k < 0 or k >= sc.seg_a.shape[0] or (k >= lo and k <= hi):
                return t, s
            kax, kay, kaz, kbx, kby, kbz, kr, kf = segment_capsule(sc, k)
            if kf != f:
                return t, s
            # a zero-length neighbour (a sphere) is always tested: Embree's cone test can miss it outright
            if (kax == kbx and kay == kby and kaz == kbz) or \
                    point_segment_dist2(px, py, pz, kax, kay, kaz, kbx, kby, kbz) < NEIGHBOUR_GATE * kr * kr:
                tk = capsule_intersect(ox, oy, oz, dx, dy, dz, kax, kay, kaz, kbx, kby, kbz, kr, tmin)
                if tk < t or (tk == t and k < s):
                    t = tk
                    s = k
            return t, s
        # a float32 hit the exact test does not confirm (a ray grazing s, or leaving it a few float32
        # steps off its surface): look again beyond it
        tnear = max(tnear, float(peek(base + 32, np.float32))) * (1.0 + 1e-6) + 1e-30
    return np.inf, -1


@njit(cache=True, _nrt=False, inline="always")
def embree_occluded(sc, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_seg, ign_window):
    """True when any segment is hit with tmin < t < tmax (``bvh.occluded``'s contract), in Embree's float32."""
    if sc.seg_a.shape[0] == 0:
        return False
    lo, hi = ignore_range(sc, ign_fiber, ign_seg, ign_window)
    base = scratch_address()
    _query(sc, base, ox, oy, oz, dx, dy, dz, tmin, tmax, lo, hi)
    _rtc_occluded1(sc.handle, base, base + ARGS)
    return peek(base + 32, np.float32) == -np.inf


@njit(cache=True, _nrt=False, inline="always")
def embree_surface_hit(sc, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window):
    """``surface_hit`` on Embree: ``segment_surface_hit``'s answer, the segment read from its row."""
    t, s = embree_intersect(sc, ox, oy, oz, dx, dy, dz, tmin, tmax, ign_fiber, ign_prim, ign_window)
    if s < 0:
        return segment_surface_hit(sc, t, s, ox, oy, oz, dx, dy, dz)
    ax, ay, az, bx, by, bz, r, f = segment_capsule(sc, s)
    return capsule_surface_hit(t, s, f, r, ax, ay, az, bx, by, bz, ox, oy, oz, dx, dy, dz)


answer_surface_queries(EmbreeFibers, embree_surface_hit, embree_occluded)
