"""Options that several commands take with the same meaning, declared once: ``--force`` and ``--budget`` of the
commands that write an artifact, and the yarns input, ``--preset`` and ``--radius`` of the commands that build
the procedural fibres from a yarns artifact (tables, realize). The chunk-task options: ``.scheduling``."""
from __future__ import annotations

import typer

from ..memory import BUDGET_HELP

FORCE = typer.Option(False, "--force", help="Rebuild even when inputs and parameters are unchanged.")
BUDGET = typer.Option(None, "--budget", help=BUDGET_HELP)
YARNS = typer.Argument(..., help="A yarns artifact (loomlight ingest).")
PRESET = typer.Option(None, "--preset", metavar="<name>", help="Give every yarn this preset (data/yarns/NAME.toml).")
RADIUS = typer.Option(None, "--radius", help="Scale every yarn type to this yarn radius (positive, at most 1e6).")
