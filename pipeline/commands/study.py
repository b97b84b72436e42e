"""``loomlight study prt-params|prt-terms``: studies of the precomputed-light-transport renderer (seed 001 §6).

``prt-params STUDY.toml -o DIR``  seed 001 §6.1 on one exemplar: IIRTF cell size (Fig. 8) and SH order
                                  (Fig. 9), each prt variant against fiberpath on the same view: image strips
                                  with error maps, mean-intensity ratios, times (DIR/report.md, study.json)
``prt-terms SWEEP.toml --sweep-dir D -o DIR``  which term holds a prt sweep's error: prt's single and multiple
                                  scattering against fiberpath with max_depth 1 and the remainder, per
                                  configuration (DIR/attribution.md, terms.json)
The runner and the file formats: ``pipeline.runners.prt_study``.
"""
from __future__ import annotations

from pathlib import Path

import typer

app = typer.Typer(name="study", no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
                  help="Study the prt renderer against fiberpath (Khungurn et al. 2017 §6): parameter strips and error "
                       "attribution.")


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="study")


_OUT = typer.Option(..., "-o", "--out", help="Output directory.")
_FORCE = typer.Option(False, "--force", help="Redo precomputes and renders even when up to date.")
_STUDY = typer.Argument(..., help="A study file (TOML; format in pipeline/runners/prt_study.py).")
_SWEEP = typer.Argument(..., help="The prt sweep file (methods 'fiberpath' and 'prt').")
_SWEEP_DIR = typer.Option(..., "--sweep-dir", help="Where loomlight evaluate --sweep wrote that sweep.")
_REFERENCE = typer.Option("fiberpath", "--reference", metavar="<name>",
                          help="The reference method's name in the sweep.")
_PRT = typer.Option("prt", "--prt", metavar="<name>", help="The prt method's name in the sweep.")


@app.command("prt-params")
def prt_params(
    study: Path = _STUDY,
    out: Path = _OUT,
    force: bool = _FORCE,
):
    """Compare prt's IIRTF cell sizes and SH orders with fiberpath on one view (Khungurn et al. 2017 §6.1)."""
    from ..outputs import DIRECTORY, check_output
    from ..runners.prt_study import run_params

    check_output(out, "-o", DIRECTORY, inputs=[study])
    res = run_params(study, out, force=force)
    for what, rows in (("cell size", res.cell_size), ("SH order", res.sh_order)):
        for e in rows:
            label = f"cells {e['cell_factor']:g} l" if what == "cell size" else f"L = {e['sh_order']}"
            typer.echo(f"  {what:9s} {label:12s} ratio " + ", ".join(f"{v:.3f}" for v in e["ratio"])
                       + f"  rel. error {e['mean_intensity_rel_error']:.1%}  RMSE {e['rmse']:.4f}")
    typer.echo(f"report: {res.report_md} ({res.rendered} rendered)")


@app.command("prt-terms")
def prt_terms(
    sweep: Path = _SWEEP,
    sweep_dir: Path = _SWEEP_DIR,
    out: Path = _OUT,
    reference: str = _REFERENCE,
    prt: str = _PRT,
    force: bool = _FORCE,
):
    """Attribute a prt sweep's error to single and multiple scattering."""
    from ..outputs import DIRECTORY, check_output
    from ..runners.prt_study import run_terms

    check_output(out, "-o", DIRECTORY, inputs=[sweep, sweep_dir])
    res = run_terms(sweep, sweep_dir, out, reference=reference, prt=prt, force=force)
    s = res.summary
    typer.echo(f"  relative RMSE of mean intensity: all {s['relative_rmse']:.1%}, single "
               f"{s['relative_rmse_single']:.1%}, multi {s['relative_rmse_multi']:.1%} (multiple scattering "
               f"{s['multi_share_reference']:.0%} of the light)")
    typer.echo(f"report: {res.report_md}")
