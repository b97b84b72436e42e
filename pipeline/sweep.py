"""Sweeps: render methods over light and view configurations and compare them with a reference method.

A sweep file (TOML, ``schemas/sweep.schema.json``) names a base scene, render methods and
configurations; seed 001 §6.3 is the model (Fig. 13: RMSE of the mean image intensity of every
configuration against path tracing; Table 2: time per image and speed-up over path tracing)::

    [sweep]
    name = "demo-sg"
    scene = "../scenes/demo.toml"   # relative to the sweep file
    reference = "fiberpath"         # a method name below
    render = { spp = 16 }           # merged into every scene's [render]
    camera = { width = 96, height = 72 }   # merged into every scene's [camera]

    [[methods]]
    name = "fiberpath"              # label: output file renders/<config>/<name>.exr
    method = "fiberpath"            # the renderer (loomlight render --method); default: name
    render = { spp = 64 }           # merged into the scene's [render] for this method only
    args = []                       # extra arguments for loomlight render ({sweep_dir}, {out} expand)

    [grid]                          # the product of these becomes configurations
    axes = [[0, 0, 1], [0.5, 0, 0.866]]   # SG axes (towards the light), normalised
    sharpness = [10, 100, 1000]     # SG sharpness lambda
    power = 1.0                     # SG power (total radiant intensity)
    directional = true              # also a directional light along -axis (the lambda -> inf limit)
    irradiance = 1.0
    views = [{ name = "top", origin = [0, 0, 3], target = [0, 0, 0], up = [0, 1, 0] }]

    [[configurations]]              # explicit configurations, after the grid's
    name = "grazing"
    lights = [{ type = "directional", direction = [-1, 0, -0.2], irradiance = 1.0 }]
    camera = { origin = [0, -3, 1] }

A configuration replaces the scene's lights (when it gives ``lights``) and merges ``camera`` and
``render`` into the scene's tables. Grid configurations are named ``<view>_a<i>_l<lambda>``
(``<view>_a<i>_dir`` for directional lights; no view prefix without views).

``run_sweep`` writes for every (configuration, method) a derived scene
``DIR/renders/<config>/<method>.scene.toml`` and renders it through ``loomlight render`` (in
process) to ``DIR/renders/<config>/<method>.exr`` unless that image exists and its stamp
``<method>.stamp.json`` records the same scene text, method, arguments, loomlight version and
content hashes of the files the scene refers to. Times per image come from the render artifact
beside the image (``<method>.zarr``), else from the wall time measured around the render call.
Method ``args`` may use ``{sweep_dir}`` (the sweep file's folder) and ``{out}`` (the output folder);
other relative paths are relative to the working directory. An argument naming an existing file or
artifact adds its content hash to the stamp, so a changed input (e.g. ``--fibers``) re-renders.
It then writes ``DIR/sweep.json``, ``DIR/metrics.json`` (per image against the reference
method's image of the same configuration), plots, ``DIR/report.md``/``.html`` and the
``evaluation`` artifact ``DIR/evaluation.zarr``.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import LoomError
from .schemas import validate


# ------------------------------------------------------------------------------------------------
# TOML output (the scene files we derive are plain data: tables, arrays, strings, numbers, booleans)
def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_toml(doc: dict) -> str:
    """A TOML document of top-level ``key = value`` lines (tables as inline tables)."""
    return "".join(f"{json.dumps(str(k))} = {_toml_value(v)}\n" for k, v in doc.items())


# ------------------------------------------------------------------------------------------------
# the sweep file
@dataclass
class Method:
    name: str
    method: str
    render: dict
    args: list[str]


@dataclass
class Configuration:
    name: str
    lights: list | None
    camera: dict
    render: dict
    label: str


@dataclass
class Sweep:
    path: Path
    name: str
    scene_path: Path
    scene_raw: dict
    reference: str
    render: dict
    camera: dict
    methods: list[Method]
    configurations: list[Configuration]


def _unit(v) -> list[float]:
    a = np.asarray(v, float)
    return (a / np.linalg.norm(a)).tolist()


def _grid_configurations(path: Path, grid: dict) -> list[Configuration]:
    axes = grid.get("axes", [])
    for i, a in enumerate(axes):
        if np.linalg.norm(np.asarray(a, float)) == 0:
            raise LoomError(path, f"grid.axes[{i}]", "zero-length vector")
    views = grid.get("views") or [None]
    power = grid.get("power", 1.0)
    out = []
    for view in views:
        prefix = f"{view['name']}_" if view else ""
        cam = {k: v for k, v in view.items() if k != "name"} if view else {}
        for i, axis in enumerate(axes):
            ax = _unit(axis)
            for lam in grid.get("sharpness", []):
                out.append(Configuration(f"{prefix}a{i}_l{lam:g}", [{"type": "sg", "axis": ax, "sharpness": float(lam), "power": power}],
                                         cam, {}, f"SG axis {np.round(ax, 3).tolist()}, lambda {lam:g}"
                                         + (f", view {view['name']}" if view else "")))
            if grid.get("directional", False):
                d = (-np.asarray(ax)).tolist()
                out.append(Configuration(f"{prefix}a{i}_dir", [{"type": "directional", "direction": d,
                                                                "irradiance": grid.get("irradiance", 1.0)}],
                                         cam, {}, f"directional towards {np.round(ax, 3).tolist()}"
                                         + (f", view {view['name']}" if view else "")))
    return out


def _absolute_paths(raw: dict, scene_path: Path) -> dict:
    """Scene file paths made absolute, so the derived scene can live in another folder."""
    raw = copy.deepcopy(raw)
    base = scene_path.parent
    fab = raw.get("fabric", {})
    if "path" in fab and not Path(fab["path"]).is_absolute():
        fab["path"] = str((base / fab["path"]).resolve())
    for light in raw.get("lights", []):
        if light.get("type") == "envmap" and "path" in light and not Path(light["path"]).is_absolute():
            light["path"] = str((base / light["path"]).resolve())
    return raw


def load_sweep(path: str | Path) -> Sweep:
    path = Path(path)
    if not path.exists():
        raise LoomError(path, None, "sweep file not found")
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise LoomError(path, None, f"not valid TOML: {e}") from None
    except UnicodeDecodeError as e:
        raise LoomError(path, f"byte {e.start}", "not a UTF-8 text file") from None
    validate(raw, "sweep", path)
    sw = raw["sweep"]
    scene_path = Path(sw["scene"])
    if not scene_path.is_absolute():
        scene_path = (path.parent / scene_path).resolve()
    if not scene_path.exists():
        raise LoomError(path, "sweep.scene", f"scene file {scene_path} not found")
    try:
        scene_raw = tomllib.loads(scene_path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise LoomError(scene_path, None, f"not a readable TOML scene: {e}") from None
    methods = [Method(m["name"], m.get("method", m["name"]), dict(m.get("render", {})), list(m.get("args", [])))
               for m in raw["methods"]]
    names = [m.name for m in methods]
    for j, n in enumerate(names):
        if names.index(n) != j:
            raise LoomError(path, f"methods[{j}].name", f"method name {n!r} is used twice")
    if sw["reference"] not in names:
        raise LoomError(path, "sweep.reference", f"{sw['reference']!r} is not one of the methods ({', '.join(names)})")
    configs = _grid_configurations(path, raw["grid"]) if "grid" in raw else []
    for c in raw.get("configurations", []):
        configs.append(Configuration(c["name"], c.get("lights"), dict(c.get("camera", {})), dict(c.get("render", {})),
                                     c.get("description", c["name"])))
    if not configs:
        raise LoomError(path, "configurations", "the sweep has no configurations (give [grid] or [[configurations]])")
    cnames = [c.name for c in configs]
    for i, n in enumerate(cnames):
        if cnames.index(n) != i:
            raise LoomError(path, "configurations", f"configuration name {n!r} occurs twice")
    return Sweep(path, sw.get("name", path.stem), scene_path, _absolute_paths(scene_raw, scene_path), sw["reference"],
                 dict(sw.get("render", {})), dict(sw.get("camera", {})), methods, configs)


def derived_scene(sweep: Sweep, config: Configuration, method: Method) -> dict:
    """The base scene with the sweep's, the configuration's and the method's overrides."""
    raw = copy.deepcopy(sweep.scene_raw)
    if config.lights is not None:
        raw["lights"] = copy.deepcopy(config.lights)
    cam = {**raw.get("camera", {}), **sweep.camera, **config.camera}
    if cam:
        raw["camera"] = cam
    render = {**raw.get("render", {}), **sweep.render, **config.render, **method.render}
    render["method"] = method.method
    raw["render"] = render
    return raw


