"""``--method fiberpath``: explicit fibres (capsule chains) path traced with the Khungurn 2015 BCSDF.

Fibres come from a ``fibers`` artifact: ``--fibers PATH.zarr`` (``--source realized`` is accepted and
means the same; it is the only fibre source this method has, so the scene's ``render.source``, which
selects volpath's density source, is ignored). Materials: ``--material bcsdf``
(default) gives every fibre the BCSDF preset of its yarn group -- scene key ``yarns.<group>.bcsdf``
(falling back to ``yarns.default.bcsdf``), else ``--bcsdf NAME``; ``--material lambert`` gives every
fibre a Lambertian surface with its yarn's albedo (for comparisons with other renderers).
``--set tint=yarn`` multiplies each yarn's TT colour C_TT by the yarn's albedo (the scene's
``yarns.<group>.color`` as realized into the fibers artifact), so dyed yarns keep their colour under a
fitted preset. A preset given as a ``.toml`` path in the scene is resolved against the scene file.
Lights, camera and the optional ground plane come from the scene.
"""
from __future__ import annotations

import os
import time

import numpy as np

from ..errors import LoomError
from ..progress import progress
from ..render_setup import GROUP_NAMES, ground_array, load_bcsdf_preset, load_fibers, pack_lights
from ..scene import camera_array
from . import RenderResult

# Rays leaving a BCSDF vertex skip the whole fibre they leave (a window of segments wider than any
# fibre): the curve BCSDF already integrates over the fibre's cross-section, and a ray that travels
# inside a straight fibre at a grazing angle would otherwise 'enter' a joint sphere further along it.
# The cost: a fibre never shadows its own distant turns (other fibres still do).
SELF_WINDOW = 1 << 40


def fiber_materials(scene, fibers, options):
    """(mat_of_fiber (F,) int32, materials (NM, MAT_SIZE)) for the chosen material model."""
    from stages.render.fiberpath import pack_material_bcsdf, pack_material_lambert

    material = options.get("material") or "bcsdf"
    if material == "lambert":
        mats = np.stack([pack_material_lambert(a) for a in fibers.yarn_albedo])
        return fibers.fiber_yarn.astype(np.int32), mats
    if material != "bcsdf":
        raise LoomError(None, "--material", f"unknown fibre material {material!r} (known: bcsdf, lambert)")
    names = {}
    for g, gname in enumerate(GROUP_NAMES):
        name = scene.yarn_type(gname).get("bcsdf")
        if name and name.endswith(".toml"):
            name = str(scene.resolve(name))
        name = name or options.get("bcsdf")
        if name:
            names[g] = name
    if fibers.yarn_group is not None:
        yarn_group = np.clip(np.asarray(fibers.yarn_group, np.int64), 0, 3)
        if len(yarn_group) < len(fibers.yarn_albedo):
            yarn_group = np.concatenate([yarn_group, np.full(len(fibers.yarn_albedo) - len(yarn_group), 3)])
    else:
        # the fibres' yarn groups are unknown (no yarns artifact among the fibers artifact's inputs):
        # 'other' (falling back to yarns.default.bcsdf, then --bcsdf), else the one preset the scene names
        yarn_group = np.full(len(fibers.yarn_albedo), 3)
        named = sorted(set(names.values()))
        if 3 not in names and len(named) == 1:
            names[3] = named[0]
    used = sorted(set(int(g) for g in yarn_group[np.unique(fibers.fiber_yarn)]))
    presets = []
    index = {}
    group_mat = {}
    for g in used:
        name = names.get(g)
        if not name:
            known = ", ".join(f"{GROUP_NAMES[k]}={v}" for k, v in sorted(names.items())) or "none"
            raise LoomError(scene.path, f"yarns.{GROUP_NAMES[g]}.bcsdf",
                            f"no BCSDF preset for the fibres of yarn group {GROUP_NAMES[g]!r} (scene names: {known}); "
                            "set it (or yarns.default.bcsdf) in the scene or pass --bcsdf NAME")
        if name not in index:
            index[name] = len(presets)
            presets.append(pack_material_bcsdf(load_bcsdf_preset(name)))
        group_mat[g] = index[name]
    lut = np.zeros(len(yarn_group), np.int32)
    for y, g in enumerate(yarn_group):
        lut[y] = group_mat.get(int(g), 0)
    tint = (options.get("extra") or {}).get("tint", "none")
    if tint == "yarn":  # one material per yarn: its group's preset with C_TT times the yarn albedo
        mats = []
        for y in range(len(fibers.yarn_albedo)):
            row = presets[lut[y]].copy() if y < len(lut) else presets[0].copy()
            row[4:7] *= fibers.yarn_albedo[y]   # packed BCSDF starts at column 1: C_TT is 3:6 there
            mats.append(row)
        return fibers.fiber_yarn.astype(np.int32), np.stack(mats)
    if tint != "none":
        raise LoomError(None, "--set tint", f"unknown tint {tint!r} (known: none, yarn)")
    return lut[fibers.fiber_yarn], np.stack(presets)


