"""Picture of a btf artifact (stage precompute btf, seed 002): what was acquired and what was fitted.

Top rows, for two view/light pairs (a view near the normal with a light at mid elevation, and a
grazing view with the light opposite it): the acquired radiance per texel r(l, v) beside the fitted
model f_r(l, v) = T(v) . f_1(l, v) of level 0 (seed 002 Eq. 1-2), on one shared scale per pair
(sRGB-encoded, the scale in the title), the texel's alpha for that view, and the per-texel difference.
A texture of several exemplars (a damask's) shows the first pair for each exemplar instead (at most
``MAX_EXEMPLAR_ROWS``), each on its own scale.
Bottom row: the mip pyramid of the first exemplar, the fitted model of every level for the first pair,
each level's texels drawn at the size of level 0 (seed 002 §5.1), with the level's fit RMSE.
A texture with the tabulated model (``precompute btf --model tabulated``) shows, in each top row, the decoded
table of level 0 beside the fit (the same view and light, the same scale) and both differences from the acquired
data; and at the end of the bottom row, the compression's relative RMSE against the component count per
exemplar (``tabulated/rel_rmse_by_components``: 0 components = the cluster means). A texture acquired with light
from below too (``--light-domain sphere``) adds a row: the first pair's light mirrored below the fabric. A relief
texture (``--plane relief``) ends the bottom row with the first exemplar's heights over its surface plane.
"""
from __future__ import annotations

import numpy as np

from . import finish, pyplot

MAX_EXEMPLAR_ROWS = 3


def _pairs(summary, views):
    """[(view index, light index, light direction)] x 2: the light index is the samples' (a half-vector cell with
    ``light_coords`` half: the one whose centre, seen from the view, is nearest the hemisphere grid's choice)."""
    from stages.core.btf import half_cell_direction, hemisphere_grid

    nv_t, nv_p = summary["view_grid"]
    half = summary.get("light_coords", "hemisphere") == "half"
    nl_t, nl_p = summary["fit_light_grid"] if half else summary["light_grid"]
    grid = hemisphere_grid(nl_t, nl_p)
    v0 = 0
    l0 = (nl_t // 2) * nl_p
    v1 = (max(nv_t - 2, 0)) * nv_p
    l1 = (nl_t // 2) * nl_p + nl_p // 2
    out = []
    for vi, li in ((v0, l0), (v1, l1)):
        if not half:
            out.append((vi, li, grid[li]))
            continue
        nx, ny = summary["light_grid"]
        cells = np.array([half_cell_direction(j, nx, ny, 0.5, 0.5, *(float(x) for x in views[vi]))
                          for j in range(nx * ny)])
        j = int(np.argmax(np.where(cells[:, 2] > 0.0, cells @ grid[li], -np.inf)))
        out.append((vi, j, cells[j]))
    return out


def model_image(rho, lobes, table, frame, view_grid, v_dir, l_dir):
    """(r, r, 3) f_r(l, v) of every texel of one level."""
    from stages.core.btf import table_lookup, texel_f1

    r = rho.shape[0]
    out = np.zeros((r, r, 3))
    nt, npz = (int(x) for x in view_grid)
    for i in range(r):
        for j in range(r):
            for c in range(3):
                f1 = texel_f1(rho[i, j].astype(np.float64), lobes[i, j].astype(np.float64),
                              frame[i, j].astype(np.float64), c, *l_dir, *v_dir)
                out[i, j, c] = f1 * table_lookup(table[i, j].astype(np.float64), nt, npz, *v_dir, c)
    return out


def _srgb(x, scale):
    y = np.clip(np.asarray(x, float) / max(scale, 1e-12), 0.0, 1.0)
    return np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1 / 2.4) - 0.055)


def _angles(d):
    theta = np.degrees(np.arccos(np.clip(d[2], -1, 1)))
    phi = np.degrees(np.arctan2(d[1], d[0])) % 360
    return f"θ {theta:.0f}° φ {phi:.0f}°"