def _referenced_files(raw: dict) -> dict[str, str]:
    from .artifacts import content_hash

    files = {}
    paths = [raw.get("fabric", {}).get("path")] + [l.get("path") for l in raw.get("lights", []) if l.get("type") == "envmap"]
    for p in paths:
        if p and Path(p).exists():
            files[p] = content_hash(p)
    return files


# ------------------------------------------------------------------------------------------------
# rendering
def known_methods() -> set[str]:
    """Render methods installed: the modules of ``pipeline.renderers``."""
    import importlib
    import pkgutil

    try:
        pkg = importlib.import_module("pipeline.renderers")
    except ModuleNotFoundError:
        return set()
    return {m.name for m in pkgutil.iter_modules(pkg.__path__) if not m.name.startswith("_")}


def cli_render(scene_file: Path, method: str, exr: Path, args: list[str]) -> None:
    """``loomlight render SCENE --method M -o EXR [args]`` in this process."""
    import importlib.util

    if importlib.util.find_spec("pipeline.commands.render") is None:
        raise LoomError(scene_file, None, "this loomlight has no 'render' command (the renderers are not installed)")
    from .cli import main

    rc = main(["render", str(scene_file), "--method", method, "-o", str(exr), *args])
    if rc != 0:
        raise LoomError(scene_file, None, f"loomlight render --method {method} failed with exit code {rc}")
    if not exr.exists():
        raise LoomError(scene_file, None, f"loomlight render --method {method} wrote no {exr.name}")


