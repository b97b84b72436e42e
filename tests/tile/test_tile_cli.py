"""`loomlight tile` end to end: the info contract, OBJ base meshes, the inspector, and every bad input of
issue 6 item 7 -> exit code 2, one line naming the cause, no artifact written and an existing artifact
at the output path untouched."""
import json

import numpy as np
import pytest

from pipeline.artifacts import read_meta
from tests.helpers import ROOT

BASE = """
seed = 1
[yarn]
fibers_per_ply = 1
[weave]
spacing = [0.1, 0.1]
[[exemplars]]
pattern = "{pattern}"
n = 5
{ex_extra}
[[exemplars]]
pattern = "satin"
n = 5
invert = true
[tiling]
repeat = [1, 1]
block_map = {block_map}
[surface]
{surface}
"""


def config(tmp_path, name="t", pattern="satin", ex_extra="", block_map="[[0, 1], [1, 0]]",
           surface='kind = "flat"\nresolution = [2, 2]'):
    p = tmp_path / f"{name}.toml"
    p.write_text(BASE.format(pattern=pattern, ex_extra=ex_extra, block_map=block_map, surface=surface))
    return p


QUAD_OBJ = """# two triangles with uv
v 0 0 0
v 1 0 0
v 1 1 0.2
v 0 1 0.2
vt 0 0
vt 1 0
vt 1 1
vt 0 1
f 1/1 2/2 3/3
f 1/1 3/3 4/4
"""


@pytest.fixture
def existing(tmp_path, cli):
    cfg = config(tmp_path, "good")
    out = tmp_path / "tiling.zarr"
    code, stdout, err = cli("tile", cfg, "-o", out)
    assert code == 0, err
    return out, read_meta(out)["content_hash"]


def test_info_reports_tiling_contract(existing, cli):
    """Contract of issue 6 item 5: kind, exemplars, blocks, tetrahedra (2 x 2 flat grid -> 8 prisms x 3)."""
    out, _ = existing
    code, stdout, err = cli("info", out, "--json")
    assert code == 0, err
    doc = json.loads(stdout)
    assert doc["kind"] == "tiling"
    assert doc["exemplars"] == 2
    assert doc["blocks"] == 25 and doc["block_grid"] == [5, 5]
    assert doc["tetrahedra"] == 2 * 2 * 2 * 3
    code, stdout, _ = cli("tile", existing[0].parent / "good.toml", "-o", out)
    assert code == 0 and "up to date" in stdout


def test_obj_base_mesh_with_uv(tmp_path, cli):
    (tmp_path / "quad.obj").write_text(QUAD_OBJ)
    cfg = config(tmp_path, "obj", surface='kind = "obj"\npath = "quad.obj"')
    out = tmp_path / "obj.zarr"
    code, _, err = cli("tile", cfg, "-o", out)
    assert code == 0, err
    from pipeline.artifacts import Artifact

    art = Artifact(out)
    assert art.summary["tetrahedra"] == 6
    np.testing.assert_allclose(art["base_uv"][:, 0] * 1.0, art["base_vertices"][:, 0])


def test_inspect_png(existing, cli, tmp_path, offscreen_gl):
    png = tmp_path / "tiling.png"
    code, _, err = cli("inspect", existing[0], "--png", png, "--width", "600", "--height", "300")
    assert code == 0, err
    from tests.inspector_checks import assert_legible_png

    assert_legible_png(png, min_size=(300, 120), max_size=(620, 320))


BAD = {
    "obj_without_uv": (dict(surface='kind = "obj"\npath = "nouv.obj"'), "nouv.obj", "texture coordinate"),
    "degenerate_triangle": (dict(surface='kind = "obj"\npath = "deg.obj"'), "triangle 2", "degenerate"),
    "flipped_triangle": (dict(surface='kind = "obj"\npath = "flip.obj"'), "triangle 1", "flipped"),
    "thickness_zero": (dict(surface='kind = "flat"\nthickness = 0.0'), "surface.thickness", "must be positive"),
    "thickness_negative": (dict(surface='kind = "flat"\nthickness = -0.1'), "surface.thickness", "must be positive"),
    "missing_exemplar": (dict(block_map="[[0, 2], [1, 0]]"), "tiling.block_map", "names exemplar 2"),
    "not_periodic": (dict(ex_extra="ends = 6\npicks = 5"), "exemplars[0]", "not periodic"),
    "missing_png": (dict(block_map='"nothere.png"'), "block_map", "not found"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_exit_2_and_previous_artifact_untouched(case, tmp_path, cli, existing):
    out, before = existing
    (tmp_path / "nouv.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "deg.obj").write_text(QUAD_OBJ + "v 2 0 0\nv 3 0 0\nvt 0.5 0.5\nvt 0.6 0.5\nf 2/2 5/5 6/6\n")
    # triangle 1 wound the other way in uv (and in 3-D) from the first
    (tmp_path / "flip.obj").write_text(QUAD_OBJ.replace("f 1/1 3/3 4/4", "f 1/1 4/4 3/3"))
    kw, place, words = BAD[case]
    cfg = config(tmp_path, case, **kw)
    code, stdout, err = cli("tile", cfg, "-o", out)
    assert code == 2, (stdout, err)
    line = err.strip()
    assert "\n" not in line and place in line and words in line, line
    assert read_meta(out)["content_hash"] == before
    code, _, _ = cli("tile", cfg, "-o", tmp_path / "fresh.zarr")
    assert code == 2 and not (tmp_path / "fresh.zarr").exists()


def test_wif_exemplar_and_its_period(tmp_path, cli):
    """A WIF draft (data/drafts/twill_2x2.wif, 8 x 8 threads) as an exemplar: 4 x 4 is its period
    (accepted, the exemplar is the draft's first 4 x 4 cells); 3 x 4 is not (exit 2)."""

    from pipeline.artifacts import Artifact
    from pipeline.io.wif import parse

    wif = ROOT / "data" / "drafts" / "twill_2x2.wif"
    ok = config(tmp_path, "wif", pattern="wif", ex_extra=f'path = "{wif}"\nends = 4\npicks = 4',
                block_map="[[0, 0], [0, 0]]")
    code, _, err = cli("tile", ok, "-o", tmp_path / "wif.zarr")
    assert code == 0, err
    art = Artifact(tmp_path / "wif.zarr")
    np.testing.assert_array_equal(art["ex_over"][:16].reshape(4, 4), parse(wif).over[:4, :4])
    bad = config(tmp_path, "wif_bad", pattern="wif", ex_extra=f'path = "{wif}"\nends = 3\npicks = 4')
    code, _, err = cli("tile", bad, "-o", tmp_path / "wif_bad.zarr")
    assert code == 2 and "exemplars[0]" in err and "not periodic" in err


def test_rebuild_is_byte_identical(existing, cli):
    """Determinism: the same configuration rebuilt (--force) gives the same content hash."""
    out, before = existing
    code, _, err = cli("tile", out.parent / "good.toml", "-o", out, "--force")
    assert code == 0, err
    assert read_meta(out)["content_hash"] == before
