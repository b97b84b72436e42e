"""``loomlight lookup tables.zarr --points pts.npy -o res.npz``: seed 000 Algorithm 1 at given points."""
from __future__ import annotations

from pathlib import Path

import typer

from .options import BUDGET


def register(app: typer.Typer) -> None:
    @app.command("lookup")
    def lookup(
        tables: Path = typer.Argument(..., help="A tables artifact (loomlight tables)."),
        points: Path = typer.Option(..., "--points", help="(N, 3) float array of fabric-space points (.npy)."),
        out: Path = typer.Option(..., "-o", "--out",
                                 help="Output .npz: inside, yarn, kind, direction, density, albedo."),
        budget: float = BUDGET,
    ):
        """Look up the procedural fibres at given points (Luan, Zhao, Bala 2017 Algorithm 1).

        For every point: inside a fibre or not, yarn index (-1 outside), kind (0 none, 1 regular, 2 loop,
        3 hair), unit fibre direction (zero outside), density and albedo."""
        from ..memory import budget as memory_budget
        from ..outputs import check_output
        from ..runners.lookup import run_lookup

        check_output(out, "-o", suffixes=(".npz",), inputs=[tables, points])
        res = run_lookup(tables, points, out, budget=memory_budget(budget))
        typer.echo(f"wrote {out} ({res['inside']} of {res['points']} points inside a fibre)")
