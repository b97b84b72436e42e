"""Issue 58's leftovers, each refusal following the contract of ``tests/hostile/contract.py`` (exit code 2,
one line naming the file or option and the place, the workspace -- previous outputs included -- byte for
byte as it was):

1. a WIF ``[WARP] Spacing=1e300`` was blamed on "curve 0, point 0" (the woven curves it made); now the
   draft's key is named with the real problem: a thread's spacing and thickness, in centimetres after
   ``Units``, lie between 1 micrometre and 1 m (``pipeline.io.wif``; ``1e-300`` was accepted, merging
   every control point);
2. random bytes given as a WIF said ``[THREADING]: missing``; now "not a WIF draft" naming the file
   (not text, or no ``[WIF]`` section and none of a draft's);
3. a fibers or tables artifact whose recorded yarns input moved named only that path, which the user
   never passed (``volpath --source realized``), or rendered without the yarn groups (``fiberpath``,
   ``volpath --tables``: the BCSDF of the wrong group); now the artifact passed and ``inputs.yarns`` are
   named, with the recorded path and what to re-run (``pipeline.render_setup.recorded_input``);
4. ``precompute btf``'s count options: ``--spp`` by time (``pipeline.limits.WorkEstimate``),
   ``--resolution`` / ``--views`` / ``--lights`` by memory naming the option, ``--max-depth``,
   ``--rr-depth``, ``--max-rounds`` by caps (numbers past int64 crashed in the kernels);
5. ``tables --bins`` by memory naming ``--bins`` and by time when the budget is raised past any memory;
   ``voxelize --supersample`` by time; ``--workers`` by memory and ``--threads-per-worker`` by the CPUs
   (a LocalCluster of a million processes was started).
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.hostile.contract import assert_refused
from tests.hostile.precomputed import SCENE as PRT_SCENE

H = Path(__file__).resolve().parent
DRAFTS = H.parents[1] / "data" / "drafts"

WIF_SCENE = """
[fabric]
source = "wif"
path = "{path}"
[camera]
origin = [0.0, -1.0, 0.3]
target = [0.0, 0.0, 0.0]
width = 8
height = 6
[[lights]]
type = "directional"
direction = [-0.4, 0.5, -0.77]
irradiance = 3.0
"""


def _draft(W: Path, name: str, old: str, new: str) -> Path:
    """The twill draft (Units=Millimeters, Spacing=1.0, Thickness=0.4 in [WARP] and [WEFT]) with the first
    line ``old`` of [WARP] replaced by ``new``."""
    text = (DRAFTS / "twill_2x2.wif").read_text()
    assert old in text
    (W / name).write_text(text.replace(old, new, 1))
    return W / name


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    """A previous yarns artifact (``y.zarr``, the -o of every WIF case) and the drafts."""
    from pipeline.cli import main

    W = tmp_path_factory.mktemp("round2")
    assert main(["ingest", str(DRAFTS / "twill_2x2.wif"), "-o", str(W / "y.zarr")]) == 0
    return W


# ------------------------------------------------------------------------------------------------ 1. WIF lengths
@pytest.mark.parametrize("old, new, says", [
    ("Spacing=1.0", "Spacing=1e300", ["Spacing = 1e300 (Millimeters) is 1e+299 cm"]),
    ("Spacing=1.0", "Spacing=1e-300", ["Spacing = 1e-300 (Millimeters) is 1e-301 cm"]),
    ("Thickness=0.4", "Thickness=1e300", ["Thickness = 1e300 (Millimeters)"]),
    ("Spacing=1.0", "Spacing=1.0e3", ["Spacing = 1.0e3 (Millimeters) is 100 cm"]),
    ("Spacing=1.0", "Spacing=inf", ["Spacing = 'inf' is not finite"]),
])
def test_wif_spacing_named_with_the_problem(cli, ws, old, new, says):
    """Blamed on the draft's own key, not on the curves made from it (was: ``curve 0, point 0: coordinate
    -3.5e+299 is beyond +-1e+06``, and ``1e-300`` went through with every control point merged)."""
    draft = _draft(ws, "draft.wif", old, new)
    try:
        line = assert_refused(cli, ws, ["ingest", draft, "-o", ws / "y.zarr"], "draft.wif: [WARP] line", *says)
        if "finite" not in line:
            assert "between 1 micrometre and 1 m" in line and "[WARP] Units" in line, line
        assert "curve 0" not in line
    finally:
        draft.unlink()


def test_wif_spacing_through_a_scene(cli, ws):
    """The same refusal when the draft is a scene's fabric: the draft file and its key are named."""
    draft = _draft(ws, "wide.wif", "Spacing=1.0", "Spacing=1e300")
    (ws / "wif_scene.toml").write_text(WIF_SCENE.format(path=draft))
    try:
        assert_refused(cli, ws, ["ingest", ws / "wif_scene.toml", "-o", ws / "y.zarr"], "wide.wif: [WARP] line",
                       "Spacing = 1e300")
    finally:
        draft.unlink()
        (ws / "wif_scene.toml").unlink()


