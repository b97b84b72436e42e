"""``loomlight warmup [--methods M,...]``: compile the kernels ahead of time, with a progress bar.

numba compiles loomlight's kernels on their first run on a machine (minutes for all methods: the
measurements page, *Compilation on a cold cache*); every later run loads them from the cache. ``warmup``
pays it once, up front, by running the commands of ``make demo`` for each method on the bundled scenes at a
few pixels (``pipeline.warmup``). Run it after installing or updating loomlight.
"""
from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    @app.command("warmup")
    def warmup(methods: str = typer.Option("volpath,fiberpath,prt,btf,bysdf", "--methods",
                                           metavar="M[,M...]",
                                           help="Methods to compile for: volpath, fiberpath, prt, btf, bysdf "
                                                "(comma-separated; default all).")):
        """Compile the kernels of the given render methods now, so their first real run starts at once."""
        from .. import compilation, progress
        from ..errors import check_name
        from ..warmup import METHODS, estimate_key, plan, run

        wanted = [m.strip() for m in methods.split(",") if m.strip()]
        if not wanted:
            check_name("", METHODS, None, "--methods", "method")
        for m in wanted:
            check_name(m, METHODS, None, "--methods", "method")
        steps = plan(wanted)
        key = estimate_key(wanted)
        est = compilation.estimate_s(key)
        how_long = (f"~{progress.clock(est)} last time on this machine" if est else
                    "a few minutes on a cold cache, seconds on a warm one")
        typer.echo(f"warmup: compiling for {', '.join(wanted)} ({len(steps)} steps; {how_long})", err=True)
        bar = progress.begin("warmup", len(steps))

        def on_step(k, step):
            if k:
                progress.advance(bar)
            progress.relabel(bar, f"warmup: {step.name}")
            if progress.mode() == "plain":
                progress.info(f"warmup {k + 1}/{len(steps)}: {step.name}")

        try:
            took = run(wanted, on_step=on_step)
            progress.advance(bar)
        finally:
            progress.end(bar)
        compilation.record(key, took)
        typer.echo(f"warmup: done in {progress.clock(took)}; the kernels are in the numba cache")
