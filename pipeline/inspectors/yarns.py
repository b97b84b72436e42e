"""Picture of a yarns artifact: each yarn as a tube (its radius) in its colour, with a legend of the yarn
groups (warp, weft, ...) and their colours; ``--frames`` adds the rotation-minimising frames as arrows
(T tangent blue, N normal red, B binormal green, named in the legend); ``--yarn K`` draws one yarn."""
from __future__ import annotations

import numpy as np

from . import pyvista_setup, view_with_legend

FRAME_COLORS = {"T (tangent)": (0.12, 0.35, 0.95), "N (normal)": (0.85, 0.1, 0.1), "B (binormal)": (0.1, 0.6, 0.15)}


def group_legend(art, chosen):
    """[(label, rgb)] for every (group, colour) among the chosen yarns, e.g. 'warp: yarns 0-7'."""
    color = np.clip(np.asarray(art["color"], float), 0, 1)
    group = np.asarray(art["group"]) if "group" in art else np.zeros(len(color), int)
    names = list(art.summary.get("groups") or [])
    entries: dict = {}
    for c in chosen:
        g = int(group[c])
        key = (g, tuple(np.round(color[c], 4)))
        entries.setdefault(key, []).append(c)
    out = []
    for (g, rgb), ys in entries.items():
        name = names[g] if 0 <= g < len(names) else f"group {g}"
        span = f"yarn {ys[0]}" if len(ys) == 1 else (f"yarns {ys[0]}-{ys[-1]}" if ys[-1] - ys[0] == len(ys) - 1
                                                      else f"{len(ys)} yarns")
        out.append((f"{name}: {span}", rgb))
    return out


def inspect(art, png, show=False, frames=False, yarn=-1, size=(1200, 900), **_):
    from stages.core.curves.frames import curve_frame_at
    from stages.ingest.spline_process import sample_curve_points

    from ..errors import LoomError
    from ..yarns import load_curves

    pv = pyvista_setup()
    cv = load_curves(art)
    color = art["color"]
    ncurve = len(cv.curve_length)
    if yarn >= ncurve:
        raise LoomError(art.path, "--yarn", f"no yarn {yarn} (yarns 0..{ncurve - 1})")
    chosen = list(range(ncurve)) if yarn < 0 else [yarn]
    plotter = pv.Plotter(off_screen=not show, window_size=[int(size[0]), int(size[1])])
    plotter.set_background("white")
    for c in chosen:
        npts = cv.offsets[c + 1] - cv.offsets[c]
        nsamp = int(min(max(8 * npts, 32), max(200, 400_000 // max(1, len(chosen)))))
        pts = sample_curve_points(cv, c, nsamp)
        if cv.closed[c]:
            pts = np.vstack([pts, pts[:1]])
        line = pv.PolyData(pts)
        line.lines = np.concatenate([[len(pts)], np.arange(len(pts))])
        tube = line.tube(radius=float(cv.radius[c]), n_sides=16, capping=True)
        plotter.add_mesh(tube, color=tuple(float(x) for x in np.clip(color[c], 0, 1)), smooth_shading=True)
        if frames:
            L = cv.curve_length[c]
            m = int(min(60, max(8, npts)))
            o, tt, nn, bb = [], [], [], []
            for s in np.linspace(0, L, m):
                pos, t, n, b = curve_frame_at(cv, c, s)
                o.append(pos)
                tt.append(t)
                nn.append(n)
                bb.append(b)
            o = np.array(o)
            scale = 2.0 * float(cv.radius[c])
            for vecs, col in zip((tt, nn, bb), FRAME_COLORS.values()):
                plotter.add_arrows(o, np.array(vecs), mag=scale, color=col)
    plotter.camera_position = "iso"
    plotter.camera.elevation = -15
    plotter.reset_camera()
    legend = group_legend(art, chosen)
    if frames:
        legend += list(FRAME_COLORS.items())
    what = f"yarn {yarn}" if yarn >= 0 else f"{ncurve} yarns"
    title = (f"yarns: {what}, {art.summary.get('source_format', '')} {art.summary.get('curve_type', '')}, "
             f"radius {float(np.min(cv.radius[chosen])):.3g}-{float(np.max(cv.radius[chosen])):.3g}"
             + (", rotation-minimising frames" if frames else ""))
    if show:
        plotter.add_text(title, font_size=12, color="black")
        plotter.add_legend([[lab, col] for lab, col in legend], bcolor="white", face="rectangle", size=(0.25, 0.2))
        plotter.show(screenshot=str(png) if png else None)
        return png
    from matplotlib.patches import Patch

    return view_with_legend(plotter, size, title,
                            [Patch(facecolor=col, edgecolor="0.3", label=lab) for lab, col in legend], "colours", png)
