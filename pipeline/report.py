"""Evaluation pictures (matplotlib, PNG) and the report (Markdown + HTML) that holds them.

Pictures
--------
- ``error_map_png``: false-colour map of the per-pixel relative squared error (the quantity relMSE
  averages: mean over channels of (t - r)^2 / (r^2 + 0.01)) on a fixed log scale 1e-4 .. 10, so
  maps of different tests and configurations read alike.
- ``crops_png``: reference | test | error side by side, cropped to the square window (at most 96
  pixels) where the mean relative error is largest, nearest-neighbour enlarged.
- ``metric_bars_png``: one bar panel per metric, one bar per test image.
- ``sweep_rmse_png``: seed 001 Fig. 13 form: RMSE of mean image intensity per method.
- ``sweep_scatter_png``: mean intensity of each method against the reference, per configuration
  and channel (points on the diagonal agree).
- ``contact_sheet_png``: every configuration (rows) by method (columns), sRGB previews.

Reports
-------
``Report`` collects headings, paragraphs, tables and images, and writes ``report.md`` and
``report.html`` (self-contained apart from the PNGs beside it) into one directory.
Every file is written to a hidden temporary name and renamed into place.
"""
from __future__ import annotations

import html
import os
import uuid
from pathlib import Path
from typing import Sequence

import numpy as np

ERR_RANGE = (1e-4, 10.0)


def _tmp(path: Path) -> Path:
    return path.parent / f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}{path.suffix}"


