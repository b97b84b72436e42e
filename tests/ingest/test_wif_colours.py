"""WIF thread colours reach the cloth (issue 54 item 5; docs/wif-colours.md).

References: the per-thread colours are read here from the raw WIF text by a literal reading of the
format (``[COLOR TABLE]`` index -> r,g,b, ``[WARP COLORS]`` / ``[WEFT COLORS]`` thread -> index) and
decoded with the sRGB transfer function written out below (IEC 61966-2-1), independently of
``pipeline/io/wif.py``; every stage must give each yarn exactly that colour (float32 where an
artifact stores float32), unless the scene sets the group's colour (precedence: scene > draft > yarn
type). The drafts are the bundled real drafts ``data/drafts/2229.wif`` (24 x 24, green warp, white
weft) and ``data/drafts/54235plain.wif`` (2 x 2 plain weave, the same colours).
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.artifacts import Artifact, read_meta
from pipeline.errors import LoomError
from pipeline.io import read_curves, wif
from pipeline.thread_colors import FROM_DRAFT, FROM_SCENE, FROM_TYPE, srgb_hex
from tests.helpers import DATA

DRAFTS = DATA / "drafts"
REAL = ("2229.wif", "54235plain.wif")


def srgb_decode(v: float) -> float:
    """IEC 61966-2-1: display value v in [0, 1] -> linear."""
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


def raw_thread_colours(path):
    """(warp, weft): per thread the linear colour of its [WARP COLORS] / [WEFT COLORS] entry, from the
    raw text (palette range 0..255, every thread listed: true of the bundled real drafts)."""
    sec, table, threads = None, {}, {"warp colors": {}, "weft colors": {}}
    for line in path.read_text().splitlines():
        line = line.strip()
        if line.startswith("["):
            sec = line.strip("[]").lower()
        elif "=" in line and sec == "color table":
            k, v = line.split("=")
            table[int(k)] = tuple(srgb_decode(int(x) / 255) for x in v.split(","))
        elif "=" in line and sec in threads:
            k, v = line.split("=")
            threads[sec][int(k)] = table[int(v)]
    return ([threads["warp colors"][k] for k in sorted(threads["warp colors"])],
            [threads["weft colors"][k] for k in sorted(threads["weft colors"])])


def linear(rgb255):
    return tuple(srgb_decode(x / 255) for x in rgb255)


@pytest.mark.parametrize("name", REAL)
def test_parse_gives_the_drafts_colours_exactly(name):
    """Every end and pick has its draft colour, sRGB-decoded: equal to the literal reading, bit for bit."""
    path = DRAFTS / name
    d = wif.parse(path)
    warp, weft = raw_thread_colours(path)
    assert len(warp) == d.over.shape[0] and len(weft) == d.over.shape[1]
    assert d.warp_colors == warp and d.weft_colors == weft
    # the documented example: 0,101,0 -> linear (0, 0.1301..., 0); white stays white
    if name == "2229.wif":
        assert d.warp_colors[0] == (0.0, ((101 / 255 + 0.055) / 1.055) ** 2.4, 0.0)
        assert d.warp_colors[0][1] == pytest.approx(0.13014, abs=1e-5)
    assert set(d.weft_colors) == {(1.0, 1.0, 1.0)}


def test_hex_round_trip_of_every_8bit_value():
    """``srgb_hex`` of a draft colour stored as float32 linear gives back the draft's own 8-bit numbers."""
    for v in range(256):
        lin = np.float32(srgb_decode(v / 255))
        assert srgb_hex([lin, 0.0, lin]) == f"#{v:02x}00{v:02x}"


def test_palette_range_65535_and_rgb_defaults(tmp_path):
    """Range 0..65535 scales by 65535; [WEFT] Color = r,g,b in that range is the default of every pick."""
    f = tmp_path / "wide.wif"
    f.write_text("[COLOR PALETTE]\nRange=0,65535\nForm=RGB\n[COLOR TABLE]\n1=65535,0,32768\n"
                 "[WARP]\nThreads=2\nColor=1\n[WEFT]\nThreads=2\nColor=0,65535,13107\n"
                 "[THREADING]\n1=1\n2=2\n[LIFTPLAN]\n1=1\n2=2\n")
    d = wif.parse(f)
    assert d.warp_colors == [(1.0, 0.0, srgb_decode(32768 / 65535))] * 2
    assert d.weft_colors == [(0.0, 1.0, srgb_decode(13107 / 65535))] * 2


