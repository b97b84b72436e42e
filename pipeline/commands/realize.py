"""``loomlight realize yarns.zarr -o fibers.zarr``: every fibre as a fabric-space polyline."""
from __future__ import annotations

from pathlib import Path

import typer

from .options import BUDGET, FORCE, PRESET, RADIUS, YARNS
from .scheduling import SCHEDULER, THREADS_PER_WORKER, WORKERS


def register(app: typer.Typer) -> None:
    @app.command("realize")
    def realize(
        yarns: Path = YARNS,
        out: Path = typer.Option(..., "-o", "--out", help="Output fibers artifact (directory ending in .zarr)."),
        preset: str = PRESET,
        radius: float = RADIUS,
        seed: int = typer.Option(0, "--seed", min=0, help="Seed of the procedural random numbers (as for tables)."),
        spacing: float = typer.Option(0.002, "--spacing",
                                      help="Largest step between vertices along z (scene units; positive, at most "
                                           "1e6)."),
        budget: float = BUDGET,
        force: bool = FORCE,
        scheduler: str = SCHEDULER,
        workers: int = WORKERS,
        threads_per_worker: int = THREADS_PER_WORKER,
    ):
        """Realize every fibre of the yarns explicitly, as a fibers artifact (Luan, Zhao, Bala 2017 Eq. 1-4 and 7).

        Regular, loop and hair fibres with radius, yarn, ply and kind, from the same random numbers as
        `loomlight tables`, so both describe one fabric."""
        from ..chunks import resolve_scheduler
        from ..memory import budget as memory_budget
        from ..outputs import ARTIFACT, check_output
        from ..runners.realize import run_realize

        check_output(out, "-o", ARTIFACT, inputs=[yarns])
        sched = resolve_scheduler(scheduler, None, workers, threads_per_worker)
        res = run_realize(yarns, out, preset=preset, radius=radius, seed=seed, spacing=spacing,
                          budget=memory_budget(budget), force=force, scheduler=sched)
        if res["skipped"]:
            typer.echo(f"{out} is up to date; use --force to rebuild")
        else:
            typer.echo(f"wrote {out} ({res['fibers']} fibres, {res['vertices']} vertices, "
                       f"{res['bytes'] / 2**20:.1f} MiB)")
