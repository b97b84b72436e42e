"""Picture of an iirtf artifact (stage precompute iirtf): the cells' response to a directional light.

For a directional light of unit irradiance from ``LIGHT`` (default: 30 degrees from the normal), each
cell's transfer matrices give the SH coefficients of the indirect incoming radiance at its segments,
c_T = a_C^T Y(w_d) per channel (seed 001 §5.3.1); the fluence  int T dw1 = sqrt(4 pi) c_T[0]  is drawn:

  top row   one panel per z layer of the exemplar's cell grid (top layer first, at most 6), RGB over the
            exemplar's x-y cells on one exposure (empty cells hatched grey), with the block grid;
  bottom    the mean fluence of each layer against its height (per channel, with its Monte Carlo standard
            error), the cell grid and mean free path in the title, the order-0 to
            order-L energy of A_C (how directional the indirect light is) and, where the artifact has
            it, the exemplar's layer transmittance against cos theta (light from above and from below).
``--exemplar K`` picks the exemplar (default: the first in the artifact).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import LoomError
from . import finish, pyplot

LIGHT = np.array([math.sin(math.radians(30.0)) * math.cos(math.radians(20.0)),
                  math.sin(math.radians(30.0)) * math.sin(math.radians(20.0)), math.cos(math.radians(30.0))])


def cell_fluence(a, order: int, w_d):
    """(C, 3) fluence int T(w_d, w1) dw1 of every cell: a (C, 3, J, J) indexed [cell, channel, j0, j1]."""
    from stages.core.sh import sh_eval

    J = (order + 1) ** 2
    Y = np.empty(J)
    sh_eval(order, float(w_d[0]), float(w_d[1]), float(w_d[2]), Y)
    return math.sqrt(4 * math.pi) * np.einsum("chk,k->ch", a[:, :, :, 0].astype(np.float64), Y)


def cell_fluence_se(se, order: int, w_d):
    """(C, 3) standard error of ``cell_fluence``, treating the entries' errors as independent."""
    from stages.core.sh import sh_eval

    J = (order + 1) ** 2
    Y = np.empty(J)
    sh_eval(order, float(w_d[0]), float(w_d[1]), float(w_d[2]), Y)
    return math.sqrt(4 * math.pi) * np.sqrt(np.einsum("chk,k->ch", se[:, :, :, 0].astype(np.float64) ** 2, Y * Y))


def _layer_panel(ax, tau, se):
    """The layer transmittance tau (2, NB, 3) against cos theta: from above solid, from below dashed."""
    from stages.core.layer import FROM_ABOVE, FROM_BELOW, bin_centre

    nb = tau.shape[1]
    mu = np.array([bin_centre(i, nb) for i in range(nb)])
    for side, style, what in ((FROM_ABOVE, "-", "from above"), (FROM_BELOW, "--", "from below")):
        for ch, col in enumerate(("red", "green", "blue")):
            ax.errorbar(mu, tau[side, :, ch], yerr=se[side, :, ch], color=col, ls=style, marker="o", ms=2, capsize=1,
                        label=what if ch == 0 else None)
    ax.set_xlabel("cos theta of the light")
    ax.set_ylabel("share crossing the layer")
    ax.set_title("layer transmittance")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def inspect(art, png, show=False, size=(1200, 900), exemplar=None, **_):
    with pyplot(show) as plt:
        fig = _figure(plt, art, size, exemplar)
        return finish(fig, png, show)


