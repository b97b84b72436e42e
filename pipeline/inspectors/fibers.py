"""Picture of a fibers artifact: the realized fibres of one yarn (or a stretch of it) as lines,
regular fibres in the yarn's albedo, loops orange, hairs red (pyvista, off-screen)."""
from __future__ import annotations

import numpy as np

from . import pyvista_setup

KIND_COLORS = {2: (1.0, 0.55, 0.1), 3: (0.85, 0.1, 0.1)}
MAX_VERTICES = 400_000


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
    plotter = pv.Plotter(off_screen=not show, window_size=list(size))
    plotter.set_background("white")
    groups = {}
    for f in fibres:
        p = pts[off[f]:off[f + 1]]
        keep = np.abs(p[:, axis] - centre) <= half
        if keep.sum() < 2:
            continue
        p = p[keep]
        groups.setdefault(int(kind[f]), []).append(p)
    for k, polys in groups.items():
        allp = np.concatenate(polys)
        lines = []
        base = 0
        for p in polys:
            lines.append(np.concatenate([[len(p)], base + np.arange(len(p))]))
            base += len(p)
        mesh = pv.PolyData(allp)
        mesh.lines = np.concatenate(lines)
        color = tuple(np.clip(albedo[y], 0, 1)) if k == 1 else KIND_COLORS[k]
        plotter.add_mesh(mesh, color=color, line_width=2 if k == 1 else 3, render_lines_as_tubes=False,
                         label={1: "regular", 2: "loop", 3: "hair"}[k])
    plotter.add_legend(bcolor="white", face="line")
    plotter.add_axes()
    plotter.camera_position = "iso"
    plotter.reset_camera()
    if show:
        plotter.show(screenshot=str(png) if png else None)
    else:
        plotter.screenshot(str(png))
        plotter.close()
    return png
