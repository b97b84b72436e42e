"""Sweeps: render methods over light and view configurations and compare them with a reference method.

``run_sweep`` writes for every (configuration, method) a derived scene
``DIR/renders/<config>/<method>.scene.toml`` and renders it through ``loomlight render`` (in
process) to ``DIR/renders/<config>/<method>.exr`` unless that image exists and its stamp
``<method>.stamp.json`` records the same scene text, method, arguments, loomlight version, the code that
decides the method's pictures (``pipeline.source_graph.render_code_version``: a change to its renderer
renders again) and content hashes of the files the scene refers to. Times per image come from the render artifact
beside the image (``<method>.zarr``), else from the wall time measured around the render call.
Method ``args`` may use ``{sweep_dir}`` (the sweep file's folder) and ``{out}`` (the output folder);
other relative paths are relative to the working directory. An argument naming an existing file or
artifact adds its content hash to the stamp, so a changed input (e.g. ``--fibers``) re-renders.
It then writes ``DIR/sweep.json``, ``DIR/metrics.json`` (per image against the reference
method's image of the same configuration), plots, ``DIR/report.md``/``.html`` and the
``evaluation`` artifact ``DIR/evaluation.zarr``.

The sweep file and its configurations: ``pipeline.runners.sweep_file``; the per-method numbers
and the report: ``pipeline.runners.sweep_report``.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import LoomError
from ..schemas import validate
from ..source_graph import render_code_version
from ..toml_file import dumps_toml
from .sweep_file import Configuration, Method, Sweep, derived_scene, load_sweep
from .sweep_report import SweepImages, summarize_methods, write_report


# ------------------------------------------------------------------------------------------------
# jobs: a derived scene and a render per (configuration, method), reused while its stamp holds
def referenced_files(raw: dict) -> dict[str, str]:
    from ..artifacts import content_hash

    files = {}
    paths = [raw.get("fabric", {}).get("path")] + [l.get("path") for l in raw.get("lights", [])
                                                   if l.get("type") == "envmap"]
    for p in paths:
        if p and Path(p).exists():
            files[p] = content_hash(p)
    return files


def known_methods() -> set[str]:
    """Render methods installed: the renderer registry's (``pipeline.renderers``)."""
    from ..renderers import known_methods as registered

    return set(registered())


def cli_render(scene_file: Path, method: str, exr: Path, args: list[str]) -> None:
    """``loomlight render SCENE --method M -o EXR [args]`` in this process."""
    import importlib.util

    if importlib.util.find_spec("pipeline.commands.render") is None:
        raise LoomError(scene_file, None, "this loomlight has no 'render' command (the renderers are not installed)")
    from ..cli import main

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


def substitute(args: list[str], places: dict[str, Path]) -> list[str]:
    """``args`` with each ``{name}`` of ``places`` replaced by that absolute directory; an argument that had
    one is normalised lexically, so ``{out}/../fibers.zarr`` names the same file (and hashes the same in
    a key) before and after ``{out}`` is created (``Path.exists`` of ``out/..`` is False while ``out`` is not
    there)."""
    dirs = {f"{{{k}}}": str(Path(v).resolve()) for k, v in places.items()}
    out = []
    for a in args:
        b = a
        for k, v in dirs.items():
            b = b.replace(k, v)
        out.append(os.path.normpath(b) if b != a else a)
    return out


def expand_args(sweep: Sweep, out: Path, args: list[str]) -> list[str]:
    return substitute(args, {"sweep_dir": sweep.path.parent, "out": out})


def arg_hashes(args: list[str]) -> dict[str, str]:
    from ..artifacts import content_hash

    out = {}
    for a in args:
        # a path, or a --set KEY=PATH option (prt's svf= and iirtf=, bysdf's yarns=): a render is stale
        # once the artifact it reads changes
        for p in (a, a.split("=", 1)[1]) if "=" in a else (a,):
            try:
                if p and Path(p).exists():
                    out[p] = content_hash(p)
            except (LoomError, OSError, ValueError):
                continue
    return out


def key_text(doc: dict) -> str:
    """The stamp key's text: compact JSON with sorted keys (the form of ``pipeline.artifacts`` keys; the
    document holds only strings, lists and dicts of them)."""
    return json.dumps(doc, sort_keys=True, separators=(",", ":"))


