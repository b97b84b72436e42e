"""``loomlight ingest INPUT -o yarns.zarr``: yarn curves from a curve file, a WIF draft or a scene."""
from __future__ import annotations

from pathlib import Path

import typer

from .options import BUDGET, FORCE


def register(app: typer.Typer) -> None:
    @app.command("ingest")
    def ingest(
        input: Path = typer.Argument(..., help="A curve file (.bcc Binary Curve Collection, .obj polylines, "
                                                ".txt 'x y z [r]' polylines), a WIF weaving draft (.wif), or a scene "
                                                "(.toml)."),
        out: Path = typer.Option(..., "-o", "--out", help="Output yarns artifact (directory ending in .zarr)."),
        radius: float = typer.Option(None, "--radius",
                                     help="Yarn radius for inputs that carry none (positive, at most 1e6)."),
        scale: float = typer.Option(None, "--scale", help="Multiply file coordinates by this factor (positive; scaled "
                                                          "coordinates must stay within +-1e6 scene units)."),
        refuse_duplicates: bool = typer.Option(False, "--refuse-duplicates",
                                               help="Refuse repeated consecutive control points instead of merging "
                                                    "them."),
        frame_samples: int = typer.Option(4, "--frame-samples", min=1, help="Stored RMF samples per spline segment."),
        write: Path = typer.Option(None, "--write", help="Also write the validated curves as .bcc, .obj or .txt."),
        force: bool = FORCE,
        budget: float = BUDGET,
    ):
        """Read, validate and spline yarn curves and publish them as a yarns artifact.

        Splines are C1 Catmull-Rom with arc length, rotation-minimising frames, the δ_i bound of
        Luan, Zhao, Bala 2017 and a segment grid. A scene's names (presets, BCSDFs, method, source, light types) are checked first."""  # noqa: E501 (command help: --help shows its line breaks)
        from ..errors import LoomError
        from ..limits import check_positive
        from ..memory import budget as memory_budget
        from ..outputs import ARTIFACT, check_output
        from ..runners.ingest import run_ingest

        check_output(out, "-o", ARTIFACT, inputs=[input])
        if write is not None:
            check_output(write, "--write", suffixes=(".bcc", ".obj", ".txt"), inputs=[input])
        check_positive(radius, "--radius")
        check_positive(scale, "--scale")
        try:
            res = run_ingest(input, out, radius=radius, scale=scale, merge_duplicates=not refuse_duplicates,
                             force=force, write=write, frame_samples=frame_samples, budget=memory_budget(budget))
        except LoomError as e:  # a key of INPUT (a scene's fabric.generator) named without its file
            if e.file is None and e.place and not e.place.startswith("-"):
                raise LoomError(input, e.place, e.message) from None
            raise
        if not res["skipped"]:
            typer.echo(f"wrote {out} ({res['curves']} curves)")
