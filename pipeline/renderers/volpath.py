"""``--method volpath``: volumetric path tracing of the fibre medium (seed 000 §5.4, App. A).

Sources (``--source``, default the scene's ``render.source``, else procedural):
- ``procedural``: lookups on the fly from a ``tables`` artifact (``--tables PATH.zarr``, which
  carries its own copy of the yarn curves), with the render-time fibre cache (``--cache MiB``,
  ``render.cache``; ``pipeline.fibre_cache``): the fibres of the bricks the camera sees, realized into
  a capsule BVH within the budget, answer there; 0 caches nothing.
- ``realized``: fibres of a ``fibers`` artifact (``--fibers PATH.zarr``) in a BVH; per-yarn density
  and roughness from the yarn types the fibres were realized with.
- ``grid``: a ``grid`` artifact of ``loomlight voxelize`` (``--set grid=PATH.zarr``).

Optics (``FibreOptics``): the volume stands for the fibres a fiberpath render shows. Its density is
the fibres' projected area per volume (``pipeline.presets``); a collision with a fibre of a yarn
whose group names a BCSDF (``yarns.<group>.bcsdf`` or ``--bcsdf``) scatters by that BCSDF dyed to
the yarn's colour (``pipeline.dye``), exactly as fiberpath's fibres do
(``stages.render.integrators.volpath``, "Fibre phase function"); ``--set phase=microflake`` (and every
voxel-grid collision) uses seed 000's specular micro-flakes instead, with the dyed BCSDF's mean albedo
as single-scattering albedo (``--set albedo=color``: the yarn's colour itself).

Scene: camera, lights, ``render.max_depth``, ``render.rr_depth``, ``render.tile_size`` and the
optional ``render.ground``. ``--set majorant_cell=X`` sets the majorant-grid cell size (scene units;
default: a quarter of the mean yarn extent bound, at most MAX_MAJORANT_CELLS cells). Where that cap
makes the grid coarser than asked (a large cloth), the fibre cache refines the cells it holds to
FINE_CELL_FRACTION of the mean extent bound (``pipeline.fibre_cache.cached_majorant``).
Statistics: paths, rays (free-flight and shadow queries), medium lookups and lookups/s, the
majorant grid (cells, occupied fraction, refined sub-cells and k), source build time.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import LoomError, unknown
from ..progress import progress, warn
from ..render_setup import (
    OTHER,
    ground_array,
    has_light,
    input_yarn_types,
    load_fibers,
    load_scene_meshes,
    pack_lights,
    recorded_input,
)
from ..scene import camera_array
from . import RenderResult

SOURCES = ("procedural", "realized", "grid")
MAX_MAJORANT_CELLS = 128 ** 3  # majorant grids hold at most this many cells (16 MiB of float64)
MAX_CELLS_PER_AXIS_HARD = 4096
CELL_FRACTION = 0.25  # default majorant cell: this fraction of the mean yarn extent bound
# where the grid is capped (a large cloth), the fibre cache refines the cells it holds to this fraction
# of the mean extent bound (a quarter of the default cell: 8 bytes a sub-cell, only where the camera looks)
FINE_CELL_FRACTION = 0.0625
MAJORANT_STEP = 0.25  # procedural majorant: core-tube capsules spaced this fraction of the tube radius apart
# tables whose frame samples would take more than this are paged: a yarn's samples are made when a ray first
# needs them (stages.core.yarn.frame_pool); below it every yarn's are made at load (no rounds of tiles)
PAGE_FRAME_BYTES = 256 * 2**20


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
    """Cells of about ``cell`` over the box, at most MAX_MAJORANT_CELLS in all: where that caps them, the most
    divided axes are coarsened first, so a flat cloth 50 cm wide and 0.2 cm thick keeps layers of the asked cell
    across its thickness (424 x 424 x 11 at cell 0.0195; cubic cells gave 3 or 4 layers of 0.067, and render
    speed hung on where they fell: volpath.md, Limits)."""
    ext = np.maximum(hi - lo, 1e-12)
    cells = np.full(3, max(float(cell), float(ext.max()) / MAX_CELLS_PER_AXIS_HARD))
    while np.prod(np.ceil(ext / cells)) > MAX_MAJORANT_CELLS:
        n = np.ceil(ext / cells)
        cells[n >= n.max() / 1.05] *= 1.05    # coarsen the most divided axes first: a flat cloth keeps its layers
    return np.maximum(1, np.ceil(ext / cells)).astype(np.int64)


def _capped(lo, hi, cell) -> bool:
    """Whether a grid of ``cell`` over the box would pass MAX_MAJORANT_CELLS (``_majorant_res`` coarsens it)."""
    ext = np.maximum(np.asarray(hi, float) - np.asarray(lo, float), 1e-12)
    return float(np.prod(np.ceil(ext / float(cell)))) > MAX_MAJORANT_CELLS


def procedural_majorant_bytes(lo, hi, mean_extent, workers) -> float:
    """Peak bytes of procedural_majorant over the box lo-hi: one grid per worker while built."""
    res = _majorant_res(np.asarray(lo, float), np.asarray(hi, float), CELL_FRACTION * float(mean_extent))
    return 8.0 * float(np.prod(res)) * max(workers, 1)


def procedural_source(tables_path, cell=None, optics=None, view=None):
    """The ``Source`` (ProceduralMedium, MajorantGrid, info, mats, pager) of a tables artifact, scattering as
    ``optics``; without optics (voxelize) the tables' own colours and micro-flake roughness, no fibre phase.
    ``view`` (``CacheView``): a render's camera and fibre cache budget; then the medium is the
    ``FibreCacheMedium`` of that view (``pipeline.fibre_cache``; budget 0: every lookup procedural).
    A progress bar (on a terminal) counts its three steps; info records their times."""
    if not tables_path:
        raise LoomError(None, "--tables", "--source procedural needs the procedural tables (loomlight tables): "
                        "pass --tables PATH.zarr")
    with progress("procedural source (tables, majorant, fibre cache)", 3 if view is not None else 2) as advance:
        return _procedural_source(tables_path, cell, optics, view, advance)


def _procedural_source(tables_path, cell, optics, view, advance):
    from stages.core.shading.material import MAT_SIZE
    from stages.core.yarn.model import ROUGHNESS
    from stages.render.media.procedural_medium import ProceduralMedium

    from ..runners.tables import load_tables

    t0 = time.perf_counter()
    # the yarn types come from the tables' recorded yarns input: one that is gone is refused before the
    # tables are loaded (loading derives the lookup structures, and compiles their kernels on a cold cache)
    types = None if optics is None else input_yarn_types(_artifact(tables_path, "tables", "--tables"))
    paged = view is not None and frame_sample_bytes(_artifact(tables_path, "tables", "--tables")) > PAGE_FRAME_BYTES
    cv, tab, art = load_tables(tables_path, paged=paged)
    pool = None
    if paged:
        from stages.core.yarn.frame_pool import FramePool

        pool = FramePool(cv, tab)
        tab = pool.tables
    advance()
    t1 = time.perf_counter()
    if optics is None:
        mats = np.zeros((len(tab.yarn_type), MAT_SIZE))
        mats[:, 0] = -1.0  # micro-flakes
    else:
        mats, has = optics.rows(tab.yarn_albedo, types)
        tparams = tab.tparams.copy()
        for t in range(len(tparams)):  # fibre phase function: the extinction of thin cylinders (roughness 0)
            if np.any(tab.yarn_type == t) and np.all(has[tab.yarn_type == t]):
                tparams[t, ROUGHNESS] = 0.0
        tab = tab._replace(yarn_albedo=np.ascontiguousarray(optics.albedo(tab.yarn_albedo, types)), tparams=tparams)
    maj = procedural_majorant(cv, tab, cell)
    advance()
    # tables_load_s: reading the artifact and deriving the lookup structures (accel.derive_lookup_accel)
    info = {"yarns": int(len(tab.yarn_type)), "tables_load_s": t1 - t0, "majorant_s": time.perf_counter() - t1,
            "frame_samples_paged": paged}
    if view is None:
        return Source(ProceduralMedium(cv, tab), maj, info, mats, pool)
    from ..fibre_cache import build_fibre_cache

    asked = cell or CELL_FRACTION * float(np.mean(tab.yarn_extent))
    capped = float(np.max((maj.hi - maj.lo) / maj.res)) > asked * (1.0 + 1e-9)  # MAX_MAJORANT_CELLS made it coarser
    built = build_fibre_cache(cv, tab, maj, view.camera, view.width, view.height, view.budget_mib,
                              fine_cell=FINE_CELL_FRACTION * float(np.mean(tab.yarn_extent)) if capped else None)
    advance()
    return Source(built.medium, built.majorant, {**info, **built.info}, mats, pool)


def frame_sample_bytes(art) -> float:
    """Bytes of every yarn's frame samples at their first-guess steps (``runners.tables.accel_estimate``'s
    count): what decides whether a render pages them (PAGE_FRAME_BYTES)."""
    from stages.core.yarn.frame_samples import FRAME_COLS

    from ..runners.tables import first_guess_frame_samples

    if not len(art["yarn_type"]):
        return 0.0
    return 8.0 * (FRAME_COLS + 1) * first_guess_frame_samples(art)[0]


def procedural_majorant(cv, tab, cell=None):
    """The ``MajorantGrid`` of procedural tables: the largest density of the capsules that hold every
    fibre surface (``stages.render.media.procedural_medium.capsule_majorants``, walked, never listed) per cell of
    ``cell`` (default a quarter of the mean yarn extent bound). Its box: the capsules' own (a second walk,
    ``capsule_box``) where the cells are as asked; where MAX_MAJORANT_CELLS coarsens them (a large cloth) the box
    of the yarns' extent tubes (``tube_box``, the axes alone: the loops and hairs are walked once, not twice),
    whose cells ``_majorant_res`` coarsens along the cloth, not across it. Paged tables (``frame_pool``) are
    walked chunk by chunk of yarns, each chunk's frame samples made for the walk and dropped after it."""
    import numba

    from stages.core.yarn.frame_pool import is_paged
    from stages.render.media.procedural_medium import capsule_box, capsule_majorants, tube_box
    from stages.render.media.tracking import make_majorant_grid

    cell = cell or CELL_FRACTION * float(np.mean(tab.yarn_extent))
    lo, hi = tube_box(cv, tab, MAJORANT_STEP)
    paged = is_paged(tab)

    def walks():  # paged tables: every chunk's frame samples made for each walk (PAGE_CHUNK_SAMPLES at a time)
        return _resident_chunks(cv, tab) if paged else [(tab, None)]

    if not _capped(lo, hi, cell):    # cells as asked: the capsules' own box, as fine as the cells
        boxes = [capsule_box(cv, t, MAJORANT_STEP, yarns=ys, grown=False) for t, ys in walks()]
        rmax = max(b[2] for b in boxes)
        lo = np.min([b[0] for b in boxes], axis=0) - rmax
        hi = np.max([b[1] for b in boxes], axis=0) + rmax
    res = _majorant_res(lo, hi, cell)
    mu = None
    for t, ys in walks():
        mu = capsule_majorants(cv, t, MAJORANT_STEP, lo, hi, res, numba.get_num_threads(), yarns=ys, into=mu)
    return make_majorant_grid(lo, hi, res, mu)


