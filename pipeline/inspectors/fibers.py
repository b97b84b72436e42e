"""Picture of a fibers artifact: the realized fibres of one yarn (or a stretch of it) as lines seen from
the side, by kind in distinct colours named in the legend: regular blue, loop orange, hair red (the same
colours as the tables inspector's cross-section), pyvista off-screen. The title gives the yarn, its
albedo, the stretch drawn and the fibre counts."""
from __future__ import annotations

import numpy as np

from . import pyvista_setup, view_with_legend

KIND_NAMES = {1: "regular", 2: "loop", 3: "hair"}
KIND_COLORS = {1: (0.12, 0.40, 0.75), 2: (1.0, 0.55, 0.05), 3: (0.85, 0.08, 0.08)}
MAX_VERTICES = 400_000
VIEWS = {0: "xz", 1: "yz", 2: "xz"}   # look across the stretch's main axis, z up where possible


def inspect(art, png, show=False, yarn=-1, z=None, size=(1200, 900), **_):
    """yarn: the yarn to draw (default 0); z: centre of the stretch along the yarn's main axis
    (default: the middle); the stretch is long enough to hold at most MAX_VERTICES vertices."""
    pv = pyvista_setup()
    pts = np.asarray(art["points"], np.float64)
    off = np.asarray(art["fiber_offsets"], np.int64)
    fy = np.asarray(art["fiber_yarn"])
    kind = np.asarray(art["fiber_kind"])
    albedo = np.asarray(art["yarn_albedo"], np.float64)
    y = max(int(yarn), 0)
    fibres = np.nonzero(fy == y)[0]
    if len(fibres) == 0:
        from ..errors import LoomError

        raise LoomError(art.path, "--yarn", f"no fibres of yarn {y} (yarns 0..{int(fy.max())})")
    sel = np.concatenate([np.arange(off[f], off[f + 1]) for f in fibres])
    ext = pts[sel].max(0) - pts[sel].min(0)
    axis = int(np.argmax(ext))
    centre = float(np.median(pts[sel, axis])) if z is None else float(z)
    half = 0.5 * ext[axis] * min(1.0, MAX_VERTICES / max(len(sel), 1))
    plotter = pv.Plotter(off_screen=not show, window_size=[int(size[0]), int(size[1])])
    plotter.set_background("white")
    groups = {}
    for f in fibres:
        p = pts[off[f]:off[f + 1]]
        keep = np.abs(p[:, axis] - centre) <= half
        if keep.sum() < 2:
            continue
        groups.setdefault(int(kind[f]), []).append(p[keep])
    for k in sorted(groups):
        polys = groups[k]
        lines, base = [], 0
        for p in polys:
            lines.append(np.concatenate([[len(p)], base + np.arange(len(p))]))
            base += len(p)
        mesh = pv.PolyData(np.concatenate(polys))
        mesh.lines = np.concatenate(lines)
        plotter.add_mesh(mesh, color=KIND_COLORS[k], line_width=1.5 if k == 1 else 2.5, render_lines_as_tubes=False,
                         label=KIND_NAMES[k])
    plotter.camera_position = VIEWS[axis]
    plotter.camera.elevation = 20
    plotter.reset_camera()
    counts = {k: len(v) for k, v in groups.items()}
    legend = [(f"{KIND_NAMES[k]} ({counts.get(k, 0)} fibres)", KIND_COLORS[k]) for k in (1, 2, 3)]
    axname = "xyz"[axis]
    title = (f"fibres of yarn {y} (albedo {', '.join(f'{v:.2f}' for v in albedo[y])}): "
             f"{axname} {centre - half:.3g} to {centre + half:.3g}, seen across {axname}")
    if show:
        plotter.add_text(title, font_size=12, color="black")
        plotter.add_legend([[lab, col] for lab, col in legend], bcolor="white", face="line", size=(0.25, 0.15))
        plotter.show(screenshot=str(png) if png else None)
        return png
    from matplotlib.lines import Line2D

    return view_with_legend(plotter, size, title, [Line2D([], [], color=col, lw=3, label=lab) for lab, col in legend],
                            "fibre kind", png)
