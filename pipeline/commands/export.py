"""``loomlight export fibers.zarr -o fibers.txt|fibers.bcc``: realized fibres for other renderers."""
from __future__ import annotations

from pathlib import Path

import typer

from .options import BUDGET


def register(app: typer.Typer) -> None:
    @app.command("export")
    def export(
        fibers: Path = typer.Argument(..., help="A fibers artifact (loomlight realize)."),
        out: Path = typer.Option(..., "-o", "--out", help=".txt: Mitsuba 3 curve text ('x y z r' per line, blank "
                                                        "line between curves); .bcc: polyline Binary Curve "
                                                        "Collection."),
        budget: float = BUDGET,
    ):
        """Write realized fibres as Mitsuba 3 curve text or a polyline BCC file."""
        from ..memory import budget as memory_budget
        from ..outputs import check_output
        from ..runners.export import run_export

        check_output(out, "-o", suffixes=(".txt", ".bcc"), inputs=[fibers])
        res = run_export(fibers, out, budget=memory_budget(budget))
        typer.echo(f"wrote {out} ({res['curves']} curves)")