@dataclass
class Job:
    config: Configuration
    method: Method
    scene_file: Path
    exr: Path
    stamp: Path
    key: str
    text: str
    args: list[str]


def expand_args(sweep: Sweep, out: Path, args: list[str]) -> list[str]:
    return [a.replace("{sweep_dir}", str(sweep.path.parent.resolve())).replace("{out}", str(out.resolve())) for a in args]


def _arg_hashes(args: list[str]) -> dict[str, str]:
    from .artifacts import content_hash

    out = {}
    for a in args:
        try:
            if Path(a).exists():
                out[a] = content_hash(a)
        except (LoomError, OSError, ValueError):
            continue
    return out


def _jobs(sweep: Sweep, out: Path) -> list[Job]:
    from . import __version__
    from .artifacts import _canonical

    jobs = []
    for i, c in enumerate(sweep.configurations):
        for m in sweep.methods:
            raw = derived_scene(sweep, c, m)
            validate(raw, "scene", sweep.path, prefix=f"configuration {c.name!r}, method {m.name!r}: ")
            text = (f"# derived by loomlight evaluate --sweep {sweep.path.name}: scene {sweep.scene_path.name}, "
                    f"configuration {c.name}, method {m.name}\n" + dumps_toml(raw))
            args = expand_args(sweep, out, m.args)
            key = hashlib.sha256(_canonical({"scene": text, "method": m.method, "args": args, "version": __version__,
                                             "files": {**_referenced_files(raw), **_arg_hashes(args)}}).encode()).hexdigest()
            d = out / "renders" / c.name
            jobs.append(Job(c, m, d / f"{m.name}.scene.toml", d / f"{m.name}.exr", d / f"{m.name}.stamp.json", key, text,
                            args))
    return jobs