# ------------------------------------------------------------------------------------------------ 2. not a WIF
@pytest.mark.parametrize("content, says", [
    (np.random.default_rng(58).bytes(4096), "not text"),
    (b"hello\nthis is a letter, not a draft\n", "no [WIF] section"),
    (b"[SETTINGS]\ncolour=blue\n", "its sections are [SETTINGS]"),
])
def test_not_a_wif_draft(cli, ws, content, says):
    """Was: ``[THREADING]: missing: the draft has no threading section``, for any file at all."""
    bad = ws / "bytes.wif"
    bad.write_bytes(content)
    try:
        line = assert_refused(cli, ws, ["ingest", bad, "-o", ws / "y.zarr"], "bytes.wif", "not a WIF draft", says)
        assert "[THREADING]: missing" not in line
    finally:
        bad.unlink()


def test_real_drafts_still_read():
    """The control: every bundled draft (one has no [WIF] section) still parses."""
    from pipeline.io import wif

    for path in sorted(DRAFTS.glob("*.wif")):
        assert wif.parse(path).over.size > 0, path


# ------------------------------------------------------------------------------------------------ 3. moved yarns
SCENE = (H / "scene_ok.toml").read_text()


@pytest.fixture(scope="module")
def moved(tmp_path_factory):
    """fibers.zarr and tables.zarr built from old/yarns.zarr, which was then moved to new/yarns.zarr; a
    previous render's files and a previous artifact at grid.zarr."""
    from pipeline.cli import main

    W = tmp_path_factory.mktemp("moved")
    (W / "scene.toml").write_text(SCENE)
    shutil.copy(H / "small.txt", W / "small.txt")
    (W / "old").mkdir()
    assert main(["ingest", str(W / "scene.toml"), "-o", str(W / "old" / "yarns.zarr")]) == 0
    assert main(["realize", str(W / "old" / "yarns.zarr"), "--spacing", "0.01", "-o", str(W / "fibers.zarr")]) == 0
    assert main(["tables", str(W / "old" / "yarns.zarr"), "-o", str(W / "tables.zarr")]) == 0
    (W / "new").mkdir()
    (W / "old" / "yarns.zarr").rename(W / "new" / "yarns.zarr")
    shutil.copytree(W / "tables.zarr", W / "grid.zarr")   # a previous artifact at voxelize's -o
    for name, text in (("render.exr", "previous EXR"), ("render.png", "previous PNG")):
        (W / name).write_text(text)
    return W


@pytest.mark.parametrize("args, artifact, stage", [
    (["--method", "fiberpath", "--fibers", "{W}/fibers.zarr"], "fibers.zarr", "loomlight realize"),
    (["--method", "volpath", "--source", "realized", "--fibers", "{W}/fibers.zarr"], "fibers.zarr",
     "loomlight realize"),
    (["--method", "volpath", "--tables", "{W}/tables.zarr"], "tables.zarr", "loomlight tables"),
])
def test_moved_yarns_named_by_the_artifact_passed(cli, moved, args, artifact, stage):
    """Was (volpath realized): ``old/yarns.zarr: artifact not found``, a path the user never typed; fiberpath
    and volpath on tables rendered on without the yarn groups."""
    W = moved
    args = [a.format(W=W) for a in args]
    line = assert_refused(cli, W, ["render", W / "scene.toml", *args, "--spp", "1", "-o", W / "render.exr"],
                          f"{W / artifact}: inputs.yarns: recorded input {W / 'old' / 'yarns.zarr'} is gone "
                          "(moved or deleted)", f"re-run {stage}")
    assert line.startswith(f"error: {W / artifact}"), line


def test_unreadable_recorded_yarns(cli, moved):
    """A recorded path that is there but no artifact: named the same way, with what is wrong with it."""
    W = moved
    (W / "old" / "yarns.zarr").mkdir()
    try:
        assert_refused(cli, W, ["render", W / "scene.toml", "--method", "fiberpath", "--fibers", W / "fibers.zarr",
                                "--spp", "1", "-o", W / "render.exr"],
                       f"{W / 'fibers.zarr'}: inputs.yarns: recorded input {W / 'old' / 'yarns.zarr'} cannot be read",
                       "artifact")
    finally:
        (W / "old" / "yarns.zarr").rmdir()