def _resident_chunks(cv, tab):
    """(tables with a chunk's frame samples resident, the chunk's yarns) for every chunk of paged tables
    (``accel.yarn_chunks``), made one at a time as the loop asks."""
    from stages.core.yarn.accel import PAGE_CHUNK_SAMPLES, yarn_chunks
    from stages.core.yarn.frame_pool import resident

    for ys in yarn_chunks(cv, tab.fs_step, PAGE_CHUNK_SAMPLES):
        yield resident(cv, tab, ys), ys


def _fibre_numbers(fart) -> np.ndarray:
    """The procedural lookup's fibre numbers of a realization's polylines (pieces of one fibre share
    one: ``stages.render.media.realized_medium``), or empty where the artifact does not say (each polyline
    its own fibre)."""
    from stages.render.media.fibre_cache import fibre_ids

    keys = ("fiber_yarn", "fiber_ply", "fiber_kind", "fiber_index")
    if not all(k in fart for k in keys):
        return np.zeros(0, np.int64)
    return fibre_ids(*(np.asarray(fart[k]) for k in keys))


def realized_source(fibers_path, cell, optics):
    """(RealizedMedium, MajorantGrid, info, mats) from a fibers artifact; per-yarn density and
    roughness from the yarn types the fibres were realized with (their yarns artifact and
    preset/radius), scattering as ``optics``."""
    from stages.core.geometry.bvh import build_fiber_bvh
    from stages.core.yarn.model import DENSITY, ROUGHNESS, extent_bound
    from stages.render.media.realized_medium import RealizedMedium, fiber_capsules
    from stages.render.media.tracking import majorants_from_capsules, make_majorant_grid

    from ..runners.yarn_types import yarn_types_of

    if not fibers_path:
        raise LoomError(None, "--fibers", "--source realized needs the realized fibres: pass --fibers PATH.zarr")
    fibers = load_fibers(fibers_path)
    fart = _artifact(fibers_path, "fibers", "--fibers")
    yarns = recorded_input(fart, "yarns", "yarns")
    if yarns is None:
        raise LoomError(fibers_path, "inputs",
                        "the fibers artifact does not name the yarns artifact it was realized from")
    _, tparams, ytype, _ = yarn_types_of(yarns, fart.params.get("preset"), fart.params.get("radius"))
    Y = len(ytype)
    if int(fibers.fiber_yarn.max()) >= Y:
        raise LoomError(fibers_path, "fiber_yarn", f"fibres name yarns beyond the {Y} yarns of {yarns.path}")
    tp = tparams[ytype]
    colour = np.zeros((Y, 3))
    colour[: min(Y, len(fibers.yarn_albedo))] = fibers.yarn_albedo[:Y]
    mats, has = optics.rows(colour, fibers.yarn_type)
    albedo = optics.albedo(colour, fibers.yarn_type)
    roughness = np.where(has, 0.0, tp[:, ROUGHNESS])  # fibre phase function: thin cylinders' extinction
    extent = float(np.mean([extent_bound(t) for t in tp]))
    t0 = time.perf_counter()
    bvh, _ = build_fiber_bvh(fibers.points, fibers.fiber_offsets, fibers.point_radius)
    med = RealizedMedium(bvh, fibers.fiber_yarn.astype(np.int32), np.ascontiguousarray(tp[:, DENSITY]),
                         np.ascontiguousarray(albedo), np.ascontiguousarray(roughness), _fibre_numbers(fart))
    a, b, r, bound = fiber_capsules(med)
    lo, hi = _box_of_capsules(a, b, r)
    res = _majorant_res(lo, hi, cell or CELL_FRACTION * extent)
    mu = majorants_from_capsules(a, b, r, bound, lo, hi, res)
    info = {"fibers": fibers.n_fibers, "segments": int(len(bvh.seg_a)), "bvh_build_s": time.perf_counter() - t0}
    return Source(med, make_majorant_grid(lo, hi, res, mu), info, mats)


