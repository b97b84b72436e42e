"""The hostile-input corpus: every command that reads a file of ``tests/hostile/`` (or a generated large
one, ``make_large.py``), or is pointed at an output it cannot or must not write, refuses it as bad input.

Contract (DEVELOPERS.md, "Bad input"): exit code 2, exactly one line on stderr starting ``error: `` that
names the file or option, no traceback, and nothing lost -- the workspace holding the previously built
artifacts and outputs (reference: the sha256 of every file in it, taken before the command) is byte
for byte as it was, with no half-written sibling left beside an output.

The workspace is built once per module: a real yarns, tables and fibers artifact of ``small.txt``;
the grid, tiling and render outputs are copies of the yarns artifact and plain files (building real
ones compiles render kernels, and what is checked is that a refused command leaves the bytes at its
``-o`` path alone, whatever they are). Each case is refused before any kernel runs.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
from pathlib import Path

import pytest

from tests.hostile.make_large import make as make_large

H = Path(__file__).resolve().parent
FIBERPATH = ["-m", "fiberpath", "--fibers", "{W}/fibers.zarr"]

# (id, command line with {H} the corpus, {W} the workspace, {L} the large files; text the error line names)
CASES = [
    # ingest: curve files and scenes
    ("ingest-empty-obj", ["ingest", "{H}/empty.obj", "-o", "{W}/yarns.zarr"], "empty.obj"),
    ("ingest-empty-txt", ["ingest", "{H}/empty.txt", "-o", "{W}/yarns.zarr"], "empty.txt"),
    ("ingest-obj-without-l", ["ingest", "{H}/no_lines.obj", "-o", "{W}/yarns.zarr"], "no_lines.obj"),
    ("ingest-random-obj", ["ingest", "{H}/random_bytes.obj", "-o", "{W}/yarns.zarr"], "random_bytes.obj"),
    ("ingest-random-bcc", ["ingest", "{H}/random_bytes.bcc", "-o", "{W}/yarns.zarr"], "random_bytes.bcc"),
    ("ingest-random-scene", ["ingest", "{H}/random_bytes.toml", "-o", "{W}/yarns.zarr"], "random_bytes.toml"),
    ("ingest-bcc-zero-curves", ["ingest", "{H}/zero_curves.bcc", "-o", "{W}/yarns.zarr"], "zero_curves.bcc"),
    ("ingest-huge-txt", ["ingest", "{H}/huge_coords.txt", "-o", "{W}/yarns.zarr"], "huge_coords.txt: line 2"),
    ("ingest-huge-obj", ["ingest", "{H}/huge_coords.obj", "-o", "{W}/yarns.zarr"], "huge_coords.obj: line 2"),
    ("ingest-huge-bcc", ["ingest", "{H}/huge_coords.bcc", "-o", "{W}/yarns.zarr"], "huge_coords.bcc: curve 0, point 1"),
    ("ingest-long-tail", ["ingest", "{L}/long_tail.txt", "-o", "{W}/yarns.zarr"], "long_tail.txt: line 100000"),
    ("ingest-many-curves", ["ingest", "{L}/many_curves.bcc", "-o", "{W}/yarns.zarr"], "curve 9999, point 1"),
    ("ingest-scene-is-dir", ["ingest", "{W}/scene_dir.toml", "-o", "{W}/yarns.zarr"], "scene_dir.toml"),
    ("ingest-scale-inf", ["ingest", "{H}/scene_scale_inf.toml", "-o", "{W}/yarns.zarr"], "fabric.scale"),
    ("ingest-radius-nan", ["ingest", "{H}/scene_radius_nan.toml", "-o", "{W}/yarns.zarr"], "fabric.radius"),
    ("ingest-option-radius-inf", ["ingest", "{H}/small.txt", "--radius", "inf", "-o", "{W}/yarns.zarr"], "--radius"),
    ("ingest-option-scale-huge", ["ingest", "{H}/small.txt", "--scale", "1e300", "-o", "{W}/yarns.zarr"], "--scale"),
    # output paths
    ("out-in-proc", ["ingest", "{H}/small.txt", "-o", "/proc/yarns.zarr"], "/proc/yarns.zarr"),
    ("out-in-sys", ["ingest", "{H}/small.txt", "-o", "/sys/yarns.zarr"], "/sys/yarns.zarr"),
    ("out-under-file", ["ingest", "{H}/small.txt", "-o", "{W}/notes.txt/yarns.zarr"], "notes.txt"),
    ("out-read-only-dir", ["ingest", "{H}/small.txt", "-o", "{W}/ro/yarns.zarr"], "ro/yarns.zarr"),
    ("out-is-plain-file", ["ingest", "{H}/small.txt", "-o", "{W}/plain.zarr"], "plain.zarr"),
    ("out-is-user-dir", ["ingest", "{H}/small.txt", "-o", "{W}/userdata.zarr"], "userdata.zarr"),
    ("write-in-proc", ["ingest", "{H}/small.txt", "--write", "/proc/curves.obj", "-o", "{W}/yarns.zarr"], "--write"),
    # tables, realize: options and presets
    ("tables-radius-inf", ["tables", "{W}/yarns.zarr", "--radius", "inf", "-o", "{W}/tables.zarr"], "--radius"),
    ("tables-preset-beta-nan", ["tables", "{W}/yarns.zarr", "--preset", "{H}/preset_beta_nan", "-o", "{W}/tables.zarr"],
     "preset_beta_nan.toml: beta"),
    ("tables-preset-alpha-tiny", ["tables", "{W}/yarns.zarr", "--preset", "{H}/preset_alpha_tiny",
                                  "-o", "{W}/tables.zarr"],
     "preset_alpha_tiny.toml: yarn_alpha"),
    ("tables-corrupt-chunk", ["tables", "{W}/corrupt_yarns.zarr", "-o", "{W}/tables.zarr"], "corrupt_yarns.zarr"),
    # artifacts are what they claim: a deleted or truncated chunk, an edited content hash or summary
    ("tables-deleted-chunk", ["tables", "{W}/deleted_chunk.zarr", "-o", "{W}/tables.zarr"],
     "deleted_chunk.zarr: array points: content does not match its checksum"),
    ("tables-truncated-chunk", ["tables", "{W}/truncated_chunk.zarr", "-o", "{W}/tables.zarr"],
     "truncated_chunk.zarr: array points: cannot be read"),
    ("tables-edited-hash", ["tables", "{W}/edited_hash.zarr", "-o", "{W}/tables.zarr"],
     "edited_hash.zarr: the summary or checksums do not match the content hash"),
    ("tables-edited-summary", ["tables", "{W}/edited_summary.zarr", "-o", "{W}/tables.zarr"],
     "edited_summary.zarr: the summary or checksums do not match the content hash"),
    ("realize-deleted-chunk", ["realize", "{W}/deleted_chunk.zarr", "-o", "{W}/fibers.zarr"], "deleted_chunk.zarr"),
    ("export-truncated-chunk", ["export", "{W}/truncated_fibers.zarr", "-o", "{W}/fibers.txt"],
     "truncated_fibers.zarr: array points"),
    ("info-edited-summary", ["info", "{W}/edited_summary.zarr"], "edited_summary.zarr"),
    # inputs of the wrong kind (also where the output is up to date), outputs over inputs or files
    ("tables-input-wrong-kind", ["tables", "{W}/tables.zarr", "-o", "{W}/t2.zarr"],
     "tables.zarr: expected a 'yarns' artifact, found a 'tables' artifact"),
    ("tables-up-to-date-wrong-kind", ["tables", "{W}/fibers.zarr", "-o", "{W}/tables.zarr"],
     "fibers.zarr: expected a 'yarns' artifact, found a 'fibers' artifact"),
    ("realize-input-is-file", ["realize", "{H}/small.txt", "-o", "{W}/fibers.zarr"],
     "small.txt: expected a 'yarns' artifact, found a file"),
    ("tables-out-is-input", ["tables", "{W}/yarns.zarr", "-o", "{W}/yarns.zarr"], "yarns.zarr"),
    ("realize-out-is-input", ["realize", "{W}/yarns.zarr", "-o", "{W}/yarns.zarr"], "yarns.zarr"),
    ("render-artifact-is-input", ["render", "{H}/scene_ok.toml", *FIBERPATH, "-o", "{W}/fibers.exr"], "fibers"),
    ("tables-out-is-plain-file", ["tables", "{W}/yarns.zarr", "-o", "{W}/plain.zarr"], "plain.zarr"),
    ("tables-out-in-proc", ["tables", "{W}/yarns.zarr", "-o", "/proc/tables.zarr"], "/proc/tables.zarr"),
    ("realize-spacing-inf", ["realize", "{W}/yarns.zarr", "--spacing", "inf", "-o", "{W}/fibers.zarr"], "--spacing"),
    ("realize-radius-nan", ["realize", "{W}/yarns.zarr", "--radius", "nan", "-o", "{W}/fibers.zarr"], "--radius"),
    ("realize-budget-inf", ["realize", "{W}/yarns.zarr", "--budget", "inf", "-o", "{W}/fibers.zarr"], "--budget"),
    ("realize-preset-beta-nan", ["realize", "{W}/yarns.zarr", "--preset", "{H}/preset_beta_nan",
                                 "-o", "{W}/fibers.zarr"],
     "preset_beta_nan.toml: beta"),
    # render: scenes, exposure, outputs
    ("render-irradiance-nan", ["render", "{H}/scene_irradiance_nan.toml", *FIBERPATH, "-o", "{W}/render.exr"],
     "lights[0].irradiance"),
    ("render-irradiance-inf", ["render", "{H}/scene_irradiance_inf.toml", *FIBERPATH, "-o", "{W}/render.exr"],
     "lights[0].irradiance[1]"),
    ("render-radiance-nan", ["render", "{H}/scene_radiance_nan.toml", *FIBERPATH, "-o", "{W}/render.exr"],
     "lights[1].radiance"),
    ("render-camera-nan", ["render", "{H}/scene_camera_nan.toml", *FIBERPATH, "-o", "{W}/render.exr"],
     "camera.origin[0]"),
    ("render-camera-huge", ["render", "{H}/scene_camera_huge.toml", *FIBERPATH, "-o", "{W}/render.exr"],
     "camera.origin[0]"),
    ("render-scene-is-dir", ["render", "{W}/scene_dir.toml", *FIBERPATH, "-o", "{W}/render.exr"], "scene_dir.toml"),
    ("render-exposure-nan", ["render", "{H}/scene_ok.toml", *FIBERPATH, "--exposure", "nan", "-o", "{W}/render.exr"],
     "--exposure"),
    ("render-out-in-proc", ["render", "{H}/scene_ok.toml", *FIBERPATH, "-o", "/proc/render.exr"], "/proc/render.exr"),
    ("render-out-under-file", ["render", "{H}/scene_ok.toml", *FIBERPATH, "-o", "{W}/notes.txt/render.exr"],
     "notes.txt"),
    ("render-artifact-is-user-dir", ["render", "{H}/scene_ok.toml", *FIBERPATH, "-o", "{W}/userdata.exr"],
     "userdata.zarr"),
    # tile, voxelize, lookup, evaluate, export
    ("tile-nan", ["tile", "{H}/tile_nan.toml", "-o", "{W}/tiling.zarr"], "tile_nan.toml: surface.size[0]"),
    ("tile-huge", ["tile", "{H}/tile_huge.toml", "-o", "{W}/tiling.zarr"], "tile_huge.toml: surface.size[0]"),
    ("tile-config-is-dir", ["tile", "{W}/scene_dir.toml", "-o", "{W}/tiling.zarr"], "scene_dir.toml"),
    ("tile-out-is-user-dir", ["tile", "{H}/tile_ok.toml", "-o", "{W}/userdata.zarr"], "userdata.zarr"),
    ("voxelize-out-in-proc", ["voxelize", "{W}/tables.zarr", "--res", "2", "2", "2", "-o", "/proc/grid.zarr"],
     "/proc/grid.zarr"),
    ("voxelize-npy-under-file", ["voxelize", "{W}/tables.zarr", "--res", "2", "2", "2", "-o", "{W}/grid.zarr",
                                 "--export-npy", "{W}/notes.txt/npy"], "--export-npy"),
    ("lookup-points-nan", ["lookup", "{W}/tables.zarr", "--points", "{H}/points_nan.npy", "-o", "{W}/res.npz"],
     "points_nan.npy: row 1"),
    ("lookup-out-under-file", ["lookup", "{W}/tables.zarr", "--points", "{H}/points_nan.npy",
                               "-o", "{W}/notes.txt/res.npz"], "notes.txt"),
    ("evaluate-random-exr", ["evaluate", "--ref", "{H}/random_bytes.exr", "--test", "{H}/random_bytes.exr",
                             "-o", "{W}/eval"], "random_bytes.exr"),
    ("evaluate-out-under-file", ["evaluate", "--ref", "{H}/random_bytes.exr", "--test", "{H}/random_bytes.exr",
                                 "-o", "{W}/notes.txt/eval"], "notes.txt"),
    ("export-out-in-proc", ["export", "{W}/fibers.zarr", "-o", "/proc/fibers.txt"], "/proc/fibers.txt"),
    ("export-out-is-dir", ["export", "{W}/fibers.zarr", "-o", "{W}/dir.txt"], "dir.txt"),
    ("export-corrupt-chunk", ["export", "{W}/corrupt_fibers.zarr", "-o", "{W}/fibers.txt"], "corrupt_fibers.zarr"),
    # info, inspect
    ("info-random-bytes", ["info", "{H}/random_bytes.bcc"], "random_bytes.bcc"),
    ("info-user-dir", ["info", "{W}/userdata.zarr"], "userdata.zarr"),
    ("info-garbled-metadata", ["info", "{W}/garbled_meta.zarr"], "garbled_meta.zarr"),
    ("inspect-png-in-proc", ["inspect", "{W}/yarns.zarr", "--png", "/proc/yarns.png"], "/proc/yarns.png"),
    ("inspect-png-under-file", ["inspect", "{W}/yarns.zarr", "--png", "{W}/notes.txt/yarns.png"], "notes.txt"),
]


def _chunk(artifact: Path, array: str) -> Path:
    """The first chunk file of ``array``."""
    return sorted(p for p in (artifact / array).rglob("*") if p.is_file() and p.name != "zarr.json")[0]


def _edit_meta(artifact: Path, edit) -> None:
    """Edit the root attributes of an artifact in place (its zarr.json), as a hand or a tool would."""
    doc = json.loads((artifact / "zarr.json").read_text())
    edit(doc["attributes"])
    (artifact / "zarr.json").write_text(json.dumps(doc))


def _garble(artifact: Path, array: str) -> None:
    """Overwrite the middle of the first chunk file of ``array`` with other bytes (same length)."""
    chunk = _chunk(artifact, array)
    data = bytearray(chunk.read_bytes())
    mid = len(data) // 2
    data[mid:mid + 16] = bytes((b ^ 0x5A) for b in data[mid:mid + 16])
    chunk.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """(W, L): the workspace of previously built outputs, and the directory of the large files."""
    from pipeline.cli import main

    W = tmp_path_factory.mktemp("workspace")
    L = tmp_path_factory.mktemp("large")
    make_large(L)
    assert main(["ingest", str(H / "small.txt"), "--radius", "0.02", "-o", str(W / "yarns.zarr")]) == 0
    assert main(["tables", str(W / "yarns.zarr"), "-o", str(W / "tables.zarr")]) == 0
    assert main(["realize", str(W / "yarns.zarr"), "--spacing", "0.01", "-o", str(W / "fibers.zarr")]) == 0
    for copy in ("grid.zarr", "tiling.zarr", "render.zarr", "corrupt_yarns.zarr", "garbled_meta.zarr"):
        shutil.copytree(W / "yarns.zarr", W / copy)
    for copy in ("deleted_chunk.zarr", "truncated_chunk.zarr", "edited_hash.zarr", "edited_summary.zarr"):
        shutil.copytree(W / "yarns.zarr", W / copy)
    shutil.copytree(W / "fibers.zarr", W / "corrupt_fibers.zarr")
    shutil.copytree(W / "fibers.zarr", W / "truncated_fibers.zarr")
    _chunk(W / "deleted_chunk.zarr", "points").unlink()
    for art in ("truncated_chunk.zarr", "truncated_fibers.zarr"):
        with open(_chunk(W / art, "points"), "r+b") as f:
            f.truncate(10)
    _edit_meta(W / "edited_hash.zarr", lambda a: a["loomlight"].__setitem__("content_hash", "0" * 64))
    _edit_meta(W / "edited_summary.zarr", lambda a: a["summary"].__setitem__("curves", a["summary"]["curves"] + 1))
    _garble(W / "corrupt_yarns.zarr", "points")
    _garble(W / "corrupt_fibers.zarr", "points")
    (W / "garbled_meta.zarr" / "zarr.json").write_bytes((H / "random_bytes.bcc").read_bytes())
    for name, text in (("render.exr", "previous EXR"), ("render.png", "previous PNG"), ("res.npz", "previous npz"),
                       ("fibers.txt", "previous export"), ("notes.txt", "a regular file"),
                       ("plain.zarr", "a regular file named like an artifact"), ("eval/report.md", "previous report"),
                       ("userdata.zarr/data.bin", "a user's data"), ("userdata.exr", "previous EXR")):
        (W / name).parent.mkdir(parents=True, exist_ok=True)
        (W / name).write_text(text)
    for d in ("scene_dir.toml", "dir.txt", "ro"):
        (W / d).mkdir()
    (W / "ro").chmod(stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH)
    yield W, L
    (W / "ro").chmod(0o755)


def _snapshot(root: Path) -> dict:
    """Every path under root: sha256 of a file's bytes, '<dir>' for a directory."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[os.path.relpath(os.path.join(dirpath, d), root)] = "<dir>"
        for f in filenames:
            p = os.path.join(dirpath, f)
            out[os.path.relpath(p, root)] = hashlib.sha256(Path(p).read_bytes()).hexdigest()
    return out


