"""Errors at the first step that can know (issue 23 items 1 and 2): every scene value that names
something (fabric source, generator kind and pattern, yarn preset, BCSDF, light type, render method and
source) and every tiling-configuration name (surface kind, yarn preset, exemplar pattern) is checked
when the file is read, by every command that reads it, before any work and before anything is
written; the one-line message names the file, the dotted key, the known names and the nearest one
(difflib). Command-line names (--method, --source, --preset) name the option; no message says
"<input>". The bundled scenes and tilings, and the scenes the sweeps and studies name, all load."""
import re
import tomllib

import pytest

from pipeline.bcsdf_presets import bcsdf_presets
from pipeline.errors import LoomError
from pipeline.presets import list_presets
from pipeline.renderers import METHODS, all_sources, known_methods
from pipeline.runners.tile import load_config
from pipeline.scene import load_scene
from tests.helpers import ROOT

DATA = ROOT / "data"
DEMO = (DATA / "scenes" / "demo.toml").read_text()
TILING = (DATA / "tilings" / "flat_satin14.toml").read_text().replace(
    '"../scenes/flat_satin.toml"', repr(str(DATA / "scenes" / "flat_satin.toml")).replace("'", '"'))
PRESETS = ", ".join(list_presets())


# ------------------------------------------------------------------------------------------------ bundled files
@pytest.mark.parametrize("path", sorted((DATA / "tilings").glob("*.toml")), ids=lambda p: p.name)
def test_bundled_tilings_and_their_scenes_load(path):
    cfg = load_config(path)
    assert cfg["surface"]["kind"] in ("flat", "cylinder", "drape", "obj")
    if "scene" in cfg:
        assert load_scene(cfg["scene"]).render.get("method") in METHODS


def _named_scenes():
    """The scenes the sweeps and studies name (relative to their file), and `make`'s scene variables."""
    out = set()
    for f in [*(DATA / "sweeps").glob("*.toml"), *(DATA / "studies").glob("*.toml")]:
        raw = tomllib.loads(f.read_text())
        for table in raw.values():
            if isinstance(table, dict) and isinstance(table.get("scene"), str):
                out.add((f.parent / table["scene"]).resolve())
    for m in re.finditer(r"^\w*SCENE \?= (\S+)", (ROOT / "Makefile").read_text(), re.MULTILINE):
        out.add((ROOT / m.group(1)).resolve())
    return sorted(out)


@pytest.mark.parametrize("path", _named_scenes(), ids=lambda p: p.name)
def test_scenes_named_by_sweeps_studies_and_make_load(path):
    s = load_scene(path)
    m = s.render.get("method")
    assert m is None or m in METHODS
    assert s.render.get("source") is None or s.render["source"] in METHODS[m].source_names


# ------------------------------------------------------------------------------------------------ scene names
def _known(names):
    return ", ".join(names)


SCENE_CASES = [  # (id, replace this, with this, dotted key, message)
    ("preset", 'preset = "cotton1"', 'preset = "coton1"', "yarns.warp.preset",
     f"unknown preset 'coton1' (known: {PRESETS}); did you mean 'cotton1'?"),
    ("bcsdf", 'bcsdf = "cotton"', 'bcsdf = "coton"', "yarns.warp.bcsdf",
     f"unknown BCSDF preset 'coton' (known: {_known(bcsdf_presets())}); did you mean 'cotton'?"),
    ("method", 'method = "volpath"', 'method = "volpth"', "render.method",
     f"unknown render method 'volpth' (known: {_known(known_methods())}); did you mean 'volpath'?"),
    ("source", 'source = "procedural"', 'source = "procedral"', "render.source",
     "unknown volpath source 'procedral' (known: procedural, realized, grid); did you mean 'procedural'?"),
    ("source-of-method", 'source = "procedural"', 'source = "precomputed"', "render.source",
     "unknown volpath source 'precomputed' (known: procedural, realized, grid)"),
    ("light", 'type = "constant"', 'type = "constnat"', "lights[1].type",
     "unknown light type 'constnat' (known: directional, constant, sg, envmap); did you mean 'constant'?"),
    ("fabric", 'source = "generator"', 'source = "generater"', "fabric.source",
     "unknown fabric source 'generater' (known: file, wif, generator); did you mean 'generator'?"),
    ("kind", 'kind = "woven"', 'kind = "wovn"', "fabric.generator.kind",
     "unknown generator kind 'wovn' (known: woven, knit); did you mean 'woven'?"),
    ("pattern", 'pattern = "plain"', 'pattern = "satn"', "fabric.generator.pattern",
     "unknown woven pattern 'satn' (known: plain, twill, satin, basket); did you mean 'satin'?"),
]


