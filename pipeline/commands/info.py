"""``loomlight info ARTIFACT [--json]``: what an artifact holds."""
from __future__ import annotations

import json
from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("info")
    def info(artifact: Path = typer.Argument(..., help="An artifact directory (*.zarr)."),
             as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table.")):
        """Show an artifact's kind, summary numbers (counts, bounds, bytes), parameters and provenance."""
        from ..artifacts import Artifact

        art = Artifact(artifact)
        doc = {"kind": art.kind, **art.summary, "path": str(artifact), "array_bytes": art.nbytes(),
               "stage": art.meta["stage"], "params": art.params,
               "inputs": art.meta["inputs"], "wall_time_s": art.meta["wall_time_s"],
               "peak_memory_bytes": art.meta["peak_memory_bytes"], "loomlight_version": art.meta["loomlight_version"],
               "content_hash": art.meta["content_hash"]}
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
            return
        from rich.console import Console
        from rich.table import Table

        t = Table(title=f"{artifact} ({art.kind})", show_header=False)
        for k, v in doc.items():
            if k in ("params", "inputs"):
                v = json.dumps(v)
            t.add_row(k, str(v))
        Console().print(t)
