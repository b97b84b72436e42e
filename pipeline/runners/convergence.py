"""Equal-error comparison: every method against a converged reference, error against time.

``loomlight evaluate --convergence FILE.toml -o DIR`` (``run_convergence``) answers "which method
gives the right picture fastest" for one scene (the comparison file: ``pipeline.runners.compare_file``):

1. **The reference** (``build_reference``): the reference method's picture from K independent batches
   (seeds ``REFERENCE_SEED + k``, ``[reference] spp`` samples each), more batches until the median
   relative standard error over cloth pixels and the relative standard error of the cloth's mean are
   within their targets (or ``max_batches``). Published as a ``render`` artifact ``reference.zarr``
   with ``reference.exr`` / ``.png`` and the relative standard error map ``reference_error.png``; its
   per-channel variance of the mean is in ``channels/variance_r|g|b``, the batches' count, spp, time
   and noise in ``summary.reference``. Its path depth is checked too (``depth_check``): batch 0's seed
   rendered again at ``DEPTH_CHECK_FACTOR`` times ``render.max_depth`` follows the same paths further, so
   the ratio of the two cloth means (per channel) is the share of the light the depth keeps; below
   ``1 - DEPTH_TOLERANCE`` the reference is flagged as truncated (printed and reported). It is keyed
   (``reference_key``) by the derived scene, the
   method and its arguments, the batch settings, the input artifacts' content and the *code version*
   (``render_code_version``: the kernels, the renderer's setup and the presets that the reference method's
   renderer imports): an existing
   reference with the same key is reused, never re-rendered; one with another key is refused (exit
   2, naming what differs) unless it is being rebuilt (``--reference-only``, ``make references``).
   Default place ``DIR/reference/reference.zarr``; ``--ref PATH`` names another.
2. **The runs**: every method at each of its budgets (seeds ``1 + j``, never a reference seed), under
   ``DIR/renders/<method>/<budget>.exr``; reused while their stamp (scene text, method, arguments,
   version, inputs) holds, like sweeps. Per run the error E of ``stages.evaluate.convergence`` (relative
   RMSE over cloth pixels, the reference's noise subtracted, with its uncertainty), the per-channel mean
   ratio, SSIM, and the render time from the render artifact (kernels only; compilation apart).
3. **The fit** per method, E(t)^2 = b^2 + c / t: its bias floor b against the fibres, its noise constant
   c, the time to reach each level of ``[compare] levels`` (measured points; the fit only interpolates)
   and the speed-up over the reference method at equal error. Where the floor is above a level, the
   report says so and splits the floor into its mean-brightness part (per channel; what rescaling the
   picture by the reference's mean removes) and the rest (structure).
4. **The equal-time strip**: every method at the time the reference method spends on
   ``equal_time_spp`` samples per pixel (its seconds per sample from its largest run), beside the
   reference, with error maps.
5. **Memory**: each method's peak memory, from one render of its smallest budget in a process of
   its own (``--no-memory`` skips it), and its geometry memory: what its setup reports
   (``geometry_bytes``), else the array bytes of the artifacts it loads.

Outputs: ``DIR/convergence.json``, ``DIR/convergence.png`` (log-log error against time, a line per
method, points measured with their uncertainty, floor dashed), ``DIR/equal_time.png``,
``DIR/report.md`` / ``.html`` and the ``evaluation`` artifact ``DIR/evaluation.zarr`` (mode
``convergence``). Targets (``methods[].target_speedup``) are printed and reported, met or not.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import LoomError
from ..memory import peak_rss_bytes
from ..source_graph import render_code_version
from ..toml_file import dumps_toml
from .compare_file import CompareMethod, Comparison, derived_scene, load_comparison
from .sweep import arg_hashes, cli_render, key_text, referenced_files, substitute

REFERENCE_SEED = 1_000_000      # batch k renders with seed REFERENCE_SEED + k; runs use seeds 1, 2, ...
EQUAL_TIME_SEED = 500_000       # the equal-time strip's renders
MEMORY_SEED = 700_000           # the peak-memory render in a process of its own
DEPTH_CHECK_FACTOR = 4          # the depth check renders batch 0 again at this many times render.max_depth
DEPTH_TOLERANCE = 0.002         # light a reference may lose to its path depth: the cloth mean's noise target
Renderer = Callable[[Path, str, Path, list], None]


# ------------------------------------------------------------------------------------------------
# keys
def expand(cmp: Comparison, out: Path, args: list) -> list[str]:
    return substitute(args, {"compare_dir": cmp.path.parent, "out": out})


def scene_text(cmp: Comparison, raw: dict, what: str) -> str:
    return (f"# derived by loomlight evaluate --convergence {cmp.path.name}: scene {cmp.scene_path.name}, {what}\n"
            + dumps_toml(raw))


def reference_key(cmp: Comparison, out: Path) -> dict:
    """What the reference depends on, in parts (so a mismatch can say which part differs)."""
    from .. import __version__

    m = cmp.method(cmp.reference)
    raw = derived_scene(cmp, m, cmp.settings.spp, 0)
    raw["render"].pop("seed")
    raw["render"]["max_spp"] = 0
    args = expand(cmp, out, m.args)
    scene = key_text({"scene": raw, "method": m.method, "args": args})
    return {"scene": hashlib.sha256(scene.encode()).hexdigest()[:16], "scene_name": cmp.scene_path.name,
            "inputs": hashlib.sha256(key_text({**referenced_files(raw), **arg_hashes(args)}).encode()).hexdigest()[:16],
            "settings": key_text({"spp": cmp.settings.spp, "pixel_error": cmp.settings.pixel_error,
                                   "mean_error": cmp.settings.mean_error}),
            "code": render_code_version(m.method), "version": __version__}


KEY_WHAT = {"scene": "another scene or settings of it (camera, lights, method, arguments)",
            "scene_name": "another scene file", "inputs": "other input artifacts (fibres, tables, precomputes)",
            "settings": "other batch settings", "code": "another code version", "version": "another loomlight version"}


# ------------------------------------------------------------------------------------------------
# rendering one picture, reused while its stamp holds
@dataclass
class Run:
    method: str
    budget: int
    exr: Path
    error: object = None          # stages.evaluate.convergence.PictureError
    time_s: float | None = None
    spp: float | None = None
    ssim: float | None = None
    stats: dict = field(default_factory=dict)


def render_once(cmp: Comparison, m: CompareMethod, out: Path, exr: Path, raw: dict, what: str,
                renderer: Renderer, force: bool = False, where: tuple = ()) -> bool:
    """Render ``raw`` to ``exr`` unless its stamp says the same render is there; True when rendered.
    ``where``: ``--scheduler`` arguments, not part of the stamp (a render's bytes do not depend on them)."""
    from .. import __version__
    from ..report import write_text

    args = expand(cmp, out, m.args)
    text = scene_text(cmp, raw, what)
    key = hashlib.sha256(key_text({"scene": text, "method": m.method, "args": args, "version": __version__,
                                    "code": render_code_version(m.method),
                                    "files": {**referenced_files(raw), **arg_hashes(args)}}).encode()).hexdigest()
    stamp = exr.with_suffix(".stamp.json")
    if not force and exr.exists():
        try:
            if json.loads(stamp.read_text()).get("key") == key:
                return False
        except (OSError, ValueError):
            pass
    scene_file = exr.with_suffix(".scene.toml")
    write_text(scene_file, text)
    stamp.unlink(missing_ok=True)
    renderer(scene_file, m.method, exr, list(args) + list(where))
    write_text(stamp, json.dumps({"key": key, "method": m.method, "args": args}, indent=2) + "\n")
    return True


def _render_time(exr: Path) -> tuple[float, dict]:
    from .evaluate import render_stats

    st = render_stats(exr)
    if "time_s" not in st:
        raise LoomError(exr.with_suffix(".zarr"), "summary.render_time_s", "the render artifact has no render time")
    return float(st["time_s"]), st


# ------------------------------------------------------------------------------------------------
# the reference
@dataclass
class Reference:
    path: Path                    # reference.zarr
    rgb: np.ndarray
    variance: np.ndarray          # (H, W, 3) variance of the pixel means
    alpha: np.ndarray
    batches: int
    summary: dict
    reused: bool = False


def default_reference_path(out: Path) -> Path:
    return out / "reference" / "reference.zarr"


def load_reference(path: Path, key: dict | None) -> Reference:
    """The reference artifact at ``path``; with ``key``, refused (exit 2) when made for another key."""
    from ..artifacts import Artifact

    art = Artifact(path, kind="render")
    ref = art.summary.get("reference")
    if not isinstance(ref, dict) or "key" not in ref:
        raise LoomError(path, "summary.reference", "a render artifact, not a converged reference (make one with "
                        "loomlight evaluate --convergence FILE --reference-only)")
    if key is not None:
        for part, want in key.items():
            got = ref["key"].get(part)
            if got != want:
                raise LoomError(path, f"summary.reference.key.{part}",
                                f"this reference was made for {KEY_WHAT.get(part, part)} ({got!r}, this comparison "
                                f"needs {want!r}); rebuild it: loomlight evaluate --convergence FILE --reference-only "
                                f"(make references)")
    var = np.stack([np.asarray(art[f"channels/variance_{c}"], np.float64) for c in "rgb"], axis=2)
    return Reference(path, np.asarray(art["image"], np.float64), var, np.asarray(art["channels/A"], np.float64),
                     int(ref["batches"]), dict(art.summary))


def build_reference(cmp: Comparison, out: Path, ref_path: Path, renderer: Renderer, rebuild: bool,
                    echo: Callable[[str], None], where: tuple = ()) -> Reference:
    """Reuse the reference at ``ref_path`` when its key matches; else (``rebuild``, or none there)
    render batches until the noise targets hold, and publish it (module doc, 1)."""
    from stages.evaluate.convergence import LUMA, batch_mean, reference_noise

    from ..artifacts import FILE, ArtifactWriter
    from ..images import read_exr, write_render
    from ..progress import progress

    key = reference_key(cmp, out)
    if (ref_path / "zarr.json").exists():
        try:
            r = load_reference(ref_path, key)
            short = not r.summary["reference"]["targets_met"] and r.batches < cmp.settings.max_batches
            if not (rebuild and short):   # a rebuild goes on where a reference stopped short of its targets
                r.reused = True
                return r
        except LoomError:
            if not rebuild:
                raise
    t_start = time.perf_counter()
    s = cmp.settings
    m = cmp.method(cmp.reference)
    bdir = ref_path.parent / "batches"
    images, alphas, times, paths = [], [], [], 0
    k = 0
    target = s.batches
    noise = None
    while True:
        with progress(f"reference {cmp.name}: batches {k + 1}-{target} of {s.spp} spp", target - k) as advance:
            while k < target:
                raw = derived_scene(cmp, m, s.spp, REFERENCE_SEED + k)
                raw["render"]["max_spp"] = 0
                exr = bdir / f"batch_{k:04d}.exr"
                render_once(cmp, m, out, exr, raw, f"reference batch {k}", renderer, where=where)
                rgb, ch = read_exr(exr)
                images.append(np.asarray(rgb, np.float64))
                alphas.append(np.asarray(ch.get("A", np.ones(rgb.shape[:2])), np.float64))
                t, st = _render_time(exr)
                times.append(t)
                paths += int(st.get("samples_per_pixel", s.spp) * rgb.shape[0] * rgb.shape[1])
                k += 1
                advance()
        stats = batch_mean(images)
        alpha = np.mean(alphas, axis=0)
        noise = reference_noise(stats.mean, stats.variance, alpha)
        met = noise.pixel_median <= s.pixel_error and noise.mean <= s.mean_error
        echo(f"reference {cmp.name}: {k} batches x {s.spp} spp: pixel error p50 {noise.pixel_median:.4f} "
             f"(target {s.pixel_error}), mean {noise.mean:.5f} (target {s.mean_error})")
        if met or k >= s.max_batches:
            break
        need = k * max((noise.pixel_median / s.pixel_error) ** 2, (noise.mean / s.mean_error) ** 2) * 1.1
        target = int(min(s.max_batches, max(k + 1, math.ceil(need))))
    depth = depth_check(cmp, out, bdir, images[0], alpha, renderer, where)
    echo(f"reference {cmp.name}: path depth {depth['max_depth']} keeps "
         + " / ".join(f"{v:.4f}" for v in depth["kept_rgb"]) + f" of the light at depth {depth['check_depth']}"
         + (" -- TRUNCATED: raise [compare] render.max_depth" if depth["truncated"] else ""))
    H, W = alpha.shape
    rgb = stats.mean.astype(np.float32)
    var_mean = stats.variance.mean(axis=2).astype(np.float32)
    render_s = float(sum(times))
    rel_se = np.sqrt(stats.variance.mean(axis=2)) / np.maximum(stats.mean @ LUMA, 1e-12)
    summary = {
        "kind": "render", "method": m.method, "width": int(W), "height": int(H), "spp": int(s.spp * k),
        "seed": REFERENCE_SEED, "wall_time_s": time.perf_counter() - t_start, "render_time_s": render_s,
        "paths": int(paths), "rays": 0, "paths_per_s": paths / max(render_s, 1e-12), "rays_per_s": 0.0,
        "peak_memory_bytes": peak_rss_bytes(), "threads": _threads(),
        "mean_rgb": [float(v) for v in rgb.reshape(-1, 3).mean(0)],
        "exr": str(ref_path.with_suffix(".exr")), "png": str(ref_path.with_suffix(".png")),
        "reference": {"key": key, "comparison": str(cmp.path), "method_name": m.name, "batches": int(k),
                      "spp_per_batch": int(s.spp), "render_time_s": render_s,
                      "pixel_error_p50": noise.pixel_median, "pixel_error_p95": noise.pixel_p95,
                      "mean_error": noise.mean, "targets": {"pixel_error": s.pixel_error, "mean_error": s.mean_error},
                      "targets_met": bool(met), "batch_seeds": [REFERENCE_SEED, REFERENCE_SEED + k - 1],
                      "depth_check": depth},
    }
    exr_path = ref_path.with_suffix(".exr")
    err_png = ref_path.parent / "reference_error.png"
    writer = ArtifactWriter(ref_path, kind="render", stage="render", params={"comparison": cmp.name, "key": key},
                            inputs={"comparison": (cmp.path, FILE), "scene": (cmp.scene_path, FILE)},
                            companions=(exr_path, ref_path.with_suffix(".png"), err_png), started=t_start)
    with writer as w:
        write_render(exr_path, rgb, {"A": alpha.astype(np.float32), "variance": var_mean}, into=w.companion)
        _error_png(w.companion(err_png), rel_se, alpha, f"reference {cmp.name}: relative standard error per pixel\n"
                   f"{k} batches x {s.spp} spp, median {noise.pixel_median:.3f} over the cloth")
        w.write("image", rgb, chunks=(min(H, 128), min(W, 128), 3), dimension_names=("y", "x", "c"))
        chans = {"A": alpha, "variance": var_mean, "rel_stderr": rel_se,
                 **{f"variance_{c}": stats.variance[..., i] for i, c in enumerate("rgb")}}
        for name, a in chans.items():
            w.write(f"channels/{name}", np.ascontiguousarray(a, np.float32), chunks=(min(H, 128), min(W, 128)),
                    dimension_names=("y", "x"))
        w.summary.update(summary)
    return load_reference(ref_path, key)


def depth_check(cmp: Comparison, out: Path, bdir: Path, first: np.ndarray, alpha: np.ndarray, renderer: Renderer,
                where: tuple = ()) -> dict:
    """How much light the reference's path depth keeps: batch 0 (``first``) against the same seed rendered at
    ``DEPTH_CHECK_FACTOR`` times the depth. Both follow the same random numbers up to the shallower depth (the
    samplers are indexed by pixel, sample and dimension), so their difference is the light of the deeper
    vertices alone, with little noise of its own. Per channel, over the cloth (alpha > 0.5)."""
    from ..images import read_exr
    from ..scene import RENDER_DEFAULTS

    m = cmp.method(cmp.reference)
    raw = derived_scene(cmp, m, cmp.settings.spp, REFERENCE_SEED)
    raw["render"]["max_spp"] = 0
    d = int(raw["render"].get("max_depth", RENDER_DEFAULTS["max_depth"]))
    raw["render"]["max_depth"] = d * DEPTH_CHECK_FACTOR
    exr = bdir / "depth_check.exr"
    render_once(cmp, m, out, exr, raw, f"depth check at {d * DEPTH_CHECK_FACTOR}", renderer, where=where)
    deep, _ = read_exr(exr)
    cloth = alpha > 0.5
    kept = [float(first[..., c][cloth].mean() / max(float(np.asarray(deep, np.float64)[..., c][cloth].mean()), 1e-30))
            for c in range(3)] if cloth.any() else [1.0, 1.0, 1.0]
    return {"max_depth": d, "check_depth": d * DEPTH_CHECK_FACTOR, "kept_rgb": kept,
            "truncated": bool(min(kept) < 1.0 - DEPTH_TOLERANCE)}


def _error_png(path: Path, rel_se: np.ndarray, alpha: np.ndarray, title: str) -> Path:
    from ..report import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.6), layout="constrained")
    im = ax.imshow(np.where(alpha > 0.5, rel_se, np.nan), cmap="magma", vmin=0.0, vmax=0.2)
    fig.colorbar(im, ax=ax, label="relative standard error (cloth pixels)")
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
    try:
        return save_figure(fig, path)
    finally:
        plt.close(fig)


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