def _jobs(sweep: Sweep, out: Path) -> list[Job]:
    from .. import __version__

    jobs = []
    for _i, c in enumerate(sweep.configurations):
        for m in sweep.methods:
            raw = derived_scene(sweep, c, m)
            validate(raw, "scene", sweep.path, prefix=f"configuration {c.name!r}, method {m.name!r}: ")
            text = (f"# derived by loomlight evaluate --sweep {sweep.path.name}: scene {sweep.scene_path.name}, "
                    f"configuration {c.name}, method {m.name}\n" + dumps_toml(raw))
            args = expand_args(sweep, out, m.args)
            key = hashlib.sha256(key_text({"scene": text, "method": m.method, "args": args, "version": __version__,
                                            "code": render_code_version(m.method),
                                            "files": {**referenced_files(raw),
                                                      **arg_hashes(args)}}).encode()).hexdigest()
            d = out / "renders" / c.name
            jobs.append(Job(c, m, d / f"{m.name}.scene.toml", d / f"{m.name}.exr", d / f"{m.name}.stamp.json", key,
                            text, args))
    return jobs


def _stamp(job: Job) -> dict | None:
    try:
        st = json.loads(job.stamp.read_text())
    except (OSError, ValueError):
        return None
    return st if st.get("key") == job.key and job.exr.exists() else None


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
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from .. import report as rp
    from ..progress import progress

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
    from ..report import write_text

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

    got = gather_images(sweep, jobs, out, render)
    configs, mnames, means, times, per_image = got.configs, got.method_names, got.means, got.times, got.per_image
    C = len(configs)
    methods = summarize_methods(mnames, sweep.reference, means, times, per_image, [c.name for c in configs])
    params = {"mode": "sweep", "sweep": sweep.name, "reference": sweep.reference, "methods": mnames,
              "configurations": [c.name for c in configs]}
    from ..artifacts import ArtifactWriter

    writer = ArtifactWriter(out / "evaluation.zarr", kind="evaluation", stage="evaluate", params=params,
                            inputs=got.inputs, started=t_start)
    md, ht = out / "report.md", out / "report.html"
    if not force and rendered == 0 and writer.up_to_date() and md.exists() and ht.exists():
        return SweepResult(out, C, methods, 0, reused, md, ht)

    doc = {"sweep": sweep.name, "scene": str(sweep.scene_path), "reference": sweep.reference,
           "configurations": [{"name": c.name, "description": c.label,
                               "mean_intensity": {n: (means[ci, mi].tolist() if not np.isnan(means[ci, mi, 0])
                                                      else None)
                                                  for mi, n in enumerate(mnames)},
                               "time_s": {n: (float(times[ci, mi]) if not np.isnan(times[ci, mi]) else None)
                                          for mi, n in enumerate(mnames)}}
                              for ci, c in enumerate(configs)],
           "methods": methods}
    rp.write_text(out / "sweep.json", json.dumps(doc, indent=2) + "\n")
    rp.write_text(out / "metrics.json", json.dumps(per_image, indent=2, sort_keys=True) + "\n")
    write_report(sweep, out, got, methods)

    with writer as w:
        w.write("mean_intensity", means, dimension_names=("configuration", "method", "channel"))
        w.write("time_per_image_s", times, dimension_names=("configuration", "method"))
        w.summary.update(kind="evaluation", mode="sweep", reference=sweep.reference, methods=methods,
                         tests=per_image, metrics=["rmse_mean_intensity", "time_per_image_s", "speedup"])
    return SweepResult(out, C, methods, rendered, reused, md, ht, images=per_image)


def gather_images(sweep: Sweep, jobs: list[Job], out: Path, render: bool) -> SweepImages:
    """The images to compare: a configuration counts when its reference and at least one method exist
    (rendered with a valid stamp; with ``render`` off, any image on disk)."""
    from stages.evaluate.metrics import mean_intensity

    from .evaluate import check_pair, image_metrics, load_image, render_stats

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
            t = st.get("time_s", stamp.get("measured_wall_time_s"))  # render time, compilation excluded
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
    return SweepImages(configs, mnames, means, times, per_image, images, inputs)
