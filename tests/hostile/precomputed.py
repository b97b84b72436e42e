"""The precomputed workspace of the hostile-input tests of issue 58 (``test_forged_summaries.py``,
``test_count_bounds.py``): the tiny two-exemplar tiling of ``tests/precompute/conftest.py``, a scene for
its materials and camera, an SVF (8 x 8 pixels) and an IIRTF (SH order 2, 4 paths a cell) of it, built
through the CLI like any user's, and a previous render's files."""
from __future__ import annotations

from tests.precompute.conftest import make_tiling

SCENE = """
[scene]
name = "hostile-prt"
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 2
picks = 2
spacing = 0.1
yarn_radius = 0.045
[yarns.warp]
preset = "cotton1"
color = [0.80, 0.76, 0.66]
bcsdf = "cotton"
[yarns.weft]
preset = "cotton1"
color = [0.16, 0.24, 0.52]
bcsdf = "cotton"
[camera]
origin = [0.1, 0.1, 0.75]
target = [0.1, 0.1, 0.0]
up = [0.0, 1.0, 0.0]
fov = 40.0
width = 8
height = 6
[[lights]]
type = "directional"
direction = [-0.4, 0.5, -0.77]
irradiance = 3.0
"""
SVF_ARGS = ["--resolution", "8", "--components", "1", "--sg-count", "4", "--threads", "2"]
IIRTF_ARGS = ["--order", "2", "--paths", "4", "--mfp-paths", "100", "--cell-factor", "3", "--threads", "2"]


def build(W):
    """Build the workspace in directory ``W`` (module doc); returns W."""
    from pipeline.cli import main

    tiling = make_tiling(W)
    (W / "scene.toml").write_text(SCENE)
    assert main(["precompute", "svf", str(tiling), "-o", str(W / "svf.zarr"), *SVF_ARGS]) == 0
    assert main(["precompute", "iirtf", str(tiling), "-o", str(W / "iirtf.zarr"), *IIRTF_ARGS,
                 "--scene", str(W / "scene.toml")]) == 0
    for name, text in (("render.exr", "previous EXR"), ("render.png", "previous PNG")):
        (W / name).write_text(text)
    return W
