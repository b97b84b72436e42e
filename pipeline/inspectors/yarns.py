"""Picture of a yarns artifact: each yarn as a tube (its radius) coloured by yarn, optional RMF glyphs."""
from __future__ import annotations

import numpy as np

from . import pyvista_setup


def inspect(art, png, show=False, frames=False, yarn=-1, size=(1200, 900), **_):
    from stages.ingest.spline_process import sample_curve_points
    from stages.core.curves.frames import curve_frame_at

    from ..yarns import load_curves

    pv = pyvista_setup()
    cv = load_curves(art)
    color = art["color"]
    ncurve = len(cv.curve_length)
    chosen = range(ncurve) if yarn < 0 else [yarn]
    total = max(1, int(art.summary["control_points"]))
    plotter = pv.Plotter(off_screen=not show, window_size=list(size))
    plotter.set_background("white")
    for c in chosen:
        npts = cv.offsets[c + 1] - cv.offsets[c]
        nsamp = int(min(max(8 * npts, 32), max(200, 400_000 // max(1, len(list(chosen))))))
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
            ss = np.linspace(0, L, m)
            o, nn, bb = [], [], []
            for s in ss:
                pos, t, n, b = curve_frame_at(cv, c, s)
                o.append(pos); nn.append(n); bb.append(b)
            o = np.array(o)
            scale = 2.0 * float(cv.radius[c])
            plotter.add_arrows(o, np.array(nn), mag=scale, color="red")
            plotter.add_arrows(o, np.array(bb), mag=scale, color="green")
    plotter.add_axes()
    plotter.camera_position = "iso"
    plotter.camera.elevation = -15
    plotter.reset_camera()
    if show:
        plotter.show(screenshot=str(png) if png else None)
    else:
        plotter.screenshot(str(png))
        plotter.close()
    return png
