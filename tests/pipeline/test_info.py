"""``loomlight info`` tells the truth (issue 23, item 4; pipeline/commands/info.py, pipeline/artifacts.py).

Contract:
- an artifact's ``wall_time_s`` is its stage's whole run (``ArtifactWriter(started=)``, the runners'
  start), not the writing alone: a render's is at least its ``render_time_s`` plus its ``compile_s``;
- ``info --json`` gives every hash whole: content hash, build key, each input's sha256 and stat
  fingerprint, each array's sha256 and crc32c, equal to the artifact's zarr.json; the summary's keys
  (but the provenance's own: wall time, compile time, peak memory) as recorded;
- the table shows compile time as a row of its own where the stage recorded it, and hashes whole
  (wrapped on a narrow terminal, never cut with an ellipsis);
- ``import pipeline.cli`` (``--help``, ``--version``) loads no numpy, numba or zarr, and ``info``
  none of them either: it reads metadata only.
"""
from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import time

import numpy as np
import pytest

from pipeline.artifacts import FILE, ArtifactWriter
from tests.helpers import ROOT

HEAVY = ("numpy", "numba", "zarr", "scipy", "stages.render", "pipeline.artifacts")

SCENE = """
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
[yarns.default]
bcsdf = "cotton"
[camera]
origin = [1.2, -1.6, 1.0]
target = [0.0, 0.0, 0.0]
width = 4
height = 3
[[lights]]
type = "constant"
radiance = 0.5
[render]
spp = 1
max_depth = 4
"""


def _zarr_attrs(path):
    return json.loads((path / "zarr.json").read_text())["attributes"]


def _small_artifact(d, started=None):
    """An artifact of two arrays (kind evaluation: its schema leaves them free), made from one input
    file, with a nested summary."""
    src = d / "in.txt"
    src.write_text("0 0 0\n1 0 0\n")
    with ArtifactWriter(d / "a.zarr", kind="evaluation", stage="test", params={"k": 1, "name": "x"},
                        inputs={"source": (src, FILE)}, started=started) as w:
        w.write("points", np.arange(12, dtype=np.float32).reshape(4, 3))
        w.write("curve_offsets", np.array([0, 4], dtype=np.int64))
        w.summary.update(kind="evaluation", mode="table1", curves=1, control_points=4, closed_curves=0,
                         curve_type="polyline",
                         bounds=[[0.0, 0.0, 0.0], [9.0, 10.0, 11.0]], bytes={"points": 48},
                         delta_max=0.25, groups=["warp"], grid={"cell": 0.5, "dims": [1, 1, 1], "items": 3})
    return d / "a.zarr", src


def _rows(text: str) -> dict[str, str]:
    """The table's (key, value) rows; a value wrapped onto more lines is joined back: without a space
    after a full line (folded mid-word: a hash, a path), with one where rich broke it at a space."""
    rows, key, full = {}, None, False
    for line in text.splitlines():
        if not line.startswith("│"):
            continue
        kc, vc = line.strip("│").split("│")
        k, v = kc.strip(), vc[1:].rstrip()
        if k:
            key, rows[key] = k, v
        elif key is not None:
            rows[key] += ("" if full else " ") + v
        full = len(v) == len(vc) - 2
    return rows


def _py(code: str) -> str:
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return r.stdout


# ------------------------------------------------------------------------------------------------
def test_cli_import_help_and_version_load_no_numerics():
    """`import pipeline.cli`, `--version` and `--help` import none of numpy, numba, zarr (the command
    modules import them inside their commands)."""
    out = _py("import sys, json\n"
              "from pipeline.cli import main\n"
              f"heavy = {HEAVY!r}\n"
              "seen = [[m for m in heavy if m in sys.modules]]\n"
              "main(['--version']); seen.append([m for m in heavy if m in sys.modules])\n"
              "main(['--help']); seen.append([m for m in heavy if m in sys.modules])\n"
              "main(['render', '--help']); seen.append([m for m in heavy if m in sys.modules])\n"
              "print(json.dumps(seen))")
    assert json.loads(out.splitlines()[-1]) == [[], [], [], []]


