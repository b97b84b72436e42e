"""One command renders a scene (issue 54 item 6, ``pipeline/autobuild.py``): ``loomlight render SCENE --method M
-o out.exr`` without artifact options builds what M reads into ``.loomlight-cache`` beside the output, keyed by
content, and a second render reuses it; explicit options win; what cannot be built is one line, exit code 2.

References: the render of a second run is the same bytes as the first (the reuse contract, a round trip
through the cache); the cached artifacts are those ``ingest`` / ``realize`` make at their defaults (their
recorded parameters); the keys change exactly with what the step reads (closed-form cases below)."""
import re
import shutil
from pathlib import Path

import pytest

from pipeline.artifacts import Artifact
from tests.helpers import ROOT

SINGLE = ROOT / "data" / "scenes" / "single_yarn.toml"
FLAT = ROOT / "data" / "scenes" / "flat_satin.toml"
SMALL = ["--width", "12", "--height", "6", "--spp", "1"]
BUILT = re.compile(r"^built (\w+) \((\d+\.\d) s\) \u2192 (\S+)$")
REUSED = re.compile(r"^reused (\w+) (\S+)$")


def _steps(out: str) -> list[tuple[str, str, str]]:
    """("built" | "reused", kind, path) of every cache line the render printed."""
    steps = []
    for line in out.splitlines():
        if m := BUILT.match(line):
            steps.append(("built", m.group(1), m.group(3)))
        elif m := REUSED.match(line):
            steps.append(("reused", m.group(1), m.group(2)))
    return steps


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    """single_yarn.toml and its curve file in a directory of their own (the scene names the file relatively)."""
    d = tmp_path_factory.mktemp("one_command")
    (d / "curves").mkdir()
    shutil.copy(ROOT / "data" / "curves" / "single_yarn.txt", d / "curves" / "single_yarn.txt")
    (d / "scenes").mkdir()
    shutil.copy(SINGLE, d / "scenes" / "single_yarn.toml")
    return d


def test_fiberpath_builds_then_reuses(cli, scene_dir, tmp_path):
    scene = scene_dir / "scenes" / "single_yarn.toml"
    code, out, err = cli("render", scene, "--method", "fiberpath", *SMALL, "-o", tmp_path / "a.exr")
    assert code == 0, err
    steps = _steps(out)
    cache = tmp_path / ".loomlight-cache"
    assert [(s, k) for s, k, _ in steps] == [("built", "yarns"), ("built", "fibers")], out
    yarns, fibers = (Path(p) for _, _, p in steps)
    assert yarns.parent == cache and fibers.parent == cache
    assert (re.fullmatch(r"yarns-[0-9a-f]{16}\.zarr", yarns.name)
            and re.fullmatch(r"fibers-[0-9a-f]{16}\.zarr", fibers.name))
    # what ingest and realize make at their commands' defaults
    assert Artifact(yarns, kind="yarns").params["frame_samples"] == 4
    fp = Artifact(fibers, kind="fibers").params
    assert (fp["seed"], fp["spacing"], fp["preset"], fp["radius"]) == (0, 0.002, None, None)
    art = Artifact(tmp_path / "a.zarr", kind="render")
    assert art.meta["inputs"]["fibers"]["path"] == str(fibers)

    # a second render (another output in the same directory) reuses the fibres and makes the same bytes
    code, out2, err = cli("render", scene, "--method", "fiberpath", *SMALL, "-o", tmp_path / "b.exr")
    assert code == 0, err
    assert _steps(out2) == [("reused", "fibers", str(fibers))], out2
    assert (tmp_path / "a.exr").read_bytes() == (tmp_path / "b.exr").read_bytes()

    # another camera reads the same fibres: reused too (the key holds what realize reads, not the camera)
    moved = scene_dir / "scenes" / "moved.toml"
    moved.write_text(scene.read_text().replace("origin = [0.0, -1.6, 0.35]", "origin = [0.2, -1.5, 0.4]"))
    code, out3, err = cli("render", moved, "--method", "fiberpath", *SMALL, "-o", tmp_path / "c.exr")
    assert code == 0, err
    assert _steps(out3) == [("reused", "fibers", str(fibers))], out3

    # explicit --fibers wins: nothing built or reused, the render reads the given artifact
    from pipeline.runners.realize import run_realize

    given = tmp_path / "given" / "fibers.zarr"
    run_realize(yarns, given, spacing=0.01)
    code, out4, err = cli("render", scene, "--method", "fiberpath", "--fibers", given, *SMALL, "-o", tmp_path / "d.exr")
    assert code == 0, err
    assert _steps(out4) == [], out4
    assert Artifact(tmp_path / "d.zarr", kind="render").meta["inputs"]["fibers"]["path"] == str(given)


def test_bysdf_builds_into_cache_dir_then_reuses(cli, scene_dir, tmp_path):
    scene = scene_dir / "scenes" / "single_yarn.toml"
    cache = tmp_path / "elsewhere"
    args = ["render", scene, "--method", "bysdf", *SMALL, "--cache-dir", cache]
    code, out, err = cli(*args, "-o", tmp_path / "a" / "x.exr")
    assert code == 0, err
    (state, kind, path), = _steps(out)
    assert (state, kind, Path(path).parent) == ("built", "yarns", cache)
    assert not (tmp_path / "a" / ".loomlight-cache").exists()
    code, out2, err = cli(*args, "-o", tmp_path / "b" / "x.exr")
    assert code == 0, err
    assert _steps(out2) == [("reused", "yarns", path)]
    assert (tmp_path / "a" / "x.exr").read_bytes() == (tmp_path / "b" / "x.exr").read_bytes()