# ------------------------------------------------------------------------------------------------
# the runs and the fit
def run_label(m: CompareMethod, budget: int) -> str:
    return f"{'spp' if m.budget == 'spp' else 'maxspp'}{budget:05d}"


def measure(run: Run, ref: Reference) -> Run:
    from stages.evaluate import metrics as mt
    from stages.evaluate.convergence import relative_error

    from .evaluate import check_pair, load_image

    img = load_image(run.exr)
    check_pair(ref.path.with_suffix(".exr"), ref.rgb, run.exr, img)
    run.error = relative_error(img, ref.rgb, ref.variance, ref.alpha, ref.batches)
    run.ssim = mt.ssim(mt.ssim_input(img), mt.ssim_input(ref.rgb))
    run.time_s, run.stats = _render_time(run.exr)
    run.spp = run.stats.get("samples_per_pixel", run.stats.get("spp"))
    return run


def brightness_part(img: np.ndarray, ref: Reference, e2: float) -> float:
    """The part of E^2 that a per-channel rescaling of the picture to the reference's cloth mean removes."""
    from stages.evaluate.convergence import cloth_mask, relative_error

    mask = cloth_mask(ref.alpha)
    scale = ref.rgb[mask].mean(0) / np.maximum(img[mask].mean(0), 1e-30)
    rescaled = relative_error(img * scale, ref.rgb, ref.variance, ref.alpha, ref.batches).e2
    return max(e2 - rescaled, 0.0)