def _stamp(job: Job) -> dict | None:
    try:
        st = json.loads(job.stamp.read_text())
    except (OSError, ValueError):
        return None
    return st if st.get("key") == job.key and job.exr.exists() else None


# ------------------------------------------------------------------------------------------------
@dataclass
class SweepResult:
    out_dir: Path
    configurations: int
    methods: dict
    rendered: int
    reused: int
    report_md: Path
    report_html: Path
    images: dict = field(default_factory=dict)


def run_sweep(sweep_path: str | Path, out_dir: str | Path, force: bool = False, render: bool = True,
              renderer: Callable[[Path, str, Path, list], None] | None = None) -> SweepResult:
    """Render what is missing (``render``), then evaluate every method against the reference."""
    from . import report as rp
    from .evaluate_runner import load_image, render_stats
    from .progress import progress

    sweep = load_sweep(sweep_path)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise LoomError(out, None, "output path exists and is not a directory")
    jobs = _jobs(sweep, out)
    if render and renderer is None:
        known = known_methods()
        for j, m in enumerate(sweep.methods):
            if m.method not in known:
                raise LoomError(sweep.path, f"methods[{j}].method", f"unknown render method {m.method!r} (installed: "
                                + (", ".join(sorted(known)) or "none") + ")")
    do_render = renderer or cli_render

    rendered = reused = 0
    todo = [j for j in jobs if force or _stamp(j) is None] if render else []
    from .report import write_text

    with progress("sweep renders", len(todo)) as advance:
        for job in todo:
            write_text(job.scene_file, job.text)
            job.stamp.unlink(missing_ok=True)
            t0 = time.perf_counter()
            do_render(job.scene_file, job.method.method, job.exr, list(job.args))
            dt = time.perf_counter() - t0
            write_text(job.stamp, json.dumps({"key": job.key, "measured_wall_time_s": dt, "method": job.method.method,
                                              "args": job.args}, indent=2) + "\n")
            rendered += 1
            advance()
    reused = sum(1 for j in jobs if j not in todo and _stamp(j) is not None)

    # gather images: a configuration counts when its reference and at least one method exist
    mnames = [m.name for m in sweep.methods]
    available = {(j.config.name, j.method.name): j for j in jobs if _stamp(j) is not None
                 or (not render and j.exr.exists())}
    configs = [c for c in sweep.configurations if (c.name, sweep.reference) in available]
    if not configs:
        raise LoomError(sweep.path, "sweep.reference", f"no configuration has a render of the reference method "
                        f"{sweep.reference!r} under {out / 'renders'}" + ("" if render else " (--no-render)"))
    C, M = len(configs), len(mnames)
    means = np.full((C, M, 3), np.nan)
    times = np.full((C, M), np.nan)
    per_image: dict[str, dict] = {}
    images: dict[tuple[str, str], np.ndarray] = {}
    inputs: dict[str, Path] = {"sweep": sweep.path, "scene": sweep.scene_path}
    from stages.evaluate.metrics import mean_intensity

    from .evaluate_runner import check_pair, image_metrics

    ri = mnames.index(sweep.reference)
    for ci, c in enumerate(configs):
        ref_job = available[(c.name, sweep.reference)]
        ref = load_image(ref_job.exr)
        for mi, name in enumerate(mnames):
            job = available.get((c.name, name))
            if job is None:
                continue
            img = ref if mi == ri else load_image(job.exr)
            if mi != ri:
                check_pair(ref_job.exr, ref, job.exr, img)
            images[(c.name, name)] = img
            means[ci, mi] = mean_intensity(img)
            st = render_stats(job.exr)
            stamp = _stamp(job) or {}
            t = st.get("wall_time_s", stamp.get("measured_wall_time_s"))
            if t is not None:
                times[ci, mi] = t
            label = f"{c.name}/{name}.exr"
            inputs[f"image:{label}"] = job.exr
            if "render_artifact" in st:
                inputs[f"render:{label}"] = Path(st["render_artifact"])
            if mi != ri:
                e = image_metrics(img, ref)
                e.update({k: v for k, v in st.items() if k != "render_artifact"})
                if t is not None:
                    e["wall_time_s"] = float(t)
                per_image[label] = e

    methods = summarize_methods(mnames, sweep.reference, means, times, per_image, [c.name for c in configs])
    params = {"mode": "sweep", "sweep": sweep.name, "reference": sweep.reference, "methods": mnames,
              "configurations": [c.name for c in configs]}
    from .artifacts import ArtifactWriter

    writer = ArtifactWriter(out / "evaluation.zarr", kind="evaluation", stage="evaluate", params=params, inputs=inputs)
    md, ht = out / "report.md", out / "report.html"
    if not force and rendered == 0 and writer.up_to_date() and md.exists() and ht.exists():
        return SweepResult(out, C, methods, 0, reused, md, ht)

    doc = {"sweep": sweep.name, "scene": str(sweep.scene_path), "reference": sweep.reference,
           "configurations": [{"name": c.name, "description": c.label,
                               "mean_intensity": {n: (means[ci, mi].tolist() if not np.isnan(means[ci, mi, 0]) else None)
                                                  for mi, n in enumerate(mnames)},
                               "time_s": {n: (float(times[ci, mi]) if not np.isnan(times[ci, mi]) else None)
                                          for mi, n in enumerate(mnames)}}
                              for ci, c in enumerate(configs)],
           "methods": methods}
    rp.write_text(out / "sweep.json", json.dumps(doc, indent=2) + "\n")
    rp.write_text(out / "metrics.json", json.dumps(per_image, indent=2, sort_keys=True) + "\n")
    _sweep_report(sweep, out, configs, mnames, means, methods, per_image, images)

    with writer as w:
        w.write("mean_intensity", means, dimension_names=("configuration", "method", "channel"))
        w.write("time_per_image_s", times, dimension_names=("configuration", "method"))
        w.summary.update(kind="evaluation", mode="sweep", reference=sweep.reference, methods=methods,
                         tests=per_image, metrics=["rmse_mean_intensity", "time_per_image_s", "speedup"])
    return SweepResult(out, C, methods, rendered, reused, md, ht, images=per_image)


