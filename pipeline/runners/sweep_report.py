"""What a sweep reports: per-method numbers against the reference method, and the report.

``summarize_methods`` gives per method the RMSE of the mean image intensity against the reference
method over all configurations and channels (seed 001 Fig. 13), its relative form, the means of the
per-image metrics, the time per image and the speed-up over the reference (seed 001 Table 2).
``write_report`` writes ``report.md``/``.html`` with those tables, the RMSE and scatter plots, the
contact sheet of every configuration by method and the per-image error maps.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .sweep_file import Configuration, Sweep


@dataclass
class SweepImages:
    """The renders of a sweep gathered for comparison (``pipeline.runners.sweep.gather_images``)."""
    configs: list[Configuration]   # the configurations that have a render of the reference method
    method_names: list[str]        # every method of the sweep, in file order
    means: np.ndarray              # (C, M, 3) mean intensity per image; NaN where there is none
    times: np.ndarray              # (C, M) seconds per image; NaN where unknown
    per_image: dict                # "<config>/<method>.exr" -> metrics against the reference image
    images: dict                   # (config, method) -> linear RGB image
    inputs: dict                   # the evaluation artifact's inputs (sweep, scene, images, render artifacts)


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
        ratio = means[ok, mi] / np.maximum(r, 1e-12)  # mean intensity over the reference's, per channel
        worst = np.unravel_index(np.argmax(np.abs(ratio - 1.0)), ratio.shape)
        st["worst_brightness_ratio"] = float(ratio[worst])
        st["brightness_within_10pct"] = float(np.mean(np.abs(ratio - 1.0) <= 0.10))
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


def write_report(sweep: Sweep, out: Path, got: SweepImages, methods: dict) -> None:
    """``report.md``/``.html`` with the per-method tables, plots, contact sheet and error maps."""
    from .. import report as rp
    from ..report import fmt_num, fmt_seconds

    configs, mnames, means, per_image, images = got.configs, got.method_names, got.means, got.per_image, got.images

    rep = rp.Report(f"Sweep {sweep.name}: methods against {sweep.reference}")
    rep.paragraph(f"Scene {sweep.scene_path}; {len(configs)} configurations x {len(mnames)} methods; "
                  f"reference method: {sweep.reference}. Sweep file: {sweep.path}.")
    rep.heading("RMSE of mean image intensity (Khungurn et al. 2017 Fig. 13 form)")
    rep.paragraph("For every configuration the mean of each colour channel of the image (3 values per image); "
                  "RMSE of these values against the reference method's over all configurations. "
                  "Relative: divided by the RMS of the reference values.")
    rows = []
    for n in mnames:
        if n not in methods:
            continue
        s = methods[n]
        rows.append([n, s["configurations"], fmt_num(s["rmse_mean_intensity"]),
                     fmt_num(s["relative_rmse_mean_intensity"]),
                     fmt_num(s["worst_brightness_ratio"]), f"{s['brightness_within_10pct']:.0%}",
                     fmt_num(s.get("mean_rmse")), fmt_num(s.get("mean_ssim")), fmt_num(s.get("mean_delta_e2000_mean"))])
    rep.table(["method", "configurations", "RMSE mean intensity", "relative", "worst ratio", "channels within 10 %",
               "mean image RMSE", "mean SSIM", "mean ΔE00"], rows,
              caption="Worst ratio: the mean intensity over the reference's farthest from 1 over configurations "
                      "and channels; channels within 10 %: the fraction of (configuration, channel) means within "
                      "10 % of the reference's.")
    rp.sweep_rmse_png({n: methods[n]["rmse_mean_intensity"] for n in mnames if n in methods and n != sweep.reference},
                      out / "sweep_rmse.png", sweep.reference)
    rep.image("sweep_rmse.png", "RMSE of mean image intensity per method against the reference")
    ri = mnames.index(sweep.reference)
    ok = ~np.isnan(means[:, :, 0])
    rp.sweep_scatter_png({n: (means[ok[:, mi], ri], means[ok[:, mi], mi]) for mi, n in enumerate(mnames)
                          if mi != ri and ok[:, mi].any()}, out / "sweep_scatter.png", sweep.reference)
    rep.image("sweep_scatter.png", "Mean intensity of each method against the reference, per configuration and channel")
    rep.heading("Time per image and speed-up (Khungurn et al. 2017 Table 2 form)")
    rep.table(["method", "time per image", "speed-up"],
              [[n, fmt_seconds(methods[n]["time_per_image_s"]),
                f"{methods[n]['speedup']:.2f}x" if methods[n]["speedup"] is not None else "-"]
               for n in mnames if n in methods])
    rep.heading("Configurations")
    lum = np.array([0.2126, 0.7152, 0.0722])
    others = [mi for mi in range(len(mnames)) if mi != ri]
    rep.table(["configuration", "lighting / view"] + [f"Y mean, {n}" for n in mnames]
              + [f"R, G, B ratio {mnames[mi]} / {sweep.reference}" for mi in others],
              [[c.name, c.label] + [fmt_num(float(means[ci, mi] @ lum)) if ok[ci, mi] else "-"
                                    for mi in range(len(mnames))]
               + [", ".join(f"{v:.3f}" for v in means[ci, mi] / np.maximum(means[ci, ri], 1e-12)) if ok[ci, mi] else "-"
                  for mi in others]
               for ci, c in enumerate(configs)])
    sheet = [[images.get((c.name, n)) for n in mnames] for c in configs]
    rp.contact_sheet_png(sheet, [c.name for c in configs], mnames, out / "contact_sheet.png")
    rep.image("contact_sheet.png", "Every configuration (rows) by method (columns), sRGB previews")
    rep.heading("Per-image metrics against the reference")
    from .evaluate import METRIC_HEADERS, metric_row, slug

    rep.table(METRIC_HEADERS[:6], [metric_row(l, per_image[l])[:6] for l in sorted(per_image)])
    for l in sorted(per_image):
        c, n = l.split("/", 1)
        name = f"maps/{slug(c)}__{slug(n)}.png"
        rp.error_map_png(images[(c, n[:-4])], images[(c, sweep.reference)], out / name, f"{l} vs {sweep.reference}")
        rep.image(name, f"{l}: per-pixel relative squared error against {sweep.reference}")
    rep.write(out)