BASE = "[WARP]\nThreads=2\n[WEFT]\nThreads=2\n[THREADING]\n1=1\n2=2\n[LIFTPLAN]\n1=1\n2=2\n"


@pytest.mark.parametrize("text,place,words", [
    ("[COLOR TABLE]\n1=0,300,0\n", "[COLOR TABLE] line 2", ["1 = '0,300,0'", "outside the palette range 0..255"]),
    ("[COLOR TABLE]\n1=0,-1,0\n", "[COLOR TABLE] line 2", ["component -1", "outside"]),
    ("[COLOR TABLE]\n2=10,20\n", "[COLOR TABLE] line 2", ["2 = '10,20'", "three numbers"]),
    ("[COLOR TABLE]\n3=red,0,0\n", "[COLOR TABLE] line 2", ["3 = 'red,0,0'", "three numbers"]),
    ("[COLOR TABLE]\n1=nan,0,0\n", "[COLOR TABLE] line 2", ["component nan"]),
    ("[COLOR TABLE]\nx=1,2,3\n", "[COLOR TABLE] line 2", ["key 'x'"]),
    ("[COLOR PALETTE]\nRange=0\n", "[COLOR PALETTE] line 2", ["Range = '0'", "lo,hi"]),
    ("[COLOR PALETTE]\nRange=255,0\n", "[COLOR PALETTE] line 2", ["hi > lo"]),
    ("[COLOR PALETTE]\nForm=HSV\n", "[COLOR PALETTE] line 2", ["Form = 'HSV'", "RGB"]),
    ("[COLOR TABLE]\n1=1,2,3\n[WARP COLORS]\n2=5\n", "[WARP COLORS] line 4", ["2 = 5", "no entry in [COLOR TABLE]"]),
    ("[COLOR TABLE]\n1=1,2,3\n[WEFT COLORS]\n1=1,1\n", "[WEFT COLORS] line 4", ["1 = 1,1", "one [COLOR TABLE] index"]),
    ("[COLOR TABLE]\n1=1,2,3\n[WEFT COLORS]\n3=1\n", "[WEFT COLORS] line 4", ["thread 3 is beyond the 2 declared"]),
])
def test_bad_colour_entries_name_section_line_and_key(tmp_path, text, place, words):
    f = tmp_path / "bad.wif"
    f.write_text(text + BASE)
    with pytest.raises(LoomError) as e:
        read_curves(f)
    msg = str(e.value)
    assert msg.startswith(f"{f}: {place}: "), msg
    for w in words:
        assert w in msg, msg


def test_bad_colour_default_through_the_cli_exit_2_nothing_written(tmp_path, cli):
    """``[WARP] Color`` naming a missing index: ingest exits 2 with one line naming the file and the
    key, and an artifact already at the output path is untouched."""
    good, out = DRAFTS / "54235plain.wif", tmp_path / "y.zarr"
    assert cli("ingest", good, "-o", out)[0] == 0
    before = read_meta(out)["content_hash"]
    bad = tmp_path / "bad.wif"
    bad.write_text(good.read_text().replace("[WARP]\n", "[WARP]\nColor=7\n"))
    code, _, err = cli("ingest", bad, "-o", out)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert str(bad) in lines[0] and "[WARP] line" in lines[0] and "Color = '7'" in lines[0], lines[0]
    assert read_meta(out)["content_hash"] == before


@pytest.mark.parametrize("name", REAL)
def test_ingest_stores_the_colours_and_info_lists_them(tmp_path, cli, name, monkeypatch):
    """The yarns artifact holds each thread's colour (float32 of the literal reading) with source draft;
    ``info`` (table and --json) lists each group's threads, colours and counts."""
    monkeypatch.setenv("COLUMNS", "200")   # the table wraps long values on a narrow terminal
    path = DRAFTS / name
    out = tmp_path / "y.zarr"
    code, _, err = cli("ingest", path, "-o", out)
    assert code == 0, err
    art = Artifact(out, kind="yarns")
    warp, weft = raw_thread_colours(path)
    np.testing.assert_array_equal(art["color"], np.asarray(warp + weft, np.float32))
    assert art["color_source"].dtype == np.int8 and set(art["color_source"].tolist()) == {FROM_DRAFT}
    np.testing.assert_array_equal(art["group"], [0] * len(warp) + [1] * len(weft))
    n = len(warp)
    green = "#006500" if name == "2229.wif" else "#006600"
    want = {"warp": f"{n} threads, 1 colour from the draft: {green} \u00d7{n}",
            "weft": f"{n} threads, 1 colour from the draft: #ffffff \u00d7{n}"}
    code, text, _ = cli("info", out, "--json")
    assert code == 0 and json.loads(text)["thread_colors"] == want
    code, text, _ = cli("info", out)
    assert code == 0
    flat = " ".join(text.replace("\u2502", " ").split())   # cells without the table's borders
    for g, line in want.items():
        assert f"thread_colors.{g}" in flat and " ".join(line.split()) in flat, text


