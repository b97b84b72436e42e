"""``--method fiberpath_shell``: the fiberpath estimator on a shell-mapped, tiled fabric (stage ``tile``).

The fibres come from a ``tiling`` artifact (``loomlight tile``): pass it as ``--fibers TILING.zarr``
(or ``--set tiling=TILING.zarr``). Rays walk the shell's tetrahedra and meet the exemplar fibres of each
block in exemplar space (``stages.core.shell_traversal``); the path tracer is ``stages.render.fiberpath``'s
estimator (``stages.render.shell_scene.render_tiles_shell``). Materials as in ``--method fiberpath``:
``--material bcsdf`` (the BCSDF preset of each yarn group, scene key ``yarns.<group>.bcsdf`` or
``--bcsdf NAME``) or ``--material lambert`` (albedo = the scene's ``yarns.<group>.color``, else the
yarn preset's albedo). ``pipeline/renderers/fiberpath.py`` hands tiling artifacts given to
``--method fiberpath --fibers`` to this module.
"""
from __future__ import annotations

import time

import numpy as np

from ..errors import LoomError
from ..render_setup import GROUP_NAMES, Fibers, ground_array, pack_lights
from ..scene import camera_array
from . import RenderResult


def tiling_path(options):
    path = (options.get("extra") or {}).get("tiling") or options.get("fibers")
    if not path:
        raise LoomError(None, "--fibers", "fiberpath_shell needs a tiling artifact: pass --fibers TILING.zarr")
    return path


def tiling_fibers(scene, art) -> Fibers:
    """``Fibers``-like view of the exemplar fibres (per fibre: a global yarn index, its group and albedo)."""
    sizes = art.summary["exemplar_sizes"]
    ex_fibers = art["ex_fibers"]
    fy = art["ex_fiber_yarn"].astype(np.int64)
    yarn_off = np.cumsum([0] + [e + p for e, p in sizes])
    for k in range(len(sizes)):
        fy[ex_fibers[k]:ex_fibers[k + 1]] += yarn_off[k]
    group = art["ex_yarn_group"].astype(np.int64)
    albedo = np.empty((len(group), 3))
    for g in (0, 1):
        yt = scene.yarn_type(GROUP_NAMES[g])
        col = yt.get("color")
        if col is None:
            from ..presets import load_preset

            col = load_preset(yt.get("preset") or (art.params["config"].get("yarn", {}).get("preset", "cotton1")))["albedo"]
        albedo[group == g] = np.broadcast_to(np.asarray(col, float), 3)
    return Fibers(art.path, art["ex_points"], art["ex_radius"], art["ex_offsets"], fy.astype(np.int32),
                  albedo, group)


def render(scene, options: dict) -> RenderResult:
    from stages.render.film import tile_grid
    from stages.render.shell_scene import render_tiles_shell

    from ..tile_runner import load_tiling
    from .fiberpath import SELF_WINDOW, fiber_materials, trace_film

    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    t0 = time.perf_counter()
    sc, art = load_tiling(tiling_path(options))
    build_s = time.perf_counter() - t0
    fibers = tiling_fibers(scene, art)
    mat_of_fiber, mats = fiber_materials(scene, fibers, options)
    lights = pack_lights(scene.lights, scene.path)
    if len(lights.lights) == 0:
        raise LoomError(scene.path, "lights", "the scene has no lights (the image would be black)")
    ground, has_ground = ground_array(scene.render)
    W, H, spp, seed = options["width"], options["height"], options["spp"], options["seed"]
    max_depth = int(options.get("max_depth") or scene.render.get("max_depth", 32))
    rr_depth = int(options.get("rr_depth") or scene.render.get("rr_depth", 5))
    cam = camera_array(scene.camera, W, H)
    lo, hi = np.asarray(art.summary["bounds"][0]), np.asarray(art.summary["bounds"][1])
    eps = 1e-7 * max(float(np.linalg.norm(hi - lo) + np.abs(np.concatenate([lo, hi])).max()), 1e-12)
    tiles = tile_grid(W, H, int(scene.render.get("tile_size", 16)))
    window = SELF_WINDOW  # BCSDF vertices skip their whole fibre, as in fiberpath

    def batch(b0, b1, film_sum, film_sq, hits, depth_sum, tile_rays):
        render_tiles_shell(cam, sc, mat_of_fiber, mats, *lights.arrays(), ground, has_ground,
                           tiles, b0, b1, spp, seed, max_depth, rr_depth, window, eps,
                           film_sum, film_sq, hits, depth_sum, tile_rays)

    rgb, extra, rays, render_s = trace_film("fiberpath (shell)", W, H, spp, tiles, batch)
    stats = {"rays": rays, "paths": W * H * spp, "render_s": render_s, "scene_build_s": build_s,
             "tetrahedra": int(art.summary["tetrahedra"]), "exemplars": int(art.summary["exemplars"]),
             "blocks": int(art.summary["blocks"]), "segments": int(len(sc.seg_a)), "fibers": fibers.n_fibers,
             "max_depth": max_depth, "rr_depth": rr_depth, "materials": int(len(mats))}
    return RenderResult(rgb, extra, stats)
