"""Voxelize runner: a voxel grid of the procedural fibre medium of a tables artifact (``grid`` artifact).

``run_voxelize`` checks the resolution (at most 512^3 voxels) and supersampling, averages
``supersample``^3 procedural lookups per voxel slab by slab (``stages.render.grid_medium.voxelize``)
over the box of all yarn tubes, publishes density, roughness, direction and albedo, and with
``export_npy`` also writes the raw numpy volumes (the layout is described in ``pipeline.commands.voxelize``).
"""
from __future__ import annotations

import time
from pathlib import Path


VOXEL_BYTES = 32           # density, roughness (float32), direction, albedo (3 x float32)
EXPORT_VOXEL_BYTES = 96    # --export-npy: the SGGX volume and its float64 temporaries


def run_voxelize(tables, out, res, supersample=2, export_npy=None, force=False, budget=None):
    """Build (or skip when up to date) the grid artifact; returns a summary line. ``budget``
    (``pipeline.memory.budget``): refuse before loading the tables when the grid, the tables and what
    loading them derives would exceed it."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    import numpy as np

    from ..artifacts import Artifact, ArtifactWriter
    from ..memory import budget as memory_budget
    from ..errors import LoomError
    from ..progress import progress
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
    out = Path(out)
    params = {"res": res, "supersample": int(supersample)}
    w = ArtifactWriter(out, kind="grid", stage="voxelize", params=params, inputs={"tables": (tables, "tables")},
                       started=t_start)
    if w.up_to_date() and not force and export_npy is None:
        return f"{out} is up to date"
    from stages.render.grid_medium import sggx_volume, voxelize

    from .tables import accel_estimate

    est = accel_estimate(Artifact(tables, kind="tables"), "loomlight voxelize")
    voxels = float(nx) * ny * nz
    est.add("voxels", voxels * (VOXEL_BYTES + (EXPORT_VOXEL_BYTES if export_npy is not None else 0)),
            f"{nx} x {ny} x {nz}")
    est.check(budget or memory_budget(), tables)
    med, maj, _, _ = procedural_source(tables)
    lo, hi = maj.lo, maj.hi
    den = np.zeros((nz, ny, nx), np.float32)
    dirs = np.zeros((nz, ny, nx, 3), np.float32)
    alb = np.zeros((nz, ny, nx, 3), np.float32)
    rough = np.zeros((nz, ny, nx), np.float32)
    resa = np.array(res, np.int64)
    step = max(1, min(nz, (1 << 16) // max(nx * ny, 1)))
    with progress(f"voxelize {nx}x{ny}x{nz}", nz) as advance:
        for z0 in range(0, nz, step):
            z1 = min(z0 + step, nz)
            voxelize(med, lo, hi, resa, int(supersample), z0, z1, den[z0:z1], dirs[z0:z1], alb[z0:z1], rough[z0:z1])
            advance(z1 - z0)
    with w:
        chunks = (min(nz, 64), min(ny, 64), min(nx, 64))
        w.write("density", den, chunks=chunks, dimension_names=("z", "y", "x"))
        w.write("roughness", rough, chunks=chunks, dimension_names=("z", "y", "x"))
        w.write("direction", dirs, chunks=chunks + (3,), dimension_names=("z", "y", "x", "c"))
        w.write("albedo", alb, chunks=chunks + (3,), dimension_names=("z", "y", "x", "c"))
        w.summary.update(kind="grid", resolution=res, bounds=[lo.tolist(), hi.tolist()],
                         voxel_size=((hi - lo) / np.array(res)).tolist(), max_density=float(den.max()),
                         occupied_fraction=float(np.mean(den > 0)), supersample=int(supersample),
                         bytes=int(den.nbytes + rough.nbytes + dirs.nbytes + alb.nbytes), source=str(tables))
    line = (f"wrote {out} ({nx}x{ny}x{nz} voxels, {100 * np.mean(den > 0):.1f}% occupied, "
            f"max density {den.max():.4g})")
    if export_npy is not None:
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
