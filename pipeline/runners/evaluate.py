"""Evaluate runner: test images against a reference image, metrics + pictures + report + artifact.

``evaluate_images(ref, tests, out_dir)`` reads linear EXRs, computes per test image (kernels in
``stages.evaluate.metrics``)

- ``rmse``: over all pixels and channels of the linear images;
- ``relmse``: mean of (t - r)^2 / (r^2 + 0.01) over pixels and channels;
- ``ssim``: Wang et al. 2004 with an 11x11 Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03, on
  the sRGB-encoded luminance clipped to [0, 1] (what the PNG preview shows), dynamic range L = 1;
- ``delta_e2000_mean``: mean CIEDE2000 over pixels, linear sRGB clipped to [0, 1] -> XYZ -> Lab (D65);
- ``mean_intensity``: per-channel image mean (seed 001 §6.3),

and, when a render artifact ``<image>.zarr`` lies beside an image, the render's resolution, samples
per pixel (asked and traced, with adaptive sampling), render time *excluding numba compilation*
(``time_s``; compilation, loading and the source build reported apart: ``compile_s``,
``wall_time_s``), peak memory, paths per second and convergence (relative standard error of the
pixels, ``pipeline.renderers.film.convergence``) from its summary, plus the speed-up over the
reference (render times) where both are known. Against the reference every test gets
``brightness_ratio`` (its mean intensity over the reference's, per channel) and
``brightness_mismatch`` (a channel off by more than ``BRIGHTNESS_TOLERANCE``), and, where both
images carry a variance channel, ``noise_rmse`` (the RMSE that Monte Carlo noise alone would give,
sqrt of the mean summed variance of the two pixel means) and ``noise_dominated`` (noise_rmse over
half the measured RMSE: the per-pixel metrics then measure noise, not the methods; the report says so).

Outputs in ``out_dir``: ``metrics.json`` ({test name: {metric: value}}), ``images.png`` (the full
images side by side, one exposure), ``error_<name>.png``,
``crops_<name>.png``, ``metrics.png``, ``report.md``, ``report.html`` and the ``evaluation``
artifact ``evaluation.zarr`` (metrics as summary; input EXR and render artifact content hashes as
provenance). An evaluation whose inputs are unchanged is not recomputed unless ``force``.

The pieces (``load_image``, ``render_stats``, ``image_metrics``, ``check_pair``, ``metric_row``) serve
the other evaluate modes too: Table 1 (``pipeline.runners.table1``) and sweeps (``pipeline.runners.sweep``).
"""
from __future__ import annotations

import json
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import LoomError

METRIC_KEYS = ("rmse", "relmse", "ssim", "delta_e2000_mean")
BRIGHTNESS_TOLERANCE = 0.10   # a test whose mean intensity differs by more in a channel is flagged
NOISE_FRACTION = 0.5          # noise_rmse above this fraction of the RMSE: the metrics measure noise
SSIM_NOTE = ("SSIM: Wang et al. 2004, 11x11 Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03, on sRGB-encoded "
             "luminance clipped to [0, 1] (dynamic range L = 1). relMSE: mean of (t - r)^2 / (r^2 + 0.01). "
             "CIEDE2000: linear sRGB clipped to [0, 1] -> XYZ -> Lab (D65), mean over pixels.")


# ------------------------------------------------------------------------------------------------
# inputs
def load_image(path: str | Path) -> np.ndarray:
    """Linear RGB float64 (H, W, 3) from an EXR; refuses non-finite pixels."""
    from ..images import read_exr

    path = Path(path)
    if path.is_dir():
        raise LoomError(path, None, "is a directory, expected an OpenEXR image")
    rgb, _ = read_exr(path)
    bad = ~np.isfinite(rgb)
    if bad.any():
        i, j, _ = np.argwhere(bad)[0]
        raise LoomError(path, f"pixel (x={j}, y={i})", "not a finite number (NaN or inf)")
    return rgb.astype(np.float64)


def _first(d: dict, *keys):
    for k in keys:
        v = d.get(k)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return v
    return None