def write_text(path: str | Path, text: str) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp(path)
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def save_figure(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp(path)
    try:
        fig.savefig(str(tmp), format="png", dpi=100, bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if tmp.exists():
            tmp.unlink()
    return path


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ------------------------------------------------------------------------------------------------
# pictures
def relative_error(test: np.ndarray, ref: np.ndarray, eps: float = 0.01) -> np.ndarray:
    """Per-pixel relative squared error, mean over channels (H, W)."""
    d = np.asarray(test, float) - np.asarray(ref, float)
    return np.mean(d * d / (np.asarray(ref, float) ** 2 + eps), axis=-1)


def preview(rgb: np.ndarray) -> np.ndarray:
    from .images import to_srgb8

    return to_srgb8(rgb)


def error_map_png(test: np.ndarray, ref: np.ndarray, path: str | Path, title: str) -> Path:
    from matplotlib.colors import LogNorm

    plt = pyplot()
    err = np.clip(relative_error(test, ref), ERR_RANGE[0], ERR_RANGE[1])
    h, w = err.shape
    scale = 6.0 / max(w, h)
    fig, ax = plt.subplots(figsize=(max(w * scale, 3.0) + 1.2, max(h * scale, 2.0) + 0.6))
    im = ax.imshow(err, cmap="inferno", norm=LogNorm(*ERR_RANGE), interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    cb.set_label("(t - r)^2 / (r^2 + 0.01)", fontsize=8)
    return save_figure(fig, Path(path))


def worst_window(err: np.ndarray, size: int) -> tuple[int, int]:
    """Top-left corner of the size x size window with the largest summed error (first on ties)."""
    h, w = err.shape
    s = np.zeros((h + 1, w + 1))
    s[1:, 1:] = np.cumsum(np.cumsum(err, axis=0), axis=1)
    box = s[size:, size:] - s[:-size, size:] - s[size:, :-size] + s[:-size, :-size]
    i, j = np.unravel_index(int(np.argmax(box)), box.shape)
    return int(i), int(j)


def crops_png(ref: np.ndarray, test: np.ndarray, path: str | Path, title: str, size: int = 96) -> Path:
    from matplotlib.colors import LogNorm

    plt = pyplot()
    err = relative_error(test, ref)
    h, w = err.shape
    n = int(min(size, h, w))
    i, j = worst_window(err, n)
    sl = (slice(i, i + n), slice(j, j + n))
    fig, axes = plt.subplots(1, 3, figsize=(9.0, 3.3))
    axes[0].imshow(preview(ref[sl]), interpolation="nearest")
    axes[0].set_title("reference", fontsize=9)
    axes[1].imshow(preview(test[sl]), interpolation="nearest")
    axes[1].set_title("test", fontsize=9)
    axes[2].imshow(np.clip(err[sl], *ERR_RANGE), cmap="inferno", norm=LogNorm(*ERR_RANGE), interpolation="nearest")
    axes[2].set_title("relative squared error", fontsize=9)
    for a in axes:
        a.set_axis_off()
    fig.suptitle(f"{title}  (crop {n}x{n} at x={j}, y={i})", fontsize=9)
    return save_figure(fig, Path(path))


METRIC_LABELS = {"rmse": "RMSE", "relmse": "relMSE", "ssim": "SSIM", "delta_e2000_mean": "mean ΔE00"}


def metric_bars_png(metrics: dict[str, dict], path: str | Path, title: str = "") -> Path:
    plt = pyplot()
    names = list(metrics)
    keys = [k for k in METRIC_LABELS if any(k in metrics[n] for n in names)]
    fig, axes = plt.subplots(1, len(keys), figsize=(3.2 * len(keys), 0.4 * len(names) + 1.8), squeeze=False)
    for ax, k in zip(axes[0], keys):
        vals = [float(metrics[n].get(k, np.nan)) for n in names]
        ax.barh(range(len(names)), vals, color="#4472c4")
        ax.set_yticks(range(len(names)))
        ax.set_yticklabels(names if ax is axes[0][0] else [""] * len(names), fontsize=8)
        ax.invert_yaxis()
        ax.set_title(METRIC_LABELS[k] + (" (higher: better)" if k == "ssim" else " (lower: better)"), fontsize=9)
        ax.tick_params(axis="x", labelsize=8)
    if title:
        fig.suptitle(title, fontsize=10, y=1.02)
    fig.tight_layout()
    return save_figure(fig, Path(path))


def sweep_rmse_png(rmse_by_method: dict[str, float], path: str | Path, reference: str, title: str = "") -> Path:
    plt = pyplot()
    names = list(rmse_by_method)
    fig, ax = plt.subplots(figsize=(1.2 * len(names) + 2.5, 3.2))
    ax.bar(range(len(names)), [rmse_by_method[n] for n in names], color="#c55a11")
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, fontsize=8)
    ax.set_ylabel(f"RMSE of mean intensity vs {reference}", fontsize=8)
    ax.set_title(title or "RMSE of mean image intensity over configurations (Khungurn et al. 2017 Fig. 13 form)",
                 fontsize=9)
    return save_figure(fig, Path(path))


def sweep_scatter_png(pairs: dict[str, tuple[np.ndarray, np.ndarray]], path: str | Path, reference: str) -> Path:
    """pairs[method] = (reference means (N, 3), method means (N, 3)): a point per configuration and channel."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.2, 4.0))
    vals = [np.asarray(v) for p in pairs.values() for v in p] or [np.zeros(1)]
    lo = float(min(0.0, min(v.min() for v in vals)))
    hi = float(max(1e-6, max(v.max() for v in vals)))
    ax.plot([lo, hi], [lo, hi], color="0.6", lw=1)
    for name, (r, v) in pairs.items():
        ax.scatter(np.ravel(r), np.ravel(v), s=12, label=name)
    ax.set_xlabel(f"mean intensity, {reference}", fontsize=8)
    ax.set_ylabel("mean intensity, method", fontsize=8)
    if pairs:
        ax.legend(fontsize=8)
    ax.set_title("per configuration and channel", fontsize=9)
    return save_figure(fig, Path(path))


def side_by_side_png(images: Sequence[np.ndarray], titles: Sequence[str], path: str | Path) -> Path:
    """The full images in one row at their own resolution, sRGB at exposure 0 (as the previews), each
    titled with its name, resolution and mean intensity."""
    plt = pyplot()
    n = len(images)
    h, w = images[0].shape[:2]
    scale = max(1.0, 320.0 / w)  # small renders are shown enlarged (nearest neighbour), never shrunk
    fig, axes = plt.subplots(1, n, figsize=(n * w * scale / 100 + 0.3 * n, h * scale / 100 + 0.7), squeeze=False)
    for ax, img, title in zip(axes[0], images, titles):
        ax.imshow(preview(img), interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        mean = ", ".join(f"{v:.3f}" for v in np.asarray(img, float).reshape(-1, 3).mean(axis=0))
        ax.set_title(f"{title}\n{img.shape[1]}x{img.shape[0]}, mean {mean}", fontsize=8)
    return save_figure(fig, Path(path))


def contact_sheet_png(images: list[list[np.ndarray | None]], rows: Sequence[str], cols: Sequence[str],
                      path: str | Path) -> Path:
    plt = pyplot()
    nr, nc = len(rows), len(cols)
    fig, axes = plt.subplots(nr, nc, figsize=(1.9 * nc + 0.8, 1.6 * nr + 0.4), squeeze=False)
    for r in range(nr):
        for c in range(nc):
            ax = axes[r][c]
            ax.set_xticks([])
            ax.set_yticks([])
            img = images[r][c]
            if img is not None:
                ax.imshow(preview(img), interpolation="nearest")
            if r == 0:
                ax.set_title(cols[c], fontsize=8)
            if c == 0:
                ax.set_ylabel(rows[r], fontsize=7, rotation=0, ha="right", va="center")
    return save_figure(fig, Path(path))


# ------------------------------------------------------------------------------------------------
# numbers
def fmt_num(v, digits: int = 4) -> str:
    if v is None:
        return "-"
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not np.isfinite(v):
            return str(v)
        if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e6):
            return f"{v:.{digits - 1}e}"
        return f"{v:.{digits}g}"
    return str(v)


def fmt_bytes(n) -> str:
    if n is None:
        return "-"
    n = float(n)
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if abs(n) < 1000.0 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000.0
    return f"{n:.1f} TB"


def fmt_seconds(s) -> str:
    if s is None:
        return "-"
    s = float(s)
    if s < 120:
        return f"{s:.3g} s"
    if s < 7200:
        return f"{s / 60:.3g} min"
    return f"{s / 3600:.3g} h"


# ------------------------------------------------------------------------------------------------
# the report document
class Report:
    """Blocks of a report, written as Markdown and HTML side by side (images by relative path)."""

    def __init__(self, title: str):
        self.title = title
        self.blocks: list[tuple] = []

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append(("h", level, text))

    def paragraph(self, text: str) -> None:
        self.blocks.append(("p", text))

    def table(self, headers: Sequence[str], rows: Sequence[Sequence], caption: str | None = None) -> None:
        self.blocks.append(("table", list(headers), [[str(c) for c in r] for r in rows], caption))

    def image(self, rel_path: str, caption: str) -> None:
        self.blocks.append(("img", rel_path, caption))

    def markdown(self) -> str:
        out = [f"# {self.title}", ""]
        for b in self.blocks:
            if b[0] == "h":
                out += ["#" * b[1] + " " + b[2], ""]
            elif b[0] == "p":
                out += [b[1], ""]
            elif b[0] == "table":
                _, headers, rows, caption = b
                if caption:
                    out += [f"*{caption}*", ""]
                def esc(s):
                    return str(s).replace("|", "\\|")
                out.append("| " + " | ".join(esc(h) for h in headers) + " |")
                out.append("|" + "|".join("---" for _ in headers) + "|")
                for r in rows:
                    out.append("| " + " | ".join(esc(c) for c in r) + " |")
                out.append("")
            elif b[0] == "img":
                out += [f"![{b[2]}]({b[1]})", "", f"*{b[2]}*", ""]
        return "\n".join(out)

    def html(self) -> str:
        e = html.escape
        out = ["<!DOCTYPE html>", "<html><head><meta charset='utf-8'>", f"<title>{e(self.title)}</title>",
               "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
               "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
               "text-align:right}th{background:#eee}td:first-child,th:first-child{text-align:left}"
               "figure{margin:1em 0}img{max-width:100%}figcaption{font-size:90%;color:#444}</style>",
               "</head><body>", f"<h1>{e(self.title)}</h1>"]
        for b in self.blocks:
            if b[0] == "h":
                out.append(f"<h{b[1]}>{e(b[2])}</h{b[1]}>")
            elif b[0] == "p":
                out.append(f"<p>{e(b[1])}</p>")
            elif b[0] == "table":
                _, headers, rows, caption = b
                out.append("<table>")
                if caption:
                    out.append(f"<caption>{e(caption)}</caption>")
                out.append("<tr>" + "".join(f"<th>{e(h)}</th>" for h in headers) + "</tr>")
                for r in rows:
                    out.append("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>")
                out.append("</table>")
            elif b[0] == "img":
                out.append(f"<figure><img src='{e(b[1])}' alt='{e(b[2])}'><figcaption>{e(b[2])}</figcaption></figure>")
        out.append("</body></html>")
        return "\n".join(out) + "\n"

    def write(self, out_dir: str | Path, stem: str = "report") -> tuple[Path, Path]:
        out_dir = Path(out_dir)
        md = write_text(out_dir / f"{stem}.md", self.markdown())
        ht = write_text(out_dir / f"{stem}.html", self.html())
        return md, ht
