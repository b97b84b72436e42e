"""Picture of a tiling artifact (stage tile), two panels:

- left: the base mesh textured with its block ids (one texel per block, through the mesh's uv: the
  exemplar of the block sets the hue, a checkerboard of blocks the shade), its triangle edges, and the
  shell's outer boundary (w = 1 faces and open sides) as a translucent surface;
- right: exemplar 0 (or ``--yarn K``: exemplar K) as fibre polylines in exemplar space, coloured by the
  block each segment belongs to, over the exemplar's block grid.
"""
from __future__ import annotations

import numpy as np

from . import pyvista_setup

PALETTE = np.array([[0.85, 0.70, 0.35], [0.55, 0.12, 0.16], [0.20, 0.45, 0.70], [0.30, 0.62, 0.32],
                    [0.60, 0.40, 0.70], [0.85, 0.50, 0.20]])


def block_texture(block_map):
    """(nbv, nbu, 3) uint8 image: row 0 = v top, hue by exemplar, shade by block parity."""
    nbu, nbv = block_map.shape
    i, j = np.meshgrid(np.arange(nbu), np.arange(nbv), indexing="ij")
    col = PALETTE[np.maximum(block_map, 0) % len(PALETTE)] * np.where((i + j) % 2 == 0, 1.0, 0.75)[..., None]
    col[block_map < 0] = 0.0
    img = np.transpose(col, (1, 0, 2))[::-1]  # (v, u) with v upwards
    return np.ascontiguousarray((np.clip(img, 0, 1) * 255).astype(np.uint8))


def inspect(art, png, show=False, yarn=-1, size=(1200, 900), **_):
    pv = pyvista_setup()
    V = art["base_vertices"]
    UV = art["base_uv"]
    F = art["base_triangles"]
    faces = np.hstack([np.full((len(F), 1), 3), F]).ravel()
    base = pv.PolyData(V, faces)
    base.active_texture_coordinates = UV.astype(np.float32)
    tex = pv.Texture(block_texture(art["block_map"]))
    tex.interpolate = False
    tri = art["bnd_tri"].reshape(-1, 3)
    bfaces = np.hstack([np.full((len(art["bnd_tri"]), 1), 3), np.arange(len(tri)).reshape(-1, 3)]).ravel()
    shell = pv.PolyData(tri, bfaces)

    plotter = pv.Plotter(off_screen=not show, window_size=list(size), shape=(1, 2))
    plotter.set_background("white")
    plotter.subplot(0, 0)
    plotter.add_text(f"base mesh + block ids ({art.summary['block_grid'][0]} x {art.summary['block_grid'][1]} blocks), "
                     f"shell ({art.summary['tetrahedra']} tetrahedra)", font_size=9, color="black")
    plotter.add_mesh(base, texture=tex, show_edges=True, edge_color="gray", line_width=0.5)
    plotter.add_mesh(shell, color="lightblue", opacity=0.25)
    plotter.camera_position = "iso"
    plotter.reset_camera()

    plotter.subplot(0, 1)
    K = int(art.summary["exemplars"])
    k = yarn if 0 <= yarn < K else 0
    name = art.summary["exemplar_names"][k]
    ex_f = art["ex_fibers"]
    O = art["ex_offsets"]
    P = art["ex_points"]
    f0, f1 = int(ex_f[k]), int(ex_f[k + 1])
    p0, p1 = int(O[f0]), int(O[f1])
    pts = P[p0:p1]
    offs = O[f0:f1 + 1] - p0
    lines = np.concatenate([np.r_[offs[f + 1] - offs[f], np.arange(offs[f], offs[f + 1])] for f in range(f1 - f0)])
    poly = pv.PolyData(pts)
    poly.lines = lines
    seg_block = art["seg_block"]
    s0 = p0 - f0  # first segment of exemplar k
    nseg = (p1 - p0) - (f1 - f0)
    # point scalars: the block of the segment that starts at the point (last point: its segment's)
    blk = np.empty(len(pts))
    sb = seg_block[s0:s0 + nseg]
    si = 0
    for f in range(f1 - f0):
        n = offs[f + 1] - offs[f]
        blk[offs[f]:offs[f + 1] - 1] = sb[si:si + n - 1]
        blk[offs[f + 1] - 1] = sb[si + n - 2]
        si += n - 1
    poly["block"] = blk
    plotter.add_text(f"exemplar {k} '{name}': {f1 - f0} fibres by block", font_size=9, color="black")
    plotter.add_mesh(poly, scalars="block", cmap="tab20", line_width=1.5, show_scalar_bar=False)
    W, H = art["ex_period"][k]
    bw, bh = art["block_size"]
    grid = []
    for x in np.arange(0, W + 1e-9, bw):
        grid.append(pv.Line((x, 0, 0), (x, H, 0)))
    for y in np.arange(0, H + 1e-9, bh):
        grid.append(pv.Line((0, y, 0), (W, y, 0)))
    for g in grid:
        plotter.add_mesh(g, color="black", line_width=1)
    plotter.view_isometric()
    plotter.reset_camera()
    if show:
        plotter.show(screenshot=str(png) if png else None)
    else:
        plotter.screenshot(str(png))
        plotter.close()
    return png