def render_stats(image: str | Path) -> dict:
    """Timing and memory of the render that made ``image``, from ``<image stem>.zarr`` beside it.

    Tolerant: a missing or incomplete artifact, or missing keys, give fewer entries (never an error).
    Keys: wall_time_s (the render command's wall time), render_time_s (time in the render kernels),
    peak_memory_bytes, spp, paths_per_s, render_artifact.
    """
    from ..artifacts import read_meta

    art = Path(image).with_suffix(".zarr")
    if not art.is_dir():
        return {}
    try:
        meta = read_meta(art)
        summary = json.loads((art / "zarr.json").read_text()).get("attributes", {}).get("summary", {}) or {}
    except (LoomError, OSError, ValueError):
        return {}
    out: dict = {"render_artifact": str(art)}

    def put(key, cast, *names, provenance=None):
        v = _first(summary, *names)
        if v is None and provenance:
            v = _first(meta, provenance)
        if v is not None:
            out[key] = cast(v)

    put("wall_time_s", float, "wall_time_s", "render_time_s", "time_s", provenance="wall_time_s")
    put("render_time_s", float, "render_time_s")
    put("peak_memory_bytes", int, "peak_memory_bytes", "memory_bytes", provenance="peak_memory_bytes")
    put("spp", int, "spp")
    put("paths_per_s", float, "paths_per_s", "paths_per_second")
    w, h = _first(summary, "width"), _first(summary, "height")
    if w is not None and h is not None:
        out["resolution"] = [int(w), int(h)]
        paths = _first(summary, "paths")
        if paths is not None and w * h > 0:
            out["samples_per_pixel"] = float(paths) / (w * h)
    ms = summary.get("method_stats") if isinstance(summary.get("method_stats"), dict) else {}
    cs = _first(ms, "compile_s")
    if cs is not None:
        out["compile_s"] = float(cs)
    if isinstance(ms.get("convergence"), dict):
        out["convergence"] = ms["convergence"]
    t = out.get("render_time_s", out.get("wall_time_s"))
    if t is not None:
        out["time_s"] = float(t)
    return out


def load_variance(path: str | Path) -> np.ndarray | None:
    """The image's ``variance`` channel (variance of each pixel's mean), None where it has none."""
    from ..images import read_exr

    try:
        _, ch = read_exr(path)
    except LoomError:
        return None
    v = ch.get("variance")
    return None if v is None or not np.all(np.isfinite(v)) else np.asarray(v, np.float64)


def agreement(test: np.ndarray, ref: np.ndarray, rmse: float, var_test=None, var_ref=None) -> dict:
    """Brightness ratio and mismatch flag of a test against the reference; the noise RMSE and whether
    noise dominates the per-pixel metrics where both variance channels are known (module doc)."""
    from stages.evaluate.metrics import mean_intensity

    mt, mr = np.asarray(mean_intensity(test), float), np.asarray(mean_intensity(ref), float)
    ratio = mt / np.maximum(mr, 1e-12)
    out = {"brightness_ratio": [float(v) for v in ratio],
           "brightness_mismatch": bool(np.any(np.abs(ratio - 1.0) > BRIGHTNESS_TOLERANCE))}
    if var_test is not None and var_ref is not None and var_test.shape == var_ref.shape == test.shape[:2]:
        noise = float(np.sqrt(np.mean(var_test + var_ref)))
        out["noise_rmse"] = noise
        out["noise_dominated"] = bool(noise > NOISE_FRACTION * rmse)
    return out


def labels_for(paths: Sequence[Path]) -> list[str]:
    """Test names: file names, or paths relative to their common folder where names repeat."""
    names = [p.name for p in paths]
    if len(set(names)) == len(names):
        return names
    resolved = [p.resolve() for p in paths]
    common = Path(*[parts[0] for parts in zip(*[r.parts for r in resolved]) if len(set(parts)) == 1]) \
        if len(resolved) > 1 else resolved[0].parent
    labels = [str(r.relative_to(common)) if r.is_relative_to(common) else str(r) for r in resolved]
    if len(set(labels)) != len(labels):
        raise LoomError(None, "--test", "the same test image is given twice")
    return labels


def slug(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label.rsplit(".", 1)[0] if label.endswith(".exr") else label)


# ------------------------------------------------------------------------------------------------
# metrics
def image_metrics(test: np.ndarray, ref: np.ndarray) -> dict:
    from stages.evaluate import metrics as m

    return {
        "rmse": m.rmse(test, ref),
        "relmse": m.relmse(test, ref),
        "ssim": m.ssim(m.ssim_input(test), m.ssim_input(ref)),
        "delta_e2000_mean": float(np.mean(m.delta_e2000_map(test, ref))),
        "mean_intensity": [float(v) for v in m.mean_intensity(test)],
    }


def check_pair(ref_path: Path, ref: np.ndarray, test_path: Path, test: np.ndarray) -> None:
    from stages.evaluate.metrics import SSIM_WINDOW

    if test.shape != ref.shape:
        raise LoomError(test_path, None, f"image is {test.shape[1]}x{test.shape[0]} pixels but the reference "
                                         f"{ref_path.name} is {ref.shape[1]}x{ref.shape[0]}")
    if ref.shape[0] < SSIM_WINDOW or ref.shape[1] < SSIM_WINDOW:
        raise LoomError(ref_path, None, f"image is {ref.shape[1]}x{ref.shape[0]} pixels; SSIM needs at least "
                                        f"{SSIM_WINDOW}x{SSIM_WINDOW}")


