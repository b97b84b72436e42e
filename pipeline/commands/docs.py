"""``loomlight docs [--check] [--only PART]``: the documentation generated from the code (``pipeline.docs_gen``).

Writes ``docs/scenes.md`` (every key of the scene, tiling, sweep, comparison and preset files, from the
schemas), the generated blocks of ``docs/methods/<method>.md`` (settings from the renderer registry and
the commands' options; measured numbers) and ``docs/measurements.md`` (``bench/results``,
``out/compare``). ``--check`` writes nothing and exits with code 1, naming what differs, when
``docs/scenes.md`` or a settings block is not what the code gives (``make test`` checks this too).
"""
from __future__ import annotations

from pathlib import Path
from typing import List

import typer


def register(app: typer.Typer) -> None:
    @app.command("docs")
    def docs(check: bool = typer.Option(False, "--check", help="Write nothing; exit with code 1, naming what "
                                                                "differs, when docs/scenes.md or a method page's "
                                                                "settings block is stale."),
             only: List[str] = typer.Option(None, "--only", metavar="<scenes | methods | measurements>",
                                            help="Write only this part (repeatable; default: all three)."),
             bench_results: Path = typer.Option(None, "--bench-results",
                                                help="Benchmark results to report (default: bench/results)."),
             compare_dir: Path = typer.Option(None, "--compare-dir",
                                              help="Comparison outputs to report (default: out/compare).")):
        """Write the documentation generated from the schemas, the renderer registry and the measurements."""
        from ..docs_gen import PARTS, ROOT, check as check_docs, generate
        from ..errors import check_name

        for part in only or ():
            check_name(part, PARTS, None, "--only", "docs part")
        if check:
            problems = check_docs()
            for p in problems:
                typer.echo(p)
            if problems:
                typer.echo("stale: run `loomlight docs` (make docs) and commit the result", err=True)
                raise typer.Exit(1)
            typer.echo("docs/scenes.md and the method pages' settings blocks are current")
            return
        changed = generate(parts=tuple(only) if only else PARTS, bench_results=bench_results, compare_dir=compare_dir)
        for path in changed:
            typer.echo(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
        if not changed:
            typer.echo("generated documentation is current")