def render(scene, options: dict) -> RenderResult:
    from stages.core.bvh import build_fiber_bvh
    from stages.render.fiberpath import render_tiles
    from stages.render.film import tile_grid

    path = options.get("fibers")
    source = options.get("source")
    if source not in (None, "realized"):
        raise LoomError(None, "--source", f"fiberpath renders realized fibres only (got {source!r}); pass --fibers PATH.zarr")
    if not path:
        raise LoomError(None, "--fibers", "fiberpath needs the realized fibres: pass --fibers PATH.zarr")
    from ..artifacts import read_meta

    if read_meta(path).get("kind") == "tiling":  # shell-mapped exemplars (stage tile)
        from .fiberpath_shell import render as render_shell

        return render_shell(scene, options)
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    fibers = load_fibers(path)
    mat_of_fiber, mats = fiber_materials(scene, fibers, options)
    lights = pack_lights(scene.lights, scene.path)
    if len(lights.lights) == 0:
        raise LoomError(scene.path, "lights", "the scene has no lights (the image would be black)")
    ground, has_ground = ground_array(scene.render)
    W, H, spp, seed = options["width"], options["height"], options["spp"], options["seed"]
    max_depth = int(options.get("max_depth") or scene.render.get("max_depth", 32))
    rr_depth = int(options.get("rr_depth") or scene.render.get("rr_depth", 5))
    tile = int(scene.render.get("tile_size", 16))
    cam = camera_array(scene.camera, W, H)

    t0 = time.perf_counter()
    bvh, _ = build_fiber_bvh(fibers.points, fibers.fiber_offsets, fibers.point_radius)
    build_s = time.perf_counter() - t0
    lo = fibers.points.min(axis=0)
    hi = fibers.points.max(axis=0)
    extent = float(np.linalg.norm(hi - lo) + np.abs(np.concatenate([lo, hi])).max())
    eps = 1e-7 * max(extent, 1e-12)

    tiles = tile_grid(W, H, tile)
    def batch(b0, b1, film_sum, film_sq, hits, depth_sum, tile_rays):
        render_tiles(cam, bvh, mat_of_fiber, mats, *lights.arrays(), ground, has_ground,
                     tiles, b0, b1, spp, seed, max_depth, rr_depth, SELF_WINDOW, eps,
                     film_sum, film_sq, hits, depth_sum, tile_rays)

    rgb, extra, rays, render_s = trace_film("fiberpath", W, H, spp, tiles, batch)
    stats = {"rays": rays, "paths": W * H * spp, "render_s": render_s, "bvh_build_s": build_s,
             "segments": int(len(bvh.seg_a)), "fibers": fibers.n_fibers, "bvh_nodes": int(len(bvh.node_left)),
             "max_depth": max_depth, "rr_depth": rr_depth, "materials": int(len(mats))}
    return RenderResult(rgb, extra, stats)


def trace_film(label, W, H, spp, tiles, render_batch):
    """Run a tile kernel over the image in batches with a progress bar and finish the film.

    ``render_batch(b0, b1, film_sum, film_sq, hits, depth_sum, tile_rays)`` renders tiles b0..b1-1.
    Returns (rgb, extra channels A/depth/variance, rays, render seconds)."""
    from stages.render.film import finalize

    film_sum = np.zeros((H, W, 3))
    film_sq = np.zeros((H, W, 3))
    hits = np.zeros((H, W))
    depth_sum = np.zeros((H, W))
    tile_rays = np.zeros(len(tiles), np.int64)
    batch = max(1, 4 * (os.cpu_count() or 1))
    t1 = time.perf_counter()
    with progress(f"{label} {W}x{H} @ {spp} spp", len(tiles)) as advance:
        for b0 in range(0, len(tiles), batch):
            b1 = min(b0 + batch, len(tiles))
            render_batch(b0, b1, film_sum, film_sq, hits, depth_sum, tile_rays)
            advance(b1 - b0)
    render_s = time.perf_counter() - t1
    rgb, var = finalize(film_sum, film_sq, spp)
    alpha = (hits / spp).astype(np.float32)
    depth = np.where(hits > 0, depth_sum / np.maximum(hits, 1), 0.0).astype(np.float32)
    return rgb, {"A": alpha, "depth": depth, "variance": var}, int(tile_rays.sum()), render_s
