"""``loomlight fit-bysdf SCENE --yarns Y.zarr --fibers F.zarr -o params.toml``: fit the BYSDF to fiberpath."""
from __future__ import annotations

from pathlib import Path

import typer

from ..limits import FULL_TRANSPORT_DEPTH


def register(app: typer.Typer) -> None:
    @app.command("fit-bysdf")
    def fit_bysdf(
        scene: Path = typer.Argument(..., help="The scene (camera; its yarn colours)."),
        yarns: Path = typer.Option(..., "--yarns", help="The yarns artifact bysdf renders (loomlight ingest)."),
        fibers: Path = typer.Option(..., "--fibers", help="The realized fibres of the same yarns (loomlight realize): "
                                                          "the fiberpath reference."),
        out: Path = typer.Option(..., "-o", "--out", help="The fitted parameters (.toml; a .json report beside it)."),
        width: int = typer.Option(96, "--width", help="Width of the fitting renders."),
        height: int = typer.Option(72, "--height", help="Height of the fitting renders."),
        spp: int = typer.Option(16, "--spp", help="Samples per pixel of the bysdf renders."),
        ref_spp: int = typer.Option(32, "--ref-spp", help="Samples per pixel of the fiberpath references."),
        iterations: int = typer.Option(6, "--iterations", help="Fitting rounds (each renders front and back)."),
        max_depth: int = typer.Option(FULL_TRANSPORT_DEPTH, "--max-depth",
                                      help="Path depth of every fitting render, both methods (the full transport, "
                                           "whatever the scene's render.max_depth)."),
        no_scene_lights: bool = typer.Option(False, "--no-scene-lights",
                                             help="Skip the comparison under the scene's own lights (a prediction "
                                                  "unless --fit-reflection scene)."),
        fit_reflection: str = typer.Option("front", "--fit-reflection", metavar="<front | scene>",
                                           help="The setup the reflection side is fitted to: the front light (the "
                                                "paper's protocol) or the scene's own lights."),
        angles: str = typer.Option("", "--angles", metavar="A,B,...",
                                   help="Also render both methods with the front light turned by these angles "
                                        "(degrees, 0-89) towards the scene's key light, and report bysdf / "
                                        "fiberpath per angle (JSON, and a plot beside the parameters). Not fitted."),
        azimuths: str = typer.Option("", "--azimuths", metavar="A,B,...",
                                     help="Also render both methods with the front light turned by these azimuths "
                                          "(degrees, 0 to under 360) about the camera's up axis, at the view's "
                                          "elevation (the same irradiance on level cloth), and report bysdf / "
                                          "fiberpath per azimuth (JSON, and a plot). Not fitted."),
    ):
        """Fit the BYSDF's energy split and per-channel body colours so bysdf matches fiberpath under front and back light."""  # noqa: E501 (command help: --help shows its line breaks)
        from ..errors import LoomError, unknown
        from ..outputs import check_output
        from ..runners.fit_bysdf import REFLECT_SETUPS, run_fit

        if fit_reflection not in REFLECT_SETUPS:
            raise LoomError(None, "--fit-reflection", unknown("setup", fit_reflection, REFLECT_SETUPS))
        for v, name in ((width, "--width"), (height, "--height"), (spp, "--spp"), (ref_spp, "--ref-spp"),
                        (iterations, "--iterations"), (max_depth, "--max-depth")):
            if v <= 0:
                raise LoomError(None, name, f"must be a positive integer, got {v}")
        turned = parse_angles(angles)
        spun = parse_angles(azimuths, "--azimuths")
        check_output(out, "-o", suffixes=(".toml",), inputs=[scene, yarns, fibers])
        rep = run_fit(scene, yarns, fibers, out, width, height, spp, ref_spp, iterations,
                      max_depth=max_depth,
                      scene_lights=False if no_scene_lights else None, reflect=fit_reflection,
                      angles=turned, azimuths=spun, progress=typer.echo)
        typer.echo(f"wrote {out}: spec_weight {rep['spec_weight']:.4f}, reflect_weight {rep['reflect_weight']:.4f}, "
                   "body colour factors " + " ".join(f"{v:.3g}" for v in rep["body_r_scale"]) + " (reflection), "
                   + " ".join(f"{v:.3g}" for v in rep["body_t_scale"]) + " (transmission)"
                   + (" (capped: no specular share left; the body colours' level carries the rest)"
                      if rep["energy_capped"] else ""))
        for n, r in rep["setups"].items():
            typer.echo(f"  {n:10s} mean error {100 * r['rel_error_luminance']:+.1f} % luminance, rgb "
                       + " ".join(f"{100 * e:+.1f}" for e in r["rel_error_rgb"]) + f" %, SSIM {r['ssim']:.3f}"
                       + ("" if r["fitted"] else " (not fitted)"))
        for r in rep["angle_check"]:
            typer.echo(f"  light {r['angle_deg']:4g} deg from the view: bysdf / fiberpath "
                       + " ".join(f"{1 + e:.3f}" for e in r["rel_error_rgb"]) + " (not fitted)")
        if rep["angle_check"]:
            typer.echo(f"  angle check plot: {out.with_suffix('.angles.png')}")
        for r in rep["azimuth_check"]:
            typer.echo(f"  light {r['azimuth_deg']:4g} deg round from the view: bysdf / fiberpath "
                       + " ".join(f"{1 + e:.3f}" for e in r["rel_error_rgb"]) + " (not fitted)")
        if rep["azimuth_check"]:
            typer.echo(f"  azimuth check plot: {out.with_suffix('.azimuths.png')}")


def parse_angles(text: str, option: str = "--angles") -> tuple:
    """``--angles`` "0,15,30" -> (0.0, 15.0, 30.0); each within [0, ANGLE_MAX] degrees (``--azimuths``: [0,
    AZIMUTH_MAX)), none twice."""
    from ..errors import LoomError
    from ..runners.fit_bysdf import ANGLE_MAX, AZIMUTH_MAX

    if not text.strip():
        return ()
    out = []
    for part in text.split(","):
        try:
            a = float(part)
        except ValueError:
            raise LoomError(None, option, f"{part.strip()!r} is not a number of degrees") from None
        top, closed = {"--angles": (ANGLE_MAX, True), "--azimuths": (AZIMUTH_MAX, False)}[option]
        if not (0.0 <= a <= top if closed else 0.0 <= a < top):
            raise LoomError(None, option, f"{a:g} degrees is outside [0, {top:g}{']' if closed else ')'}")
        if a in out:
            raise LoomError(None, option, f"{a:g} degrees is given twice")
        out.append(a)
    return tuple(out)