def test_info_counts_mixed_colours_and_threads_without_one(tmp_path, cli):
    """The bundled satin (range 0..65535): warp all colour 1; picks 1, 3, ... colour 2, picks 2, 4, ...
    none (their yarn type's colour)."""
    out = tmp_path / "s.zarr"
    assert cli("ingest", DRAFTS / "satin_5_liftplan.wif", "-o", out)[0] == 0
    s = Artifact(out, kind="yarns").summary["thread_colors"]
    assert s["warp"] == "10 threads, 1 colour from the draft: #ffcc00 \u00d710"
    assert s["weft"] == ("10 threads, 1 colour from the draft: #333399 \u00d75; "
                         "5 threads in the yarn type's colour (its preset's albedo)")
    src = Artifact(out, kind="yarns")["color_source"]
    assert src[10:].tolist() == [FROM_DRAFT, FROM_TYPE] * 5


SCENE = """
[fabric]
source = "wif"
path = "{path}"
{fabric_extra}
[yarns.default]
bcsdf = "cotton"
{yarns}
[camera]
origin = [0.0, 0.0, 0.5]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 12.0
width = 8
height = 8
[[lights]]
type = "constant"
radiance = 0.5
"""


def scene_file(tmp_path, name, draft, yarns="", fabric_extra=""):
    p = tmp_path / f"{name}.toml"
    p.write_text(SCENE.format(path=DRAFTS / draft, yarns=yarns, fabric_extra=fabric_extra))
    return p


RED = [0.7, 0.05, 0.05]


def dyed_cotton(cotton, colour):
    """The cotton BCSDF dyed to ``colour`` on the scenes' yarn (the default preset, cotton1): pipeline.dye."""
    from pipeline import dye
    from pipeline.presets import resolve_yarn_types

    refl = dye.preset_reflection("cotton")
    curve = dye.albedo_curve(cotton, refl, resolve_yarn_types([{}], [0.0])[0])
    return dye.dyed_bcsdf(cotton, curve.invert(colour)[0], refl)


def test_scene_colour_wins_and_every_stage_carries_the_result(tmp_path, cli):
    """Precedence: a scene's yarns.warp.color beats the draft's warp colour; the weft keeps the draft's.
    The yarns artifact records it (source scene / draft); the per-yarn albedo of tables, of realize's
    fibres, of fiberpath's materials (the BCSDF dyed to it) and of bysdf is exactly that."""
    from pipeline.bcsdf_presets import load_bcsdf_preset
    from pipeline.render_setup import load_fibers
    from pipeline.renderers.bysdf import yarn_setup
    from pipeline.renderers.fiberpath import fiber_materials
    from pipeline.scene import load_scene
    from stages.core.shading.material import pack_material_bcsdf

    sc = scene_file(tmp_path, "red", "54235plain.wif", yarns=f"[yarns.warp]\ncolor = {RED}\n")
    y, f, t = tmp_path / "y.zarr", tmp_path / "f.zarr", tmp_path / "t.zarr"
    assert cli("ingest", sc, "-o", y)[0] == 0
    art = Artifact(y, kind="yarns")
    assert art["color_source"].tolist() == [FROM_SCENE] * 2 + [FROM_DRAFT] * 2
    want = np.asarray([RED, RED, [1, 1, 1], [1, 1, 1]], np.float32)
    np.testing.assert_array_equal(art["color"], want)
    assert art.summary["thread_colors"]["warp"].startswith("2 threads, 1 colour from the scene: #")
    code, _, err = cli("realize", y, "--spacing", "0.01", "-o", f)
    assert code == 0, err
    np.testing.assert_array_equal(Artifact(f, kind="fibers")["yarn_albedo"], want)
    code, _, err = cli("tables", y, "-o", t)
    assert code == 0, err
    # float64 stages: the scene's colour as the scene gives it, the draft's as the yarns artifact stores it
    want64 = np.asarray([RED, RED, want[2], want[3]], np.float64)
    np.testing.assert_array_equal(Artifact(t, kind="tables")["yarn_albedo"], want64)
    # fiberpath: every fibre's material is its group's BCSDF dyed to its yarn's colour
    fibers = load_fibers(f)
    mof, mats = fiber_materials(load_scene(sc), fibers, {"material": "bcsdf", "extra": {}})
    cotton = load_bcsdf_preset("cotton")
    for yarn in range(4):
        fib = int(np.flatnonzero(fibers.fiber_yarn == yarn)[0])
        np.testing.assert_array_equal(mats[mof[fib]],
                                      pack_material_bcsdf(dyed_cotton(cotton, want[yarn].astype(float))))
    # bysdf reads the same per-yarn albedo
    np.testing.assert_array_equal(yarn_setup(y)[2].albedo, want64)