def summarize_methods(mnames: list[str], reference: str, means: np.ndarray, times: np.ndarray,
                      per_image: dict, config_names: list[str]) -> dict:
    """Per method: RMSE of mean intensity against the reference over configurations x channels
    (seed 001 Fig. 13), relative RMSE, means of the per-image metrics, time per image and
    speed-up = reference time per image / method time per image (seed 001 Table 2)."""
    ri = mnames.index(reference)
    ref_t = float(np.nanmean(times[:, ri])) if np.any(~np.isnan(times[:, ri])) else None
    out = {}
    for mi, name in enumerate(mnames):
        ok = ~np.isnan(means[:, mi, 0])
        if not ok.any():
            continue
        d = means[ok, mi] - means[ok, ri]
        r = means[ok, ri]
        rms_ref = float(np.sqrt(np.mean(r * r)))
        st = {"configurations": int(ok.sum()), "rmse_mean_intensity": float(np.sqrt(np.mean(d * d))),
              "relative_rmse_mean_intensity": float(np.sqrt(np.mean(d * d)) / rms_ref) if rms_ref > 0 else None}
        tt = times[ok, mi]
        t = float(np.nanmean(tt)) if np.any(~np.isnan(tt)) else None
        st["time_per_image_s"] = t
        st["speedup"] = (ref_t / t) if (t and ref_t is not None and t > 0) else None
        if name != reference:
            labels = [f"{c}/{name}.exr" for c, o in zip(config_names, ok) if o]
            for k in ("rmse", "relmse", "ssim", "delta_e2000_mean"):
                st[f"mean_{k}"] = float(np.mean([per_image[l][k] for l in labels]))
        out[name] = st
    return out


