"""Render outputs atomic as a set (issue 16, item 5), with real processes killed by SIGKILL.

A render is started in a subprocess with ``LOOMLIGHT_PAUSE_AT`` naming one moment of its publication
(``pipeline.artifacts.pause_point``): ``built`` (EXR, PNG and artifact complete in hidden temporaries,
no journal yet), ``journal`` (the journal listing the moves written, nothing moved), ``half-published``
(the EXR moved, the PNG and the artifact not). When the process announces the moment on stderr it is
killed with SIGKILL. The next run of ``render`` on that path -- here one refused by a 1 MiB memory
budget after it has opened the output, so that it publishes nothing itself -- discards a publication
that had no journal and finishes one that had.

Contract: after that next run the EXR, PNG and render artifact are one set -- the artifact's recorded
sha256 of the EXR and of the PNG (``companions``) equal the files' -- and it is the old set (killed
before the journal) or the new one (killed after it), never a mix; no hidden temporary
(``.<name>.tmp-<pid>-...``, ``.old-``, ``.publish-``) of the killed process is left. The same cleaning
happens when the next run finds its output up to date (an ingest killed after building, then re-run
with the old parameters: skipped, the artifact untouched, the temporaries gone).
"""
from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT

H = ROOT / "tests" / "hostile"


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _kill_at(point: str, argv: list, cwd: Path) -> None:
    """Run ``loomlight argv`` in a subprocess, SIGKILL it when it announces pause point ``point``."""
    env = {**os.environ, "LOOMLIGHT_PAUSE_AT": point, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", *map(str, argv)], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if line.strip() == f"loomlight: paused at {point}":
            proc.send_signal(signal.SIGKILL)
            break
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "".join(seen)


def _leftovers(d: Path) -> list:
    return sorted(p.name for p in d.iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def fibers(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("publication")
    assert main(["ingest", str(H / "small.txt"), "--radius", "0.02", "-o", str(d / "yarns.zarr")]) == 0
    assert main(["realize", str(d / "yarns.zarr"), "--spacing", "0.01", "-o", str(d / "fibers.zarr")]) == 0
    return d / "fibers.zarr"


@pytest.mark.parametrize("point, survivor", [("built", "old"), ("journal", "new"), ("half-published", "new")])
def test_killed_render_leaves_one_set(cli, tmp_path, fibers, monkeypatch, point, survivor):
    from pipeline.artifacts import read_meta

    out = tmp_path / "img" / "r.exr"
    png, art = out.with_suffix(".png"), out.with_suffix(".zarr")
    render = ["render", H / "scene_ok.toml", "--method", "fiberpath", "--fibers", fibers, "--width", "16",
              "--height", "12", "--spp", "1", "-o", out]

    def the_set():
        comp = read_meta(art)["companions"]
        files = {"exr": _sha(out), "png": _sha(png)}
        assert files == {"exr": comp["r.exr"]["sha256"], "png": comp["r.png"]["sha256"]}, "a mixed set"
        return {**files, "artifact": read_meta(art)["content_hash"]}

    assert cli(*render, "--seed", "1")[0] == 0
    old = the_set()
    _kill_at(point, render + ["--seed", "2"], tmp_path)
    assert _leftovers(out.parent), "the killed render should have left its hidden temporaries"
    monkeypatch.setenv("LOOMLIGHT_MEMORY_BUDGET", "1")  # the next run opens the output, then is refused
    code, _, err = cli(*render, "--seed", "3")
    assert code == 2 and "over the budget" in err, err
    after = the_set()
    if survivor == "old":
        assert after == old
    else:  # the killed run's images: all three differ from the old ones
        assert all(after[k] != old[k] for k in after)
    assert _leftovers(out.parent) == []
    # and a run that publishes afterwards gives a consistent set again
    monkeypatch.delenv("LOOMLIGHT_MEMORY_BUDGET")
    assert cli(*render, "--seed", "4")[0] == 0
    assert the_set() not in (old, after) and _leftovers(out.parent) == []


def test_up_to_date_run_removes_a_killed_runs_temporaries(cli, tmp_path):
    from pipeline.artifacts import read_meta

    out = tmp_path / "yarns.zarr"
    ingest = ["ingest", H / "small.txt", "--radius", "0.02", "-o", out]
    assert cli(*ingest)[0] == 0
    before = read_meta(out)["content_hash"]
    _kill_at("built", ["ingest", H / "small.txt", "--radius", "0.03", "-o", out], tmp_path)
    left = _leftovers(tmp_path)
    assert left and all(n.startswith(".yarns.zarr.tmp-") for n in left), left
    code, _, err = cli(*ingest)
    assert code == 0 and "up to date" in err, err
    assert read_meta(out)["content_hash"] == before and _leftovers(tmp_path) == []