def _figure(plt, art, size, exemplar):
    from matplotlib.patches import Patch

    infos = art.summary["exemplars"]
    ks = [i["exemplar"] for i in infos]
    k = ks[0] if exemplar is None else exemplar
    if k not in ks:
        raise LoomError(art.path, "--exemplar", f"exemplar {k} is not in this artifact (has {ks})")
    info = infos[ks.index(k)]
    L = int(art.summary["order"])
    a = art[f"exemplar_{k}/transfer"]
    se = art[f"exemplar_{k}/transfer_se"]
    cell_row = art[f"exemplar_{k}/cell_row"]
    NX, NY, NZ = info["cell_grid"]
    flu = np.zeros((len(cell_row), 3))
    flu_se = np.zeros((len(cell_row), 3))
    full = cell_row >= 0
    flu[full] = cell_fluence(a, L, LIGHT)[cell_row[full]]
    flu_se[full] = cell_fluence_se(se, L, LIGHT)[cell_row[full]]
    flu = flu.reshape(NZ, NY, NX, 3)
    empty = (~full).reshape(NZ, NY, NX)
    show_layers = list(range(NZ - 1, -1, -1))[:6]
    ncol = max(3, len(show_layers))
    fig = plt.figure(figsize=(size[0] / 100, size[1] / 100), dpi=100, layout="constrained")
    gs = fig.add_gridspec(2, ncol, height_ratios=[size[0] / ncol / 100 + 0.6, 4.0])
    expo = float(np.percentile(flu[~empty], 99)) if np.any(~empty) else 1.0
    expo = expo if expo > 0 else 1.0
    W, H = NX * info["cell_size"][0], NY * info["cell_size"][1]
    nbx, nby = (NX // info["cells_per_block"][0], NY // info["cells_per_block"][1])
    th = math.degrees(math.acos(LIGHT[2]))
    fig.suptitle(f"IIRTF of exemplar {k} '{info['name']}': response to a directional light {th:.0f} deg from the "
                 f"normal; {NX}x{NY}x{NZ} cells of {info['cell_size'][0]:.3g} x {info['cell_size'][1]:.3g} x "
                 f"{info['cell_size'][2]:.3g}, mean free path {info['mean_free_path']:.3g}, SH order {L}, "
                 f"{art.summary['paths']:,} paths/cell", fontsize=9)
    for i, iz in enumerate(show_layers):
        ax = fig.add_subplot(gs[0, i])
        img = np.clip(flu[iz] / expo, 0, 1) ** (1 / 2.2)
        img[empty[iz]] = 0.5
        ax.imshow(img, origin="lower", extent=[0, W, 0, H], interpolation="nearest")
        for bx in range(1, nbx):
            ax.axvline(bx * W / nbx, color="white", lw=0.4)
        for by in range(1, nby):
            ax.axhline(by * H / nby, color="white", lw=0.4)
        z0 = info["slab"][0] + iz * info["cell_size"][2]
        ax.set_title(f"layer {iz}: z {z0:.3f}-{z0 + info['cell_size'][2]:.3f}", fontsize=9)
        ax.set_xlabel("x (exemplar)")
        ax.set_ylabel("y (exemplar)")
    ax = fig.add_subplot(gs[1, : ncol // 2 + 1])
    zc = info["slab"][0] + (np.arange(NZ) + 0.5) * info["cell_size"][2]
    se0 = flu_se.reshape(NZ, NY * NX, 3)
    for ch, col in enumerate(("red", "green", "blue")):
        m = np.array([flu[iz][~empty[iz]][:, ch].mean() if np.any(~empty[iz]) else np.nan for iz in range(NZ)])
        e = np.array([np.sqrt((se0[iz][~empty[iz].ravel()][:, ch] ** 2).mean()) if np.any(~empty[iz]) else np.nan
                      for iz in range(NZ)])
        ax.errorbar(zc, m, yerr=e, color=col, marker="o", ms=3, capsize=2,
                    label=f"{col} (bars: RMS of the cells' Monte Carlo SE)")
    ax.set_xlabel("cell layer height z (exemplar space; the light comes from +z)")
    ax.set_ylabel("mean fluence of the indirect light, int T dw1")
    ax.legend(fontsize=9)
    ax.set_title("mean fluence per layer (the top row shows it per cell)")
    ax.grid(alpha=0.3)
    g = f"exemplar_{k}/"
    has_tau = "layer_bins" in art.summary   # IIRTFs made before 2026-12-07 have no layer transmittance
    right = gs[1, ncol // 2 + 1:].subgridspec(2 if has_tau else 1, 1)
    ax = fig.add_subplot(right[0])
    energy = []
    for l in range(L + 1):
        sl = slice(l * l, (l + 1) * (l + 1))
        energy.append(float((a[:, :, sl, :].astype(np.float64) ** 2).sum()))
    energy = np.array(energy) / max(sum(energy), 1e-300)
    ax.bar(np.arange(L + 1), energy, color="gray")
    ax.set_xlabel("SH order l of the light direction (rows of A_C)")
    ax.set_ylabel("share of sum a^2")
    ax.set_title("energy of A_C by order")
    if has_tau:
        _layer_panel(fig.add_subplot(right[1]), art[g + "layer_tau"], art[g + "layer_tau_se"])
    fig.legend(handles=[Patch(facecolor=(0.5, 0.5, 0.5), label="empty cell (no fibre)"),
                        Patch(facecolor="white", edgecolor="0.3", label="white lines: block grid"),
                        Patch(facecolor=(1, 0.85, 0.6), label=f"cell RGB = fluence / {expo:.3g} (99th pct.), sRGB")],
               loc="outside lower center", ncol=3, frameon=False, fontsize=9)
    return fig
