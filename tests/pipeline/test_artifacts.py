"""The artifact store's contract (pipeline/artifacts.py): provenance attributes, schema checks on write
and read, atomic publication (a killed or failing stage leaves the previous artifact untouched and no
partial one), refusal of incomplete artifacts, the unchanged-inputs skip, and chunk tasks."""
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import zarr

from pipeline.artifacts import Artifact, ArtifactWriter, read_meta
from pipeline.chunks import ChunkTask, open_for_chunk, run_tasks
from pipeline.errors import IncompleteArtifact, LoomError
from tests.helpers import ROOT


def _yarn_like(w, n=4):
    """The arrays a yarns artifact must hold (schemas/yarns.schema.json), filled trivially: one curve of n
    points (the counts agree with the summary, ``pipeline.artifact_checks``)."""
    for name in ("points", "tangents", "frame_normal", "color"):
        w.write(name, np.zeros((n, 3), np.float32))
    w.write("curve_offsets", np.array([0, n]))
    for name in ("closed", "group", "yarn_type"):
        w.write(name, np.zeros(1))
    for name in ("radius", "seg_length", "seg_arclen",
                 "curve_length", "delta", "frame_s", "frame_offsets", "grid_cell_start", "grid_items",
                 "seg_curve", "frame_twist", "grid_lo", "grid_cell", "grid_dims", "grid_pad"):
        w.write(name, np.zeros(n))
    w.summary.update(kind="yarns", curves=1, closed_curves=0, control_points=n, bounds=[[0, 0, 0], [1, 1, 1]],
                     groups=["warp"], yarn_types=[{}], total_length=1.0)


def _write(path, value=1.0, params=None, inputs=None):
    with ArtifactWriter(path, kind="yarns", stage="test", params=params or {"a": 1}, inputs=inputs or {}) as w:
        _yarn_like(w)
        w.group["points"][...] = np.full((4, 3), value, np.float32)
    return path


def test_attributes_carry_provenance(tmp_path):
    src = tmp_path / "in.txt"
    src.write_text("hello")
    p = _write(tmp_path / "a.zarr", inputs={"source": src})
    meta = read_meta(p)
    for key in ("schema", "schema_version", "stage", "params", "inputs", "loomlight_version", "wall_time_s",
                "peak_memory_bytes", "content_hash", "build_key"):
        assert key in meta
    assert meta["complete"] is True and meta["schema"] == "loomlight/yarns"
    import hashlib
    assert meta["inputs"]["source"]["sha256"] == hashlib.sha256(b"hello").hexdigest()
    assert meta["peak_memory_bytes"] > 0
    art = Artifact(p, kind="yarns")
    assert np.all(art["points"] == 1.0)


def test_schema_checked_on_write_keeps_previous(tmp_path):
    p = _write(tmp_path / "a.zarr", value=2.0)
    before = read_meta(p)["content_hash"]
    with pytest.raises(LoomError, match="points|required"):
        with ArtifactWriter(p, kind="yarns", stage="test", params={}) as w:
            w.write("radius", np.zeros(3))  # missing every other required array
    assert read_meta(p)["content_hash"] == before
    assert not list(tmp_path.glob(".a.zarr.*"))


def test_exception_inside_stage_leaves_previous(tmp_path):
    p = _write(tmp_path / "a.zarr", value=3.0)
    with pytest.raises(RuntimeError):
        with ArtifactWriter(p, kind="yarns", stage="test", params={"a": 2}) as w:
            _yarn_like(w)
            raise RuntimeError("stage failed")
    assert np.all(Artifact(p)["points"] == 3.0)
    assert not list(tmp_path.glob(".a.zarr.*"))