def inspect(art, png, show=False, size=(1200, 900), **_):
    s = art.summary
    views = art["view_dirs"]
    samples = art["samples"]
    alpha = art["alpha"]
    levels = int(s["levels"])
    lev0 = {n: art[f"level_0/{n}"] for n in ("rho", "lobes", "table", "frame")}
    pairs = _pairs(s, views)
    names = s.get("exemplar_names", [])
    E = int(lev0["rho"].shape[0])
    rows = [(0, pr) for pr in pairs] if E == 1 else [(e, pairs[0]) for e in range(min(E, MAX_EXEMPLAR_ROWS))]
    if s.get("light_domain") == "sphere":   # the first pair's light mirrored below the fabric: light through it
        vi, li, ldir = pairs[0]
        rows.append((0, (vi, li + int(np.prod(s["light_grid"])), np.asarray(ldir) * np.array([1.0, 1.0, -1.0]))))
    res = int(s["resolution"])
    tabulated = "tabulated/weights" in art.arrays()
    tables = {}
    if tabulated:       # the renderer's decoded table (pipeline.renderers.btf.load_table): exemplar e's level 0
        from ..renderers.btf import load_table, table_lights

        V, L = len(views), table_lights(s)
        table = load_table(art, art.path, E, res, levels, V, L)
        per = len(table) // E
        tables = {e: table[e * per:e * per + res * res].reshape(res, res, V, L, 3) for e, _ in rows}
    with pyplot(show) as plt:
        fig = plt.figure(figsize=(size[0] / 100, size[1] / 100), layout="constrained")
        top = fig.subfigures(len(rows) + 1, 1, height_ratios=[1] * len(rows) + [0.9])
        for row, (e, (vi, li, ldir)) in enumerate(rows):
            acq = samples[e, :, :, vi, li, :].astype(np.float64)
            fit = model_image(lev0["rho"][e], lev0["lobes"][e], lev0["table"][e], lev0["frame"][e], s["view_grid"],
                              views[vi], ldir)
            scale = float(max(np.percentile(acq, 99.5), 1e-6))
            models = [("fitted T(v) f₁(l, v)" if not tabulated else "Lafortune fit", "fit", fit)]
            if tabulated:
                models.append(("tabulated (decoded)", "table", tables[e][:, :, vi, li, :].astype(float)))
            axes = list(top[row].subplots(1, 2 + 2 * len(models)))
            axes[0].imshow(_srgb(acq, scale), origin="lower", interpolation="nearest")
            axes[0].set_title(f"acquired, scale {scale:.3g}" if tabulated else f"acquired r(l, v), scale {scale:.3g}")
            for ax, (title, _, img) in zip(axes[1:], models):
                ax.imshow(_srgb(img, scale), origin="lower", interpolation="nearest")
                ax.set_title(title)
            a_ax = axes[1 + len(models)]
            im = a_ax.imshow(alpha[e, :, :, vi], origin="lower", vmin=0, vmax=1, cmap="gray", interpolation="nearest")
            a_ax.set_title("alpha" if tabulated else "alpha of this view")
            fig.colorbar(im, ax=a_ax, shrink=0.8)
            diffs = [(img - acq).mean(axis=-1) / scale for _, _, img in models]
            lim = max(max(float(np.abs(d).max()) for d in diffs), 1e-6)
            for ax, (_, short, _), diff in zip(axes[2 + len(models):], models, diffs):
                im = ax.imshow(diff, origin="lower", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
                ax.set_title(f"{short} − acquired" + ("" if tabulated else " (/ scale)"))
                fig.colorbar(im, ax=ax, shrink=0.8)
            for ax in axes:
                ax.set_xticks([])
                ax.set_yticks([])
            who = f"{names[e]}: " if E > 1 and e < len(names) else ""
            cell = f" (half-vector cell {li}'s centre)" if s.get("light_coords") == "half" else ""
            if ldir[2] < 0.0:
                cell = " (below the fabric: the light through it; the fit is a reflectance)"
            top[row].suptitle(f"{who}view {_angles(views[vi])}, light {_angles(ldir)}{cell}  (level 0, texels x → , y ↑"
                              + ("; differences / scale)" if tabulated else ")"))
        relief = "heights" in art.arrays()
        axes = np.atleast_1d(top[len(rows)].subplots(1, levels + (1 if tabulated else 0) + (1 if relief else 0)))
        if relief:      # each texel's plane (the renderer's height field) over the surface plane
            ax = axes[-1]
            h = np.asarray(art["heights"][0], np.float64) - float(s["plane_z"])
            lim = max(float(np.abs(h).max()), 1e-9)
            im = ax.imshow(h, origin="lower", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
            ax.set_title("relief: height over the\nsurface plane")
            ax.set_xticks([])
            ax.set_yticks([])
            fig.colorbar(im, ax=ax, shrink=0.8)
            axes = axes[:-1]
        if tabulated:
            ax = axes[-1]
            curves = np.asarray(art["tabulated/rel_rmse_by_components"])
            for e in range(curves.shape[0]):
                ax.plot(np.arange(curves.shape[1]), curves[e], marker="o", ms=3,
                        label=names[e] if e < len(names) else f"exemplar {e}")
            ax.set_xlabel("components per cluster")
            ax.xaxis.get_major_locator().set_params(integer=True)
            ax.set_ylabel("relative RMSE of the table")
            ax.set_title(f"table: {s.get('table_clusters', '?')} clusters")
            ax.set_ylim(bottom=0)
            ax.legend(fontsize=7)
            axes = axes[:-1]
        vi, li, ldir = pairs[0]
        acq0 = samples[0, :, :, vi, li, :].astype(np.float64)
        scale = float(max(np.percentile(acq0, 99.5), 1e-6))
        per = s.get("per_exemplar") or [{}]
        rmse = per[0].get("fit_rmse", s.get("fit_rmse", []))
        for lev, ax in enumerate(axes):
            f = {n: art[f"level_{lev}/{n}"][0] for n in ("rho", "lobes", "table", "frame")}
            img = model_image(f["rho"], f["lobes"], f["table"], f["frame"], s["view_grid"], views[vi], ldir)
            rep = res // img.shape[0]
            ax.imshow(_srgb(np.kron(img, np.ones((rep, rep, 1))), scale), origin="lower", interpolation="nearest")
            ax.set_title(f"level {lev}: {img.shape[0]}²" + (f"\nRMSE {rmse[lev]:.3g}" if lev < len(rmse) else ""))
            ax.set_xticks([])
            ax.set_yticks([])
        first = names[0] if names else "exemplar 0"
        top[len(rows)].suptitle(f"mip pyramid (first pair) -- {first} of {s['source']}, {s['lobes']} lobe(s)"
                                + (f"; {E} exemplars" if E > 1 else ""))
        return finish(fig, png, show)
