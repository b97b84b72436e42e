"""Artifacts named by ``render --set KEY=PATH.zarr`` are checked for kind and provenance (issue 58, item 5;
cases 4 and 7), as ``--fibers`` and ``--tables`` are: each refusal follows the contract of
``tests/hostile/contract.py`` (exit code 2, one line naming the file and the place, nothing written).

- Case 4: ``bysdf --set yarns=`` the yarns of another scene rendered that scene's yarns under this one
  (exit 0); now the scene's fabric is compared with the one the yarns artifact records it was made of
  (``pipeline.render_setup.check_scene_matches``). Reference: the same scene and its own yarns pass.
- Case 7: ``fiberpath --fibers FIBERS.zarr --set tiling=`` an artifact of another kind was ignored
  (exit 0); now a ``--set`` value naming an artifact must be of the kind its key reads, and a tiling
  named twice (``--fibers`` and ``--set tiling``) must be one tiling.
"""
from __future__ import annotations

import pytest

from tests.hostile.contract import assert_refused

SCENE = """
[scene]
name = "hostile-{name}"
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
ends = {n}
picks = {n}
spacing = 0.1
yarn_radius = 0.045
[yarns.warp]
preset = "cotton1"
[yarns.weft]
preset = "cotton1"
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


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    """W: scenes a.toml (2 x 2 plain) and b.toml (3 x 3 plain), their yarns, a's fibers, previous outputs."""
    from pipeline.cli import main

    W = tmp_path_factory.mktemp("render_settings")
    for name, n in (("a", 2), ("b", 3)):
        (W / f"{name}.toml").write_text(SCENE.format(name=name, n=n))
        assert main(["ingest", str(W / f"{name}.toml"), "-o", str(W / f"{name}_yarns.zarr")]) == 0
    assert main(["realize", str(W / "a_yarns.zarr"), "--spacing", "0.02", "-o", str(W / "a_fibers.zarr")]) == 0
    for name, text in (("render.exr", "previous EXR"), ("render.png", "previous PNG")):
        (W / name).write_text(text)
    return W


def test_bysdf_yarns_of_another_scene(cli, ws):
    """Case 4."""
    assert_refused(cli, ws, ["render", ws / "a.toml", "--method", "bysdf", "--set", f"yarns={ws / 'b_yarns.zarr'}",
                             "--spp", "1", "-o", ws / "render.exr"], "a.toml: fabric", "b_yarns.zarr (--set yarns",
                   "re-run ingest on this scene")


def test_bysdf_yarns_of_this_scene_pass(ws):
    """Reference for case 4: the scene's own yarns pass the same check that refuses the other scene's."""
    from pipeline.errors import LoomError
    from pipeline.render_setup import check_scene_matches
    from pipeline.scene import load_scene

    scene = load_scene(ws / "a.toml")
    check_scene_matches(scene, ws / "a_yarns.zarr", "set yarns")
    with pytest.raises(LoomError, match="fabric"):
        check_scene_matches(scene, ws / "b_yarns.zarr", "set yarns")


def test_set_artifact_of_the_wrong_kind(cli, ws):
    """Case 7: the tiling setting names a yarns artifact (a tables one in the issue): refused by kind,
    with --fibers or alone."""
    fp = ["render", ws / "a.toml", "--method", "fiberpath", "--spp", "1", "-o", ws / "render.exr"]
    assert_refused(cli, ws, [*fp, "--fibers", ws / "a_fibers.zarr", "--set", f"tiling={ws / 'a_yarns.zarr'}"],
                   "a_yarns.zarr: --set tiling", "expected a 'tiling' artifact, found a 'yarns' artifact")
    assert_refused(cli, ws, [*fp, "--set", f"tiling={ws / 'a_yarns.zarr'}"], "a_yarns.zarr", "'yarns' artifact")
    assert_refused(cli, ws, ["render", ws / "a.toml", "--method", "bysdf", "--set", f"yarns={ws / 'a_fibers.zarr'}",
                             "--spp", "1", "-o", ws / "render.exr"], "a_fibers.zarr: --set yarns",
                   "expected a 'yarns' artifact, found a 'fibers' artifact")


def test_tiling_named_twice(cli, ws, tmp_path):
    """``--fibers A --set tiling=B``: one of the two would be passed over."""
    from tests.precompute.conftest import make_tiling

    tiling = make_tiling(tmp_path)
    fp = ["render", ws / "a.toml", "--method", "fiberpath", "--spp", "1", "-o", ws / "render.exr"]
    assert_refused(cli, ws, [*fp, "--fibers", ws / "a_fibers.zarr", "--set", f"tiling={tiling}"], "--set tiling",
                   "while --fibers names", "give the tiling once")
