"""Voxelize runner: a voxel grid of the procedural fibre medium of a tables artifact (``grid`` artifact).

``run_voxelize`` checks the resolution (at most 512^3 voxels) and supersampling (the lookups' least time
within the time limit, ``LOOKUPS_PER_THREAD_S``), averages
``supersample``^3 procedural lookups per voxel (``stages.render.media.grid_medium.voxelize``) over the box of
all yarn tubes, publishes density, roughness, direction and albedo, and with ``export_npy`` also
writes the raw numpy volumes (the layout is described in ``pipeline.commands.voxelize``).

Each slab of ``SLAB`` z-slices is a chunk task (``pipeline.chunks``) that writes its chunks of the four
arrays straight into the artifact under construction and returns its maximum density and occupied
voxels; the tasks run here or on a Dask scheduler (``--scheduler``), where a worker loads the
procedural tables once. The driver never holds the grid (``--export-npy`` reads it back).
"""
from __future__ import annotations

import time
from pathlib import Path

VOXEL_BYTES = 32           # density, roughness (float32), direction, albedo (3 x float32)
# --supersample: each voxel averages supersample^3 procedural lookups; their least time
# (``pipeline.limits.WorkEstimate``) at a rate no thread reaches (a lookup finds the yarns near a point,
# projects onto each and tests its fibres: well under 1e7 a thread-second) bounds it.
LOOKUPS_PER_THREAD_S = 1e8
EXPORT_VOXEL_BYTES = 96    # --export-npy: the SGGX volume and its float64 temporaries
SLAB = 16                  # z-slices per stored chunk and per chunk task


def _medium(tables, tables_hash):
    from ..chunks import worker_cache
    from ..renderers.volpath import procedural_source

    return worker_cache(("voxelize", str(tables), tables_hash), lambda: procedural_source(tables)[0])


def _voxelize_task(tables, tables_hash, store, lo, hi, res, supersample, z0, z1):
    """Chunk task: voxel slices z0..z1-1 of all four arrays."""
    import numpy as np

    from stages.render.media.grid_medium import voxelize

    from ..chunks import open_for_chunk

    nx, ny, _ = (int(r) for r in res)
    den = np.zeros((z1 - z0, ny, nx), np.float32)
    dirs = np.zeros((z1 - z0, ny, nx, 3), np.float32)
    alb = np.zeros((z1 - z0, ny, nx, 3), np.float32)
    rough = np.zeros((z1 - z0, ny, nx), np.float32)
    voxelize(_medium(tables, tables_hash), lo, hi, np.asarray(res, np.int64), int(supersample), z0, z1, den, dirs,
             alb, rough)
    for name, a in (("density", den), ("roughness", rough), ("direction", dirs), ("albedo", alb)):
        open_for_chunk(store, name)[z0:z1] = a
    return {"max_density": float(den.max()) if den.size else 0.0, "occupied": int(np.count_nonzero(den > 0))}