def _bad_scene(tmp_path, old, new):
    assert old in DEMO
    p = tmp_path / "scene.toml"
    p.write_text(DEMO.replace(old, new, 1))
    return p


@pytest.mark.parametrize("case", SCENE_CASES, ids=lambda c: c[0])
def test_scene_names_checked_when_read(tmp_path, case):
    _, old, new, key, msg = case
    p = _bad_scene(tmp_path, old, new)
    with pytest.raises(LoomError) as e:
        load_scene(p)
    assert e.value.one_line() == f"{p}: {key}: {msg}"


@pytest.mark.parametrize("command", ["ingest", "render"])
def test_every_command_that_reads_a_scene_refuses_a_misspelt_preset(cli, tmp_path, command):
    """The issue's example: `preset = "coton1"` fails at ingest (it passed, and failed only at tables,
    naming neither file nor key), and render refuses the same scene, before writing anything."""
    p = _bad_scene(tmp_path, 'preset = "cotton1"', 'preset = "coton1"')
    out = tmp_path / ("y.zarr" if command == "ingest" else "x.exr")
    args = [p, "-o", out] + (["--tables", tmp_path / "t.zarr"] if command == "render" else [])
    code, _, err = cli(command, *args)
    assert code == 2
    assert err == (f"error: {p}: yarns.warp.preset: unknown preset 'coton1' (known: {PRESETS}); "
                   f"did you mean 'cotton1'?\n")
    assert list(tmp_path.iterdir()) == [p]


def test_generator_errors_name_the_scene(cli, tmp_path):
    p = tmp_path / "satin.toml"
    p.write_text('[fabric]\nsource = "generator"\n[fabric.generator]\nkind = "woven"\npattern = "satin"\n'
                 'n = 4\nstep = 2\nends = 8\npicks = 8\n')
    code, _, err = cli("ingest", p, "-o", tmp_path / "y.zarr")
    assert code == 2 and err.startswith(f"error: {p}: fabric.generator: satin 4: no valid step"), err


def test_a_bcsdf_file_is_checked_when_the_scene_is_read(tmp_path):
    p = _bad_scene(tmp_path, 'bcsdf = "cotton"', 'bcsdf = "mine.toml"')
    with pytest.raises(LoomError) as e:
        load_scene(p)
    assert e.value.one_line().startswith(f"{p}: yarns.warp.bcsdf: BCSDF preset file {tmp_path / 'mine.toml'} not found")
    (tmp_path / "mine.toml").write_text('c_r = [0.1, 0.1, 0.1]\nc_tt = [0.5, 0.5, 0.5]\nbeta_r = -3.0\n'
                                        'beta_tt = 10.0\ngamma_tt = 20.0\n')
    with pytest.raises(LoomError) as e:
        load_scene(p)
    assert e.value.file == str(tmp_path / "mine.toml") and e.value.place == "beta_r"


# ------------------------------------------------------------------------------------------------ tiling names
TILING_CASES = [
    ("surface", 'kind = "flat"', 'kind = "flt"', "surface.kind",
     "unknown surface kind 'flt' (known: flat, cylinder, drape, obj); did you mean 'flat'?"),
    ("preset", 'preset = "silk1"', 'preset = "slik1"', "yarn.preset",
     f"unknown preset 'slik1' (known: {PRESETS}); did you mean 'silk1'?"),
    ("pattern", 'pattern = "satin"', 'pattern = "sateen"', "exemplars[0].pattern",
     "unknown exemplar pattern 'sateen' (known: plain, twill, satin, basket, wif, stockinette, garter, rib1x1); "
     "did you mean 'satin'?"),
]


@pytest.mark.parametrize("case", TILING_CASES, ids=lambda c: c[0])
def test_tiling_names_checked_by_tile(cli, tmp_path, case):
    _, old, new, key, msg = case
    assert old in TILING
    p = tmp_path / "tiling.toml"
    p.write_text(TILING.replace(old, new, 1))
    code, _, err = cli("tile", p, "-o", tmp_path / "t.zarr")
    assert (code, err) == (2, f"error: {p}: {key}: {msg}\n")
    assert not (tmp_path / "t.zarr").exists()