# ------------------------------------------------------------------------------------------------
@dataclass
class Evaluation:
    out_dir: Path
    metrics: dict
    reference: dict
    report_md: Path
    report_html: Path
    skipped: bool = False
    pictures: list[Path] = field(default_factory=list)


def evaluate_images(ref_path: str | Path, test_paths: Sequence[str | Path], out_dir: str | Path,
                    force: bool = False, title: str | None = None) -> Evaluation:
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from .. import report as rp
    from ..artifacts import FILE, ArtifactWriter

    ref_path = Path(ref_path)
    test_paths = [Path(p) for p in test_paths]
    out_dir = Path(out_dir)
    if not test_paths:
        raise LoomError(None, "--test", "give at least one test image")
    if out_dir.exists() and not out_dir.is_dir():
        raise LoomError(out_dir, None, "output path exists and is not a directory")
    labels = labels_for(test_paths)
    for p in [ref_path, *test_paths]:
        if not p.exists():
            raise LoomError(p, None, "file not found")

    ref_stats = render_stats(ref_path)
    test_stats = [render_stats(p) for p in test_paths]
    inputs: dict[str, tuple] = {"reference": (ref_path, FILE)}
    if "render_artifact" in ref_stats:
        inputs["reference_render"] = (Path(ref_stats["render_artifact"]), "render")
    for lab, p, st in zip(labels, test_paths, test_stats):
        inputs[f"test:{lab}"] = (p, FILE)
        if "render_artifact" in st:
            inputs[f"render:{lab}"] = (Path(st["render_artifact"]), "render")
    params = {"mode": "images", "labels": labels, "relmse_eps": 0.01,
              "ssim": {"window": 11, "sigma": 1.5, "K1": 0.01, "K2": 0.03, "on": "srgb_luminance", "L": 1.0},
              "delta_e": {"formula": "CIE 2000", "input": "linear sRGB clipped to [0, 1]", "white": "D65"}}
    writer = ArtifactWriter(out_dir / "evaluation.zarr", kind="evaluation", stage="evaluate",
                            params=params, inputs=inputs, started=t_start)
    md, ht = out_dir / "report.md", out_dir / "report.html"
    if not force and writer.up_to_date() and (out_dir / "metrics.json").exists() and md.exists() and ht.exists():
        metrics = json.loads((out_dir / "metrics.json").read_text())
        return Evaluation(out_dir, metrics, ref_stats, md, ht, skipped=True)

    ref = load_image(ref_path)
    tests = []
    for p in test_paths:  # every input checked before anything is written
        tests.append(load_image(p))
        check_pair(ref_path, ref, p, tests[-1])
    metrics: dict[str, dict] = {}
    rel_maps = []
    pictures: list[Path] = []
    rep = rp.Report(title or f"Evaluation against {ref_path.name}")
    var_ref = load_variance(ref_path)
    for lab, p, st, test in zip(labels, test_paths, test_stats, tests):
        entry = image_metrics(test, ref)
        entry.update(agreement(test, ref, entry["rmse"], load_variance(p), var_ref))
        entry.update({k: v for k, v in st.items() if k != "render_artifact"})
        if "time_s" in st and "time_s" in ref_stats and st["time_s"] > 0:
            entry["speedup_vs_reference"] = ref_stats["time_s"] / st["time_s"]
        metrics[lab] = entry
        rel_maps.append(rp.relative_error(test, ref).astype(np.float32))
        s = slug(lab)
        pictures.append(rp.error_map_png(test, ref, out_dir / f"error_{s}.png", f"{lab} vs {ref_path.name}"))
        pictures.append(rp.crops_png(ref, test, out_dir / f"crops_{s}.png", lab))
    from stages.evaluate.metrics import mean_intensity

    ref_entry = {"name": ref_path.name, "mean_intensity": [float(v) for v in mean_intensity(ref)],
                 **{k: v for k, v in ref_stats.items() if k != "render_artifact"}}
    pictures.append(rp.metric_bars_png(metrics, out_dir / "metrics.png", f"against {ref_path.name}"))
    pictures.append(rp.side_by_side_png([ref, *tests], [f"{ref_path.name} (reference)", *labels],
                                        out_dir / "images.png"))

    # metrics.json, report
    rp.write_text(out_dir / "metrics.json", json.dumps(metrics, indent=2, sort_keys=True) + "\n")
    _images_report(rep, ref_path, ref_entry, metrics, labels)
    md, ht = rep.write(out_dir)

    # the evaluation artifact, last: it marks a finished evaluation
    with writer as w:
        w.write("mean_intensity",
                np.array([ref_entry["mean_intensity"]] + [metrics[l]["mean_intensity"] for l in labels]),
                dimension_names=("image", "channel"))
        w.write("relative_error", np.stack(rel_maps), dimension_names=("test", "y", "x"))
        w.summary.update(kind="evaluation", mode="images", reference=ref_entry, tests=metrics,
                         image_size=[int(ref.shape[1]), int(ref.shape[0])], metrics=list(METRIC_KEYS))
    return Evaluation(out_dir, metrics, ref_entry, md, ht, pictures=pictures)


