"""Picture of a tiling artifact (stage tile):

- left: the base mesh textured with its block map (one texel per block, through the mesh's uv): the
  block's exemplar sets the hue (named in the legend), alternate blocks are shaded 25% darker so single
  blocks stand out, with the triangle edges and the shell's outer boundary (w = 1 faces and open sides)
  as a translucent surface (pyvista off-screen);
- right: every exemplar (``--yarn K``: exemplar K only) seen from the top over one repeat, its fibres
  coloured by yarn group (warp / weft), drawn bottom to top and darker the deeper they lie, so the weave
  (which yarn floats over which) is visible; the exemplar's block grid with the block ids
  (bx + nbx by) on top.

A picture smaller than ``FULL_LAYOUT`` (pixels) has no room for the exemplar panels at legible type sizes:
it shows the base view and its legend alone, and says so in its title.
"""
from __future__ import annotations

import numpy as np

from . import finish, image_panel, pyplot, pyvista_setup, screenshot

PALETTE = np.array([[0.85, 0.70, 0.35], [0.55, 0.12, 0.16], [0.20, 0.45, 0.70], [0.30, 0.62, 0.32],
                    [0.60, 0.40, 0.70], [0.85, 0.50, 0.20]])
GROUP_COLORS = {0: ("warp", (0.90, 0.60, 0.10)), 1: ("weft", (0.15, 0.38, 0.80)), 2: ("knit", (0.75, 0.25, 0.20))}
SHELL_COLOR = "lightblue"
MAX_BLOCK_LABELS = 64
FULL_LAYOUT = (900, 500)     # the least (width, height) in pixels that holds the exemplar panels


def block_texture(block_map):
    """(nbv, nbu, 3) uint8 image: row 0 = v top, hue by exemplar, shade by block parity."""
    nbu, nbv = block_map.shape
    i, j = np.meshgrid(np.arange(nbu), np.arange(nbv), indexing="ij")
    col = PALETTE[np.maximum(block_map, 0) % len(PALETTE)] * np.where((i + j) % 2 == 0, 1.0, 0.75)[..., None]
    col[block_map < 0] = 0.0
    img = np.transpose(col, (1, 0, 2))[::-1]  # (v, u) with v upwards
    return np.ascontiguousarray((np.clip(img, 0, 1) * 255).astype(np.uint8))


def exemplar_segments(art, k: int):
    """(segments (S, 2, 3), yarn group (S,), block (S,)) of exemplar k's fibre polylines."""
    ex_f, O, P = art["ex_fibers"], art["ex_offsets"], art["ex_points"]
    sizes = art.summary["exemplar_sizes"]
    g0 = int(sum(e + p for e, p in sizes[:k]))
    groups = art["ex_yarn_group"][g0:g0 + sum(sizes[k])]
    fyarn = art["ex_fiber_yarn"]
    f0, f1 = int(ex_f[k]), int(ex_f[k + 1])
    p0, p1 = int(O[f0]), int(O[f1])
    pts = P[p0:p1]
    counts = np.diff(O[f0:f1 + 1])
    starts = np.ones(p1 - p0, bool)            # a segment starts at every point but each fibre's last
    starts[np.cumsum(counts) - 1] = False
    idx = np.nonzero(starts)[0]
    seg = np.stack([pts[idx], pts[idx + 1]], axis=1)
    fib = np.repeat(np.arange(f0, f1), counts - 1)
    grp = groups[fyarn[fib]]
    s0 = p0 - f0                               # the first segment of exemplar k in seg_block
    blk = art["seg_block"][s0:s0 + len(seg)]
    return seg, grp, blk


