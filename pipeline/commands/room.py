"""``loomlight room -o DIR``: write the Sponza-class room scene (pipeline/room.py) with its meshes and pile."""
from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("room")
    def room(
        out: Path = typer.Option(..., "-o", "--out",
                                 help="Directory to write the scene into: room.toml, its OBJ meshes, the rug's pile "
                                      "(rug_pile.bcc) and the wall hanging's WIF draft."),
        scale: float = typer.Option(1.0, "--scale",
                                    help="Threads per centimetre of the woven fabrics and knits and tufts per "
                                         "square centimetre of the rug, relative to the full room (0.01-4; 0.1 "
                                         "gives the same room with about a tenth of the yarns, for previews)."),
    ):
        """Write a living room dressed in eleven procedural textiles (Sponza-class: 42,752 yarns, 899 GB if realized).

        Four pleated curtains, a tablecloth draped over the table, three knitted cushions, a throw, a
        loop-pile rug and a wall hanging from a WIF draft, with walls, furniture, a glass vase, a lamp and
        window panes that emit. Render it with any method that takes several fabrics, e.g.
        `loomlight render DIR/room.toml --method bysdf -o room.exr`."""
        from ..room import write_room

        files = write_room(out, scale=scale)
        parts = ", ".join(f"{k} {v:,}" for k, v in files.yarns.items())
        typer.echo(f"wrote {files.scene}: {len(files.yarns)} textiles, {files.total_yarns:,} yarns ({parts}); "
                   f"{len(files.meshes)} OBJ meshes")