def metric_row(label: str, e: dict) -> list[str]:
    from ..report import fmt_bytes, fmt_num, fmt_seconds

    sp = e.get("speedup_vs_reference")
    return [label, fmt_num(e.get("rmse")), fmt_num(e.get("relmse")), fmt_num(e.get("ssim")),
            fmt_num(e.get("delta_e2000_mean")), fmt_seconds(e.get("time_s", e.get("wall_time_s"))),
            f"{sp:.2f}x" if sp is not None else "-", fmt_bytes(e.get("peak_memory_bytes"))]


METRIC_HEADERS = ["image", "RMSE", "relMSE", "SSIM", "mean ΔE00", "render time", "speed-up", "peak memory"]
IMAGE_HEADERS = ["image", "resolution", "spp (traced)", "mean R, G, B", "ratio to reference", "render time",
                 "compile", "pixel rel. error p50 / p95"]


def image_row(label: str, e: dict, reference: bool = False) -> list[str]:
    """One image's line: resolution, samples, mean intensity, brightness ratio, times, convergence."""
    from ..report import fmt_seconds

    res = e.get("resolution")
    spp = e.get("spp")
    traced = e.get("samples_per_pixel")
    spp_s = "-" if spp is None else (f"{spp} ({traced:.1f})" if traced is not None and abs(traced - spp) > 1e-9
                                     else f"{spp}")
    mean = ", ".join(f"{v:.4f}" for v in e.get("mean_intensity", []))
    ratio = "1 (reference)" if reference else ", ".join(f"{v:.3f}" for v in e.get("brightness_ratio", []))
    if e.get("brightness_mismatch"):
        ratio += " **MISMATCH**"
    conv = e.get("convergence") or {}
    conv_s = f"{conv['rel_error_p50']:.3f} / {conv['rel_error_p95']:.3f}" if "rel_error_p50" in conv else "-"
    return [label, f"{res[0]}x{res[1]}" if res else "-", spp_s, mean or "-", ratio,
            fmt_seconds(e.get("time_s")), fmt_seconds(e.get("compile_s")), conv_s]


def _images_report(rep, ref_path: Path, ref_entry: dict, metrics: dict, labels: list[str]) -> None:
    from ..report import fmt_bytes, fmt_seconds

    rep.paragraph(f"Reference: {ref_path} (render time {fmt_seconds(ref_entry.get('time_s'))} excluding "
                  f"compilation, peak memory {fmt_bytes(ref_entry.get('peak_memory_bytes'))}).")
    rep.heading("Images")
    rep.table(IMAGE_HEADERS, [image_row(ref_path.name, ref_entry, reference=True)]
              + [image_row(l, metrics[l]) for l in labels],
              caption="Render time excludes numba compilation (compile column: compiling or loading the kernels). "
                      "spp: samples asked per pixel, traced in brackets where adaptive sampling added some. "
                      "Pixel rel. error: relative standard error of the pixels' means (50th / 95th percentile).")
    rep.image("images.png", "The full images side by side, one exposure")
    flags = [f"**Brightness mismatch**: {l} differs from the reference by more than "
             f"{BRIGHTNESS_TOLERANCE:.0%} in mean intensity (ratios "
             f"{', '.join(f'{v:.3f}' for v in metrics[l]['brightness_ratio'])})." for l in labels
             if metrics[l].get("brightness_mismatch")]
    flags += [f"**Noise dominates** {l}: Monte Carlo noise alone would give an RMSE of "
              f"{metrics[l]['noise_rmse']:.4g} against the measured {metrics[l]['rmse']:.4g}; its per-pixel "
              f"metrics (RMSE, relMSE, SSIM, ΔE) measure noise more than the methods. Render more samples."
              for l in labels if metrics[l].get("noise_dominated")]
    for f in flags or ["Every test agrees with the reference in mean intensity within "
                       f"{BRIGHTNESS_TOLERANCE:.0%} per channel, and no test's per-pixel metrics are dominated "
                       "by noise "
                       "(where variance channels tell)."]:
        rep.paragraph(f)
    rep.paragraph(SSIM_NOTE)
    rep.heading("Metrics")
    rep.table(METRIC_HEADERS, [metric_row(l, metrics[l]) for l in labels])
    rep.image("metrics.png", "Metrics per test image")
    rep.heading("Error maps and crops")
    for l in labels:
        s = slug(l)
        rep.image(f"error_{s}.png", f"{l}: per-pixel relative squared error (log scale)")
        rep.image(f"crops_{s}.png", f"{l}: reference | test | error, at the worst window")
