"""``loomlight voxelize tables.zarr -o grid.zarr --res NX NY NZ``: a voxel grid of the fibre medium.

Averages ``--supersample``^3 procedural lookups per voxel (``stages.render.media.grid_medium.voxelize``):
mean density, principal fibre direction, density-weighted albedo and roughness, over the box of all
yarn tubes. The grid renders with ``loomlight render --method volpath --source grid --grid GRID.zarr``.
``--export-npy DIR`` also writes raw numpy volumes for other renderers (Mitsuba 3 ``gridvolume``
layout, (Z, Y, X[, C]) over the box in ``grid_bounds.npy``): density.npy, albedo.npy,
direction.npy, roughness.npy and sggx.npy (6-channel Sxx, Syy, Szz, Sxy, Sxz, Syz).
"""
from __future__ import annotations

from pathlib import Path

import typer

from .options import BUDGET, FORCE
from .scheduling import SCHEDULER, THREADS_PER_WORKER, WORKERS


def register(app: typer.Typer) -> None:
    @app.command("voxelize")
    def voxelize_cmd(tables: Path = typer.Argument(..., help="A tables artifact (loomlight tables)."),
                     out: Path = typer.Option(..., "-o", "--out",
                                              help="Output grid artifact (directory ending in .zarr)."),
                     res: tuple[int, int, int] = typer.Option(..., "--res", help="Voxels along x, y, z: NX NY NZ."),
                     supersample: int = typer.Option(2, "--supersample", help="Lookups per voxel along each axis."),
                     export_npy: Path = typer.Option(None, "--export-npy",
                                                     help="Also write raw numpy volumes to this directory."),
                     force: bool = FORCE,
                     budget: float = BUDGET,
                     scheduler: str = SCHEDULER, workers: int = WORKERS, threads_per_worker: int = THREADS_PER_WORKER):
        """Voxelize the procedural fibre medium: density and mean fibre direction per voxel."""
        from ..chunks import resolve_scheduler
        from ..memory import budget as memory_budget
        from ..outputs import ARTIFACT, DIRECTORY, check_output
        from ..runners.voxelize import run_voxelize

        check_output(out, "-o", ARTIFACT, inputs=[tables])
        if export_npy is not None:
            check_output(export_npy, "--export-npy", DIRECTORY, inputs=[tables, out])
        sched = resolve_scheduler(scheduler, None, workers, threads_per_worker)
        typer.echo(run_voxelize(tables, out, res, supersample, export_npy, force, memory_budget(budget), sched))
