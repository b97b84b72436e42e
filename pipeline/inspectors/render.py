"""Picture of a ``render`` artifact: the sRGB preview of its image beside its alpha and depth channels,
titled with the method and statistics (spp, wall time, paths/s, rays/s)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def inspect(artifact, png, show=False, size=(1200, 900), **_options):
    import matplotlib

    if not show:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..images import to_srgb8

    rgb = artifact["image"]
    panels = [("image (sRGB preview)", to_srgb8(rgb), None)]
    for name in ("A", "depth", "variance"):
        key = f"channels/{name}"
        if key in artifact:
            panels.append((name, artifact[key], "viridis"))
    s = artifact.summary
    dpi = 100
    fig, axes = plt.subplots(1, len(panels), figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi, squeeze=False)
    for ax, (title, img, cmap) in zip(axes[0], panels):
        im = ax.imshow(img, cmap=cmap, interpolation="nearest")
        ax.set_title(title)
        ax.set_axis_off()
        if cmap is not None:
            fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    fig.suptitle(f"{s.get('method')} {s.get('width')}x{s.get('height')} @ {s.get('spp')} spp: "
                 f"{s.get('wall_time_s', 0):.2f} s wall, {s.get('paths_per_s', 0):.3g} paths/s, "
                 f"{s.get('rays_per_s', 0):.3g} rays/s, mean rgb {np.round(s.get('mean_rgb', [0, 0, 0]), 4).tolist()}")
    fig.tight_layout()
    out = None
    if png is not None:
        out = Path(png)
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out)
    if show:
        plt.show()
    plt.close(fig)
    return out