def grid_source(grid_path, cell, optics):
    """(GridMedium, MajorantGrid, info, mats) from a grid artifact (macrocells of 4 voxels by default):
    micro-flakes (voxels know no yarn), the voxels' colours made albedos by ``optics``."""
    from stages.render.media.grid_medium import GridMedium
    from stages.render.media.tracking import majorants_from_voxels, make_majorant_grid

    art = _artifact(grid_path, "grid", "--set grid=PATH.zarr")
    lo, hi = (np.asarray(v, float) for v in art.summary["bounds"])
    den = np.ascontiguousarray(art["density"], np.float32)
    colour = np.asarray(art["albedo"], np.float32)
    albedo = optics.albedo(colour.reshape(-1, 3), None).reshape(colour.shape)
    med = GridMedium(lo, hi, den, np.ascontiguousarray(art["direction"], np.float32),
                     np.ascontiguousarray(albedo, np.float32), np.ascontiguousarray(art["roughness"], np.float32))
    vox = (hi - lo) / np.array(den.shape[::-1])
    res = _majorant_res(lo, hi, cell or 4.0 * float(vox.max()))
    mu = majorants_from_voxels(den, lo, hi, res)
    return Source(med, make_majorant_grid(lo, hi, res, mu), {"voxels": list(den.shape[::-1])},
                  optics.rows(np.zeros((0, 3)), None)[0])


