"""fiberpath throughput: BVH build, primary rays per second per core, full paths per second.

Fibres: the realized demo fibres when present (``$LOOMLIGHT_BENCH_FIBERS`` or ``out/demo/fibers.zarr``,
written by ``make demo``), else a synthetic plain-weave swatch of helical fibres of the same size
(16 yarns x 64 fibres x 100 points, about 10^5 segments). Camera and lights: data/scenes/demo.toml;
material: the cotton BCSDF preset.
"""
from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np
from numba import njit, prange

from stages.core.geometry.bvh import intersect
from stages.render.camera import camera_ray

ROOT = Path(__file__).resolve().parents[1]


def synthetic_swatch(n_yarns=8, fibres=64, points=100, spacing=0.1, yarn_r=0.045, fibre_r=0.003, seed=0):
    rng = np.random.default_rng(seed)
    pts, offs, rad = [], [0], []
    half = n_yarns * spacing / 2
    s = np.linspace(-half, half, points)
    for direction in (0, 1):
        for y in range(n_yarns):
            c = -half + (y + 0.5) * spacing
            phase = math.pi * (y % 2) + math.pi * direction
            for _ in range(fibres):
                rr = yarn_r * math.sqrt(rng.uniform(0.0, 0.9))
                a0 = rng.uniform(0, 2 * math.pi)
                twist = 2 * math.pi / 0.3
                ang = a0 + twist * s
                z = yarn_r * np.cos(math.pi * s / spacing + phase) + rr * np.sin(ang)
                lat = c + rr * np.cos(ang)
                p = np.stack([s, lat, z], -1) if direction == 0 else np.stack([lat, s, z], -1)
                pts.append(p)
                rad.append(np.full(points, fibre_r))
                offs.append(offs[-1] + points)
    return np.concatenate(pts), np.asarray(offs), np.concatenate(rad)


@njit(parallel=True)
def _primary(bvh, cam, W, H, spp):
    hits = np.zeros(H, np.int64)
    for row in prange(H):
        h = 0
        for col in range(W):
            for s in range(spp):
                o, d = camera_ray(cam, row, col, (s + 0.5) / spp, 0.5)
                t, seg = intersect(bvh, o[0], o[1], o[2], d[0], d[1], d[2], 0.0, np.inf, -1, -1, 0)
                if seg >= 0:
                    h += 1
        hits[row] = h
    return hits.sum()


def run(out_dir) -> dict:
    import numba

    from pipeline.bcsdf_presets import load_bcsdf_preset
    from pipeline.render_setup import ground_array, load_fibers, pack_lights
    from pipeline.scene import camera_array, load_scene
    from stages.core.geometry.bvh import build_fiber_bvh
    from stages.core.shading.material import pack_material_bcsdf, pack_material_lambert
    from stages.render.film import F_HIT, finalize, new_film, tile_grid
    from stages.render.integrators.fiberpath import FiberpathIntegrator
    from stages.render.meshes import no_meshes
    from stages.render.tiles import render_tiles

    src = Path(os.environ.get("LOOMLIGHT_BENCH_FIBERS", ROOT / "out" / "demo" / "fibers.zarr"))
    if (src / "zarr.json").exists():
        f = load_fibers(src)
        pts, offs, rad, source = f.points, f.fiber_offsets, f.point_radius, str(src)
    else:
        pts, offs, rad = synthetic_swatch()
        source = "synthetic plain-weave swatch (realized demo fibres not found)"
    scene = load_scene(ROOT / "data" / "scenes" / "demo.toml")
    t0 = time.perf_counter()
    bvh, _ = build_fiber_bvh(pts, offs, rad)   # first call includes compilation
    t1 = time.perf_counter()
    bvh, _ = build_fiber_bvh(pts, offs, rad)
    build_s = time.perf_counter() - t1

    W, H = 256, 192
    cam = camera_array(scene.camera, W, H)
    nthreads = numba.config.NUMBA_NUM_THREADS
    _primary(bvh, camera_array(scene.camera, 8, 6), 8, 6, 1)  # compile
    res = {}
    for threads in sorted({1, nthreads}):
        numba.set_num_threads(threads)
        t = time.perf_counter()
        hits = _primary(bvh, cam, W, H, 4)
        dt = time.perf_counter() - t
        res[threads] = (W * H * 4 / dt, hits)
    numba.set_num_threads(nthreads)

    lights = pack_lights(scene.lights, scene.path)
    ground, has_ground = ground_array(scene.render)
    mats = np.stack([pack_material_bcsdf(load_bcsdf_preset("cotton"))])
    mof = np.zeros(len(offs) - 1, np.int32)
    PW, PH, spp = 128, 96, 4
    pcam = camera_array(scene.camera, PW, PH)
    tiles = tile_grid(PW, PH, 16)
    extent = float(np.linalg.norm(pts.max(0) - pts.min(0)))

    integ = FiberpathIntegrator(bvh, mof, mats, pack_material_lambert(ground[1:4]), lights.table(), ground, has_ground,
                                no_meshes(), int(scene.render["max_depth"]), int(scene.render["rr_depth"]), 1 << 40,
                                1e-7 * extent)

    def render(spp_):
        t = time.perf_counter()
        film = render_tiles(integ, pcam, 1, spp_, 0, spp_, tiles, new_film(PW, PH))
        dt = time.perf_counter() - t
        return dt, finalize(film, spp_).rays, float(film[..., F_HIT].mean() / spp_)

    render(1)  # compile
    dt, rays, coverage = render(spp)
    return {
        "fibres_source": source, "fibres": int(len(offs) - 1), "segments": int(len(bvh.seg_a)),
        "bvh_nodes": int(len(bvh.node_left)), "bvh_build_s": build_s, "bvh_first_build_incl_compile_s": t1 - t0,
        "primary_image": f"{W}x{H} x 4 rays", "primary_hit_fraction": res[1][1] / (W * H * 4),
        "primary_rays_per_s_per_core": res[1][0], "primary_rays_per_s_all_threads": res[nthreads][0],
        "threads": nthreads, "path_image": f"{PW}x{PH} @ {spp} spp", "path_coverage": coverage,
        "paths_per_s": PW * PH * spp / dt, "rays_per_s": rays / dt, "rays_per_s_per_core": rays / dt / nthreads,
        "rays_per_path": rays / (PW * PH * spp), "path_render_s": dt,
    }