def method_summary(cmp: Comparison, m: CompareMethod, runs: list[Run], ref: Reference) -> dict:
    from stages.evaluate.convergence import fit_bias_noise, time_to_error

    from .evaluate import load_image

    t = [r.time_s for r in runs]
    fit = fit_bias_noise(t, [r.error.e2 for r in runs], [r.error.e2_se for r in runs])
    errs = [r.error.error for r in runs]
    levels = {}
    for lv in cmp.levels:
        tt = time_to_error(lv, t, errs, fit)
        levels[f"{lv:g}"] = {"time_s": tt.time, "bound": tt.bound, "floor_blocks": tt.floor_blocks}
    last = runs[-1]
    bright = brightness_part(load_image(last.exr), ref, last.error.e2)
    return {
        "name": m.name, "method": m.method, "budget": m.budget,
        "floor": fit.floor, "floor_se": fit.floor_se, "b2": fit.b2, "noise_constant": fit.c,
        "noise_constant_se": fit.c_se,
        "levels": levels, "seconds_per_spp": last.time_s / max(float(last.spp or 1), 1e-12),
        "floor_terms": {"brightness_e2": bright, "structure_e2": max(last.error.e2 - bright, 0.0),
                        "mean_ratio": list(last.error.mean_ratio)},
        "runs": [{"budget": r.budget, "exr": str(r.exr), "time_s": r.time_s, "spp": r.spp, "error": r.error.error,
                  "e2": r.error.e2, "e2_se": r.error.e2_se, "raw_e2": r.error.raw_e2,
                  "ref_noise_e2": r.error.ref_noise_e2,
                  "mean_ratio": list(r.error.mean_ratio), "ssim": r.ssim} for r in runs],
    }