class FibreOptics:
    """How the volume scatters, from the fibres it stands for (``--set phase`` and ``--set albedo``).

    ``rows(colours, types)`` -> (mats (Y, MAT_SIZE), has (Y,) bool): per yarn its yarn type's BCSDF dyed to
    its colour (``pipeline.dye``, as fiberpath), the fibre phase function of
    ``stages.render.integrators.volpath``; model -1 (micro-flakes) where the scene names no BCSDF for the type or
    with ``phase=microflake``. ``albedo(colours, types)``: the micro-flake albedo, the dyed BCSDF's
    mean albedo (``bcsdf_mean_albedo`` of the dyed BCSDF) unless ``albedo=color`` or no BCSDF (then the colour itself).
    ``types`` None: the yarns are unknown (voxels): the scene's one BCSDF applies, if it names one."""

    def __init__(self, scene, options):
        extra = options.get("extra") or {}
        self.scene, self.options = scene, options
        self.phase = extra.get("phase", "bcsdf")
        self.albedo_mode = extra.get("albedo", "bcsdf")
        if self.phase not in ("bcsdf", "microflake"):
            raise LoomError(None, "--set phase", f"unknown phase function {self.phase!r} (known: bcsdf, microflake)")
        if self.albedo_mode not in ("bcsdf", "color"):
            raise LoomError(None, "--set albedo", f"unknown albedo {self.albedo_mode!r} (known: bcsdf, color)")

    def _params(self, n, types):
        from .fiberpath import yarn_bcsdfs

        return yarn_bcsdfs(self.scene, types, n, np.arange(n), self.options, required=False)

    def _dyed(self, colours, types):
        """Per yarn its type's BCSDF dyed to the yarn's colour (``fiberpath.dyed_bcsdfs``), None where the
        type names no BCSDF; ``types`` None: every yarn 'other' (the scene's one BCSDF, if it names one)."""
        from .fiberpath import dyed_bcsdfs

        n = len(colours)
        return dyed_bcsdfs(self.scene, self.options, colours, types, self._params(n, types))

    def albedo(self, colours, types):
        from stages.core.shading.bcsdf import bcsdf_mean_albedo

        colours = np.asarray(colours, np.float64)
        if self.albedo_mode == "color":
            return colours
        flat = colours.reshape(-1, 3)
        if types is None:      # voxels: one BCSDF for all, dyed at once
            from ..dye import Dyer
            from .fiberpath import bcsdf_names

            p = self._params(1, None)[0]
            if p is None:
                return colours
            names = bcsdf_names(self.scene, self.options)
            named = sorted(set(names.values()))
            name = names.get(OTHER) or (named[0] if len(named) == 1 else "")   # the one yarn_bcsdfs took
            dyer = Dyer(self.scene)
            q = dyer.row(p, flat, "other", name)
            dyer.report()
            return bcsdf_mean_albedo(q).reshape(colours.shape)
        rows = self._dyed(flat, types)
        return np.stack([c if q is None else bcsdf_mean_albedo(q) for c, q in zip(flat, rows)]).reshape(colours.shape)

    def rows(self, colours, types):
        from stages.core.shading.material import MAT_SIZE, pack_material_bcsdf

        n = len(colours)
        mats = np.zeros((n, MAT_SIZE))
        mats[:, 0] = -1.0  # micro-flakes
        if self.phase == "bcsdf" and types is not None:
            for y, q in enumerate(self._dyed(np.asarray(colours, np.float64), types)):
                if q is not None:
                    mats[y] = pack_material_bcsdf(q)
        return mats, mats[:, 0] >= 0.0


