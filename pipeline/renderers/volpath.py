"""``--method volpath``: volumetric path tracing of the fibre medium (seed 000 §5.4, App. A).

Sources (``--source``, default the scene's ``render.source``, else procedural):
- ``procedural``: lookups on the fly from a ``tables`` artifact (``--set tables=PATH.zarr``, which
  carries its own copy of the yarn curves).
- ``realized``: fibres of a ``fibers`` artifact (``--fibers PATH.zarr``) in a BVH; per-yarn density
  and roughness from the yarn types the fibres were realized with.
- ``grid``: a ``grid`` artifact of ``loomlight voxelize`` (``--set grid=PATH.zarr``).

Scene: camera, lights, ``render.max_depth``, ``render.rr_depth``, ``render.tile_size`` and the
optional ``render.ground``. ``--set majorant_cell=X`` sets the majorant-grid cell size (scene units;
default: a quarter of the mean yarn extent bound, at most 128 cells along an axis).
Statistics: paths, rays (free-flight and shadow queries), medium lookups and lookups/s, the
majorant grid (cells, occupied fraction), source build time.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import LoomError
from ..progress import warn
from ..render_setup import ground_array, load_fibers, pack_lights
from ..scene import camera_array
from . import RenderResult

SOURCES = ("procedural", "realized", "grid")
MAX_CELLS_PER_AXIS = 128
CELL_FRACTION = 0.25  # default majorant cell: this fraction of the mean yarn extent bound


# ------------------------------------------------------------------------------------------------
# sources
def _artifact(path, kind, place):
    from ..artifacts import Artifact

    if not path:
        raise LoomError(None, place, f"the {kind} artifact is needed: pass {place}")
    return Artifact(Path(path), kind=kind)


def _box_of_capsules(a, b, r):
    lo = np.minimum(a, b).min(axis=0) - r.max()
    hi = np.maximum(a, b).max(axis=0) + r.max()
    return lo, hi


def _majorant_res(lo, hi, cell):
    ext = np.maximum(hi - lo, 1e-12)
    cell = max(float(cell), float(ext.max()) / MAX_CELLS_PER_AXIS)
    return np.maximum(1, np.ceil(ext / cell)).astype(np.int64)


def procedural_source(tables_path, cell=None):
    """(ProceduralMedium, MajorantGrid, info) from a tables artifact."""
    from stages.render.procedural_medium import ProceduralMedium, fiber_capsules
    from stages.render.tracking import majorants_from_capsules, make_majorant_grid

    from ..runners.tables import load_tables

    if not tables_path:
        raise LoomError(None, "--set tables=PATH.zarr", "--source procedural needs a tables artifact (loomlight tables)")
    cv, tab, _ = load_tables(tables_path)
    a, b, r, bound = fiber_capsules(cv, tab, 0.25)
    lo, hi = _box_of_capsules(a, b, r)
    res = _majorant_res(lo, hi, cell or CELL_FRACTION * float(np.mean(tab.yarn_extent)))
    mu = majorants_from_capsules(a, b, r, bound, lo, hi, res)
    return ProceduralMedium(cv, tab), make_majorant_grid(lo, hi, res, mu), {"yarns": int(len(tab.yarn_type))}


def realized_source(fibers_path, cell=None):
    """(RealizedMedium, MajorantGrid, info) from a fibers artifact; per-yarn density and roughness
    from the yarn types the fibres were realized with (their yarns artifact and preset/radius)."""
    from stages.core.geometry.bvh import build_fiber_bvh
    from stages.core.yarn.model import DENSITY, ROUGHNESS, extent_bound
    from stages.render.realized_medium import RealizedMedium, fiber_capsules
    from stages.render.tracking import majorants_from_capsules, make_majorant_grid

    from ..artifacts import Artifact
    from ..runners.yarn_types import yarn_types_of

    if not fibers_path:
        raise LoomError(None, "--fibers", "--source realized needs the realized fibres: pass --fibers PATH.zarr")
    fibers = load_fibers(fibers_path)
    fart = _artifact(fibers_path, "fibers", "--fibers")
    yarns_in = fart.meta.get("inputs", {}).get("yarns")
    if not yarns_in:
        raise LoomError(fibers_path, "inputs", "the fibers artifact does not name the yarns artifact it was realized from")
    yarns = Artifact(yarns_in["path"], kind="yarns")
    _, tparams, ytype, _ = yarn_types_of(yarns, fart.params.get("preset"), fart.params.get("radius"))
    Y = len(ytype)
    if int(fibers.fiber_yarn.max()) >= Y:
        raise LoomError(fibers_path, "fiber_yarn", f"fibres name yarns beyond the {Y} yarns of {yarns.path}")
    tp = tparams[ytype]
    albedo = np.zeros((Y, 3))
    albedo[: min(Y, len(fibers.yarn_albedo))] = fibers.yarn_albedo[:Y]
    extent = float(np.mean([extent_bound(t) for t in tp]))
    t0 = time.perf_counter()
    bvh, _ = build_fiber_bvh(fibers.points, fibers.fiber_offsets, fibers.point_radius)
    med = RealizedMedium(bvh, fibers.fiber_yarn.astype(np.int32), np.ascontiguousarray(tp[:, DENSITY]),
                         albedo, np.ascontiguousarray(tp[:, ROUGHNESS]))
    a, b, r, bound = fiber_capsules(med)
    lo, hi = _box_of_capsules(a, b, r)
    res = _majorant_res(lo, hi, cell or CELL_FRACTION * extent)
    mu = majorants_from_capsules(a, b, r, bound, lo, hi, res)
    info = {"fibers": fibers.n_fibers, "segments": int(len(bvh.seg_a)), "bvh_build_s": time.perf_counter() - t0}
    return med, make_majorant_grid(lo, hi, res, mu), info


def grid_source(grid_path, cell=None):
    """(GridMedium, MajorantGrid, info) from a grid artifact (macrocells of 4 voxels by default)."""
    from stages.render.grid_medium import GridMedium
    from stages.render.tracking import majorants_from_voxels, make_majorant_grid

    art = _artifact(grid_path, "grid", "--set grid=PATH.zarr")
    lo, hi = (np.asarray(v, float) for v in art.summary["bounds"])
    den = np.ascontiguousarray(art["density"], np.float32)
    med = GridMedium(lo, hi, den, np.ascontiguousarray(art["direction"], np.float32),
                     np.ascontiguousarray(art["albedo"], np.float32), np.ascontiguousarray(art["roughness"], np.float32))
    vox = (hi - lo) / np.array(den.shape[::-1])
    res = _majorant_res(lo, hi, cell or 4.0 * float(vox.max()))
    mu = majorants_from_voxels(den, lo, hi, res)
    return med, make_majorant_grid(lo, hi, res, mu), {"voxels": list(den.shape[::-1])}


def open_source(source, options):
    extra = options.get("extra") or {}
    tables = options.get("tables") or extra.get("tables")
    cell = extra.get("majorant_cell")
    if cell is not None:
        try:
            cell = float(cell)
        except ValueError:
            raise LoomError(None, "--set majorant_cell", f"not a number: {cell!r}") from None
        if not cell > 0:
            raise LoomError(None, "--set majorant_cell", f"must be positive, got {cell}")
    if source == "procedural":
        return procedural_source(tables, cell)
    if source == "realized":
        return realized_source(options.get("fibers"), cell)
    if source == "grid":
        return grid_source(options.get("grid") or extra.get("grid"), cell)
    raise LoomError(None, "--source", f"unknown volpath source {source!r} (known: {', '.join(SOURCES)})")


# ------------------------------------------------------------------------------------------------
def _sees_fabric(maj, cam, W, H, n=24):
    from stages.render.camera import camera_ray
    from stages.render.tracking import ray_meets_majorant

    for i in range(n):
        for j in range(n):
            o, d = camera_ray(cam, (i + 0.5) * H / n, (j + 0.5) * W / n, 0.0, 0.0)
            if ray_meets_majorant(maj, o[0], o[1], o[2], d[0], d[1], d[2]):
                return True
    return False


def render(scene, options: dict) -> RenderResult:
    from stages.render.film import VARIANCE_LUMINANCE
    from stages.render.volpath import VolpathIntegrator

    from .film import render_film

    source = options.get("source") or scene.render.get("source") or "procedural"
    if source not in SOURCES:
        raise LoomError(None, "--source", f"unknown volpath source {source!r} (known: {', '.join(SOURCES)})")
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    lights = pack_lights(scene.lights, scene.path)
    if len(lights.lights) == 0:
        raise LoomError(scene.path, "lights", "the scene has no lights (the image would be black)")
    W, H, spp, seed = options["width"], options["height"], options["spp"], options["seed"]
    max_depth, rr_depth = int(options["max_depth"]), int(options["rr_depth"])
    ground, has_ground = ground_array(scene.render)
    cam = camera_array(scene.camera, W, H)

    t0 = time.perf_counter()
    med, maj, info = open_source(source, options)
    build_s = time.perf_counter() - t0
    if not _sees_fabric(maj, cam, W, H):
        warn(f"the camera of {scene.path} sees no fabric (source {source}); rendering anyway")
    integ = VolpathIntegrator(med, maj, lights.table(), ground, bool(has_ground), max_depth, rr_depth)
    rgb, extra, img, render_s = render_film(f"volpath ({source})", integ, cam, W, H, spp, seed, options["tile_size"],
                                           VARIANCE_LUMINANCE, options.get("threads"))
    stats = {"rays": img.rays, "paths": W * H * spp, "render_s": render_s, "source": source,
             "medium_lookups": img.lookups, "medium_lookups_per_s": img.lookups / max(render_s, 1e-12),
             "source_build_s": build_s, "majorant_cells": [int(x) for x in maj.res],
             "majorant_occupied": float(np.mean(maj.mu > 0)), "max_depth": max_depth, "rr_depth": rr_depth, **info}
    return RenderResult(rgb, extra, stats)