def add_speedups(cmp: Comparison, methods: dict) -> None:
    """Per method and level the reference method's time over the method's (``stages.evaluate.convergence.speedup``),
    and at the lowest level where both have a time: the headline speed-up at equal error."""
    from stages.evaluate.convergence import TimeToError, speedup

    def tte(s, lv):
        d = s["levels"][lv]
        return TimeToError(float(lv), d["time_s"], d["bound"], d["floor_blocks"])

    ref = methods[cmp.reference]
    for s in methods.values():
        s["speedup"] = {}
        best = None
        for lv in s["levels"]:
            v, bound = speedup(tte(ref, lv), tte(s, lv))
            s["speedup"][lv] = {"value": v, "bound": bound}
            if v is not None and bound != "~":
                best = (lv, v, bound)
        s["speedup_at_equal_error"] = ({"level": float(best[0]), "value": best[1], "bound": best[2]}
                                       if best else None)


# ------------------------------------------------------------------------------------------------
# memory
def geometry_bytes(cmp: Comparison, m: CompareMethod, out: Path, method_stats: dict) -> tuple[int | None, str]:
    """What the method keeps of the cloth: its setup's ``geometry_bytes``, else its input artifacts' arrays."""
    from ..artifacts import Artifact

    g = method_stats.get("geometry_bytes")
    if isinstance(g, (int, float)):
        return int(g), "setup"
    total, found = 0, False
    for a in expand(cmp, out, m.args):
        for p in (a.split("=", 1)[1], ) if "=" in a else (a,):
            if p.endswith(".zarr") and Path(p).is_dir():
                try:
                    total += Artifact(p).nbytes()
                    found = True
                except LoomError:
                    continue
    return (total, "input artifacts") if found else (None, "")


