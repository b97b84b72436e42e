"""Render honours its scene (issue 16, item 6).

Contract (``pipeline.render_setup.check_scene_matches``, ``pipeline.runners.render``): with
``--fibers`` or ``--tables``, the scene's fabric (source file by its bytes, or generator table) and
the yarn types of the groups the fabric has (preset, radius, colour, ...; not ``bcsdf``, the
renderer's own) must be those the artifact was made of -- recorded by ingest, carried by tables and
realize -- and a ``--preset`` the artifact was made with must be the one the scene states; else
exit 2, one line naming the scene, the place and the artifact with what it was made from. Unknown
BCSDF names (in any group, or ``--bcsdf``), unknown ``--set`` keys and values are errors, whether a
yarn uses them or not. Every refusal comes before any rendering and leaves no output.
"""
from __future__ import annotations

import shutil

import pytest

from tests.helpers import ROOT

H = ROOT / "tests" / "hostile"
SCENE = (H / "scene_ok.toml").read_text()
RED = SCENE.replace('[yarns.default]\nbcsdf = "cotton"\n',
                    '[yarns.default]\nbcsdf = "cotton"\n\n[yarns.other]\npreset = "cotton1"\ncolor = [0.9, 0.1, 0.1]\n')


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A scene naming a red 'other' yarn of cotton1 over small.txt, its yarns, fibres and tables; the
    same fabric ingested bare; tables of the red scene made with --preset silk1."""
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("scene_match")
    shutil.copy(H / "small.txt", d / "small.txt")
    (d / "red.toml").write_text(RED)
    run = lambda *a: main([str(x) for x in a])  # noqa: E731
    assert run("ingest", d / "red.toml", "-o", d / "red_yarns.zarr") == 0
    assert run("realize", d / "red_yarns.zarr", "--spacing", "0.05", "-o", d / "red_fibers.zarr") == 0
    assert run("tables", d / "red_yarns.zarr", "-o", d / "red_tables.zarr") == 0
    assert run("tables", d / "red_yarns.zarr", "--preset", "silk1", "-o", d / "silk_tables.zarr") == 0
    assert run("ingest", d / "small.txt", "--radius", "0.02", "-o", d / "bare_yarns.zarr") == 0
    assert run("realize", d / "bare_yarns.zarr", "--spacing", "0.05", "-o", d / "bare_fibers.zarr") == 0
    return d


def _scene(d, name, text):
    (d / name).write_text(text)
    return d / name


def _refused(cli, d, args, words):
    out = d / "out" / "r.exr"
    code, so, err = cli("render", *args, "--width", 8, "--height", 6, "--spp", 1, "-o", out)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (code, so, err)
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert not (d / "out").exists()
    return lines[0]


def test_yarn_colour_of_another_scene_refused(cli, made):
    """Fibres of the red scene rendered with the scene that states no colour (their colour would be
    silently the red), and fibres of the bare file rendered with the red scene (the red dropped)."""
    plain = _scene(made, "plain.toml", SCENE)
    _refused(cli, made, [plain, "--method", "fiberpath", "--fibers", made / "red_fibers.zarr"],
             ["plain.toml: yarns.other.color", "red_fibers.zarr (--fibers, made from red.toml)", "0.9, 0.1, 0.1"])
    _refused(cli, made, [made / "red.toml", "--method", "fiberpath", "--fibers", made / "bare_fibers.zarr"],
             ["red.toml: yarns.other", "bare_fibers.zarr (--fibers, made from small.txt)"])
    _refused(cli, made, [plain, "--method", "volpath", "--tables", made / "red_tables.zarr"],
             ["plain.toml: yarns.other.color", "red_tables.zarr (--tables, made from red.toml)",
              "re-run ingest and tables"])


def test_another_preset_refused(cli, made):
    silk = _scene(made, "silk.toml", RED.replace('preset = "cotton1"', 'preset = "silk1"'))
    _refused(cli, made, [silk, "--method", "fiberpath", "--fibers", made / "red_fibers.zarr"],
             ["silk.toml: yarns.other.preset", "silk1", "cotton1", "red_fibers.zarr"])
    _refused(cli, made, [made / "red.toml", "--method", "volpath", "--tables", made / "silk_tables.zarr"],
             ["red.toml: yarns.other.preset", "--preset silk1", "silk_tables.zarr"])


def test_another_fabric_refused(cli, made):
    """Another curve file (one coordinate differs) and a generator, against fibres of small.txt."""
    (made / "other.txt").write_text((made / "small.txt").read_text().replace("0.1", "0.11", 1))
    other = _scene(made, "other.toml", SCENE.replace('path = "small.txt"', 'path = "other.txt"'))
    _refused(cli, made, [other, "--method", "fiberpath", "--fibers", made / "bare_fibers.zarr"],
             ["other.toml: fabric", "file other.txt", "file small.txt", "bare_fibers.zarr"])
    gen = _scene(made, "gen.toml", SCENE.replace('source = "file"\npath = "small.txt"\nradius = 0.02',
                                                 'source = "generator"\nradius = 0.02\n[fabric.generator]\n'
                                                 'kind = "woven"\npattern = "plain"\n'))
    _refused(cli, made, [gen, "--method", "fiberpath", "--fibers", made / "bare_fibers.zarr"],
             ["gen.toml: fabric", "generator", "small.txt"])


def test_what_matches(made):
    """The same fabric under another name, another BCSDF, or the same scene: accepted."""
    from pipeline.render_setup import check_scene_matches
    from pipeline.scene import load_scene

    shutil.copy(made / "small.txt", made / "renamed.txt")
    renamed = _scene(made, "renamed.toml", RED.replace('path = "small.txt"', 'path = "renamed.txt"')
                     .replace('bcsdf = "cotton"', 'bcsdf = "silk"'))
    check_scene_matches(load_scene(renamed), made / "red_fibers.zarr", "fibers")
    check_scene_matches(load_scene(made / "red.toml"), made / "red_tables.zarr", "tables")
    check_scene_matches(load_scene(H / "scene_ok.toml"), made / "bare_fibers.zarr", "fibers")


def test_unknown_bcsdf_and_settings_refused(cli, made):
    fib = ["--fibers", made / "bare_fibers.zarr"]
    unused = _scene(made, "velvet.toml", SCENE + '\n[yarns.knit]\nbcsdf = "velvet"\n')  # no knit yarns in small.txt
    _refused(cli, made, [unused, "--method", "fiberpath", *fib], ["velvet.toml: yarns.knit.bcsdf", "velvet", "known:"])
    _refused(cli, made, [H / "scene_ok.toml", "--method", "fiberpath", *fib, "--bcsdf", "velvet"],
             ["--bcsdf", "unknown BCSDF preset 'velvet'"])
    _refused(cli, made, [H / "scene_ok.toml", "--method", "fiberpath", *fib, "--set", "tinted=none"],
             ["--set tinted", "fiberpath has no setting 'tinted'", "did you mean 'tint'"])
    _refused(cli, made, [H / "scene_ok.toml", "--method", "fiberpath", *fib, "--material", "lambert",
                         "--set", "tint=blue"], ["--set tint", "unknown tint 'blue'", "yarn, none"])
    _refused(cli, made, [H / "scene_ok.toml", "--method", "volpath", "--source", "realized", *fib,
                         "--set", "phase=mie"], ["--set phase", "unknown phase 'mie'"])
