"""A WIF draft's thread colours show in the rendered cloth (issue 54 item 5; docs/wif-colours.md).

Reference: the bundled plain weave ``data/drafts/54235plain.wif`` (green warp 0,102,0, white weft),
repeated 4 x 4, ingested, realized and rendered by ``fiberpath`` (BCSDF dyed to each yarn's colour)
from straight above. Where the draft's interlacement puts a warp end on top (``stages.core.curves.woven``
places end e at x_e and pick p at y_p), the pixel over that crossing must be green: its chromaticity
g / (r + g + b) well above 1/3 (median > 0.7), since light that passes through a green fibre keeps no red
or blue -- only the fibres' uncoloured surface reflection (a dielectric's, pipeline/dye.py) is grey; where
the weft is on top, near 1/3 (white fibres, grey light). Dropped colours (every yarn its preset's albedo) or swapped
ones fail it.
"""
from __future__ import annotations

import math

import numpy as np

from tests.helpers import DATA

DRAFT = DATA / "drafts" / "54235plain.wif"
W = H = 48
FOV = 14.0
HEIGHT = 0.5

SCENE = f"""
[fabric]
source = "wif"
path = "{DRAFT}"
repeat = [4, 4]
[yarns.default]
bcsdf = "cotton"
[camera]
origin = [0.0, 0.0, {HEIGHT}]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = {FOV}
width = {W}
height = {H}
[[lights]]
type = "directional"
direction = [0.1, 0.2, -1.0]
irradiance = 3.0
[[lights]]
type = "constant"
radiance = 0.3
[render]
spp = 4
max_depth = 6
"""


def pixel_of(p):
    """(row, col) of the pixel the top-down camera above sees fabric point p through (the inverse of
    ``stages.render.camera.camera_ray_into`` for this camera: right = +x, up = +y, forward = -z)."""
    t = math.tan(math.radians(FOV) / 2)
    dz = HEIGHT - p[2]
    sx, sy = p[0] / dz, p[1] / dz
    return int((1 - sy * W / (t * H)) * H / 2), int((sx / t + 1) * W / 2)


def test_plain_weave_renders_in_the_drafts_colours(tmp_path, cli):
    from pipeline.generators import from_wif
    from pipeline.images import read_exr

    scene = tmp_path / "plain.toml"
    scene.write_text(SCENE)
    y, f, out = tmp_path / "y.zarr", tmp_path / "f.zarr", tmp_path / "plain.exr"
    assert cli("ingest", scene, "-o", y)[0] == 0
    code, _, err = cli("realize", y, "--spacing", "0.005", "-o", f)
    assert code == 0, err
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", f, "-o", out, "--seed", "1")
    assert code == 0, err
    rgb = read_exr(out)[0].astype(np.float64)

    cs = from_wif(DRAFT, repeat=[4, 4])
    over = cs.notes["interlacement"]
    E, P = over.shape
    sx, sy = cs.notes["spacing"]
    chroma = {True: [], False: []}
    for e in range(E):
        for p in range(P):
            r, c = pixel_of(((e - (E - 1) / 2) * sx, (p - (P - 1) / 2) * sy, 0.02))
            if not (2 <= r < H - 2 and 2 <= c < W - 2):
                continue
            block = rgb[r - 1:r + 2, c - 1:c + 2].reshape(-1, 3)
            s = block.sum(axis=1)
            assert np.all(s > 0), (e, p, block)
            chroma[bool(over[e, p])].append(float(np.median(block[:, 1] / s)))
    warp_top, weft_top = np.asarray(chroma[True]), np.asarray(chroma[False])
    assert len(warp_top) >= 8 and len(weft_top) >= 8
    assert np.all(warp_top > 0.4) and np.median(warp_top) > 0.7, warp_top
    # grey light on white fibres (the cotton BCSDF's own lobe colours make it slightly off-grey)
    assert np.all((weft_top > 0.2) & (weft_top < 0.5)), weft_top
    assert abs(float(np.median(weft_top)) - 1 / 3) < 0.03, weft_top
