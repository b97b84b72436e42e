"""``loomlight evaluate``: measure renders against a reference; three modes.

Images
    ``loomlight evaluate --ref REF.exr --test A.exr [--test B.exr ...] -o DIR``
    Per test image: RMSE, relative MSE, SSIM on luminance, mean CIEDE2000, plus wall time, peak
    memory, spp and paths/s from the render artifact ``A.zarr`` beside ``A.exr`` when it exists.
    Writes DIR/metrics.json, error maps, crops, a summary plot, DIR/report.md, DIR/report.html and
    the ``evaluation`` artifact DIR/evaluation.zarr.

Sweep (seed 001 §6.3: Fig. 13 and Table 2)
    ``loomlight evaluate --sweep data/sweeps/demo.toml -o DIR``
    Renders every (configuration, method) of the sweep file that is missing or out of date under
    DIR/renders/<config>/<method>.exr (through ``loomlight render``), then reports per method the
    RMSE of mean image intensity against the reference method over all configurations and the time
    per image with its speed-up over the reference. ``--no-render`` only evaluates what exists.

Table 1 (seed 000 Table 1)
    ``loomlight evaluate --table1 --scene A.toml [--scene B.toml] [--procedural P.exr --realized R.exr ...]
    [--unrealized U.exr ...] -o DIR``
    Data sizes from ``pipeline.memory_table`` (full realization against the procedural model) and
    the volpath render times of the procedural and realized renders given, the i-th
    ``--procedural``/``--realized`` pair belonging to the i-th ``--scene``; each ``--unrealized``
    (a procedural render of a fabric too large to realize: its time, peak memory and that memory
    against the full realization) belongs to the next scene after the pairs.

Equal error (which method gives the right picture fastest)
    ``loomlight evaluate --convergence data/compare/demo.toml -o DIR [--ref REF.zarr] [--reference-only]``
    Makes (or reuses) the comparison's converged reference from independent batches, renders every
    method at its increasing budgets, fits each method's error against time E(t)^2 = b^2 + c/t against
    the reference (bias floor b, noise constant c), and reports times to each error level, speed-ups at
    equal error, an equal-time strip, memory and targets (``pipeline.runners.convergence``).
    ``--reference-only`` builds the reference and stops (``make references``); ``--ref`` names a
    reference made elsewhere, refused when made for another scene, settings or code version.

Exit code 2 with one line naming the file on bad input (missing file, not an EXR, size mismatch).
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from .scheduling import SCHEDULER


def register(app: typer.Typer) -> None:
    @app.command("evaluate")
    def evaluate(
        ref: Optional[Path] = typer.Option(None, "--ref",
                                           help="Reference image (linear EXR); with --convergence the reference "
                                                "artifact (default DIR/reference/reference.zarr)."),
        test: Optional[List[Path]] = typer.Option(None, "--test", help="Test image (EXR); repeat for several."),
        sweep: Optional[Path] = typer.Option(None, "--sweep", help="A sweep file (TOML, schemas/sweep.schema.json)."),
        convergence: Optional[Path] = typer.Option(None, "--convergence",
                                                   help="A comparison file (TOML, schemas/compare.schema.json, "
                                                        "data/compare/): every method's error against time at equal "
                                                        "error."),
        reference_only: bool = typer.Option(False, "--reference-only",
                                            help="--convergence: build (or check) the converged reference and stop."),
        no_memory: bool = typer.Option(False, "--no-memory",
                                       help="--convergence: skip the peak-memory render of each method in a process of "
                                            "its own."),
        table1: bool = typer.Option(False, "--table1",
                                    help="Build the Table 1 form of Luan, Zhao, Bala 2017 (data sizes and render "
                                         "times)."),
        scene: Optional[List[Path]] = typer.Option(None, "--scene", help="--table1: a scene file; repeat for several."),
        procedural: Optional[List[Path]] = typer.Option(None, "--procedural",
                                                        help="--table1: procedural volpath render (EXR) of the "
                                                             "matching --scene."),
        realized: Optional[List[Path]] = typer.Option(None, "--realized",
                                                      help="--table1: realized volpath render (EXR) of the matching "
                                                           "--scene."),
        unrealized: Optional[List[Path]] = typer.Option(None, "--unrealized",
                                                        help="--table1: procedural volpath render (EXR) of a scene too "
                                                             "large to realize; these follow the "
                                                             "--procedural/--realized pairs' scenes."),
        out: Path = typer.Option(..., "-o", "--out", help="Output directory for metrics, pictures and the report."),
        force: bool = typer.Option(False, "--force", help="Recompute even when the inputs are unchanged."),
        no_render: bool = typer.Option(False, "--no-render",
                                       help="--sweep: do not render; evaluate the renders that exist."),
        scheduler: str = SCHEDULER,
    ):
        """Compare renders against a reference: metrics, error maps, report (and sweeps, Table 1)."""
        from ..errors import LoomError
        from ..outputs import DIRECTORY, check_output

        modes = [m for m, on in (("--ref/--test", (ref is not None and convergence is None) or bool(test)),
                                 ("--sweep", sweep is not None), ("--table1", table1),
                                 ("--convergence", convergence is not None)) if on]
        if len(modes) != 1:
            raise LoomError(None, " and ".join(modes) if modes else "--ref/--test",
                            "give exactly one of --ref/--test, --sweep, --table1 or --convergence"
                            + (f" (got {len(modes)})" if modes else " (got none)"))
        for flag, on in (("--reference-only", reference_only), ("--no-memory", no_memory), ("--scheduler", scheduler)):
            if on and modes[0] != "--convergence":
                raise LoomError(None, flag, "goes with --convergence")
        check_output(out, "-o", DIRECTORY, inputs=[ref, *(test or ()), sweep, convergence, *(scene or ()),
                                                   *(procedural or ()), *(realized or ()), *(unrealized or ())])
        if modes[0] == "--convergence":
            from ..runners.convergence import run_convergence

            res = run_convergence(convergence, out, ref_path=ref, reference_only=reference_only, force=force,
                                  memory=not no_memory, echo=typer.echo, scheduler=scheduler)
            if reference_only:
                typer.echo(f"reference: {res.reference['path']}")
                return
            for name, s in res.methods.items():
                se = s.get("speedup_at_equal_error")
                typer.echo(f"  {name:22s} bias floor {s['floor']:.3f} +- {s['floor_se']:.3f}  noise constant "
                           f"{s['noise_constant']:.3g} s" + (f"  speed-up at {se['level']:.0%}: "
                                                            f"{se['bound'].replace('~', '~ ')}{se['value']:.3g}x"
                                                            if se else ""))
            for t in res.targets:
                got = "-" if t["value"] is None else f"{t['bound']}{t['value']:.3g}x at {t['level']:.0%}"
                typer.echo(f"  target {t['method']}: >= {t['target']:g}x at equal error: {got}: "
                           + ("met" if t["met"] else "NOT met" + (f" ({t['why']})" if t.get("why") else "")))
            typer.echo(f"report: {res.report_md}")
            return
        if modes[0] == "--sweep":
            from ..runners.sweep import run_sweep

            res = run_sweep(sweep, out, force=force, render=not no_render)
            typer.echo(f"sweep: {res.configurations} configurations x {len(res.methods)} methods, "
                       f"{res.rendered} rendered, {res.reused} reused")
            for name, st in res.methods.items():
                t = st.get("time_per_image_s")
                sp = st.get("speedup")
                typer.echo(f"  {name:20s} RMSE(mean intensity) {st['rmse_mean_intensity']:.4g}"
                           + (f"  time/image {t:.3g} s" if t is not None else "")
                           + (f"  speed-up {sp:.2f}x" if sp is not None else ""))
            typer.echo(f"report: {res.report_md}")
            return
        if modes[0] == "--table1":
            from ..runners.table1 import run_table1

            md = run_table1(scene or [], procedural or [], realized or [], out, force=force,
                            unrealized=unrealized or [])
            typer.echo(f"report: {md}")
            return
        if ref is None:
            raise LoomError(None, "--ref", "give the reference image with --ref")
        if not test:
            raise LoomError(None, "--test", "give at least one test image with --test")
        from ..runners.evaluate import evaluate_images

        ev = evaluate_images(ref, test, out, force=force)
        if ev.skipped:
            typer.echo(f"{out}: up to date (inputs unchanged; --force recomputes)")
        for name, e in ev.metrics.items():
            typer.echo(f"  {name:24s} RMSE {e['rmse']:.4g}  relMSE {e['relmse']:.4g}  SSIM {e['ssim']:.4f}  "
                       f"dE00 {e['delta_e2000_mean']:.3g}")
        typer.echo(f"report: {ev.report_md}")