def test_draft_colours_reach_fibres_of_the_24_thread_draft(tmp_path, cli):
    """The second real draft (2229.wif, cropped to 6 x 6 threads by the scene): realize's fibres carry
    the draft's colours, and nothing else, when the scene sets none."""
    sc = scene_file(tmp_path, "g", "2229.wif", fabric_extra="max_threads = 6")
    y, f = tmp_path / "y.zarr", tmp_path / "f.zarr"
    assert cli("ingest", sc, "-o", y)[0] == 0
    assert cli("realize", y, "--spacing", "0.01", "-o", f)[0] == 0
    warp, weft = raw_thread_colours(DRAFTS / "2229.wif")
    np.testing.assert_array_equal(Artifact(f, kind="fibers")["yarn_albedo"],
                                  np.asarray(warp[:6] + weft[:6], np.float32))


TILE = """
seed = 1
scene = "{scene}"
[yarn]
fibers_per_ply = 1
[weave]
spacing = [0.1, 0.1]
[[exemplars]]
pattern = "wif"
path = "{path}"
[[exemplars]]
pattern = "plain"
[tiling]
repeat = [1, 1]
block_map = [[0, 1], [1, 0]]
[surface]
kind = "flat"
resolution = [2, 2]
"""


def test_tiling_records_draft_colours_and_its_materials_use_them(tmp_path, cli):
    """A WIF exemplar's yarns get the draft's colours (source draft), the plain exemplar's none; the
    renderers' view of the tiling (fiberpath on the shell, and through ``tiling_materials`` prt, the IIRTF
    and the BTF) gives them those colours, the plain exemplar its preset's albedo, and a scene colour wins."""
    from pipeline.bcsdf_presets import load_bcsdf_preset
    from pipeline.presets import load_preset
    from pipeline.renderers.fiberpath import tiling_fibers
    from pipeline.runners.precompute import tiling_materials
    from pipeline.scene import load_scene
    from stages.core.shading.material import pack_material_bcsdf

    plain = scene_file(tmp_path, "plain", "54235plain.wif")
    cfg = tmp_path / "tile.toml"
    cfg.write_text(TILE.format(scene=plain, path=DRAFTS / "54235plain.wif"))
    out = tmp_path / "tiling.zarr"
    code, _, err = cli("tile", cfg, "-o", out)
    assert code == 0, err
    art = Artifact(out, kind="tiling")
    warp, weft = raw_thread_colours(DRAFTS / "54235plain.wif")
    draft = np.asarray(warp + weft, np.float32)
    assert art["ex_yarn_color_source"].tolist() == [FROM_DRAFT] * 4 + [FROM_TYPE] * 4
    np.testing.assert_array_equal(art["ex_yarn_color"][:4], draft)
    cotton1 = np.asarray(load_preset("cotton1")["albedo"], float)
    fib = tiling_fibers(load_scene(plain), art)
    np.testing.assert_array_equal(fib.yarn_albedo[:4], draft.astype(float))
    np.testing.assert_array_equal(fib.yarn_albedo[4:], np.tile(cotton1, (4, 1)))
    mof, mats = tiling_materials(load_scene(plain), art, {"tint": "yarn"})
    cotton = load_bcsdf_preset("cotton")
    for yarn in (0, 2, 4):
        f0 = int(np.flatnonzero(fib.fiber_yarn == yarn)[0])
        np.testing.assert_array_equal(mats[mof[f0]], pack_material_bcsdf(dyed_cotton(cotton, fib.yarn_albedo[yarn])))
    red = scene_file(tmp_path, "red", "54235plain.wif", yarns=f"[yarns.warp]\ncolor = {RED}\n")
    fib = tiling_fibers(load_scene(red), art)
    np.testing.assert_array_equal(fib.yarn_albedo[[0, 1, 4, 5]], np.tile(RED, (4, 1)))   # warp of both exemplars
    np.testing.assert_array_equal(fib.yarn_albedo[[2, 3]], draft[2:].astype(float))       # the draft's weft
