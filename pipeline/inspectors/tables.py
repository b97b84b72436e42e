"""Picture of a tables artifact: a yarn-space cross-section at z (matplotlib) -- the fibre centres of
every ply (regular, loop) and the hairs crossing z, drawn at their fibre radius, the ply ellipses,
and the azimuth bins of the regular-fibre tables (seed 000 Fig. 7) as rays from each ply centre."""
from __future__ import annotations

import math

import numpy as np

from . import finish, pyplot


def cross_section(tab, c, z):
    """(centres (n, 2), kinds (n,), plies (n,)) of the fibres of yarn c crossing yarn-space z."""
    from stages.core.yarn import model as M

    t = int(tab.yarn_type[c])
    tp = tab.tparams[t]
    P, N = int(tp[M.PLY_NUM]), int(tp[M.FIBER_NUM])
    yseed = np.uint64(tab.yarn_seed[c])
    out, kinds, plies = [], [], []
    fo = int(tab.type_fib_off[t])
    for k in range(P):
        for j in range(N):
            f = fo + k * N + j
            x, y, kd = M.regular_xy(tp, yseed, k, j, tab.fib_R[f], tab.fib_th[f], tab.fib_th0[f], z)
            out.append((x, y))
            kinds.append(kd)
            plies.append(k)
        g = int(tab.yarn_ply_off[c]) + k
        base = int(tab.hair_off[g])
        for h in range(int(tab.hair_count[g]) if len(tab.hair_z1) else 0):
            z1, ze = tab.hair_z1[base + h], tab.hair_ze[base + h]
            if ze == 0 or not (min(z1, z1 + ze) <= z <= max(z1, z1 + ze)):
                continue
            r0, r1, th1, pe = M.hair_params(tp, yseed, k, h)
            x, y, _ = M.hair_point(tp, k, r0, r1, th1, pe, z1, ze, (z - z1) / ze)
            out.append((x, y))
            kinds.append(3)
            plies.append(k)
    return np.array(out).reshape(-1, 2), np.array(kinds), np.array(plies)


def inspect(art, png, show=False, yarn=-1, z=None, size=(1200, 900), **_):
    with pyplot(show) as plt:
        return finish(_figure(plt, art, yarn, z, size), png, show)


def _figure(plt, art, yarn, z, size):
    from matplotlib.patches import Circle, Ellipse

    from stages.core.yarn import model as M

    from ..errors import LoomError
    from ..runners.tables import load_tables

    cv, tab, _ = load_tables(art.path)
    c = max(int(yarn), 0)
    if c >= len(tab.yarn_type):
        raise LoomError(art.path, "--yarn", f"no yarn {c} (yarns 0..{len(tab.yarn_type) - 1})")
    L = float(tab.yarn_length[c])
    zz = 0.5 * L if z is None else float(z)
    if not 0.0 <= zz <= L:
        raise LoomError(art.path, "--z", f"z = {zz} lies outside the yarn's length [0, {L:.6g}]")
    t = int(tab.yarn_type[c])
    tp = tab.tparams[t]
    rf = tp[M.FIBER_RADIUS]
    pts, kinds, plies = cross_section(tab, c, zz)
    fig, ax = plt.subplots(figsize=(size[0] / 100, size[1] / 100), dpi=100)
    colors = {1: "tab:blue", 2: "tab:orange", 3: "tab:red"}
    for (x, y), k in zip(pts, kinds):
        ax.add_patch(Circle((x, y), rf, color=colors[int(k)], lw=0))
    B = int(tab.type_nbins[t])
    reach = tp[M.U_MAX] * tp[M.E_LONG]
    twist = M.fiber_twist(tp, zz)
    for k in range(int(tp[M.PLY_NUM])):
        cx, cy, drx, dry = M.ply_frame(tp, k, zz)
        ang = math.degrees(math.atan2(dry, drx))
        ax.add_patch(Ellipse((cx, cy), 2 * tp[M.E_SHORT], 2 * tp[M.E_LONG], angle=ang, fill=False, color="0.3", lw=1))
        for b in range(B):  # bin boundary: unit-disc azimuth b 2 pi / B in the twisted frame
            a = 2 * math.pi * b / B + twist
            u, v = math.cos(a) * tp[M.E_SHORT], math.sin(a) * tp[M.E_LONG]
            s = reach / max(math.hypot(u, v), 1e-12)
            ex, ey = M.ply_to_yarn(tp, k, zz, u * s, v * s)
            ax.plot([cx, ex], [cy, ey], color="0.75", lw=0.5, zorder=0)
    for k, lab in colors.items():
        ax.plot([], [], "o", color=lab, label={1: "regular", 2: "loop", 3: "hair"}[k])
    ax.plot([], [], color="0.3", lw=1, label="ply ellipse")
    ax.plot([], [], color="0.75", lw=1, label="azimuth bin boundary")
    ax.legend(loc="upper right", title="fibre centres (at fibre radius)")
    ax.set_aspect("equal")
    ext = float(tab.yarn_extent[c])
    ax.set_xlim(-ext, ext)
    ax.set_ylim(-ext, ext)
    ax.set_xlabel("x (along n)")
    ax.set_ylabel("y (along b)")
    ax.set_title(f"yarn {c} cross-section at z = {zz:.4g}: {len(pts)} fibres, {B} azimuth bins per ply")
    return fig