def peak_memory(cmp: Comparison, m: CompareMethod, out: Path) -> int | None:
    """Peak resident memory of one render of the method's smallest budget, in a process of its own."""
    d = out / "memory"
    d.mkdir(parents=True, exist_ok=True)
    raw = derived_scene(cmp, m, m.budgets[0], MEMORY_SEED)
    scene_file = d / f"{m.name}.scene.toml"
    from ..report import write_text

    write_text(scene_file, scene_text(cmp, raw, f"method {m.name}, peak memory"))
    exr = d / f"{m.name}.exr"
    cmd = [sys.executable, "-m", "pipeline.cli", "render", str(scene_file), "--method", m.method, "-o", str(exr),
           *expand(cmp, out, m.args)]
    p = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    if p.returncode != 0:
        raise LoomError(cmp.path, f"methods {m.name!r}", "the peak-memory render failed: "
                        + (p.stderr.strip().splitlines() or ["(no message)"])[-1])
    from .evaluate import render_stats

    return render_stats(exr).get("peak_memory_bytes")


# ------------------------------------------------------------------------------------------------
@dataclass
class ConvergenceResult:
    out_dir: Path
    reference: dict
    methods: dict
    targets: list
    rendered: int
    report_md: Path | None
    report_html: Path | None


def run_convergence(path: str | Path, out_dir: str | Path, ref_path: str | Path | None = None,
                    reference_only: bool = False, force: bool = False, memory: bool = True,
                    renderer: Renderer | None = None, echo: Callable[[str], None] = print,
                    scheduler: str | None = None) -> ConvergenceResult:
    """The comparison of ``path`` into ``out_dir`` (module doc). ``scheduler``: where every render's tile
    tasks run (``--scheduler`` of ``loomlight render``: a Dask cluster spreads the reference's batches)."""
    t_start = time.perf_counter()
    from stages.evaluate.convergence import equal_time_spp

    from ..progress import progress

    cmp = load_comparison(path)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise LoomError(out, None, "output path exists and is not a directory")
    do_render = renderer or cli_render
    where = ("--scheduler", scheduler) if scheduler else ()
    explicit = ref_path is not None
    rpath = Path(ref_path) if explicit else default_reference_path(out)
    if rpath.suffix != ".zarr":
        raise LoomError(rpath, "--ref", "the reference is a render artifact (a .zarr directory)")
    if explicit and not reference_only:
        if not (rpath / "zarr.json").exists():
            raise LoomError(rpath, "--ref", "no reference artifact here (make one with --reference-only)")
        ref = load_reference(rpath, reference_key(cmp, out))
    else:
        ref = build_reference(cmp, out, rpath, do_render, rebuild=reference_only, echo=echo, where=where)
    rs = ref.summary["reference"]
    ref_info = {"path": str(rpath), "spp": int(ref.summary["spp"]), "batches": ref.batches,
                "render_time_s": float(rs["render_time_s"]), "pixel_error_p50": rs["pixel_error_p50"],
                "pixel_error_p95": rs["pixel_error_p95"], "mean_error": rs["mean_error"],
                "targets_met": rs["targets_met"], "reused": ref.reused, "method": cmp.reference,
                "code": rs["key"]["code"], "depth_check": rs.get("depth_check")}
    echo(f"reference {cmp.name}: {ref.batches} batches, {ref_info['spp']} spp, "
         f"{ref_info['render_time_s']:.1f} s render "
         f"({'reused' if ref.reused else 'rendered'}); pixel error p50 {ref_info['pixel_error_p50']:.4f}, "
         f"mean {ref_info['mean_error']:.5f}" + ("" if ref_info["targets_met"] else " (targets NOT met)"))
    if reference_only:
        return ConvergenceResult(out, ref_info, {}, [], 0, None, None)

    # 2. the runs
    rendered = 0
    runs: dict[str, list[Run]] = {}
    total = sum(len(m.budgets) for m in cmp.methods)
    with progress(f"convergence {cmp.name}: runs", total) as advance:
        for m in cmp.methods:
            runs[m.name] = []
            for j, b in enumerate(m.budgets):
                exr = out / "renders" / m.name / f"{run_label(m, b)}.exr"
                rendered += render_once(cmp, m, out, exr, derived_scene(cmp, m, b, 1 + j),
                                        f"method {m.name}, budget {b}", do_render, force, where)
                runs[m.name].append(measure(Run(m.name, b, exr), ref))
                advance()
    # 3. the fit, times to each level, speed-ups
    methods = {m.name: method_summary(cmp, m, runs[m.name], ref) for m in cmp.methods}
    add_speedups(cmp, methods)
    # 4. the equal-time strip
    T = equal_time_target(cmp, methods[cmp.reference])
    strip = {}
    with progress(f"convergence {cmp.name}: equal-time strip", len(cmp.methods)) as advance:
        for m in cmp.methods:
            n = cmp.equal_time_spp if m.name == cmp.reference else equal_time_spp(T, methods[m.name]["seconds_per_spp"])
            em = CompareMethod(m.name, m.method, {**m.render, "max_spp": 0}, m.args, "spp", (n,))
            exr = out / "equal_time" / f"{m.name}.exr"
            rendered += render_once(cmp, em, out, exr, derived_scene(cmp, em, n, EQUAL_TIME_SEED), f"method {m.name}, "
                                    f"equal time", do_render, force, where)
            r = measure(Run(m.name, n, exr), ref)
            strip[m.name] = {"spp": n, "asked_time_s": T, "time_s": r.time_s, "error": r.error.error, "exr": str(exr),
                             "ssim": r.ssim}
            advance()
    # 5. memory
    for m in cmp.methods:
        s = methods[m.name]
        g, how = geometry_bytes(cmp, m, out, _method_stats(runs[m.name][-1].exr))
        s["geometry_bytes"], s["geometry_from"] = g, how
        s["peak_memory_bytes"] = peak_memory(cmp, m, out) if memory and renderer is None else None
    targets = check_targets(cmp, methods)
    from .convergence_report import write_outputs

    md, ht = write_outputs(cmp, out, ref, ref_info, methods, strip, targets, t_start)
    return ConvergenceResult(out, ref_info, methods, targets, rendered, md, ht)