def draw_exemplar(ax, art, k: int) -> None:
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Rectangle

    seg, grp, _ = exemplar_segments(art, k)
    W, H = (float(v) for v in art["ex_period"][k])
    bw, bh = (float(v) for v in art["block_size"])
    zmid = seg[:, :, 2].mean(axis=1)
    order = np.argsort(zmid, kind="stable")    # deepest first: upper fibres cover lower ones
    lo, hi = float(zmid.min()), float(zmid.max())
    shade = 0.35 + 0.65 * (zmid - lo) / max(hi - lo, 1e-12)
    base = np.array([GROUP_COLORS.get(int(g), ("", (0.5, 0.5, 0.5)))[1] for g in range(int(grp.max()) + 1)])
    colors = base[grp] * shade[:, None]
    radius = float(np.median(art["ex_radius"]))
    # line width: the fibre's diameter in points at the panel's scale (at least a hairline)
    bbox = ax.get_window_extent().transformed(ax.figure.dpi_scale_trans.inverted())
    pts_per_unit = 72.0 * bbox.width / (1.1 * W)
    lw = max(0.3, 2 * radius * pts_per_unit)
    ax.add_collection(LineCollection(seg[order][:, :, :2], colors=np.clip(colors[order], 0, 1), linewidths=lw,
                                     capstyle="round"))
    nbx, nby = (int(v) for v in art["ex_nblocks"][k])
    for i in range(nbx + 1):
        ax.axvline(i * bw, color="black", lw=0.8, alpha=0.7)
    for j in range(nby + 1):
        ax.axhline(j * bh, color="black", lw=0.8, alpha=0.7)
    if nbx * nby <= MAX_BLOCK_LABELS:
        for j in range(nby):
            for i in range(nbx):
                ax.text((i + 0.04) * bw, (j + 0.04) * bh, str(i + nbx * j), ha="left", va="bottom", fontsize=9,
                        color="black", bbox=dict(boxstyle="square,pad=0.1", fc="white", ec="none", alpha=0.6))
    ax.add_patch(Rectangle((0, 0), W, H, fill=False, ec="black", lw=1.6))
    m = 0.05 * max(W, H)
    ax.set_xlim(-m, W + m)
    ax.set_ylim(-m, H + m)
    ax.set_aspect("equal")
    ax.set_xlabel("x (exemplar)")
    ax.set_ylabel("y (exemplar)")
    E, Pk = art.summary["exemplar_sizes"][k]
    size = f"{E} ends x {Pk} picks"
    if art.summary.get("exemplar_kind") == "knit":
        wales, courses = art.summary["exemplar_stitches"][k]
        size = f"{wales} wales x {courses} courses"
    ax.set_title(f"exemplar {k} '{art.summary['exemplar_names'][k]}' from the top:\n"
                 f"{size}, {nbx} x {nby} blocks (ids)")


def base_view(art, pv, size, off_screen):
    V, UV, F = art["base_vertices"], art["base_uv"], art["base_triangles"]
    base = pv.PolyData(V, np.hstack([np.full((len(F), 1), 3), F]).ravel())
    base.active_texture_coordinates = UV.astype(np.float32)
    tex = pv.Texture(block_texture(art["block_map"]))
    tex.interpolate = False
    tri = art["bnd_tri"].reshape(-1, 3)
    shell = pv.PolyData(tri, np.hstack([np.full((len(art["bnd_tri"]), 1), 3),
                                        np.arange(len(tri)).reshape(-1, 3)]).ravel())
    plotter = pv.Plotter(off_screen=off_screen, window_size=[int(size[0]), int(size[1])])
    plotter.set_background("white")
    plotter.add_mesh(base, texture=tex, show_edges=True, edge_color="gray", line_width=0.5)
    plotter.add_mesh(shell, color=SHELL_COLOR, opacity=0.25)
    plotter.camera_position = "iso"
    plotter.reset_camera()
    return plotter


def base_legend(art):
    bm = np.asarray(art["block_map"])
    names = art.summary["exemplar_names"]
    out = [(f"exemplar {k} '{n}': {int((bm == k).sum())} blocks", tuple(PALETTE[k % len(PALETTE)]))
           for k, n in enumerate(names)]
    out.append(("alternate blocks: 25% darker", tuple(PALETTE[0] * 0.75)))
    if np.any(bm < 0):
        out.append((f"no exemplar: {int((bm < 0).sum())} blocks", (0.0, 0.0, 0.0)))
    out.append(("shell outer boundary", SHELL_COLOR))
    return out


