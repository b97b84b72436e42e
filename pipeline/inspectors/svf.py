"""Picture of an svf artifact (stage precompute svf): seed 001 Fig. 4 for one fibre segment, four panels
over (phi, theta) in equirectangular projection (phi 0-360 degrees across, theta 0-180 degrees from +z
down, the fabric's normal at the top):

  (a) the binary visibility image (white visible, black occluded);
  (b) the PCA-reconstructed SSDF in degrees (diverging colours, 0 at the boundary);
  (c) the sign of (b) as a binary image, with the pixels where it differs from (a) marked red;
  (d) the sum-of-SGs visibility V^ssg, with the segment's SG axes as dots.

``--segment K`` picks the segment by its tiling segment id (default: the segment of ``--exemplar`` (default:
the first in the artifact) that sees closest to half the upper hemisphere); the title gives the exemplar,
segment and visible solid angle.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import LoomError
from . import finish, pyplot


def segment_svf(art, k: int, s: int):
    """(visibility (R, C), reconstructed SSDF (R, C), V^ssg (R, C), axes (Q, 3)) of the s-th segment of
    exemplar k (index within the exemplar)."""
    from stages.core.svf import pixel_direction, ssdf_reconstruct, ssg_visibility
    from stages.precompute.svf import sg_axes, unpack_images

    R, C = art.summary["resolution"]
    g = f"exemplar_{k}/"
    packed = art[g + "visibility"][s:s + 1]   # whole arrays: every read is checked against its checksum
    vis = unpack_images(packed, R, C)[0].reshape(R, C)
    coeffs = art[g + "ssdf_coeffs"][s]
    d = np.empty(R * C, np.float32)
    ssdf_reconstruct(art[g + "ssdf_mean"], art[g + "ssdf_basis"], coeffs, d)
    angle = float(art[g + "sg_angle"][s])
    weights = art[g + "sg_weights"][s].astype(np.float64)
    Q = int(art.summary["sg_count"])
    axes = sg_axes(angle, Q)
    lam = float(art.summary["sg_sharpness"])
    ssg = np.empty((R, C))
    for r in range(R):
        for c in range(C):
            ssg[r, c] = ssg_visibility(axes, weights, lam, np.array(pixel_direction(r, c, R, C)))
    return vis, d.reshape(R, C), ssg, axes


def _pick(art, segment, exemplar):
    infos = art.summary["exemplars"]
    ks = [i["exemplar"] for i in infos]
    if segment is not None:
        for i in infos:
            a, b = i["segment_range"]
            if a <= segment < b:
                return i, segment - a
        ranges = ", ".join(f"exemplar {i['exemplar']}: {i['segment_range'][0]}..{i['segment_range'][1] - 1}"
                           for i in infos)
        raise LoomError(art.path, "--segment", f"segment {segment} is not in this artifact ({ranges})")
    k = ks[0] if exemplar is None else exemplar
    if k not in ks:
        raise LoomError(art.path, "--exemplar", f"exemplar {k} is not in this artifact (has {ks})")
    packed = art[f"exemplar_{k}/visibility"]
    R, C = art.summary["resolution"]
    seen = np.unpackbits(packed, axis=1, count=R * C).sum(axis=1)   # pixels, not solid angle: a picture, not a measure
    return infos[ks.index(k)], int(np.argmin(np.abs(seen - R * C / 4)))


def inspect(art, png, show=False, size=(1200, 900), segment=None, exemplar=None, **_):
    with pyplot(show) as plt:
        return finish(_figure(plt, art, size, segment, exemplar), png, show)


def _figure(plt, art, size, segment, exemplar):
    from matplotlib.colors import TwoSlopeNorm

    info, s = _pick(art, segment, exemplar)
    k = info["exemplar"]
    vis, d, ssg, axes = segment_svf(art, k, s)
    R, C = vis.shape
    seg_id = info["segment_range"][0] + s
    ext = [0, 360, 180, 0]
    fig, ax = plt.subplots(2, 2, figsize=(size[0] / 100, size[1] / 100), dpi=100, constrained_layout=True)
    omega = (np.cos(np.arange(R) * math.pi / R) - np.cos((np.arange(R) + 1) * math.pi / R)) * 2 * math.pi / C
    visible = float((vis * omega[:, None]).sum())
    fig.suptitle(f"SVF of segment {seg_id} (exemplar {k} '{info['name']}', {R}x{C} pixels): visible solid angle "
                 f"{visible:.3f} sr of 4pi; PCA {art.summary['components']} components, exemplar rel. error "
                 f"{info['pca_rel_error']:.3f}", fontsize=10)
    a = ax[0, 0]
    a.imshow(vis, cmap="gray", vmin=0, vmax=1, extent=ext, aspect="auto", interpolation="nearest")
    a.set_title("(a) binary visibility (white = sky visible)")
    a = ax[0, 1]
    lim = max(1e-6, float(np.abs(np.degrees(d)).max()))
    im = a.imshow(np.degrees(d), cmap="coolwarm_r", norm=TwoSlopeNorm(0.0, -lim, lim), extent=ext, aspect="auto",
                  interpolation="nearest")
    a.contour(np.degrees(d), levels=[0.0], colors="black", linewidths=0.8, origin="upper", extent=ext)
    a.set_title("(b) PCA-reconstructed SSDF (degrees; black: zero)")
    fig.colorbar(im, ax=a, label="signed angular distance (deg)")
    a = ax[1, 0]
    sign = (d > 0).astype(float)
    a.imshow(sign, cmap="gray", vmin=0, vmax=1, extent=ext, aspect="auto", interpolation="nearest")
    wrong = np.argwhere(sign != vis)
    if len(wrong):
        a.scatter((wrong[:, 1] + 0.5) * 360 / C, (wrong[:, 0] + 0.5) * 180 / R, s=4, c="red",
                  label=f"{len(wrong)} pixels differ from (a)")
        a.legend(loc="lower right", fontsize=9)
    a.set_title("(c) sign of the SSDF (white > 0)")
    a = ax[1, 1]
    im = a.imshow(ssg, cmap="viridis", extent=ext, aspect="auto", interpolation="nearest")
    th = np.degrees(np.arccos(np.clip(axes[:, 2], -1, 1)))
    ph = np.degrees(np.arctan2(axes[:, 1], axes[:, 0])) % 360
    a.scatter(ph, th, s=6, c="white", edgecolors="black", linewidths=0.3, label="SG axes")
    a.legend(loc="lower right", fontsize=9)
    a.set_title(f"(d) sum of {len(axes)} SGs, lambda_svf = {art.summary['sg_sharpness']:g}")
    fig.colorbar(im, ax=a, label="V^ssg")
    for a in ax.ravel():
        a.set_xlabel("phi (degrees)")
        a.set_ylabel("theta from +z (degrees)")
        a.axhline(90, color="orange", lw=0.8, ls="--", label="horizon (theta 90)")
    ax[0, 0].legend(loc="lower right", fontsize=9)
    return fig