def test_method_on_a_tiling_without_a_configuration_is_one_line(cli, tmp_path):
    """prt reads a tiling, which render builds only from a tiling configuration: none named -> exit 2, one
    line naming the scene, the scene key and the option; nothing written, no cache made."""
    out = tmp_path / "x.exr"
    code, so, err = cli("render", FLAT, "--method", "prt", "-o", out)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, (code, so, err)
    assert lines[0].startswith(f"error: {FLAT}: render.tiling: prt needs a tiling artifact")
    assert "--set tiling=CONFIG.toml" in lines[0] and "--fibers PATH.zarr" in lines[0]
    assert list(tmp_path.iterdir()) == []
    # a configuration that does not exist: its path and the option
    code, _, err = cli("render", FLAT, "--method", "prt", "--set", f"tiling={tmp_path / 'nope.toml'}", "-o", out)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "nope.toml" in err and "--set tiling" in err, err
    # --no-build: the refusal of before (what to pass)
    code, _, err = cli("render", FLAT, "--method", "prt", "--no-build", "-o", out)
    assert (code, err) == (2, "error: --fibers: prt needs a tiling artifact (loomlight tile): "
                              "pass --fibers PATH.zarr\n")
    assert list(tmp_path.iterdir()) == []


def test_what_render_does_not_build_is_one_line(cli, tmp_path):
    """volpath --source grid: voxelize needs a resolution, so render says to pass --grid."""
    code, _, err = cli("render", SINGLE, "--method", "volpath", "--source", "grid", "-o", tmp_path / "x.exr")
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "--grid PATH.zarr" in err and "does not build" in err
    assert list(tmp_path.iterdir()) == []


def _planner(scene_path, method, out, **options):
    from pipeline.autobuild import Planner, cache_root
    from pipeline.renderers import method as registered
    from pipeline.runners.render import RenderRequest, render_source, resolve_options
    from pipeline.scene import load_scene

    scene = load_scene(scene_path)
    m = registered(method)
    opts = resolve_options(scene, m, RenderRequest(**options))
    return Planner(scene, m, render_source(scene, m, opts), opts, cache_root(out, None))


def test_keys_follow_what_each_step_reads(tmp_path):
    """Closed-form cases of the key: the camera, a light, the render settings and a BCSDF (the renderer's
    own) leave the yarns, tables and fibres keys unchanged; a yarn colour (read by ingest) or the
    weave changes all three; the tables' key differs from the fibres' (another step); the same scene
    elsewhere gives the same keys."""
    text = FLAT.read_text()
    variants = {
        "same": text,
        "camera": text.replace("fov = 22.0", "fov = 30.0").replace("origin = [0.75, -0.95, 2.1]",
                                                                   "origin = [0, -1, 2]"),
        "light": text.replace("irradiance = 3.0", "irradiance = 5.0"),
        "render": text.replace("spp = 16", "spp = 64\nmax_spp = 64"),
        "bcsdf": text.replace('bcsdf = "gabardine"', 'bcsdf = "cotton"'),
        "colour": text.replace("color = [0.42, 0.10, 0.12]", "color = [0.1, 0.2, 0.3]"),
        "weave": text.replace("n = 5\nends = 5", "n = 5\nends = 10"),
    }
    keys = {}
    for name, t in variants.items():
        assert name == "same" or t != text, name
        p = tmp_path / f"{name}.toml"
        p.write_text(t)
        pl = _planner(p, "volpath", tmp_path / "o.exr")
        keys[name] = (pl.yarns().key, pl.tables().key, pl.fibers().key)
    base = _planner(FLAT, "volpath", tmp_path / "o.exr")
    assert keys["same"] == (base.yarns().key, base.tables().key, base.fibers().key)
    for name in ("camera", "light", "render", "bcsdf"):
        assert keys[name] == keys["same"], name
    for name in ("colour", "weave"):
        assert all(a != b for a, b in zip(keys[name], keys["same"])), name
    assert len(set(keys["same"])) == 3
    assert base.tables().path == tmp_path / ".loomlight-cache" / f"tables-{base.tables().key}.zarr"


def test_a_second_render_waits_for_the_first_then_reuses(scene_dir, tmp_path):
    """Two renders wanting one artifact: the second waits on the lock beside it while the first builds, then
    reuses what the first published (it does not build it again)."""
    import fcntl
    import threading
    import time

    from pipeline.autobuild import ensure
    from pipeline.runners.ingest import run_ingest

    pl = _planner(scene_dir / "scenes" / "single_yarn.toml", "bysdf", tmp_path / "o.exr")
    node = pl.yarns()
    node.path.parent.mkdir(parents=True)
    lines = []
    with open(node.path.parent / f".{node.path.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)                      # the first render, building
        t = threading.Thread(target=ensure, args=(node, lines.append))
        t.start()
        time.sleep(0.5)
        assert t.is_alive() and lines == []                   # the second waits
        run_ingest(scene_dir / "scenes" / "single_yarn.toml", node.path)   # the first publishes
    t.join(30)
    assert not t.is_alive()
    assert lines == [f"reused yarns {node.path}"]
