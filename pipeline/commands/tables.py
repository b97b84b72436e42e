"""``loomlight tables yarns.zarr -o tables.zarr``: seed 000's realization-minimizing tables."""
from __future__ import annotations

from pathlib import Path

import typer

from .options import BUDGET, FORCE, PRESET, RADIUS, YARNS


def register(app: typer.Typer) -> None:
    @app.command("tables")
    def tables(
        yarns: Path = YARNS,
        out: Path = typer.Option(..., "-o", "--out", help="Output tables artifact (directory ending in .zarr)."),
        preset: str = PRESET,
        radius: float = RADIUS,
        seed: int = typer.Option(0, "--seed", min=0, help="Seed of the procedural random numbers."),
        bins: int = typer.Option(32, "--bins",
                                 help="Azimuth bins of the regular-fibre tables (Luan, Zhao, Bala 2017 Fig. 7)."),
        hair_mode: str = typer.Option("hybrid", "--hair-mode", metavar="<hybrid | free>",
                                      help="'hybrid' (stored hair z extents, z-bins) or 'free' (Algorithm 3)."),
        force: bool = FORCE,
        budget: float = BUDGET,
    ):
        """Build the procedural fibre tables of a yarns artifact (Luan, Zhao, Bala 2017), all a renderer needs.

        Per yarn type and ply: fibre trajectories binned by azimuth; per yarn: hair tables (hybrid mode);
        loops from consistent random numbers; plus a copy of the yarn curves."""
        from ..memory import budget as memory_budget
        from ..outputs import ARTIFACT, check_output
        from ..runners.tables import run_tables

        check_output(out, "-o", ARTIFACT, inputs=[yarns])
        res = run_tables(yarns, out, preset=preset, radius=radius, seed=seed, nbins=bins, hair_mode=hair_mode,
                         force=force, budget=memory_budget(budget))
        if res["skipped"]:
            typer.echo(f"{out} is up to date; use --force to rebuild")
        else:
            typer.echo(f"wrote {out} ({res['yarns']} yarns)")
            if res["folded"]:
                typer.echo(f"warning: {res['folded']} yarn(s) bend more tightly than their fibre extent: "
                           "the yarn-space map folds there and lookups are not exact", err=True)