def inspect(art, png, show=False, yarn=-1, size=(1200, 900), **_):
    pv = pyvista_setup()
    s = art.summary
    K = int(s["exemplars"])
    ks = [yarn] if 0 <= yarn < K else list(range(K))
    ncol = 1 if len(ks) == 1 else 2
    nrow = (len(ks) + ncol - 1) // ncol
    base_title = (f"base mesh ({s['surface']}) textured by block map, {s['block_grid'][0]} x {s['block_grid'][1]} "
                  f"blocks;\nshell of {s['tetrahedra']} tetrahedra, thickness {s['thickness']:.3g}")
    if show:
        plotter = base_view(art, pv, size, off_screen=False)
        plotter.add_text(base_title, font_size=12, color="black")
        plotter.add_legend([[lab, col] for lab, col in base_legend(art)], bcolor="white", face="rectangle",
                           size=(0.3, 0.2))
        plotter.show()
    if size[0] < FULL_LAYOUT[0] or size[1] < FULL_LAYOUT[1]:
        return _compact(art, pv, png, show, size, base_title)
    wl = size[0] * 0.45
    img = screenshot(base_view(art, pv, (wl, size[1]), off_screen=True))
    # figure height from the content: the base view at its aspect in the left 45%, titles and legends
    h_in = min(size[1] / 100, 0.45 * size[0] / 100 * img.shape[0] / img.shape[1] + 1.6)
    with pyplot(show) as plt:
        from matplotlib.patches import Patch

        fig = plt.figure(figsize=(size[0] / 100, h_in), layout="constrained")
        gs = fig.add_gridspec(nrow, 1 + ncol, width_ratios=[1.3] + [1] * ncol)
        ax = fig.add_subplot(gs[:, 0])
        image_panel(ax, img, base_title)
        ax.legend(handles=[Patch(facecolor=c, edgecolor="0.3", alpha=0.5 if c == SHELL_COLOR else 1, label=l)
                           for l, c in base_legend(art)], loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=2,
                  frameon=False, title="block colours")
        axes = [fig.add_subplot(gs[i // ncol, 1 + i % ncol]) for i in range(len(ks))]
        for ax, k in zip(axes, ks):
            draw_exemplar(ax, art, k)
        axes[len(axes) - ncol if len(axes) >= ncol else 0].legend(
            handles=[Patch(facecolor=c, label=n) for g, (n, c) in GROUP_COLORS.items()
                     if np.any(art["ex_yarn_group"] == g)], loc="upper left",
            bbox_to_anchor=(0.0, -0.16), ncol=2, frameon=False, title="yarn (darker = deeper in the cloth)",
            alignment="left")
        return finish(fig, png, show)


def _compact(art, pv, png, show, size, base_title):
    """The base view and its legend alone, at ``size`` (smaller than ``FULL_LAYOUT``)."""
    from matplotlib.patches import Patch

    img = screenshot(base_view(art, pv, (size[0] * 0.55, size[1]), off_screen=True))
    with pyplot(show) as plt:
        fig = plt.figure(figsize=(size[0] / 100, size[1] / 100), layout="constrained")
        ax_img, ax_leg = fig.subplots(1, 2, width_ratios=[1.2, 1])
        image_panel(ax_img, img, "")
        fig.suptitle(base_title)        # across the figure: the view's own width is too narrow for it
        ax_leg.set_axis_off()
        ax_leg.legend(handles=[Patch(facecolor=c, edgecolor="0.3", alpha=0.5 if c == SHELL_COLOR else 1, label=l)
                               for l, c in base_legend(art)], loc="center left", frameon=False,
                      title=f"block colours (exemplar panels:\n{FULL_LAYOUT[0]} x {FULL_LAYOUT[1]} px or more)",
                      alignment="left")
        return finish(fig, png, show)
