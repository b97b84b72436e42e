"""The equal-error comparison's outputs (``pipeline.runners.convergence``): plot, strip, table, report, artifact.

- ``convergence.png``: log-log relative error E against render time (kernels only), a line per method:
  the measured points with their uncertainty, the fit E(t)^2 = b^2 + c/t through them, the bias floor b
  dashed, the error levels dotted.
- ``equal_time.png``: the reference, then every method at the time the reference method spends on
  ``equal_time_spp`` samples per pixel (top row, sRGB at exposure 0), their per-pixel relative error
  maps below (cloth pixels, 0 .. 0.5).
- ``report.md`` / ``report.html``: the reference (spp, time, noise), one sentence per error level saying
  which method reaches it first, the table (method | bias floor | noise constant | time to each level |
  speed-up at equal error | geometry memory | peak memory), the targets, the plot and the strip.
- ``convergence.json`` and the ``evaluation`` artifact ``evaluation.zarr`` (mode ``convergence``; arrays
  ``error`` and ``time_s`` per method and budget).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .. import report as rp

COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")


def _time_text(d: dict) -> str:
    t, b = d["time_s"], d["bound"]
    if t is None:
        return "-"
    if b == ">":
        return f"> {rp.fmt_seconds(t)}" + (" (floor)" if d["floor_blocks"] else "")
    return ("≤ " if b == "<=" else "") + rp.fmt_seconds(t)


def _speedup_text(s: dict | None) -> str:
    if not s or s.get("value") is None:
        return "-"
    sym = {">=": "≥ ", "<=": "≤ ", "~": "~"}.get(s["bound"], "")
    return f"{sym}{s['value']:.3g}×"


def convergence_png(cmp, methods: dict, path: Path) -> Path:
    plt = rp.pyplot()
    fig, ax = plt.subplots(figsize=(7.2, 4.8))
    for k, (name, s) in enumerate(methods.items()):
        col = COLORS[k % len(COLORS)]
        t = np.array([r["time_s"] for r in s["runs"]])
        e2 = np.array([r["e2"] for r in s["runs"]])
        se = np.array([r["e2_se"] for r in s["runs"]])
        e = np.sqrt(np.maximum(e2, 1e-12))
        lo = e - np.sqrt(np.maximum(e2 - se, 1e-12))
        hi = np.sqrt(np.maximum(e2 + se, 1e-12)) - e
        ax.errorbar(t, e, yerr=[lo, hi], fmt="o", color=col, ms=4, capsize=2,
                    label=f"{name}{' (reference method)' if name == cmp.reference else ''}")
        tt = np.geomspace(t.min() / 1.5, t.max() * 1.5, 100)
        ax.plot(tt, np.sqrt(np.maximum(s["b2"] + s["noise_constant"] / tt, 1e-12)), color=col, lw=1.2)
        if s["floor"] > 0:
            ax.axhline(s["floor"], color=col, ls="--", lw=1)
    for lv in cmp.levels:
        ax.axhline(lv, color="0.6", ls=":", lw=0.8)
        ax.text(0.995, lv, f"{lv:.0%}", transform=ax.get_yaxis_transform(), ha="right",
                va="bottom", fontsize=7, color="0.4")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("render time (s, kernels only)")
    ax.set_ylabel("relative RMSE over cloth pixels\n(reference noise subtracted)")
    ax.set_title(f"{cmp.name}: error against time; points measured, lines E² = b² + c/t, floors dashed", fontsize=9)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8)
    return rp.save_figure(fig, path)


def equal_time_png(cmp, ref, strip: dict, path: Path) -> Path:
    from stages.evaluate.convergence import error_map

    from .evaluate import load_image

    plt = rp.pyplot()
    names = list(strip)
    n = len(names) + 1
    h, w = ref.rgb.shape[:2]
    scale = max(1.0, 240.0 / w)
    fig, axes = plt.subplots(2, n, figsize=(n * (w * scale / 100 + 0.3), 2 * (h * scale / 100 + 0.6)), squeeze=False)
    axes[0][0].imshow(rp.preview(ref.rgb), interpolation="nearest")
    axes[0][0].set_title(f"reference ({cmp.reference})\n{ref.summary['spp']} spp", fontsize=8)
    axes[1][0].set_axis_off()
    im = None
    for k, name in enumerate(names, start=1):
        d = strip[name]
        img = load_image(d["exr"])
        axes[0][k].imshow(rp.preview(img), interpolation="nearest")
        axes[0][k].set_title(f"{name}: {d['spp']} spp, {rp.fmt_seconds(d['time_s'])}\nE = {d['error']:.3f}", fontsize=8)
        im = axes[1][k].imshow(error_map(img, ref.rgb, ref.alpha), cmap="inferno", vmin=0.0, vmax=0.5,
                               interpolation="nearest")
        axes[1][k].set_title("relative error per pixel", fontsize=7)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    if im is not None:
        fig.colorbar(im, ax=list(axes[1][1:]), fraction=0.03)
    fig.suptitle(f"{cmp.name}: every method at the time {cmp.reference} spends on {cmp.equal_time_spp} spp "
                 f"({rp.fmt_seconds(next(iter(strip.values()))['asked_time_s'])})", fontsize=9)
    return rp.save_figure(fig, path)


def floor_sentence(name: str, s: dict) -> str:
    ft = s["floor_terms"]
    total = ft["brightness_e2"] + ft["structure_e2"]
    ratio = ", ".join(f"{v:.2f}" for v in ft["mean_ratio"])
    if total <= 0:
        return f"{name}'s floor is within the reference's noise."
    share = ft["brightness_e2"] / total
    if share == 0.0:
        return (f"{name}'s bias floor b = {s['floor']:.3f} is set by the structure of its picture, not by its mean "
                f"brightness (per channel {ratio} of the reference's): rescaling it to the reference's mean does not "
                f"lower its per-pixel error.")
    part = "its mean brightness" if share >= 0.5 else "the structure of its picture more than its mean brightness"
    return (f"{name}'s bias floor b = {s['floor']:.3f} is set by {part}: per channel {ratio} of the reference's "
            f"mean; rescaling it to that mean removes {share:.0%} of its squared error at the largest budget.")


def crossover(m: dict, r: dict) -> tuple[str, float | None]:
    """Where a method's fitted error curve crosses the reference method's: with E(t)^2 = b^2 + c/t for
    both, the times to an error E are equal where c_m (E^2 - b_r^2) = c_r (E^2 - b_m^2), i.e. at
    E*^2 = (c_r b_m^2 - c_m b_r^2) / (c_r - c_m). Returns ("above", E*) when the method is the faster one
    at errors above E* (it has less noise, more bias), ("below", E*) when below, ("always", None) or
    ("never", None) when the curves do not cross where both are defined."""
    bm2, cm, br2, cr = m["b2"], m["noise_constant"], r["b2"], r["noise_constant"]
    lo = max(bm2, br2)
    if cm == cr:
        return ("always", None) if bm2 < br2 else ("never", None)
    e2 = (cr * bm2 - cm * br2) / (cr - cm)
    if cm < cr:   # less noise: faster at large errors, down to the crossing (or to its own floor)
        return ("above", math.sqrt(e2)) if e2 > lo else (("always", None) if bm2 <= br2 else ("above", math.sqrt(bm2)))
    return ("below", math.sqrt(e2)) if e2 > lo else ("never", None)


def crossover_sentences(cmp, methods: dict) -> list[str]:
    """One sentence per method on the errors at which it beats the reference method (the fits' crossing)."""
    ref = methods[cmp.reference]
    out = []
    for name, s in methods.items():
        if name == cmp.reference:
            continue
        how, e = crossover(s, ref)
        if how == "always":
            out.append(f"{name} is faster than {cmp.reference} at every error it reaches (fits).")
        elif how == "never":
            out.append(f"{name} is slower than {cmp.reference} at every error (fits).")
        elif how == "above":
            out.append(f"{name} is faster than {cmp.reference} above {e:.0%} error and cannot go below its floor "
                       f"{s['floor']:.0%}; {cmp.reference} wins below {e:.0%} (fits)." if e <= s["floor"] * 1.0001 else
                       f"{name} is faster than {cmp.reference} above {e:.0%} error, {cmp.reference} below it (fits).")
        else:
            out.append(f"{name} is faster than {cmp.reference} below {e:.0%} error, slower above it (fits).")
    return out


def winner_sentences(cmp, methods: dict) -> list[str]:
    out = []
    for lv in (f"{v:g}" for v in cmp.levels):
        reached = [(s["levels"][lv]["time_s"], name) for name, s in methods.items()
                   if s["levels"][lv]["time_s"] is not None and s["levels"][lv]["bound"] != ">"]
        blocked = [name for name, s in methods.items() if s["levels"][lv]["floor_blocks"]]
        if not reached:
            out.append(f"At {float(lv):.0%} error no method reaches it within its budgets"
                       + (f" ({', '.join(blocked)}: bias floor above it)" if blocked else "") + ".")
            continue
        t, name = min(reached)
        sp = methods[name]["speedup"][lv]
        text = f"At {float(lv):.0%} error **{name}** is fastest ({_time_text(methods[name]['levels'][lv])}"
        if name != cmp.reference and sp["value"] is not None:
            text += f", {_speedup_text(sp)} {cmp.reference}'s speed"
        text += ")"
        if blocked:
            text += f"; {', '.join(blocked)} cannot reach it (bias floor above it)"
        out.append(text + ".")
    return out


def depth_sentence(dc: dict | None) -> str:
    """The reference's path-depth check (``convergence.depth_check``) in a sentence."""
    if not dc:
        return "Its path depth was not checked (a reference made before the depth check)."
    kept = ", ".join(f"{v:.4f}" for v in dc["kept_rgb"])
    return (f"Its path depth {dc['max_depth']} keeps {kept} (per channel) of the light that depth "
            f"{dc['check_depth']} gives on the same paths"
            + (": **truncated — the reference misses light that deeper paths carry; raise the comparison's "
               "render.max_depth**." if dc["truncated"] else "."))


def write_outputs(cmp, out: Path, ref, ref_info: dict, methods: dict, strip: dict, targets: list, t_start: float):
    from ..artifacts import FILE, ArtifactWriter

    names = list(methods)
    inputs = {"comparison": (cmp.path, FILE), "scene": (cmp.scene_path, FILE), "reference": (ref.path, "render")}
    for name, s in methods.items():
        for r in s["runs"]:
            inputs[f"run:{name}:{r['budget']}"] = (Path(r["exr"]), FILE)
    for name, d in strip.items():
        inputs[f"equal_time:{name}"] = (Path(d["exr"]), FILE)
    writer = ArtifactWriter(out / "evaluation.zarr", kind="evaluation", stage="evaluate",
                            params={"mode": "convergence", "comparison": cmp.name, "methods": names}, inputs=inputs,
                            started=t_start)
    doc = {"comparison": cmp.name, "description": cmp.description, "scene": str(cmp.scene_path),
           "reference": ref_info, "levels": list(cmp.levels), "methods": methods, "equal_time": strip,
           "targets": targets}
    rp.write_text(out / "convergence.json", json.dumps(doc, indent=2) + "\n")
    convergence_png(cmp, methods, out / "convergence.png")
    equal_time_png(cmp, ref, strip, out / "equal_time.png")

    rep = rp.Report(f"Equal-error comparison: {cmp.name}")
    if cmp.description:
        rep.paragraph(cmp.description)
    rep.paragraph(" ".join(winner_sentences(cmp, methods) + crossover_sentences(cmp, methods)))
    rep.image("convergence.png", "Relative error against render time, log-log: points measured, lines the fit "
              "E² = b² + c/t, bias floors dashed, error levels dotted")
    rep.heading("Reference")
    rep.paragraph(f"{cmp.reference} from {ref_info['batches']} independent batches, {ref_info['spp']} spp in all, "
                  f"{rp.fmt_seconds(ref_info['render_time_s'])} of rendering "
                  f"({'reused' if ref_info['reused'] else 'rendered in this run'}; code version {ref_info['code']}). "
                  f"Relative standard error over cloth pixels: median {ref_info['pixel_error_p50']:.3f}, "
                  "95th percentile "
                  f"{ref_info['pixel_error_p95']:.3f}; of the cloth's mean {ref_info['mean_error']:.4f}"
                  + ("" if ref_info["targets_met"] else " (**its targets were not met within max_batches**)") + ". "
                  "Every error below has the reference's own noise subtracted (E² − σ²_ref, with its uncertainty). "
                  + depth_sentence(ref_info.get("depth_check")))
    rep.image("reference/reference_error.png", "The reference's relative standard error per cloth pixel")
    rep.heading("Methods")
    lv = [f"{v:g}" for v in cmp.levels]
    headers = (["method", "bias floor b", "noise constant c (s)"] + [f"time to {float(v):.0%}" for v in lv]
               + ["speed-up at equal error", "geometry memory", "peak memory"])
    rows = []
    for name, s in methods.items():
        se = s["speedup_at_equal_error"]
        sp = "reference method" if name == cmp.reference else (
            f"{_speedup_text(se)} at {se['level']:.0%}" if se else "-")
        rows.append([name, f"{s['floor']:.3f} ± {s['floor_se']:.3f}", f"{s['noise_constant']:.3g}"]
                    + [_time_text(s["levels"][v]) for v in lv]
                    + [sp, rp.fmt_bytes(s.get("geometry_bytes")), rp.fmt_bytes(s.get("peak_memory_bytes"))])
    rep.table(headers, rows, caption="Error: relative RMSE over cloth pixels (alpha > 0.5) against the reference, "
              "its noise subtracted. Times: render kernels only (numba compilation apart), measured points; the fit "
              "E² = b² + c/t only interpolates between the two that bracket a level (≤: reached at the first budget "
              "already; >: not reached by the last). Speed-up: the reference method's time over the method's at the "
              "lowest level both reach. Geometry memory: the method's setup's own count, else the arrays of the "
              "artifacts it loads. Peak memory: one render in a process of its own.")
    own = methods[cmp.reference]
    if own["floor"] > 3.0 * own["floor_se"] and own["floor"] > 0.05:
        rep.paragraph(f"**Caution**: {cmp.reference}'s own floor against its own reference is {own['floor']:.3f} ± "
                      f"{own['floor_se']:.3f}, not consistent with zero. Its budgets end before its error falls as 1/t "
                      "(heavy-tailed noise: rare bright paths that small budgets miss), so the fitted floors and noise "
                      "constants on this scene overstate the bias; render larger budgets.")
    floors = [floor_sentence(name, s) for name, s in methods.items()
              if any(d["floor_blocks"] for d in s["levels"].values())]
    if floors:
        rep.paragraph(" ".join(floors))
    if targets:
        rep.heading("Targets")
        rep.table(["method", "target speed-up", "measured", "at error", "met"],
                  [[t["method"], f"≥ {t['target']:g}×",
                    _speedup_text({"value": t["value"], "bound": t.get("bound", "")}),
                    f"{t['level']:.0%}" if t["level"] is not None else "-",
                    "yes" if t["met"] else f"no{': ' + t['why'] if t.get('why') else ''}"] for t in targets])
    rep.heading("Equal time")
    rep.image("equal_time.png", f"Every method at the time {cmp.reference} spends on {cmp.equal_time_spp} spp, "
              "beside the reference, with per-pixel relative error maps")
    rep.table(["method", "spp", "asked time", "render time", "error E", "SSIM"],
              [[n, d["spp"], rp.fmt_seconds(d["asked_time_s"]), rp.fmt_seconds(d["time_s"]), f"{d['error']:.3f}",
                f"{d['ssim']:.3f}"] for n, d in strip.items()])
    rep.heading("Runs")
    rep.table(["method", "budget", "spp traced", "render time", "E", "E² ± se", "reference noise σ²",
               "mean ratio R, G, B", "SSIM"],
              [[name, r["budget"], rp.fmt_num(r["spp"]), rp.fmt_seconds(r["time_s"]), f"{r['error']:.4f}",
                f"{r['e2']:.3g} ± {r['e2_se']:.2g}", f"{r['ref_noise_e2']:.2g}",
                ", ".join(f"{v:.3f}" for v in r["mean_ratio"]), f"{r['ssim']:.3f}"]
               for name, s in methods.items() for r in s["runs"]])
    md, ht = rep.write(out)

    B = max(len(s["runs"]) for s in methods.values())
    err = np.full((len(names), B), np.nan)
    tim = np.full((len(names), B), np.nan)
    for i, s in enumerate(methods.values()):
        for j, r in enumerate(s["runs"]):
            err[i, j], tim[i, j] = r["error"], r["time_s"]
    summary_methods = {n: {k: v for k, v in s.items() if k != "runs"} for n, s in methods.items()}
    with writer as w:
        w.write("error", err, dimension_names=("method", "budget"))
        w.write("time_s", tim, dimension_names=("method", "budget"))
        w.summary.update(kind="evaluation", mode="convergence", comparison=cmp.name, reference=ref_info,
                         convergence=_finite(summary_methods), equal_time=_finite(strip), targets=_finite(targets),
                         levels=list(cmp.levels), metrics=["relative_rmse_cloth", "time_s"])
    return md, ht


def _finite(obj):
    """JSON-safe: inf and nan become None."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
