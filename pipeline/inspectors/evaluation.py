"""Picture of an ``evaluation`` artifact (stage evaluate), by its mode:

- ``images`` (``loomlight evaluate --ref --test``): top row the reference and every test image (sRGB,
  exposure 0, read from the EXRs the artifact records as its inputs; a missing or since-changed file is
  said so in its panel), middle row the mean intensity of every image per channel and every test's
  per-pixel relative squared error map (the artifact's ``relative_error``, log scale 1e-4 .. 10 as in
  the report), bottom the metrics table (RMSE, relMSE, SSIM, mean dE00, brightness ratio, noise, render
  time, speed-up);
- ``sweep``: every method's mean intensity (mean of R, G, B) and render time per configuration, and the
  per-method summary table;
- ``table1``: the data-size and render-time table (seed 000 Table 1 form) and the render times;
- ``convergence`` (``loomlight evaluate --convergence``): every method's relative error against render
  time (log-log, the artifact's ``error`` and ``time_s``, floors dashed) and the table of bias floors,
  noise constants and speed-ups at equal error.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from . import DPI, finish, pyplot

TABLE_FONT = 9
CHANNEL_COLORS = ("#d62728", "#2ca02c", "#1f77b4")


def _resolve(art, rec: dict):
    """(path or None, note): an input file of the evaluation, found as recorded (relative to the working
    directory), or relative to the artifact's directory or one of its parents."""
    p = Path(rec.get("path", ""))
    cands = [p] if p.is_absolute() else [p] + [d / p for d in [art.path.parent, *art.path.resolve().parents]]
    for c in cands:
        if c.is_file():
            h = hashlib.sha256()
            with open(c, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
            return c, ("" if rec.get("sha256") in (None, h.hexdigest()) else " (changed since the evaluation)")
    return None, f"{p} not found"


def _image(art, key):
    from ..images import read_exr, to_srgb8

    rec = art.meta.get("inputs", {}).get(key)
    if rec is None:
        return None, "not recorded"
    path, note = _resolve(art, rec)
    if path is None:
        return None, note
    try:
        rgb, _ = read_exr(path)
    except Exception as e:  # an unreadable file is a note in the picture, not a failure of the picture
        return None, f"{path.name} unreadable ({type(e).__name__})"
    return to_srgb8(rgb), note


def _table(ax, headers, rows, title):
    ax.set_axis_off()
    ax.set_title(title)
    if not rows:
        ax.text(0.5, 0.5, "no rows", ha="center", va="center")
        return
    t = ax.table(cellText=rows, colLabels=headers, loc="upper center", cellLoc="center")
    t.auto_set_font_size(False)
    t.set_fontsize(TABLE_FONT)
    t.auto_set_column_width(list(range(len(headers))))
    t.scale(1.0, 1.5)
    for (r, _), cell in t.get_celld().items():
        if r == 0:
            cell.set_facecolor("#e8e8e8")
            cell.set_text_props(weight="bold")


def _images_mode(art, plt, size):
    from matplotlib.colors import LogNorm

    from ..report import ERR_RANGE, fmt_num
    from ..runners.evaluate import METRIC_HEADERS, metric_row

    s = art.summary
    labels = list(art.params.get("labels") or s.get("tests", {}).keys())
    tests = s.get("tests", {})
    ref = s.get("reference", {})
    n = len(labels)
    ncol = max(2, n + 1)
    w, h = s.get("image_size", [4, 3])
    aspect = h / w
    fw = size[0] / DPI
    table_h = 0.35 * (n + 3)
    # panel width: the full width shared by the columns, less where the height would pass --height
    pw = max(min(fw / ncol, (size[1] / DPI - table_h - 1.8) / (2 * aspect)), 1.0)
    fh = 2 * (pw * aspect + 0.6) + 0.6 + table_h
    fig = plt.figure(figsize=(fw, fh), layout="constrained")
    gs = fig.add_gridspec(3, ncol, height_ratios=[pw * aspect + 0.6, pw * aspect + 0.6, 0.35 * (n + 3)])
    mi = np.asarray(art["mean_intensity"], float)
    # images
    keys = [("reference", f"reference: {ref.get('name', '?')}", mi[0])] + \
           [(f"test:{lab}", f"test: {lab}", mi[1 + i]) for i, lab in enumerate(labels)]
    for i, (key, title, mean) in enumerate(keys):
        ax = fig.add_subplot(gs[0, i])
        img, note = _image(art, key)
        if img is None:
            ax.text(0.5, 0.5, f"image {note}", ha="center", va="center", wrap=True)
            ax.set_xlim(0, 1)
            ax.set_ylim(0, 1)
        else:
            ax.imshow(img, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        extra = f"\n{note}" if img is not None and note else ""
        ax.set_title(f"{title}\nmean RGB {', '.join(f'{v:.3f}' for v in mean)}{extra}")
    # mean intensity per channel
    ax = fig.add_subplot(gs[1, 0])
    names = ["reference"] + labels
    x = np.arange(len(names))
    for c in range(3):
        ax.bar(x + (c - 1) * 0.27, mi[:, c], width=0.27, color=CHANNEL_COLORS[c], label="RGB"[c])
    ax.set_xticks(x, [nm if len(nm) <= 14 else nm[:13] + "…" for nm in names], rotation=15)
    ax.set_ylabel("mean intensity (linear)")
    ax.set_title("mean intensity per channel")
    ax.set_ylim(0, 1.25 * max(float(mi.max()), 1e-12))
    ax.legend(ncol=3, loc="upper center")
    # error maps
    err = art["relative_error"]
    im = None
    for i, lab in enumerate(labels):
        ax = fig.add_subplot(gs[1, 1 + i])
        im = ax.imshow(np.clip(err[i], *ERR_RANGE), cmap="inferno", norm=LogNorm(*ERR_RANGE), interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"relative squared error: {lab}\nrelMSE {fmt_num(tests.get(lab, {}).get('relmse'))}")
    if im is not None:
        fig.colorbar(im, ax=fig.axes[-n:], label="(t - r)^2 / (r^2 + 0.01), mean over RGB", fraction=0.03)
    # metrics table
    ax = fig.add_subplot(gs[2, :])
    headers = METRIC_HEADERS + ["brightness ratio", "noise RMSE"]
    rows = []
    for lab in labels:
        e = tests.get(lab, {})
        ratio = ", ".join(f"{v:.3f}" for v in e.get("brightness_ratio", [])) or "-"
        if e.get("brightness_mismatch"):
            ratio += " MISMATCH"
        noise = fmt_num(e.get("noise_rmse")) + (" (dominates)" if e.get("noise_dominated") else "")
        rows.append(metric_row(lab, e) + [ratio, noise])
    _table(ax, headers, rows, "metrics against the reference (render time excludes compilation)")
    fig.suptitle(f"evaluation ({s.get('mode')}): {n} test image(s) against {ref.get('name', '?')}, {w}x{h} pixels")
    return fig


def _sweep_mode(art, plt, size):
    from ..report import fmt_num, fmt_seconds

    s = art.summary
    params = art.params
    configs = list(params.get("configurations") or [])
    mnames = list(params.get("methods") or s.get("methods", {}).keys())
    means = np.asarray(art["mean_intensity"], float)       # (configuration, method, channel)
    times = np.asarray(art["time_per_image_s"], float)      # (configuration, method)
    C = means.shape[0]
    configs = configs if len(configs) == C else [str(i) for i in range(C)]
    table_h = 0.35 * (len(mnames) + 3)
    fig = plt.figure(figsize=(size[0] / DPI, min(size[1] / DPI, 5.0 + table_h)), layout="constrained")
    gs = fig.add_gridspec(2, 2, height_ratios=[4.4, table_h])
    x = np.arange(C)
    markers = "os^Dv<>p"
    ax = fig.add_subplot(gs[0, 0])
    for m, nm in enumerate(mnames):
        ax.plot(x, means[:, m].mean(axis=-1), marker=markers[m % len(markers)], lw=1.2, label=nm)
    ax.set_xticks(x, configs, rotation=60, ha="right")
    ax.set_ylabel("mean intensity (mean of R, G, B)")
    ax.set_title(f"mean intensity per configuration (reference: {s.get('reference')})")
    ax.legend(title="method")
    ax.grid(alpha=0.3)
    ax = fig.add_subplot(gs[0, 1])
    for m, nm in enumerate(mnames):
        ax.plot(x, times[:, m], marker=markers[m % len(markers)], lw=1.2, label=nm)
    ax.set_xticks(x, configs, rotation=60, ha="right")
    if np.nanmin(times) > 0:
        ax.set_yscale("log")
    ax.set_ylabel("render time per image (s)")
    ax.set_title("render time per configuration")
    ax.legend(title="method")
    ax.grid(alpha=0.3)
    headers = ["method", "configs", "time / image", "speed-up", "RMSE of mean int.", "relative", "within 10%",
               "worst ratio", "mean SSIM", "mean relMSE"]
    rows = []
    for nm in mnames:
        e = s.get("methods", {}).get(nm, {})
        rows.append([nm, fmt_num(e.get("configurations")), fmt_seconds(e.get("time_per_image_s")),
                     f"{e['speedup']:.2f}x" if e.get("speedup") is not None else "-",
                     fmt_num(e.get("rmse_mean_intensity")), fmt_num(e.get("relative_rmse_mean_intensity")),
                     f"{100 * e['brightness_within_10pct']:.0f}%" if e.get("brightness_within_10pct") is not None
                     else "-",
                     fmt_num(e.get("worst_brightness_ratio")), fmt_num(e.get("mean_ssim")),
                     fmt_num(e.get("mean_relmse"))])
    _table(fig.add_subplot(gs[1, :]), headers, rows, "methods against the reference over all configurations")
    fig.suptitle(f"evaluation (sweep '{params.get('sweep', '?')}'): {C} configurations x {len(mnames)} methods")
    return fig


def _table1_mode(art, plt, size):
    from ..report import fmt_bytes, fmt_num, fmt_seconds
    from ..runners.table1 import TABLE1_COLUMNS

    rows = art.summary.get("rows", [])
    keys = [k for k, _ in TABLE1_COLUMNS if any(r.get(k) is not None for r in rows)]

    def cell(k, v):
        if v is None:
            return "-"
        if k.endswith("_bytes"):
            return fmt_bytes(v)
        if k.endswith("_time_s"):
            return fmt_seconds(v)
        return fmt_num(v) if not isinstance(v, str) else v

    # transposed (one column per scene): the Table 1 headers are long
    headers = ["", *[str(r.get("scene", i)) for i, r in enumerate(rows)]]
    body = [[dict(TABLE1_COLUMNS)[k]] + [cell(k, r.get(k)) for r in rows] for k in keys if k != "scene"]
    fig = plt.figure(figsize=(size[0] / DPI, size[1] / DPI), layout="constrained")
    gs = fig.add_gridspec(1, 2, width_ratios=[1.6, 1])
    _table(fig.add_subplot(gs[0, 0]), headers, body, "data size and render time (Luan, Zhao, Bala 2017 Table 1 form)")
    ax = fig.add_subplot(gs[0, 1])
    t = np.asarray(art["render_time_s"], float)
    x = np.arange(len(rows))
    ax.bar(x - 0.2, t[:, 0], width=0.4, label="procedural", color="#1f77b4")
    ax.bar(x + 0.2, t[:, 1], width=0.4, label="realized", color="#ff7f0e")
    ax.set_xticks(x, headers[1:], rotation=30, ha="right")
    ax.set_ylabel("render time (s)")
    ax.set_title("volumetric path tracer: render time")
    ax.legend(title="fibre model")
    fig.suptitle(f"evaluation (table1): {len(rows)} scene(s)")
    return fig


def _convergence_mode(art, plt, size):
    from ..report import fmt_bytes

    s = art.summary
    methods = s.get("convergence", {})
    names = list(art.params.get("methods") or methods)
    err, tim = np.asarray(art["error"], float), np.asarray(art["time_s"], float)
    table_h = 0.35 * (len(names) + 3)
    fig = plt.figure(figsize=(size[0] / DPI, min(size[1] / DPI, 5.0 + table_h)), layout="constrained")
    gs = fig.add_gridspec(2, 1, height_ratios=[4.4, table_h])
    ax = fig.add_subplot(gs[0, 0])
    for i, nm in enumerate(names):
        ok = np.isfinite(err[i]) & np.isfinite(tim[i]) & (err[i] > 0)
        line, = ax.plot(tim[i][ok], err[i][ok], marker="o", lw=1.2, label=nm)
        floor = (methods.get(nm) or {}).get("floor")
        if floor:
            ax.axhline(floor, color=line.get_color(), ls="--", lw=1)
    for lv in s.get("levels", []):
        ax.axhline(lv, color="0.6", ls=":", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("render time (s, kernels only)")
    ax.set_ylabel("relative RMSE (cloth, reference noise subtracted)")
    ax.set_title(f"error against time (reference: {s.get('reference', {}).get('method', '?')}, "
                 f"{s.get('reference', {}).get('spp', '?')} spp)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(title="method")
    rows = []
    for nm in names:
        e = methods.get(nm, {})
        sp = e.get("speedup_at_equal_error") or {}
        rows.append([nm, f"{e.get('floor', float('nan')):.3f}", f"{e.get('noise_constant', float('nan')):.3g}",
                     f"{sp.get('bound', '')}{sp['value']:.3g}x at {sp['level']:.0%}" if sp.get("value") else "-",
                     fmt_bytes(e.get("geometry_bytes")), fmt_bytes(e.get("peak_memory_bytes"))])
    _table(fig.add_subplot(gs[1, 0]), ["method", "bias floor", "noise constant (s)", "speed-up at equal error",
                                       "geometry memory", "peak memory"], rows, "methods at equal error")
    fig.suptitle(f"evaluation (convergence '{s.get('comparison', '?')}'): {len(names)} methods")
    return fig


def _other_mode(art, plt, size):
    fig, ax = plt.subplots(figsize=(size[0] / DPI, size[1] / DPI))
    rows = [[k, str(v)[:90]] for k, v in sorted(art.summary.items())]
    _table(ax, ["summary key", "value"], rows, f"evaluation (mode {art.summary.get('mode')!r}): summary")
    return fig


MODES = {"images": _images_mode, "sweep": _sweep_mode, "table1": _table1_mode, "convergence": _convergence_mode}


def inspect(art, png, show=False, size=(1200, 900), **_):
    with pyplot(show) as plt:
        fig = MODES.get(art.summary.get("mode"), _other_mode)(art, plt, size)
        return finish(fig, png, show)