def run_voxelize(tables, out, res, supersample=2, export_npy=None, force=False, budget=None, scheduler=None):
    """Build (or skip when up to date) the grid artifact; returns a summary line. ``budget``
    (``pipeline.memory.budget``): refuse before loading the tables when the grid, the tables and what
    loading them derives would exceed it. ``scheduler`` (``pipeline.chunks``): where the slabs run."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    import numpy as np

    from ..artifacts import Artifact, ArtifactWriter
    from ..chunks import ChunkTask, run_tasks, session, worker_cache
    from ..errors import LoomError
    from ..memory import budget as memory_budget
    from ..renderers.volpath import procedural_source

    res = [int(r) for r in res]
    for name, r in zip("XYZ", res):
        if r <= 0:
            raise LoomError(None, "--res", f"N{name} must be a positive integer, got {r}")
    if int(supersample) <= 0:
        raise LoomError(None, "--supersample", f"must be a positive integer, got {supersample}")
    nx, ny, nz = res
    if nx * ny * nz > 512 ** 3:
        raise LoomError(None, "--res", f"{nx} x {ny} x {nz} voxels is more than 512^3")
    import numba

    from ..limits import WorkEstimate

    s = int(supersample)
    WorkEstimate("loomlight voxelize", scheduler.workers * scheduler.threads_per_worker
                 if scheduler is not None and scheduler.kind == "processes" else numba.get_num_threads()).add(
        "procedural lookups", float(nx) * ny * nz * float(s) ** 3, LOOKUPS_PER_THREAD_S,
        f"{nx} x {ny} x {nz} voxels x {s:,}^3 lookups (--supersample)").check(None, "--supersample", "lower it")
    out = Path(out)
    params = {"res": res, "supersample": int(supersample)}
    w = ArtifactWriter(out, kind="grid", stage="voxelize", params=params, inputs={"tables": (tables, "tables")},
                       started=t_start)
    if w.up_to_date() and not force and export_npy is None:
        return f"{out} is up to date"
    from stages.render.media.grid_medium import sggx_volume

    from .tables import accel_estimate

    est = accel_estimate(Artifact(tables, kind="tables"), "loomlight voxelize")
    voxels = float(nx) * ny * nz
    est.add("voxels", voxels * (VOXEL_BYTES + (EXPORT_VOXEL_BYTES if export_npy is not None else 0)),
            f"{nx} x {ny} x {nz}")
    est.check(budget or memory_budget(), tables)
    tables_art = Artifact(tables, kind="tables")
    tables_hash = tables_art.meta["content_hash"]
    tables_abs = str(Path(tables).resolve())  # chunk tasks may run in another directory
    with session(scheduler), w:
        med, maj = procedural_source(tables)[:2]
        worker_cache(("voxelize", tables_abs, tables_hash), lambda: med)  # local tasks take it
        lo, hi = maj.lo, maj.hi
        chunks = (min(nz, SLAB), min(ny, 64), min(nx, 64))
        w.create("density", (nz, ny, nx), np.float32, chunks, dimension_names=("z", "y", "x"))
        w.create("roughness", (nz, ny, nx), np.float32, chunks, dimension_names=("z", "y", "x"))
        w.create("direction", (nz, ny, nx, 3), np.float32, chunks + (3,), dimension_names=("z", "y", "x", "c"))
        w.create("albedo", (nz, ny, nx, 3), np.float32, chunks + (3,), dimension_names=("z", "y", "x", "c"))
        tasks = [ChunkTask(_voxelize_task, (tables_abs, tables_hash, str(w.store_path), lo, hi, res,
                                            int(supersample), z0, min(z0 + SLAB, nz))) for z0 in range(0, nz, SLAB)]
        parts = run_tasks(tasks, f"voxelize {nx}x{ny}x{nz}")
        max_density = max(r["max_density"] for r in parts)
        occupied = sum(r["occupied"] for r in parts) / float(nx * ny * nz)
        w.summary.update(kind="grid", resolution=res, bounds=[lo.tolist(), hi.tolist()],
                         voxel_size=((hi - lo) / np.array(res)).tolist(), max_density=max_density,
                         occupied_fraction=occupied, supersample=int(supersample),
                         bytes=int(nx * ny * nz * VOXEL_BYTES), source=str(tables))
    line = (f"wrote {out} ({nx}x{ny}x{nz} voxels, {100 * occupied:.1f}% occupied, "
            f"max density {max_density:.4g})")
    if export_npy is not None:
        grid = Artifact(out, kind="grid")
        den, alb, dirs, rough = (grid[n] for n in ("density", "albedo", "direction", "roughness"))
        d = Path(export_npy)
        d.mkdir(parents=True, exist_ok=True)
        np.save(d / "density.npy", den)
        np.save(d / "albedo.npy", alb)
        np.save(d / "direction.npy", dirs)
        np.save(d / "roughness.npy", rough)
        np.save(d / "sggx.npy", sggx_volume(dirs, rough))
        np.save(d / "grid_bounds.npy", np.stack([lo, hi]))
        line += f"; numpy volumes in {d}"
    return line