def test_info_reads_metadata_only(tmp_path):
    """`info` (table and --json) imports neither numpy, numba nor zarr: no array is read."""
    art, _ = _small_artifact(tmp_path)
    out = _py("import sys, json, contextlib, io\n"
              "from pipeline.cli import main\n"
              "codes = []\n"
              "with contextlib.redirect_stdout(io.StringIO()):\n"
              f"    codes.append(main(['info', {str(art)!r}]))\n"
              f"    codes.append(main(['info', {str(art)!r}, '--json']))\n"
              "print(json.dumps([codes, [m for m in ('numpy', 'numba', 'zarr') if m in sys.modules]]))")
    assert json.loads(out.splitlines()[-1]) == [[0, 0], []]


def test_wall_time_runs_from_the_stage_start(tmp_path):
    """wall_time_s counts from `started` (the runner's start), not from the first write; by default
    from the writer's construction."""
    art, _ = _small_artifact(tmp_path, started=time.perf_counter() - 3.0)
    assert _zarr_attrs(art)["loomlight"]["wall_time_s"] >= 3.0
    src = tmp_path / "in.txt"
    w = ArtifactWriter(tmp_path / "b.zarr", kind="evaluation", stage="test", inputs={"source": (src, FILE)})
    time.sleep(0.2)  # work the stage does before writing (reading inputs, compute)
    with w:
        w.write("points", np.zeros((1, 3), np.float32))
        w.write("curve_offsets", np.array([0, 1], np.int64))
        w.summary.update(kind="evaluation", mode="table1")
    assert _zarr_attrs(tmp_path / "b.zarr")["loomlight"]["wall_time_s"] >= 0.2


def test_info_json_is_the_recorded_metadata_whole(tmp_path, cli):
    """--json: every hash whole and equal to zarr.json's (and to the bytes they hash), the summary as
    recorded, array bytes from the arrays' shapes and dtypes."""
    art, src = _small_artifact(tmp_path)
    code, out, err = cli("info", art, "--json")
    assert code == 0, err
    doc = json.loads(out)
    attrs = _zarr_attrs(art)
    meta, summary = attrs["loomlight"], attrs["summary"]
    expected = {"kind": "evaluation", **summary, "path": str(art), "array_bytes": 4 * 3 * 4 + 2 * 8, "stage": "test",
                "params": {"k": 1, "name": "x"}, "inputs": meta["inputs"], "wall_time_s": meta["wall_time_s"],
                "peak_memory_bytes": meta["peak_memory_bytes"], "created": meta["created"],
                "loomlight_version": meta["loomlight_version"], "build_key": meta["build_key"],
                "content_hash": meta["content_hash"], "arrays": meta["arrays"], "arrays_verified": False}
    assert doc == expected
    assert list(doc) == list(expected)
    assert doc["inputs"]["source"]["sha256"] == hashlib.sha256(src.read_bytes()).hexdigest()
    assert doc["arrays"]["points"]["sha256"] == hashlib.sha256(np.arange(12, dtype=np.float32).tobytes()).hexdigest()
    for h in (doc["content_hash"], doc["build_key"], doc["inputs"]["source"]["sha256"],
              doc["inputs"]["source"]["stat"], doc["arrays"]["points"]["sha256"]):
        assert len(h) == 64 and int(h, 16) >= 0


@pytest.mark.parametrize("columns", [80, 200])
def test_info_table_rows_exact(tmp_path, cli, monkeypatch, columns):
    """The table: one row per scalar, nested values as dotted rows, floats to 6 significant digits,
    *_bytes with MiB, hashes whole (wrapped at 80 columns, one line at 200), no ellipsis."""
    monkeypatch.setenv("COLUMNS", str(columns))
    art, src = _small_artifact(tmp_path)
    code, out, err = cli("info", art)
    assert code == 0, err
    assert "…" not in out and max(len(line) for line in out.splitlines()) <= columns
    meta = _zarr_attrs(art)["loomlight"]
    mib = meta["peak_memory_bytes"] / 2**20
    assert _rows(out) == {
        "kind": "evaluation", "bounds": "[[0, 0, 0], [9, 10, 11]]", "bytes.points": "48", "closed_curves": "0",
        "control_points": "4", "curve_type": "polyline", "curves": "1", "delta_max": "0.25",
        "grid.cell": "0.5", "grid.dims": "[1, 1, 1]", "grid.items": "3", "groups": "[warp]", "mode": "table1",
        "path": str(art), "array_bytes": "64 (0.0 MiB)", "stage": "test", "params.k": "1", "params.name": "x",
        "inputs.source": str(src), "inputs.source.sha256": hashlib.sha256(src.read_bytes()).hexdigest(),
        "wall_time_s": f"{meta['wall_time_s']:.6g}",
        "peak_memory_bytes": f"{meta['peak_memory_bytes']} ({mib:.1f} MiB)", "created": meta["created"],
        "loomlight_version": meta["loomlight_version"], "build_key": meta["build_key"],
        "content_hash": meta["content_hash"], "arrays.curve_offsets": "int64 [2]", "arrays.points": "float32 [4, 3]"}
    hash_lines = [line for line in out.splitlines() if meta["content_hash"] in line]
    assert len(hash_lines) == (1 if columns == 200 else 0)


