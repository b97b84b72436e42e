"""Messages that name the file, the key and the real problem (issue 58, item 7), each refusal following
the contract of ``tests/hostile/contract.py`` (exit code 2, one line, nothing written):

- a scene whose ``fabric.path`` is missing said ``nope.bcc: No such file or directory`` (neither the
  scene nor the key) and ``render`` then compared ``sha256 None``; now the scene and ``fabric.path`` are
  named when the scene is read, by every command;
- ``--set mesh=DIR`` said "mesh file not found" (it is a directory); ``--set mesh=X.bcc`` said "no faces"
  (it is not an OBJ mesh);
- a tiling configuration's missing WIF was placed at ``exemplar0`` (the input's internal name), not at
  ``exemplars[0].path``, the key the user wrote.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from tests.hostile.contract import assert_refused

H = Path(__file__).resolve().parent

SCENE = """
[scene]
name = "hostile-messages"
[fabric]
source = "file"
path = "{path}"
radius = 0.02
[camera]
origin = [0.0, -1.0, 0.3]
target = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40.0
width = 8
height = 6
[[lights]]
type = "directional"
direction = [-0.4, 0.5, -0.77]
irradiance = 3.0
"""

TILE = """
seed = 1
[yarn]
fibers_per_ply = 1
[weave]
spacing = [0.1, 0.1]
[[exemplars]]
pattern = "wif"
path = "{path}"
ends = 4
picks = 4
[tiling]
repeat = [1, 1]
block_map = [[0, 0], [0, 0]]
[surface]
kind = "flat"
resolution = [2, 2]
"""


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    W = tmp_path_factory.mktemp("messages")
    (W / "missing.toml").write_text(SCENE.format(path="nope.bcc"))
    (W / "curves_dir").mkdir()
    (W / "dir.toml").write_text(SCENE.format(path="curves_dir"))
    (W / "tile.toml").write_text(TILE.format(path=W / "nope.wif"))
    (W / "mesh_dir").mkdir()
    (W / "ring.bcc").write_bytes((H / "zero_curves.bcc").read_bytes())
    (W / "render.exr").write_text("previous EXR")
    return W


def test_scene_fabric_path_missing(cli, ws):
    for args in (["ingest", ws / "missing.toml", "-o", ws / "y.zarr"],
                 ["render", ws / "missing.toml", "--method", "bysdf", "--set", f"yarns={ws / 'y.zarr'}",
                  "-o", ws / "render.exr"]):
        assert_refused(cli, ws, args, "missing.toml: fabric.path", "nope.bcc not found")
    assert_refused(cli, ws, ["ingest", ws / "dir.toml", "-o", ws / "y.zarr"], "dir.toml: fabric.path",
                   "is a directory, not a curve file")


@pytest.fixture(scope="module")
def btf(tmp_path_factory):
    from tests.render.test_btf_render import write_btf

    return Path(write_btf(tmp_path_factory.mktemp("btf") / "btf.zarr"))


@pytest.mark.parametrize("mesh, says", [("mesh_dir", "is a directory"), ("ring.bcc", "is not a Wavefront OBJ mesh"),
                                        ("nope.obj", "mesh file not found")])
def test_btf_mesh_setting(cli, ws, btf, mesh, says):
    (ws / "scene.toml").write_text(SCENE.format(path=H / "small.txt"))
    try:
        assert_refused(cli, ws, ["render", ws / "scene.toml", "--method", "btf", "--set", f"btf={btf}",
                                 "--set", f"mesh={ws / mesh}", "--spp", "1", "-o", ws / "render.exr"],
                       f"{mesh}: --set mesh", says)
    finally:
        (ws / "scene.toml").unlink()


def test_tiling_missing_wif_named_by_its_key(cli, ws):
    assert_refused(cli, ws, ["tile", ws / "tile.toml", "-o", ws / "tiling.zarr"], "tile.toml: exemplars[0].path",
                   "nope.wif")