def _sweep_report(sweep: Sweep, out: Path, configs: list[Configuration], mnames: list[str], means: np.ndarray,
                  methods: dict, per_image: dict, images: dict) -> None:
    from . import report as rp
    from .report import fmt_num, fmt_seconds

    rep = rp.Report(f"Sweep {sweep.name}: methods against {sweep.reference}")
    rep.paragraph(f"Scene {sweep.scene_path}; {len(configs)} configurations x {len(mnames)} methods; "
                  f"reference method: {sweep.reference}. Sweep file: {sweep.path}.")
    rep.heading("RMSE of mean image intensity (seed 001 Fig. 13 form)")
    rep.paragraph("For every configuration the mean of each colour channel of the image (3 values per image); "
                  "RMSE of these values against the reference method's over all configurations. "
                  "Relative: divided by the RMS of the reference values.")
    rows = []
    for n in mnames:
        if n not in methods:
            continue
        s = methods[n]
        rows.append([n, s["configurations"], fmt_num(s["rmse_mean_intensity"]), fmt_num(s["relative_rmse_mean_intensity"]),
                     fmt_num(s.get("mean_rmse")), fmt_num(s.get("mean_ssim")), fmt_num(s.get("mean_delta_e2000_mean"))])
    rep.table(["method", "configurations", "RMSE mean intensity", "relative", "mean image RMSE", "mean SSIM",
               "mean ΔE00"], rows)
    rp.sweep_rmse_png({n: methods[n]["rmse_mean_intensity"] for n in mnames if n in methods and n != sweep.reference},
                      out / "sweep_rmse.png", sweep.reference)
    rep.image("sweep_rmse.png", "RMSE of mean image intensity per method against the reference")
    ri = mnames.index(sweep.reference)
    ok = ~np.isnan(means[:, :, 0])
    rp.sweep_scatter_png({n: (means[ok[:, mi], ri], means[ok[:, mi], mi]) for mi, n in enumerate(mnames)
                          if mi != ri and ok[:, mi].any()}, out / "sweep_scatter.png", sweep.reference)
    rep.image("sweep_scatter.png", "Mean intensity of each method against the reference, per configuration and channel")
    rep.heading("Time per image and speed-up (seed 001 Table 2 form)")
    rep.table(["method", "time per image", "speed-up"],
              [[n, fmt_seconds(methods[n]["time_per_image_s"]),
                f"{methods[n]['speedup']:.2f}x" if methods[n]["speedup"] is not None else "-"]
               for n in mnames if n in methods])
    rep.heading("Configurations")
    lum = np.array([0.2126, 0.7152, 0.0722])
    rep.table(["configuration", "lighting / view"] + [f"Y mean, {n}" for n in mnames],
              [[c.name, c.label] + [fmt_num(float(means[ci, mi] @ lum)) if ok[ci, mi] else "-" for mi in range(len(mnames))]
               for ci, c in enumerate(configs)])
    sheet = [[images.get((c.name, n)) for n in mnames] for c in configs]
    rp.contact_sheet_png(sheet, [c.name for c in configs], mnames, out / "contact_sheet.png")
    rep.image("contact_sheet.png", "Every configuration (rows) by method (columns), sRGB previews")
    rep.heading("Per-image metrics against the reference")
    from .evaluate_runner import METRIC_HEADERS, metric_row, slug

    rep.table(METRIC_HEADERS[:6], [metric_row(l, per_image[l])[:6] for l in sorted(per_image)])
    for l in sorted(per_image):
        c, n = l.split("/", 1)
        name = f"maps/{slug(c)}__{slug(n)}.png"
        rp.error_map_png(images[(c, n[:-4])], images[(c, sweep.reference)], out / name, f"{l} vs {sweep.reference}")
        rep.image(name, f"{l}: per-pixel relative squared error against {sweep.reference}")
    rep.write(out)
