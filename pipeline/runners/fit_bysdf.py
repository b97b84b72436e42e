"""``loomlight fit-bysdf``: match the BYSDF to explicit fibres (seed 004 §5's protocol).

The paper fits its few parameters so that its renders match its reference under three lights: front
only, back only, and both. Here the reference is ``fiberpath`` on the realized fibres of the same
yarns (the same yarn curves, the same procedural model: ``loomlight realize``), rendered with the
scene's camera under

- ``front``: one directional light travelling along the camera's view direction (lit from the viewer's side),
- ``back``: one travelling against it (lit from behind the cloth, seen through it),
- ``front+back``: both (not fitted: it checks that the fitted reflection and transmission add up),

each of irradiance ``IRRADIANCE``, no environment (the background stays black, so the image mean
is the cloth's). Fitted: the BYSDF's energy split (``stages.core.shading.bysdf``), as the body energy
reflected at the entry point, x = (1 - spec_weight) reflect_weight, and the body energy transmitted to
the exit point, y = (1 - spec_weight) (1 - reflect_weight); the specular lobes take the rest,
spec_weight = 1 - x - y. The front setup's light is mostly x's, the back setup's mostly y's, so
``iterations`` rounds of the multiplicative update x <- x mean_ref / mean_bysdf (front) and
y <- y mean_ref / mean_bysdf (back) on the image's mean luminance converge in a few rounds (each
round renders both setups); x + y is capped at 1 (energy: no negative specular share), and a cap that
binds is reported (the fibres are then brighter than the yarn colours allow). Output: a TOML of
parameters (``[default]`` table: ``spec_weight``, ``reflect_weight``) for ``--set params=`` and a JSON
report with the reference and fitted means and the residual relative error of each setup per channel
and in luminance.
"""
from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from ..errors import LoomError

IRRADIANCE = 3.0
SETUPS = ("front", "back", "front+back")
LUMA = np.array([0.2126, 0.7152, 0.0722])


def setup_lights(scene) -> dict:
    """The three light setups from the scene's camera."""
    cam = scene.camera
    view = np.asarray(cam["target"], float) - np.asarray(cam["origin"], float)
    view /= np.linalg.norm(view)
    front = {"type": "directional", "direction": [float(x) for x in view], "irradiance": IRRADIANCE}
    back = {"type": "directional", "direction": [float(-x) for x in view], "irradiance": IRRADIANCE}
    return {"front": [front], "back": [back], "front+back": [front, back]}


class _Renderer:
    """One method's integrator, set up once (the fibres' BVH is the costly part), rendered under each light
    setup by swapping the integrator's light table."""

    def __init__(self, scene, method_name, options, extra):
        import importlib

        from ..renderers import method
        from ..runners.render import resolve_options

        sc = dataclasses.replace(scene, lights=next(iter(setup_lights(scene).values())))
        m = method(method_name)
        self.scene = sc
        self.opts = resolve_options(sc, m, width=options["width"], height=options["height"], spp=options["spp"],
                                    seed=options["seed"], fibers=options.get("fibers"),
                                    max_depth=options.get("max_depth"), threads=options.get("threads"),
                                    extra=dict(extra))
        self.setup = importlib.import_module(f"pipeline.renderers.{m.module}").film_setup(sc, self.opts)

    def mean(self, lights, **fields) -> np.ndarray:
        """The image mean under ``lights``, with any other integrator ``fields`` replaced too."""
        from ..render_setup import pack_lights
        from ..renderers.film import render_film, sampling_of

        s, o = self.setup, self.opts
        integ = s.integ._replace(lights=pack_lights(lights, self.scene.path).table(), **fields)
        run = render_film(s.label, integ, s.cam, o["width"], o["height"], sampling_of(o), o["seed"], o["tile_size"],
                          s.variance, o.get("threads"), None)
        return np.asarray(run.rgb, np.float64).reshape(-1, 3).mean(axis=0)