def test_tile_reads_the_scene_its_configuration_names(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text((DATA / "scenes" / "flat_satin.toml").read_text().replace('method = "fiberpath"',
                                                                              'method = "fibrepath"'))
    p = tmp_path / "tiling.toml"
    p.write_text(TILING.replace(str(DATA / "scenes" / "flat_satin.toml"), str(scene)))
    with pytest.raises(LoomError) as e:
        load_config(p)
    assert e.value.one_line() == (f"{scene}: render.method: unknown render method 'fibrepath' "
                                  f"(known: {_known(known_methods())}); did you mean 'fiberpath'?")


# ------------------------------------------------------------------------------------------------ options
def test_render_method_and_source_options(cli, tmp_path):
    demo = DATA / "scenes" / "demo.toml"
    out = tmp_path / "x.exr"
    code, _, err = cli("render", demo, "--method", "volpth", "-o", out)
    assert (code, err) == (2, (f"error: --method: unknown render method 'volpth' (known: {_known(known_methods())}); "
                               "did you mean 'volpath'?\n"))
    code, _, err = cli("render", demo, "--method", "volpath", "--source", "procedral", "-o", out)
    assert (code, err) == (2, ("error: --source: unknown volpath source 'procedral' "
                               "(known: procedural, realized, grid); did you mean 'procedural'?\n"))
    code, _, err = cli("render", demo, "--source", "realised", "-o", out)
    assert (code, err) == (2, ("error: --source: unknown render source 'realised' "
                               f"(known: {_known(all_sources())}); did you mean 'realized'?\n"))
    # procedural without tables and --no-build: the option the render command has (it said `--set tables=`)
    code, _, err = cli("render", demo, "--no-build", "-o", out)
    assert (code, err) == (2, ("error: --tables: volpath --source procedural needs the procedural tables "
                               "(loomlight tables): pass --tables PATH.zarr\n"))
    assert list(tmp_path.iterdir()) == []


def test_procedural_source_without_tables_names_the_option():
    from pipeline.renderers.volpath import procedural_source

    with pytest.raises(LoomError) as e:
        procedural_source(None)
    assert e.value.one_line() == ("--tables: --source procedural needs the procedural tables (loomlight tables): "
                                  "pass --tables PATH.zarr")


def test_preset_option_and_recorded_preset():
    from pipeline.presets import load_preset, resolve_yarn_types

    with pytest.raises(LoomError) as e:
        load_preset("coton1")
    assert e.value.one_line() == f"--preset: unknown preset 'coton1' (known: {PRESETS}); did you mean 'cotton1'?"
    with pytest.raises(LoomError) as e:   # a yarns artifact recorded before names were checked at ingest
        resolve_yarn_types([{"preset": "coton1"}], [0.03], file="y.zarr")
    assert e.value.one_line() == (f"y.zarr: yarn_types[0].preset: unknown preset 'coton1' (known: {PRESETS}); "
                                  "did you mean 'cotton1'?")


def test_evaluate_modes_name_the_options(cli, tmp_path):
    code, _, err = cli("evaluate", "-o", tmp_path / "e")
    assert (code, err) == (2, "error: --ref/--test: give exactly one of --ref/--test, --sweep, --table1 or "
                              "--convergence (got none)\n")
    code, _, err = cli("evaluate", "--sweep", "s.toml", "--convergence", "c.toml", "-o", tmp_path / "e")
    assert (code, err) == (2, "error: --sweep and --convergence: give exactly one of --ref/--test, --sweep, "
                              "--table1 or --convergence (got 2)\n")
    code, _, err = cli("evaluate", "--sweep", "s.toml", "--reference-only", "-o", tmp_path / "e")
    assert (code, err) == (2, "error: --reference-only: goes with --convergence\n")


# ------------------------------------------------------------------------------------------------ no placeholder
def test_no_input_placeholder():
    assert LoomError(None, "--method", "m").one_line() == "--method: m"
    assert LoomError(None, None, "m").one_line() == "m"
    assert LoomError("s.toml", "render.method", "m").one_line() == "s.toml: render.method: m"
    assert LoomError("s.toml", None, "a\n  b").one_line() == "s.toml: a b"
    for path in (ROOT / "pipeline").rglob("*.py"):
        assert "<input>" not in path.read_text(), path
