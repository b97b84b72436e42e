"""btf render speed (Daubert et al. 2001 §7: "about 1 frame per second for a resolution of 730 x 400"):
frames per second.

Geometry: the draped damask's base surface (``data/tilings/damask.toml``: a 4 x 4 cloth over a sphere of
radius 1, 40 x 40 quads, 3200 triangles, ``stages.tile.base_surfaces.sphere_drape``) with 8 texture
repeats across its uv. Texture: a synthetic btf of the paper's size -- 32 x 32 texels, 6 levels,
2 lobes, 64 views (8 x 8) and 64 lights -- random rho, lobes, view table and frames with a few holes,
written as an artifact (float32 arrays) and read back by the renderer's loader, so ``fit_bytes`` is
the bytes of the arrays it reads (target <= 4 MB, the paper's "4 MB ... including all mip-map levels"). The
same artifact holds a tabulated model (``--set model=tabulated``): random non-negative rows of rank 24 over the
64 x 64 x 3 (view, light, channel) values of every texel of every level, compressed by ``compress_texels`` at the
defaults (8 clusters x 8 components; ``table_bytes``, target <= 16 MB a fabric), timed the same way
(``tabulated_fps``, ``tabulated_scene_lights_fps``); and a second artifact's table on 15 x 15 half-vector light cells
(``precompute btf --light-coords half``: the rows zero where a cell has no light, as an acquisition leaves them;
``tabulated_half_fps``, ``tabulated_half_scene_lights_fps``, ``table_half_bytes``).
Camera: the draped damask scene's at 730 x 400, 1 spp, one directional light, no shadow rays, mip on; and
under the scene's own lights (its directional light and its constant sky, whose light-grid quadrature
the renderer tabulates per texel and grid view once: ``sky_table``, timed apart as ``sky_table_s``).
Frames per second on 2 threads after compilation (target >= 10), the median of 7 frames, through the
shared tile loop (``stages.render.tiles.render_tiles``) with 64-pixel tiles; also with the default
16-pixel tiles (``render.tile_size``: with threads, the loop hands every tile to a thread pool, about
60 us of Python per tile, which at this speed costs as much as rendering the tile), 1 thread, mip off
and shadows on, and the CPU seconds a frame takes (all threads together: on a machine shared with
other work, wall-clock frames per second understate what the code does).
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
W, H = 730, 400


def synthetic_btf(path, res=32, levels=6, lobes=2, view_grid=(8, 8), light_grid=(8, 8), period=(0.5, 0.5), seed=0,
                  half=False):
    """A btf artifact of random (plausible) texels; every level independent. ``half``: the table's lights are
    half-vector cells (``light_grid`` (nx, ny); the fit's grid 8 x 8)."""
    from pipeline.artifacts import ArtifactWriter
    from stages.core.btf import half_cell_geometry, half_grid, hemisphere_grid

    rng = np.random.default_rng(seed)
    V = view_grid[0] * view_grid[1]
    fit_grid = (8, 8) if half else light_grid
    with ArtifactWriter(path, kind="btf", stage="precompute btf", params={"synthetic": seed}, inputs={}) as w:
        w.write("view_dirs", hemisphere_grid(*view_grid))
        w.write("light_dirs", hemisphere_grid(*fit_grid))
        mask = None
        if half:
            w.write("half_dirs", half_grid(*light_grid))
            mask = half_cell_geometry(*view_grid, *light_grid, True).valid
        for lv in range(levels):
            r = res >> lv
            w.write(f"level_{lv}/rho", rng.uniform(0.02, 0.25, (1, r, r, 3)).astype(np.float32))
            lob = np.empty((r, r, lobes, 3, 4), np.float32)
            lob[..., 0] = rng.uniform(-1.2, -0.6, (r, r, lobes, 1))
            lob[..., 1] = lob[..., 0] * 1.22
            lob[..., 2] = rng.uniform(0.6, 1.0, (r, r, lobes, 1))
            lob[..., 3] = rng.uniform(2.0, 30.0, (r, r, lobes, 1))
            w.write(f"level_{lv}/lobes", lob[None])
            tb = rng.uniform(0.6, 1.4, (r, r, V, 4)).astype(np.float32)
            tb[..., 3] = np.where(rng.uniform(size=(r, r, V)) < 0.05, 0.0, 1.0)
            w.write(f"level_{lv}/table", tb[None])
            n = np.stack([rng.normal(0, 0.1, (r, r)), rng.normal(0, 0.1, (r, r)), np.ones((r, r))], -1)
            n /= np.linalg.norm(n, axis=-1, keepdims=True)
            t = np.cross(np.cross(n, [1.0, 0.0, 0.0]), n)
            t /= np.linalg.norm(t, axis=-1, keepdims=True)
            w.write(f"level_{lv}/frame", np.stack([n, t], -2).astype(np.float32)[None])
        tabulated_rows(w, rng, res, levels, V, light_grid[0] * light_grid[1], mask=mask)
        w.summary.update(kind="btf", source="synthetic", source_hash="synthetic", exemplars=[0],
                         exemplar_names=["synthetic"], periods=[list(period)], resolution=res, levels=levels,
                         lobes=lobes,
                         view_grid=list(view_grid), light_grid=list(light_grid))
        if half:
            w.summary.update(light_coords="half", fit_light_grid=list(fit_grid), directions="cell")


def tabulated_rows(w, rng, res, levels, V, L, rank=24, mask=None) -> int:
    """Write a tabulated model of random rows (module doc) into the artifact, times ``mask`` (V, L) when given; its
    bytes."""
    from pipeline.runners.precompute_btf import write_tables
    from stages.precompute.btf_compress import compress_texels

    rows = sum((res >> lv) ** 2 for lv in range(levels))
    B = rng.uniform(0.0, 0.02, (rank, V, L, 3))
    if mask is not None:
        B *= mask[None, :, :, None]
    X = (rng.uniform(0.0, 1.0, (rows, rank)) @ B.reshape(rank, -1)).astype(np.float32)
    return write_tables(w, [compress_texels(X, 8, 8)], V, L)


def run(out_dir) -> dict:
    import stages  # noqa: F401  (before numba: importing stages points numba's cache at the project's)
    # isort: split
    import numba

    from pipeline.errors import LoomError
    from pipeline.render_setup import pack_lights
    from pipeline.renderers.btf import ONE_EXEMPLAR, DressedMesh, load_btf, pack_integrator
    from pipeline.scene import camera_array, load_scene
    from stages.core.btf import hemisphere_grid
    from stages.core.geometry.triangles import area_weighted_normals
    from stages.render.film import F_HIT, new_film, tile_grid
    from stages.render.integrators.btf import sky_table  # (importing it registers the integrator's radiance)
    from stages.render.tiles import load_tile_kernel, render_tiles
    from stages.tile.base_surfaces import sphere_drape

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "bench_btf.zarr"
    try:
        load_btf(path, "tabulated")
    except LoomError:           # absent, or written by older code
        synthetic_btf(path)
    tex = load_btf(path)
    V, UV, F = sphere_drape(4.0, 1.0, 40, 40, folds=6, fold_amplitude=0.25)
    geom = DressedMesh(V, F, area_weighted_normals(V, F), UV * 8.0, ONE_EXEMPLAR, "draped damask base surface")
    scene = load_scene(ROOT / "data" / "scenes" / "draped_damask.toml")
    lights = pack_lights([lt for lt in scene.lights if lt["type"] == "directional"][:1], scene.path)
    cam = camera_array(scene.camera, W, H)
    ground, has_ground = np.zeros(4), False
    counts = np.ones((H, W), np.int64)

    def fps(integ, threads, tile=64, frames=7):
        """(frames per second, coverage, CPU seconds per frame) of the shared tile loop."""
        tiles = tile_grid(W, H, tile)
        numba.set_num_threads(threads)
        load_tile_kernel(integ, cam)
        render_tiles(integ, cam, 0, 1, 0, counts, tiles, new_film(W, H), threads)   # warm caches
        times, cpu = [], []
        film = None
        for _ in range(frames):
            film = new_film(W, H)
            film[...] = 0.0   # its pages mapped before the clock starts, as in one long render
            t = time.perf_counter()
            c = time.process_time()
            render_tiles(integ, cam, 0, 1, 0, counts, tiles, film, threads)
            cpu.append(time.process_time() - c)
            times.append(time.perf_counter() - t)
        return 1.0 / float(np.median(times)), float(film[..., F_HIT].mean()), float(np.median(cpu))

    t0 = time.perf_counter()
    integ = pack_integrator(geom, tex, lights, ground, has_ground, cam, mip=True, shadows=False)
    setup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    load_tile_kernel(integ, cam)
    compile_s = time.perf_counter() - t0
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    load = os.getloadavg()[0]
    fps2, coverage, cpu2 = fps(integ, threads)
    fps16, _, cpu16 = fps(integ, threads, tile=16)
    fps1, _, cpu1 = fps(integ, 1, frames=3)
    fps_nomip, _, _ = fps(integ._replace(mip=False), threads, frames=3)
    fps_shadows, _, _ = fps(integ._replace(shadows=1), threads, frames=3)
    integ_sky = pack_integrator(geom, tex, pack_lights(scene.lights, scene.path), ground, has_ground, cam, mip=True,
                                shadows=False)
    t0 = time.perf_counter()            # the sky table alone (compiled or loaded by the setup above)
    sky_table(tex.texels, tex.light_dirs, hemisphere_grid(*tex.view_grid))
    sky_s = time.perf_counter() - t0
    fps_sky, _, cpu_sky = fps(integ_sky, threads)
    tab = load_btf(path, "tabulated")
    integ_tab = pack_integrator(geom, tab, lights, ground, has_ground, cam, mip=True, shadows=False)
    fps_tab, _, cpu_tab = fps(integ_tab, threads)
    integ_tab_sky = pack_integrator(geom, tab, pack_lights(scene.lights, scene.path), ground, has_ground, cam,
                                    mip=True, shadows=False)
    fps_tab_sky, _, _ = fps(integ_tab_sky, threads)
    path_half = out / "bench_btf_half.zarr"
    try:
        half = load_btf(path_half, "tabulated")
    except LoomError:
        synthetic_btf(path_half, light_grid=(15, 15), half=True)
        half = load_btf(path_half, "tabulated")
    fps_half, _, cpu_half = fps(pack_integrator(geom, half, lights, ground, has_ground, cam, mip=True, shadows=False),
                                threads)
    fps_half_sky, _, _ = fps(pack_integrator(geom, half, pack_lights(scene.lights, scene.path), ground, has_ground,
                                             cam, mip=True, shadows=False), threads)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return {
        "image": f"{W}x{H} @ 1 spp", "triangles": int(len(F)), "btf": "32 x 32, 6 levels, 2 lobes, 64 views, 64 lights",
        "fit_bytes": int(tex.fit_bytes), "fit_bytes_target": 4 * 2**20, "coverage": coverage,
        "threads": threads, "fps": fps2, "fps_target": 10.0, "cpu_s_per_frame": cpu2,
        "fps_tiles_16": fps16, "cpu_s_per_frame_tiles_16": cpu16,
        "fps_1_thread": fps1, "cpu_s_per_frame_1_thread": cpu1, "fps_mip_off": fps_nomip,
        "fps_shadows_on": fps_shadows, "scene_lights": ", ".join(lt["type"] for lt in scene.lights),
        "scene_lights_fps": fps_sky, "scene_lights_fps_target": 10.0, "scene_lights_cpu_s_per_frame": cpu_sky,
        "sky_table_s": sky_s, "pixels_per_s": fps2 * W * H, "load_average_before": load,
        "setup_s": setup_s, "first_tile_incl_compile_s": compile_s,
        "table_bytes": int(tab.fit_bytes), "table_bytes_target": 16 * 2**20, "tabulated_fps": fps_tab,
        "tabulated_fps_target": 10.0, "tabulated_cpu_s_per_frame": cpu_tab, "tabulated_scene_lights_fps": fps_tab_sky,
        "tabulated_scene_lights_fps_target": 10.0, "table_half_bytes": int(half.fit_bytes),
        "tabulated_half_fps": fps_half, "tabulated_half_fps_target": 10.0, "tabulated_half_cpu_s_per_frame": cpu_half,
        "tabulated_half_scene_lights_fps": fps_half_sky, "tabulated_half_scene_lights_fps_target": 10.0,
    }


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(run(sys.argv[1] if len(sys.argv) > 1 else "/tmp/bench_btf"), indent=1))