def run_fit(scene_path, yarns, fibers, out: Path, width=96, height=72, spp=16, ref_spp=32, iterations=4,
            max_depth=None, threads=None, progress=print) -> dict:
    from stages.core.shading import bysdf as B

    from ..artifacts import Artifact
    from ..scene import load_scene

    scene = load_scene(scene_path)
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    Artifact(fibers, kind="fibers")
    Artifact(yarns, kind="yarns")
    lights = setup_lights(scene)
    t0 = time.perf_counter()
    progress("fiberpath reference: front, back and front+back light")
    fp = _Renderer(scene, "fiberpath", {"width": width, "height": height, "spp": ref_spp, "seed": scene.seed,
                                        "fibers": str(fibers), "max_depth": max_depth, "threads": threads}, {})
    ref = {name: fp.mean(lights[name]) for name in SETUPS}
    del fp
    ref_s = time.perf_counter() - t0
    p0 = B.pack_bysdf()
    x = (1.0 - p0[B.SPEC_WEIGHT]) * p0[B.REFLECT_WEIGHT]
    y = (1.0 - p0[B.SPEC_WEIGHT]) * (1.0 - p0[B.REFLECT_WEIGHT])
    capped = False
    history = []
    base = {"width": width, "height": height, "spp": spp, "seed": scene.seed, "max_depth": max_depth,
            "threads": threads}
    by = _Renderer(scene, "bysdf", base, {"yarns": str(yarns)})   # tubes, BVH and tables built once

    def bysdf_means(setups):
        # the rows --set params= would give: the split's two weights (as written, 6 digits) over the rest
        params = by.setup.integ.params.copy()
        sp = {k: float(f"{v:.6g}") for k, v in split(x, y).items()}
        params[:, B.SPEC_WEIGHT] = sp["spec_weight"]
        params[:, B.REFLECT_WEIGHT] = sp["reflect_weight"]
        return {n: by.mean(lights[n], params=params) for n in setups}

    t1 = time.perf_counter()
    for it in range(iterations):
        got = bysdf_means(("front", "back"))
        history.append({"iteration": it, "reflect_energy": x, "transmit_energy": y,
                        **{f"{n}_rel_error": float(LUMA @ got[n] / max(LUMA @ ref[n], 1e-12) - 1.0) for n in got}})
        progress(f"round {it + 1}/{iterations}: body energy reflected {x:.4f}, transmitted {y:.4f}: "
                 f"front {history[-1]['front_rel_error']:+.3f}, back {history[-1]['back_rel_error']:+.3f}")
        x = float(np.clip(x * (LUMA @ ref["front"]) / max(LUMA @ got["front"], 1e-12), 1e-4, 1.0))
        y = float(np.clip(y * (LUMA @ ref["back"]) / max(LUMA @ got["back"], 1e-12), 1e-4, 1.0))
        capped = x + y > 1.0
        if capped:
            x, y = x / (x + y), y / (x + y)
    final = bysdf_means(SETUPS)
    fit_s = time.perf_counter() - t1
    residual = {n: {"reference_rgb": ref[n].tolist(), "bysdf_rgb": final[n].tolist(),
                    "rel_error_rgb": (final[n] / np.maximum(ref[n], 1e-12) - 1.0).tolist(),
                    "rel_error_luminance": float(LUMA @ final[n] / max(LUMA @ ref[n], 1e-12) - 1.0)}
                for n in SETUPS}
    write_params(out, x, y, residual)
    report = {"scene": str(scene.path), "yarns": str(yarns), "fibers": str(fibers), "width": width, "height": height,
              "spp": spp, "reference_spp": ref_spp, "iterations": iterations, **split(x, y),
              "energy_capped": capped, "setups": residual, "history": history, "reference_s": ref_s, "fit_s": fit_s}
    Path(out).with_suffix(".json").write_text(json.dumps(report, indent=2))
    return report


def split(x, y) -> dict:
    """spec_weight and reflect_weight of the body energies x (reflected) and y (transmitted)."""
    return {"spec_weight": max(0.0, 1.0 - x - y), "reflect_weight": x / (x + y)}


def write_params(path, x, y, residual=None):
    lines = ["# BYSDF parameters fitted by loomlight fit-bysdf (render with --set params=THIS.toml)"]
    for n, r in (residual or {}).items():
        lines.append(f"# {n}: mean-luminance error {100 * r['rel_error_luminance']:+.1f} % against fiberpath")
    sp = split(x, y)
    lines += ["[default]", f"spec_weight = {sp['spec_weight']:.6g}", f"reflect_weight = {sp['reflect_weight']:.6g}", ""]
    tmp = Path(str(path) + ".tmp")
    tmp.write_text("\n".join(lines))
    tmp.replace(path)
