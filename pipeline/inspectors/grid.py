"""Picture of a ``grid`` artifact (loomlight voxelize): density projected along z (mean over z, i.e.
the optical depth per unit sigma_t), one density slice through the middle of z, the density-weighted
albedo seen from above, and the mean fibre direction's |x| vs |y| balance (warp vs weft) of the slice."""
from __future__ import annotations

import numpy as np

from . import finish, pyplot


def inspect(artifact, png, show=False, size=(1200, 900), z=None, **_options):
    with pyplot(show) as plt:
        return finish(_figure(plt, artifact, size, z), png, show)


def _figure(plt, artifact, size, z):
    from ..errors import LoomError

    den = artifact["density"]
    alb = artifact["albedo"]
    dirs = artifact["direction"]
    s = artifact.summary
    lo, hi = (np.asarray(v, float) for v in s["bounds"])
    nz = den.shape[0]
    if z is None:
        k = nz // 2
    else:
        if not lo[2] <= z <= hi[2]:
            raise LoomError(artifact.path, "--z", f"z = {z} is outside the grid's z range [{lo[2]:.4g}, {hi[2]:.4g}]")
        k = min(int((z - lo[2]) / (hi[2] - lo[2]) * nz), nz - 1)
    w = den.sum(axis=0)
    top = np.where(w[..., None] > 0, (alb * den[..., None]).sum(axis=0) / np.maximum(w[..., None], 1e-30), 0.0)
    ext = [lo[0], hi[0], lo[1], hi[1]]
    d = dirs[k]
    balance = np.where(den[k] > 0, np.abs(d[..., 0]) - np.abs(d[..., 1]), np.nan)
    panels = [("density, mean over z", den.mean(axis=0), "magma", "density (1/length)"),
              (f"density, slice z = {lo[2] + (k + 0.5) * (hi[2] - lo[2]) / nz:.4g}", den[k], "magma",
               "density (1/length)"),
              ("albedo (density-weighted, top view, RGB)", np.clip(top, 0, 1), None, None),
              ("slice direction |x| - |y| (red: along x, blue: along y)", balance, "coolwarm", "|d_x| - |d_y|")]
    dpi = 100
    fig, axes = plt.subplots(2, 2, figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    for ax, (title, img, cmap, label) in zip(axes.ravel(), panels):
        im = ax.imshow(img, cmap=cmap, origin="lower", extent=ext, interpolation="nearest",
                       **({"vmin": -1, "vmax": 1} if cmap == "coolwarm" else {}))
        ax.set_title(title)
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        if cmap is not None:
            fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label=label)
    r = s["resolution"]
    fig.suptitle(f"grid {r[0]}x{r[1]}x{r[2]}, {100 * s['occupied_fraction']:.1f}% occupied, "
                 f"max density {s['max_density']:.4g}")
    fig.tight_layout()
    return fig
