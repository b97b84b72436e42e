"""Every count option has an upper bound, with an estimate in the refusal (issue 58, cases 1, 8 and 10;
item 3), each refusal following the contract of ``tests/hostile/contract.py`` (exit code 2, one line
naming the option, the workspace untouched):

- cells (memory): the ``--cell-factor`` of case 1 made ~1e20 cells, an int64 overflow and a numpy
  ValueError (exit 1); the cell count is now computed before any cell is allocated;
- SGs: past the pixels of the visibility image (an SG's weight is the solid angle of the pixels nearest
  its axis), past the time limit (the fit's least time), past the memory prt needs to load them;
- paths (time: ``pipeline.limits.WorkEstimate``, at rates no thread reaches).

The workspace: ``tests/hostile/precomputed.py``.
"""
from __future__ import annotations

import json

import pytest

from tests.hostile.contract import assert_refused
from tests.hostile.precomputed import IIRTF_ARGS, build


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    return build(tmp_path_factory.mktemp("count_bounds"))


def test_cell_factor_bounded_by_memory(cli, ws):
    """Case 1: cells of 1e-6 mean free paths were ~1e20 cells, an int64 overflow and a numpy ValueError
    (exit 1); now refused from the cell count, computed before any cell is allocated."""
    args = [a if a != "3" else "1e-6" for a in IIRTF_ARGS]
    assert_refused(cli, ws, ["precompute", "iirtf", ws / "tiling.zarr", "-o", ws / "iirtf.zarr", *args, "--paths", "20",
                             "--scene", ws / "scene.toml"], "--cell-factor", "cells", "raise --cell-factor")
    # within the cell cap but past the memory budget: the estimate names the cell grids
    args = [a if a != "3" else "0.01" for a in IIRTF_ARGS]
    assert_refused(cli, ws, ["precompute", "iirtf", ws / "tiling.zarr", "-o", ws / "iirtf.zarr", *args,
                             "--scene", ws / "scene.toml", "--budget", "200"], "--cell-factor", "cell grids",
                   "over the budget")


def test_sg_count_bounded(cli, ws, monkeypatch):
    """Case 8: 100,000 SGs over 128 x 128 pixels ran 112 s and published 2.4 GB; SGs past the pixel count
    get no weight (each SG's weight is the solid angle of the pixels nearest its axis), past the time
    limit the fit's estimate refuses them, past the budget the memory prt would need."""
    base = ["precompute", "svf", ws / "tiling.zarr", "-o", ws / "svf.zarr", "--components", "1", "--threads", "2"]
    assert_refused(cli, ws, [*base, "--sg-count", "100000"], "--sg-count", "16384 visibility pixels")
    monkeypatch.setenv("LOOMLIGHT_TIME_LIMIT", "0.001")
    assert_refused(cli, ws, [*base, "--resolution", "1024", "--sg-count", "100000"], "--sg-count",
                   "would take at least an estimated", "SG fit", "LOOMLIGHT_TIME_LIMIT")
    monkeypatch.delenv("LOOMLIGHT_TIME_LIMIT")
    S = json.loads((ws / "tiling.zarr" / "zarr.json").read_text())["attributes"]["summary"]["segments"]
    budget = S * 16384 * 4 / 2 / 2 ** 20   # half the SG weights of 16,384 SGs (as many as 128 x 128 pixels)
    assert_refused(cli, ws, [*base, "--sg-count", "16384", "--budget", f"{budget:.6f}"], "--sg-count",
                   "render --method prt on this SVF", "SG weights", "over the budget")


def test_paths_bounded_by_time(cli, ws, monkeypatch):
    """Case 10: 1e12 paths a cell were accepted with no bound; the least time (at 1e6 paths a second a
    thread, ~40x the measured rate) is printed with the refusal, before the mean free paths are traced."""
    monkeypatch.delenv("LOOMLIGHT_TIME_LIMIT", raising=False)
    args = [a for a in IIRTF_ARGS]
    args[args.index("--paths") + 1] = "1000000000000"
    line = assert_refused(cli, ws, ["precompute", "iirtf", ws / "tiling.zarr", "-o", ws / "iirtf.zarr", *args,
                                    "--scene", ws / "scene.toml"], "--paths", "would take at least an estimated",
                          "transfer matrices", "24 h")
    assert "days" in line or "years" in line
    args = [a for a in IIRTF_ARGS]
    args[args.index("--mfp-paths") + 1] = "1000000000000"
    assert_refused(cli, ws, ["precompute", "iirtf", ws / "tiling.zarr", "-o", ws / "iirtf.zarr", *args,
                             "--scene", ws / "scene.toml"], "--mfp-paths", "mean free paths")


def test_time_limit_setting_checked(cli, ws, monkeypatch):
    monkeypatch.setenv("LOOMLIGHT_TIME_LIMIT", "soon")
    assert_refused(cli, ws, ["precompute", "iirtf", ws / "tiling.zarr", "-o", ws / "iirtf.zarr", *IIRTF_ARGS,
                             "--scene", ws / "scene.toml"], "LOOMLIGHT_TIME_LIMIT", "hours")


def test_render_spp_bounded_by_time(cli, ws):
    """``render --spp`` (and ``--max-spp``, the adaptive pass's most) had no bound: the camera paths' least
    time (at 1e7 paths a thread-second, ~200x the measured rate) is refused past the time limit."""
    base = ["render", ws / "scene.toml", "--method", "fiberpath", "--fibers", ws / "tiling.zarr", "--threads", "2",
            "-o", ws / "render.exr"]
    line = assert_refused(cli, ws, [*base, "--spp", "100000000000000"], "--spp", "camera paths",
                          "8 x 6 pixels x 100,000,000,000,000 spp", "would take at least an estimated")
    assert "years" in line
    assert_refused(cli, ws, [*base, "--spp", "1", "--max-spp", "100000000000000"], "--max-spp", "adaptive paths")


@pytest.mark.parametrize("where", ["render", "iirtf", "scene"])
def test_path_depth_capped(cli, ws, where):
    """``max_depth`` / ``rr_depth`` cap work that Russian roulette ends long before
    (``pipeline.limits.MAX_PATH_DEPTH``): past the cap a number is a typo; before, a render or an IIRTF
    precompute took any depth, and one past int64 was a numba OverflowError (exit 1)."""
    huge = "100000000000000000000000"
    if where == "render":
        assert_refused(cli, ws, ["render", ws / "scene.toml", "--method", "fiberpath", "--fibers", ws / "tiling.zarr",
                                 "--max-depth", "20000", "-o", ws / "r.exr"], "--max-depth", "from 1 to 10,000")
    elif where == "iirtf":
        for opt in ("--max-depth", "--rr-depth"):
            assert_refused(cli, ws, ["precompute", "iirtf", ws / "tiling.zarr", "-o", ws / "iirtf.zarr", *IIRTF_ARGS,
                                     "--scene", ws / "scene.toml", opt, huge], opt, "from 1 to 10,000")
    else:
        scene = ws / "deep_scene.toml"
        try:
            scene.write_text((ws / "scene.toml").read_text() + "\n[render]\nmax_depth = 20000\n")
            assert_refused(cli, ws, ["render", scene, "--method", "fiberpath", "--fibers", ws / "tiling.zarr",
                                     "-o", ws / "r.exr"], "deep_scene.toml", "max_depth", "10000")
        finally:
            scene.unlink()
