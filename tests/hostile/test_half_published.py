"""The half-published window is closed for readers (issue 58, item 6): a render publishes its EXR, PNG
and artifact as one set through a journal (``pipeline.artifacts._publish_set``); killed while pinned at
``LOOMLIGHT_PAUSE_AT=half-published`` (the new EXR moved, the PNG and artifact not yet) it used to leave
the new EXR beside the old PNG and artifact until the next *writer* of that path repaired it, and a
reader in between saw a mixed set. Now every reader settles the set first (``pipeline.artifacts.settle``,
called by ``read_meta`` and ``images.read_exr``): a publication whose process is dead is finished, one in
progress is waited for, then refused as one line. Make, the reader that judges by file times, sees the
unfinished set's EXR at the epoch (out of date) and the finished set's at the time it finished.

Reference: the artifact's recorded sha256 of its EXR and PNG (``companions``) against the files' bytes,
and the seeds: the killed render's set (all three files differ from the previous render's).
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


def _paused(point: str, argv: list, cwd: Path) -> subprocess.Popen:
    """``loomlight argv`` in a subprocess, returned once it announces pause point ``point`` (still alive)."""
    env = {**os.environ, "LOOMLIGHT_PAUSE_AT": point, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", *map(str, argv)], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if line.strip() == f"loomlight: paused at {point}":
            return proc
    proc.wait()
    raise AssertionError("".join(seen))


def _kill(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL


@pytest.fixture(scope="module")
def fibers(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("half_published")
    assert main(["ingest", str(H / "small.txt"), "--radius", "0.02", "-o", str(d / "yarns.zarr")]) == 0
    assert main(["realize", str(d / "yarns.zarr"), "--spacing", "0.01", "-o", str(d / "fibers.zarr")]) == 0
    return d / "fibers.zarr"


def _render(fibers, out):
    return ["render", H / "scene_ok.toml", "--method", "fiberpath", "--fibers", fibers, "--width", "16",
            "--height", "12", "--spp", "1", "-o", out]


def _set(out: Path) -> dict:
    """The files' sha256 (and the artifact's content hash), once the artifact's record says they are one set."""
    import json

    meta = json.loads((out.with_suffix(".zarr") / "zarr.json").read_text())["attributes"]["loomlight"]
    files = {"exr": _sha(out), "png": _sha(out.with_suffix(".png"))}
    comp = meta["companions"]
    assert files == {"exr": comp[out.name]["sha256"], "png": comp[out.with_suffix(".png").name]["sha256"]}, \
        "a mixed set"
    return {**files, "artifact": meta["content_hash"]}


@pytest.mark.parametrize("reader", ["info", "read_exr"])
def test_reader_after_a_killed_publication_sees_the_new_set(cli, tmp_path, fibers, reader):
    out = tmp_path / "r.exr"
    assert cli(*_render(fibers, out), "--seed", "1")[0] == 0
    old = _set(out)
    _kill(_paused("half-published", _render(fibers, out) + ["--seed", "2"], tmp_path))
    with pytest.raises(AssertionError, match="a mixed set"):
        _set(out)   # the files as the kill left them: the new EXR beside the old PNG and artifact
    assert out.stat().st_mtime == 0   # Make (which judges the EXR by its time) sees it out of date, not done
    if reader == "info":
        code, _, err = cli("info", out.with_suffix(".zarr"), "--json")
        assert code == 0, err
    else:
        from pipeline.images import read_exr

        read_exr(out)
    new = _set(out)
    assert all(new[k] != old[k] for k in new)
    assert out.stat().st_mtime > fibers.stat().st_mtime   # the finished set's time: Make sees it done
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".") and "publish" in p.name) == []


def test_reader_waits_for_a_live_publication_then_refuses(cli, tmp_path, fibers, monkeypatch):
    out = tmp_path / "r.exr"
    assert cli(*_render(fibers, out), "--seed", "1")[0] == 0
    proc = _paused("half-published", _render(fibers, out) + ["--seed", "2"], tmp_path)
    try:
        monkeypatch.setenv("LOOMLIGHT_PUBLISH_WAIT", "0.3")
        code, _, err = cli("info", out.with_suffix(".zarr"))
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1, err
        assert "r.zarr" in lines[0] and f"is being published by process {proc.pid}" in lines[0]
    finally:
        _kill(proc)
    code, _, err = cli("info", out.with_suffix(".zarr"))
    assert code == 0, err
    _set(out)
