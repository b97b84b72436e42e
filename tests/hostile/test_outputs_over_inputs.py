"""No command writes into or over one of its inputs (issue 58, item 4; cases 5 and 6), whatever the
path's form: the same path, a relative one, a symbolic link to the input (or an input reached through
one), a hard link, a file inside an input artifact's directory, an artifact directory holding the input.
One check does it (``pipeline.outputs.check_output(..., inputs=...)``), before any work; each refusal
follows the contract of ``tests/hostile/contract.py`` (exit code 2, one line naming the output and its
option, the workspace byte for byte as it was). Reference: the inputs' bytes before and after.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.hostile.contract import assert_refused

H = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    """W: ring.bcc (written by ingest --write), yarns.zarr and fibers.zarr of it, a scene whose fabric is
    curves.txt, links to them, and previous outputs."""
    from pipeline.cli import main

    W = tmp_path_factory.mktemp("outputs")
    assert main(["ingest", str(H / "small.txt"), "--radius", "0.02", "--write", str(W / "ring.bcc"),
                 "-o", str(W / "yarns.zarr")]) == 0
    assert main(["realize", str(W / "yarns.zarr"), "--spacing", "0.01", "-o", str(W / "fibers.zarr")]) == 0
    (W / "curves.txt").write_bytes((H / "small.txt").read_bytes())
    (W / "scene.toml").write_text('[scene]\nname = "hostile"\n[fabric]\nsource = "file"\npath = "curves.txt"\n'
                                  'radius = 0.02\n')
    os.symlink(W / "ring.bcc", W / "link.bcc")
    os.symlink(W / "fibers.zarr", W / "link.zarr")
    os.link(W / "ring.bcc", W / "hard.bcc")
    (W / "fibers.txt").write_text("previous export")
    return W


def test_ingest_write_over_its_input(cli, ws):
    """Case 5: ``ingest ring.bcc --write ring.bcc`` overwrote its input (exit 0)."""
    y = ws / "y.zarr"
    assert_refused(cli, ws, ["ingest", ws / "ring.bcc", "--write", ws / "ring.bcc", "-o", y], "ring.bcc", "--write",
                   "is the input")
    assert_refused(cli, ws, ["ingest", ws / "link.bcc", "--write", ws / "ring.bcc", "-o", y], "--write", "is the input")
    assert_refused(cli, ws, ["ingest", ws / "ring.bcc", "--write", ws / "link.bcc", "-o", y], "--write", "is the input")
    assert_refused(cli, ws, ["ingest", ws / "ring.bcc", "--write", ws / "hard.bcc", "-o", y], "--write", "is the input")


def test_ingest_write_relative_path(cli, ws, monkeypatch):
    monkeypatch.chdir(ws)
    assert_refused(cli, ws, ["ingest", "ring.bcc", "--write", f"../{ws.name}/ring.bcc", "-o", "y.zarr"], "--write",
                   "is the input")


def test_ingest_write_over_the_scenes_curve_file(cli, ws):
    """The scene's fabric.path is an input too (the runner knows it once the scene is read)."""
    assert_refused(cli, ws, ["ingest", ws / "scene.toml", "--write", ws / "curves.txt", "-o", ws / "y.zarr"],
                   "curves.txt", "--write", "is the input")


def test_export_into_its_input(cli, ws):
    """Case 6: ``export F.zarr -o F.zarr/fibers.txt`` wrote inside the input artifact (exit 0)."""
    assert_refused(cli, ws, ["export", ws / "fibers.zarr", "-o", ws / "fibers.zarr" / "fibers.txt"], "fibers.txt",
                   "-o", "lies inside the input")
    assert_refused(cli, ws, ["export", ws / "link.zarr", "-o", ws / "fibers.zarr" / "fibers.txt"], "-o",
                   "lies inside the input")
    assert_refused(cli, ws, ["export", ws / "fibers.zarr", "-o", ws / "link.zarr" / "points" / "fibers.bcc"], "-o",
                   "lies inside the input")


def test_other_commands(cli, ws):
    """inspect --png, tables / realize -o over or around their input."""
    assert_refused(cli, ws, ["inspect", ws / "fibers.zarr", "--png", ws / "fibers.zarr" / "x.png"], "--png",
                   "lies inside the input")
    assert_refused(cli, ws, ["tables", ws / "yarns.zarr", "-o", ws / "yarns.zarr"], "-o", "is the input")
    os.symlink(ws / "yarns.zarr", ws / "ylink.zarr")
    try:
        assert_refused(cli, ws, ["realize", ws / "ylink.zarr", "-o", ws / "yarns.zarr"], "-o", "is the input")
    finally:
        os.unlink(ws / "ylink.zarr")


def test_check_output_unit(tmp_path):
    """``check_output`` directly: an artifact output holding an input is refused; outputs beside inputs
    pass."""
    from pipeline.errors import LoomError
    from pipeline.outputs import ARTIFACT, check_output

    (tmp_path / "a.zarr").mkdir()
    (tmp_path / "a.zarr" / "in.txt").write_text("x")
    with pytest.raises(LoomError, match="holds the input"):
        check_output(tmp_path / "a.zarr", "-o", ARTIFACT, inputs=[tmp_path / "a.zarr" / "in.txt"])
    assert check_output(tmp_path / "b.zarr", "-o", ARTIFACT, inputs=[tmp_path / "a.zarr", None]) == tmp_path / "b.zarr"
    assert check_output(tmp_path / "out.txt", "-o", inputs=[tmp_path / "a.zarr" / "in.txt"]) == tmp_path / "out.txt"
