"""``loomlight tile CONFIG.toml -o tiling.zarr``: exemplars, block map and shell mesh (seed 001 §2)."""
from __future__ import annotations

from pathlib import Path

import typer

from .options import BUDGET, FORCE


def register(app: typer.Typer) -> None:
    @app.command("tile")
    def tile(
        config: Path = typer.Argument(..., help="A tiling configuration (.toml, schemas/tile-config.schema.json): "
                                                "exemplar weaves, yarn, block map, base surface, scene."),
        out: Path = typer.Option(..., "-o", "--out", help="Output tiling artifact (directory ending in .zarr)."),
        force: bool = FORCE,
        budget: float = BUDGET,
    ):
        """Lay fibre exemplars of weave drafts over a surface and build the shell that maps them onto it.

        Realizes periodic fibre exemplars from weave drafts, cuts them into blocks, lays the blocks over the
        cloth's (u, v) domain by the block map, and builds the shell (base surface offset along its smoothed
        normals, split into tetrahedra) that maps them onto the surface (Khungurn et al. 2017 §2)."""
        from ..memory import budget as memory_budget
        from ..outputs import ARTIFACT, check_output
        from ..runners.tile import run_tile

        check_output(out, "-o", ARTIFACT, inputs=[config])
        res = run_tile(config, out, force=force, budget=memory_budget(budget))
        if res["skipped"]:
            typer.echo(f"{out} is up to date")
        else:
            typer.echo(f"wrote {out} ({res['exemplars']} exemplars, {res['blocks']} blocks, "
                       f"{res['tetrahedra']} tetrahedra)")