def test_killed_stage_leaves_previous_untouched(tmp_path):
    p = _write(tmp_path / "a.zarr", value=4.0)
    before = read_meta(p)["content_hash"]
    script = textwrap.dedent(f"""
        import sys, time, numpy as np
        sys.path.insert(0, {str(ROOT)!r})
        from pipeline.artifacts import ArtifactWriter
        with ArtifactWriter({str(p)!r}, kind="yarns", stage="test", params={{"a": 9}}) as w:
            for i in range(1000):
                w.write(f"big{{i}}", np.zeros((1000, 3)))
                print("wrote", i, flush=True)
                time.sleep(0.01)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    for _ in range(3):
        proc.stdout.readline()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert Artifact(p)["points"][0, 0] == 4.0 and read_meta(p)["content_hash"] == before
    # the killed build's hidden directory is cleaned by the next writer
    leftovers = list(tmp_path.glob(".a.zarr.tmp-*"))
    assert leftovers, "the killed stage should have left only a hidden build directory"
    _write(tmp_path / "a.zarr", value=5.0)
    assert not list(tmp_path.glob(".a.zarr.tmp-*"))


def test_incomplete_artifact_refused(tmp_path, cli):
    p = tmp_path / "half.zarr"
    g = zarr.open_group(str(p), mode="w")
    g.attrs["loomlight"] = {"kind": "yarns", "complete": False}
    with pytest.raises(IncompleteArtifact):
        Artifact(p)
    code, out, err = cli("info", p)
    assert code == 2 and "incomplete" in err and str(p) in err and len(err.strip().splitlines()) == 1


def test_unchanged_inputs_are_not_rebuilt(tmp_path):
    src = tmp_path / "in.txt"
    src.write_text("one")
    p = _write(tmp_path / "a.zarr", inputs={"source": src}, params={"k": 1})
    assert ArtifactWriter(p, kind="yarns", stage="test", params={"k": 1}, inputs={"source": src}).up_to_date()
    assert not ArtifactWriter(p, kind="yarns", stage="test", params={"k": 2}, inputs={"source": src}).up_to_date()
    src.write_text("two")
    assert not ArtifactWriter(p, kind="yarns", stage="test", params={"k": 1}, inputs={"source": src}).up_to_date()


def _fill_chunk(store, name, k, size):
    a = open_for_chunk(store, name)
    a[k * size:(k + 1) * size] = np.arange(k * size, (k + 1) * size, dtype=np.float64) ** 2


def test_chunk_tasks_write_their_own_chunks(tmp_path):
    with ArtifactWriter(tmp_path / "c.zarr", kind="yarns", stage="test", params={}) as w:
        _yarn_like(w)
        w.create("squares", shape=(40,), dtype=np.float64, chunks=(10,))
        tasks = [ChunkTask(_fill_chunk, (str(w.store_path), "squares", k, 10)) for k in range(4)]
        run_tasks(tasks[::-1], "chunks")  # any order
    assert np.array_equal(Artifact(tmp_path / "c.zarr")["squares"], np.arange(40.0) ** 2)


def test_input_identity_is_recomputed_from_bytes(tmp_path):
    """The up-to-date check hashes an input artifact's chunk files, not what its metadata claims: a chunk
    rewritten with other bytes of the same size (its zarr.json, content hash and mtime put back as they
    were) makes the artifact built from it out of date; an input of the wrong kind is refused."""
    a = _write(tmp_path / "a.zarr", value=1.0)
    b_args = dict(kind="yarns", stage="test", params={"k": 1}, inputs={"yarns": (a, "yarns")})
    with ArtifactWriter(tmp_path / "b.zarr", **b_args) as w:
        _yarn_like(w)
    assert ArtifactWriter(tmp_path / "b.zarr", **b_args).up_to_date()
    root = (a / "zarr.json").read_bytes()
    chunk = sorted(p for p in (a / "points").rglob("*") if p.is_file() and p.name != "zarr.json")[0]
    st = chunk.stat()
    with ArtifactWriter(tmp_path / "other.zarr", kind="yarns", stage="test", params={}) as w:
        _yarn_like(w)
        w.group["points"][...] = np.full((4, 3), 7.0, np.float32)
    other = sorted(p for p in (tmp_path / "other.zarr" / "points").rglob("*")
                   if p.is_file() and p.name != "zarr.json")[0]
    data = other.read_bytes()
    assert len(data) == st.st_size and data != chunk.read_bytes()
    chunk.write_bytes(data)
    os.utime(chunk, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert (a / "zarr.json").read_bytes() == root
    assert not ArtifactWriter(tmp_path / "b.zarr", **b_args).up_to_date()
    with pytest.raises(LoomError, match="expected a 'fibers' artifact, found a 'yarns' artifact"):
        ArtifactWriter(tmp_path / "b.zarr", kind="yarns", stage="test", params={"k": 1},
                       inputs={"yarns": (a, "fibers")}).up_to_date()