class Source(NamedTuple):
    """What a volpath source opens to: the medium, its majorant grid, its statistics, the per-yarn material
    rows (``FibreOptics.rows``), and the ``FramePool`` of paged procedural tables (None otherwise)."""
    medium: object
    majorant: object
    info: dict
    mats: np.ndarray
    pager: object = None


class CacheView(NamedTuple):
    """What the procedural source's fibre cache is built for: the render's camera array and size, the
    budget in MiB (``--cache``)."""
    camera: np.ndarray
    width: int
    height: int
    budget_mib: float


def open_source(source, options, optics, view=None):
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
        return procedural_source(tables, cell, optics, view)
    if source == "realized":
        return realized_source(options.get("fibers"), cell, optics)
    if source == "grid":
        return grid_source(options.get("grid") or extra.get("grid"), cell, optics)
    raise LoomError(None, "--source", unknown("volpath source", source, SOURCES))


# ------------------------------------------------------------------------------------------------
def _sees_fabric(maj, cam, W, H, n=24):
    from stages.render.camera import camera_ray
    from stages.render.media.tracking import ray_meets_majorant

    for i in range(n):
        for j in range(n):
            o, d = camera_ray(cam, (i + 0.5) * H / n, (j + 0.5) * W / n, 0.0, 0.0)
            if ray_meets_majorant(maj, o[0], o[1], o[2], d[0], d[1], d[2]):
                return True
    return False