@pytest.mark.parametrize("args, names", [pytest.param(a, n, id=i) for i, a, n in CASES])
def test_refused_cleanly(cli, workspace, monkeypatch, args, names):
    W, L = workspace
    argv = [a.format(H=H, W=W, L=L) for a in args]
    if "{W}/ro/" in " ".join(args) and os.geteuid() == 0:
        # root writes through directory permissions: emulate a read-only file system for W/ro
        real_access = os.access
        monkeypatch.setattr(os, "access", lambda p, mode, **kw: (Path(p) != W / "ro") and real_access(p, mode, **kw))
    before = _snapshot(W)
    code, out, err = cli(*argv)
    lines = err.strip().splitlines()
    assert code == 2, (code, out, err)
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert names.format(H=H, W=W, L=L) in lines[0], lines[0]
    assert "Traceback" not in err + out
    assert _snapshot(W) == before


def test_bug_is_one_line_exit_1_traceback_on_request(cli, tmp_path, monkeypatch):
    """An exception from code (not input) is not dressed up as bad input: exit code 1, one line naming it
    and asking for a report; LOOMLIGHT_DEBUG=1 adds the traceback."""
    import pipeline.runners.export as export_runner

    def broken(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(export_runner, "run_export", broken)
    code, _, err = cli("export", tmp_path / "f.zarr", "-o", tmp_path / "f.txt")
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert "ZeroDivisionError" in err and "report" in err and "LOOMLIGHT_DEBUG=1" in err and "Traceback" not in err
    monkeypatch.setenv("LOOMLIGHT_DEBUG", "1")
    code, _, err = cli("export", tmp_path / "f.zarr", "-o", tmp_path / "f.txt")
    assert code == 1 and "Traceback" in err and "ZeroDivisionError" in err


def test_unexpected_os_error_is_one_line_exit_2(cli, tmp_path, monkeypatch):
    """The last-resort net: an OSError the specific checks could not foresee (a full disk) names its file."""
    import pipeline.runners.export as export_runner

    def disk_full(fibers, out, **kwargs):
        raise OSError(28, "No space left on device", str(out))

    monkeypatch.setattr(export_runner, "run_export", disk_full)
    code, _, err = cli("export", tmp_path / "f.zarr", "-o", tmp_path / "f.txt")
    assert code == 2 and err.strip() == f"error: {tmp_path / 'f.txt'}: No space left on device"
