"""``loomlight inspect ARTIFACT --png FILE``: a picture of an intermediate artifact."""
from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("inspect")
    def inspect(artifact: Path = typer.Argument(..., help="An artifact directory (*.zarr)."),
                png: Path = typer.Option(None, "--png", help="Write the picture to this PNG file."),
                show: bool = typer.Option(False, "--show", help="Open an interactive window (needs a display)."),
                frames: bool = typer.Option(False, "--frames", help="yarns: draw rotation-minimising frame glyphs."),
                yarn: int = typer.Option(-1, "--yarn", help="Restrict to one yarn index where the kind supports it."),
                z: float = typer.Option(None, "--z", help="tables: cross-section height (yarn-space z)."),
                segment: int = typer.Option(None, "--segment", help="svf: the fibre segment (tiling segment id) "
                                                                     "whose visibility functions to draw."),
                exemplar: int = typer.Option(None, "--exemplar", help="svf / iirtf: the exemplar to draw (default 0)."),
                width: int = typer.Option(1200, "--width", help="Picture width in pixels."),
                height: int = typer.Option(900, "--height", help="Picture height in pixels.")):
        """Draw an artifact (yarn tubes, fibres, cross-sections, shells, ...) to a PNG, off-screen."""
        from ..artifacts import Artifact
        from ..errors import LoomError
        from ..inspectors import inspector_for
        from ..outputs import check_output

        if png is None and not show:
            raise LoomError(artifact, "--png", "give --png FILE or --show")
        if png is not None:
            check_output(png, "--png", inputs=[artifact])
        art = Artifact(artifact)
        mod = inspector_for(art.kind)
        if png is not None:
            png.parent.mkdir(parents=True, exist_ok=True)  # as every output's missing directories are
        out = mod.inspect(art, png, show=show, frames=frames, yarn=yarn, z=z, size=(width, height), segment=segment,
                          exemplar=exemplar)
        if png is not None:
            typer.echo(str(out or png))
