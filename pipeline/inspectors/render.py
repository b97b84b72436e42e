"""Picture of a ``render`` artifact: the sRGB preview of its image beside its alpha (A), depth and
variance channels (each with a colour bar), titled with the method and statistics (spp, wall time,
paths/s, rays/s, mean RGB). The panels are laid out in the grid of columns that shows the image
largest within ``--width`` x ``--height``, and the figure is cut to its content (no empty margins)."""
from __future__ import annotations

import math

import numpy as np

from . import DPI, finish, pyplot

CHANNELS = {"A": ("alpha", "viridis"), "depth": ("distance", "viridis"), "variance": ("of the mean", "magma")}
MIN_PANEL_IN = 1.8  # a panel at least this wide (inches), for its two-line title
TITLE_IN = 0.95     # inches for the figure's title lines
PANEL_TITLE_IN = 0.5
COLORBAR = 1.2      # a panel with a colour bar is this much wider than its image


def wrap(parts, width: int) -> str:
    """``parts`` joined by commas, broken into lines of at most ``width`` characters between parts."""
    lines = [parts[0]]
    for p in parts[1:]:
        if len(lines[-1]) + 2 + len(p) > width:
            lines.append(p)
        else:
            lines[-1] += ", " + p
    return "\n".join(lines)


def layout(n: int, aspect: float, size) -> tuple[int, float, float]:
    """(columns, figure width, figure height) in inches: the most columns-efficient grid for n panels of
    height/width ``aspect`` within ``size`` pixels."""
    W, H = size[0] / DPI, size[1] / DPI
    best = None
    for c in range(1, n + 1):
        r = math.ceil(n / c)
        if c > 1 and W / c < MIN_PANEL_IN:
            break
        pw = W / (c * COLORBAR)                                # image width per panel
        pw = min(pw, (H - TITLE_IN - r * PANEL_TITLE_IN) / (r * aspect))
        if pw <= 0:
            continue
        if best is None or pw > best[1] + 1e-9:
            best = (c, pw, r)
    c, pw, r = best or (n, W / (n * COLORBAR), 1)
    return c, min(W, c * max(pw * COLORBAR, MIN_PANEL_IN)), r * (pw * aspect + PANEL_TITLE_IN) + TITLE_IN


def inspect(artifact, png, show=False, size=(1200, 900), **_options):
    from ..images import to_srgb8

    rgb = artifact["image"]
    panels = [("image\nsRGB, exposure 0", to_srgb8(rgb), None, None)]
    for name, (label, cmap) in CHANNELS.items():
        key = f"channels/{name}"
        if key in artifact:
            panels.append((f"{name}\n{label}", artifact[key], cmap, label))
    s = artifact.summary
    h, w = rgb.shape[:2]
    ncol, fw, fh = layout(len(panels), h / w, size)
    nrow = math.ceil(len(panels) / ncol)
    with pyplot(show) as plt:
        fig, axes = plt.subplots(nrow, ncol, figsize=(fw, fh), squeeze=False, layout="constrained")
        for ax in axes.ravel()[len(panels):]:
            ax.set_axis_off()
        for ax, (title, img, cmap, _label) in zip(axes.ravel(), panels):
            im = ax.imshow(img, cmap=cmap, interpolation="nearest")
            ax.set_title(title)
            ax.set_xticks([])
            ax.set_yticks([])
            if cmap is not None:
                fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
        mean = np.round(s.get("mean_rgb", [0, 0, 0]), 4).tolist()
        parts = [f"{s.get('method')} render {s.get('width', w)}x{s.get('height', h)} @ {s.get('spp')} spp",
                 f"{s.get('wall_time_s', 0):.2f} s wall", f"{s.get('paths_per_s', 0):.3g} paths/s",
                 f"{s.get('rays_per_s', 0):.3g} rays/s", f"mean RGB {mean}"]
        fig.suptitle(wrap(parts, int(fw * 10)))
        return finish(fig, png, show)