# ------------------------------------------------------------------------------------------------ 4. precompute btf
@pytest.fixture(scope="module")
def tiled(tmp_path_factory):
    """The tiny tiling of the precompute tests, the hostile prt scene (its materials), and a previous
    artifact at the -o path (a copy of the tiling: any artifact stands for the previous output)."""
    from tests.precompute.conftest import make_tiling

    W = tmp_path_factory.mktemp("btf_bounds")
    make_tiling(W)
    (W / "scene.toml").write_text(PRT_SCENE)
    shutil.copytree(W / "tiling.zarr", W / "btf.zarr")
    return W


@pytest.mark.parametrize("opts, names", [
    (["--spp", "1000000000000"], ["--spp", "would take at least an estimated", "camera rays",
                                  "1,000,000,000,000 samples", "24 h"]),
    (["--resolution", "256", "--views", "64x64", "--lights", "64x64"],
     ["--views", "needs an estimated", "4,096 views x 4,096 lights", "over the budget"]),
    (["--resolution", "256", "--views", "64x64", "--lights", "1x1"], ["--resolution", "needs an estimated", "fit"]),
    (["--resolution", "512"], ["--resolution", "power of two from 1 to 256"]),
    (["--views", "100x100"], ["--views", "at most 4096 directions"]),
    (["--max-depth", "100000000000000000000000"], ["--max-depth", "past the cap of 10,000"]),
    (["--rr-depth", "20000"], ["--rr-depth", "past the cap of 10,000"]),
    (["--max-rounds", "1000000"], ["--max-rounds", "past the cap of 1,000"]),
])
def test_btf_counts_bounded(cli, tiled, monkeypatch, opts, names):
    """Before: --spp, --max-depth, --rr-depth and --max-rounds had no upper bound (a number past int64 was a
    numba OverflowError, exit 1), and a memory refusal named the tiling, not the option."""
    monkeypatch.delenv("LOOMLIGHT_TIME_LIMIT", raising=False)
    W = tiled
    assert_refused(cli, W, ["precompute", "btf", W / "tiling.zarr", "-o", W / "btf.zarr", "--scene", W / "scene.toml",
                            "--threads", "2", *opts], *names)


def test_btf_time_limit_names_the_estimate(cli, tiled, monkeypatch):
    """The time bound follows LOOMLIGHT_TIME_LIMIT, with the parts of the estimate in the line."""
    monkeypatch.setenv("LOOMLIGHT_TIME_LIMIT", "0.000001")
    W = tiled
    assert_refused(cli, W, ["precompute", "btf", W / "tiling.zarr", "-o", W / "btf.zarr", "--scene", W / "scene.toml",
                            "--threads", "2", "--spp", "100000"], "--spp", "light directions", "LOOMLIGHT_TIME_LIMIT")


# ------------------------------------------------------------------------------------------------ 5. tables, voxelize
def test_tables_bins_bounded(cli, moved, monkeypatch):
    """--bins was bounded by memory but refused naming only the yarns artifact; now --bins too (the bins
    are at fault: the default would have passed), and past any memory (a raised --budget) by time."""
    monkeypatch.delenv("LOOMLIGHT_TIME_LIMIT", raising=False)
    W = moved
    base = ["tables", W / "new" / "yarns.zarr", "-o", W / "tables.zarr"]
    assert_refused(cli, W, [*base, "--bins", "1000000000000"], "yarns.zarr: --bins: loomlight tables needs an "
                   "estimated", "1000000000000 bins", "over the budget", "lower --bins")
    assert_refused(cli, W, [*base, "--bins", "1000000000000000", "--budget", "1e30"], "yarns.zarr: --bins",
                   "would take at least an estimated", "regular-fibre bins", "24 h")


def test_voxelize_supersample_bounded_by_time(cli, moved, monkeypatch):
    monkeypatch.delenv("LOOMLIGHT_TIME_LIMIT", raising=False)
    W = moved
    assert_refused(cli, W, ["voxelize", W / "tables.zarr", "-o", W / "grid.zarr", "--res", "32", "32", "32",
                            "--supersample", "100000"], "--supersample", "would take at least an estimated",
                   "procedural lookups", "100,000^3 lookups")


@pytest.mark.parametrize("cmd", ["realize", "voxelize"])
def test_local_cluster_bounded(cli, moved, cmd):
    """A LocalCluster of a million worker processes was started (a machine's worth of memory and more);
    a worker's numba threads past the CPUs only wait for each other."""
    W = moved
    base = (["realize", W / "new" / "yarns.zarr", "-o", W / "fibers.zarr"] if cmd == "realize" else
            ["voxelize", W / "tables.zarr", "-o", W / "grid.zarr", "--res", "8", "8", "8"])
    assert_refused(cli, W, [*base, "--scheduler", "processes", "--workers", "1000000"], "--workers",
                   "1,000,000 workers", "needs an estimated", "over the budget")
    assert_refused(cli, W, [*base, "--scheduler", "processes", "--threads-per-worker", "100000"],
                   "--threads-per-worker", "CPUs")