def film_setup(scene, options: dict):
    """The ``FilmSetup`` of a volpath render (``pipeline.renderers.film``): integrator, camera, label."""
    from stages.render.film import VARIANCE_LUMINANCE
    from stages.render.integrators.volpath import VolpathIntegrator

    from .film import FilmSetup

    source = options.get("source") or scene.render.get("source") or "procedural"
    if source not in SOURCES:
        raise LoomError(None, "--source", unknown("volpath source", source, SOURCES))
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    lights = pack_lights(scene.lights, scene.path)
    if not has_light(scene):
        raise LoomError(scene.path, "lights", "the scene has no lights and no mesh emits (the image would be black)")
    W, H = options["width"], options["height"]
    max_depth, rr_depth = int(options["max_depth"]), int(options["rr_depth"])
    ground, has_ground = ground_array(scene.render)
    cam = camera_array(scene.camera, W, H)

    t0 = time.perf_counter()
    view = None
    if source == "procedural":
        from ..fibre_cache import default_cache_mib

        budget = options.get("cache")
        view = CacheView(cam, W, H, default_cache_mib() if budget is None else float(budget))
    med, maj, info, mats, pool = open_source(source, options, FibreOptics(scene, options), view)
    build_s = time.perf_counter() - t0
    if not _sees_fabric(maj, cam, W, H):
        warn(f"the camera of {scene.path} sees no fabric (source {source}); rendering anyway")
    meshes, _, mesh_stats = load_scene_meshes(scene)
    integ = VolpathIntegrator(med, maj, lights.table(), ground, bool(has_ground), meshes, max_depth, rr_depth,
                              np.ascontiguousarray(mats, np.float64))
    stats = {"source": source, "source_build_s": build_s, "majorant_cells": [int(x) for x in maj.res],
             "majorant_occupied": float(np.mean(maj.mu > 0)), "max_depth": max_depth, "rr_depth": rr_depth,
             "fibre_phase_yarns": int(np.sum(mats[:, 0] >= 0)), **info, **mesh_stats}
    return FilmSetup(f"volpath ({source})", integ, cam, VARIANCE_LUMINANCE, stats, pager=pool)


def render(scene, options: dict) -> RenderResult:
    from .film import render_with_film

    s, run = render_with_film(__name__, scene, options)
    lookups, render_s = run.image.lookups, run.render_s
    stats = {**run.stats(), "medium_lookups": lookups, "medium_lookups_per_s": lookups / max(render_s, 1e-12),
             **s.stats, **(s.pager.info() if s.pager is not None else {})}
    return RenderResult(run.rgb, run.extra, stats)