def equal_time_target(cmp: Comparison, ref_summary: dict) -> float:
    """The time the reference method spends on ``equal_time_spp``: its run at that budget where it has one,
    else its seconds per sample (largest run) times that many samples."""
    for r in ref_summary["runs"]:
        if r["budget"] == cmp.equal_time_spp and cmp.method(cmp.reference).budget == "spp":
            return float(r["time_s"])
    return ref_summary["seconds_per_spp"] * cmp.equal_time_spp


def _method_stats(exr: Path) -> dict:
    try:
        doc = json.loads((exr.with_suffix(".zarr") / "zarr.json").read_text())
        return doc.get("attributes", {}).get("summary", {}).get("method_stats", {}) or {}
    except (OSError, ValueError):
        return {}


def check_targets(cmp: Comparison, methods: dict) -> list[dict]:
    """``methods[].target_speedup`` of the comparison file against the measured speed-ups at equal error."""
    out = []
    for m in cmp.methods:
        if m.target_speedup is None:
            continue
        s = methods[m.name]
        got = s.get("speedup_at_equal_error")
        if got is None:
            blocked = [lv for lv, d in s["levels"].items() if d["floor_blocks"]]
            out.append({"method": m.name, "target": m.target_speedup, "met": False, "value": None, "level": None,
                        "bound": "", "why": (f"its bias floor {s['floor']:.3f} is above {', '.join(blocked)}" if blocked
                                             else "no error level reached by both it and the reference method")})
            continue
        v, bound = got["value"], got["bound"]
        out.append({"method": m.name, "target": m.target_speedup,
                    "met": bool(bound in ("", ">=") and v >= m.target_speedup),
                    "value": v, "bound": bound, "level": got["level"], "why": ""})
    return out