def test_render_wall_time_covers_render_and_compilation(tmp_path, cli):
    """A 4x3 px, 1 spp fiberpath render: the artifact's wall_time_s (whole stage) >= render_time_s +
    compile_s (both inside it); info shows compile_s as its own row and wall_time_s the stage's."""
    rng = np.random.default_rng(1)
    pts = np.concatenate([np.linspace(-0.4, 0.4, 6)[:, None] * rng.normal(size=3) + rng.uniform(-0.2, 0.2, 3)
                          for _ in range(4)]).astype(np.float32)
    F = 4
    with ArtifactWriter(tmp_path / "fibers.zarr", kind="fibers", stage="realize", params={"test": True}) as w:
        w.write("points", pts)
        w.write("point_radius", np.full(len(pts), 0.05, np.float32))
        w.write("fiber_offsets", np.arange(0, 6 * F + 1, 6, dtype=np.int64))
        w.write("fiber_yarn", np.zeros(F, np.int32))
        w.write("fiber_ply", np.zeros(F, np.int16))
        w.write("fiber_kind", np.ones(F, np.int8))
        w.write("yarn_albedo", np.full((1, 3), 0.6, np.float32))
        w.summary.update(kind="fibers", fibers=F, vertices=len(pts), yarns=1, spacing=0.08, max_chord_error=0.0,
                         bytes={"total": int(pts.nbytes), "regular": int(pts.nbytes), "loop": 0, "hair": 0})
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "r.exr"
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", tmp_path / "fibers.zarr", "-o", out)
    assert code == 0, err
    attrs = _zarr_attrs(out.with_suffix(".zarr"))
    meta, s = attrs["loomlight"], attrs["summary"]
    compile_s = s["method_stats"]["compile_s"]
    assert compile_s > 0 and s["render_time_s"] > 0
    assert meta["wall_time_s"] >= s["render_time_s"] + compile_s
    assert meta["wall_time_s"] >= s["wall_time_s"]  # the renderer's own time is part of the stage's
    code, text, err = cli("info", out.with_suffix(".zarr"), "--json")
    doc = json.loads(text)
    assert code == 0 and doc["wall_time_s"] == meta["wall_time_s"] and doc["compile_s"] == compile_s
    assert doc["render_time_s"] == s["render_time_s"]
    code, text, err = cli("info", out.with_suffix(".zarr"))
    assert code == 0, err
    rows = _rows(text)
    assert rows["compile_s"] == f"{compile_s:.6g}" and rows["wall_time_s"] == f"{meta['wall_time_s']:.6g}"
    assert rows["method_stats.compile_s"] == f"{compile_s:.6g}"


def test_precompute_compile_time_is_a_row():
    """A stage whose summary records compile_s at its top (precompute) gets the same row."""
    from pipeline.commands.info import compile_seconds, table_rows

    assert compile_seconds({"compile_s": 0.5, "method_stats": {"compile_s": 0.1}}) == 0.5
    assert compile_seconds({"method_stats": {"compile_s": 0.1}}) == 0.1
    assert compile_seconds({"method_stats": {}}) is None and compile_seconds({}) is None
    assert ("compile_s", "0.123457") in table_rows({"kind": "svf", "compile_s": 0.1234567})
