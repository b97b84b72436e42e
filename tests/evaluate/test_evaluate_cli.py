"""``loomlight evaluate --ref --test``: metrics.json against closed forms, render-artifact timings,
the evaluation artifact's provenance, up-to-date skipping, and exit code 2 on bad input with the
previous outputs left untouched.

References: a constant offset c gives RMSE = |c| and relMSE = c^2 / (r^2 + 0.01) on a constant
reference r; identical images give SSIM 1 and mean dE00 0; the content hash of an input is the
sha256 of its bytes.
"""
import hashlib
import json

import numpy as np
import pytest
import zarr

from pipeline.images import write_render


def _scene_image(h=24, w=28, seed=0):
    rng = np.random.default_rng(seed)
    return (0.2 + 0.6 * rng.random((h, w, 3))).astype(np.float32)


def _fake_render_artifact(exr_path, wall_time_s, peak_memory_bytes, spp=16, paths_per_s=1.0e6):
    """A complete render artifact beside an EXR, written by hand (only the attributes the evaluate
    stage reads; the render kind's schema belongs to the render stage)."""
    g = zarr.open_group(str(exr_path.with_suffix(".zarr")), mode="w", zarr_format=3)
    g.attrs["summary"] = {"kind": "render", "wall_time_s": wall_time_s, "peak_memory_bytes": peak_memory_bytes,
                          "spp": spp, "paths_per_s": paths_per_s}
    g.attrs["loomlight"] = {"kind": "render", "complete": True, "wall_time_s": wall_time_s + 1.0,
                            "peak_memory_bytes": 1,
                            "content_hash": hashlib.sha256(str(wall_time_s).encode()).hexdigest()}


@pytest.fixture
def images(tmp_path):
    ref = np.full((16, 18, 3), 0.3, np.float32)
    write_render(tmp_path / "ref.exr", ref)
    write_render(tmp_path / "same.exr", ref)
    write_render(tmp_path / "offset.exr", ref + np.float32(0.125))  # 0.125, 0.425 exact in float32
    return tmp_path


def test_metrics_json_closed_forms(cli, images):
    out = images / "eval"
    code, stdout, err = cli("evaluate", "--ref", images / "ref.exr", "--test", images / "same.exr",
                            "--test", images / "offset.exr", "-o", out)
    assert code == 0, err
    m = json.loads((out / "metrics.json").read_text())
    assert set(m) == {"same.exr", "offset.exr"}
    assert set(m["same.exr"]) >= {"rmse", "relmse", "ssim", "delta_e2000_mean"}
    assert m["same.exr"]["rmse"] == 0.0 and m["same.exr"]["delta_e2000_mean"] == 0.0
    assert m["same.exr"]["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert m["offset.exr"]["rmse"] == pytest.approx(0.125, rel=1e-6)
    assert m["offset.exr"]["relmse"] == pytest.approx(0.125 ** 2 / (0.3 ** 2 + 0.01), rel=1e-5)
    # constant images: SSIM = (2ab + C1) / (a^2 + b^2 + C1) on the sRGB-encoded luminance
    enc = lambda v: 1.055 * v ** (1 / 2.4) - 0.055  # noqa: E731
    a, b, c1 = enc(0.425), enc(0.3), 1e-4
    assert m["offset.exr"]["ssim"] == pytest.approx((2 * a * b + c1) / (a * a + b * b + c1), rel=1e-5)
    assert m["offset.exr"]["delta_e2000_mean"] > 1.0
    for f in ("report.md", "report.html", "metrics.png", "error_offset.png", "crops_offset.png", "error_same.png"):
        assert (out / f).stat().st_size > 0, f
    md = (out / "report.md").read_text()
    assert "offset.exr" in md and "](error_offset.png)" in md
    assert str(out / "report.md") in stdout


def test_render_artifacts_give_time_memory_and_speedup(cli, tmp_path):
    ref, test = _scene_image(seed=1), _scene_image(seed=2)
    write_render(tmp_path / "ref.exr", ref)
    write_render(tmp_path / "fast.exr", test)
    _fake_render_artifact(tmp_path / "ref.exr", 12.0, 3_000_000)
    _fake_render_artifact(tmp_path / "fast.exr", 3.0, 1_000_000, spp=8, paths_per_s=2.5e5)
    out = tmp_path / "eval"
    code, _, err = cli("evaluate", "--ref", tmp_path / "ref.exr", "--test", tmp_path / "fast.exr", "-o", out)
    assert code == 0, err
    e = json.loads((out / "metrics.json").read_text())["fast.exr"]
    assert e["wall_time_s"] == 3.0 and e["peak_memory_bytes"] == 1_000_000
    assert e["spp"] == 8 and e["paths_per_s"] == 2.5e5
    assert e["speedup_vs_reference"] == pytest.approx(4.0)
    assert e["rmse"] == pytest.approx(np.sqrt(np.mean((test.astype(float) - ref) ** 2)), rel=1e-9)


def test_evaluation_artifact_provenance_and_skip(cli, images):
    from pipeline.artifacts import Artifact

    out = images / "eval"
    args = ("evaluate", "--ref", images / "ref.exr", "--test", images / "offset.exr", "-o", out)
    assert cli(*args)[0] == 0
    art = Artifact(out / "evaluation.zarr", kind="evaluation")
    m = json.loads((out / "metrics.json").read_text())
    assert art.summary["tests"]["offset.exr"]["rmse"] == m["offset.exr"]["rmse"]
    sha = hashlib.sha256((images / "ref.exr").read_bytes()).hexdigest()
    assert art.meta["inputs"]["reference"]["sha256"] == sha
    assert art["relative_error"].shape == (1, 16, 18)
    np.testing.assert_allclose(art["mean_intensity"], [[0.3] * 3, [0.425] * 3], rtol=1e-6)
    # unchanged inputs: skipped; a changed input: recomputed
    code, stdout, _ = cli(*args)
    assert code == 0 and "up to date" in stdout
    write_render(images / "offset.exr", np.full((16, 18, 3), 0.55, np.float32))
    code, stdout, _ = cli(*args)
    assert code == 0 and "up to date" not in stdout
    assert json.loads((out / "metrics.json").read_text())["offset.exr"]["rmse"] == pytest.approx(0.25, rel=1e-6)


def test_bad_inputs_exit_2_and_leave_previous_outputs(cli, images):
    out = images / "eval"
    assert cli("evaluate", "--ref", images / "ref.exr", "--test", images / "offset.exr", "-o", out)[0] == 0
    before = (out / "metrics.json").read_bytes()
    meta_before = (out / "evaluation.zarr" / "zarr.json").read_bytes()

    write_render(images / "small.exr", np.zeros((12, 18, 3), np.float32))
    (images / "text.exr").write_text("not an image\n")
    cases = [
        (("--test", images / "small.exr"), "small.exr"),       # mismatched size
        (("--test", images / "missing.exr"), "missing.exr"),   # missing file
        (("--test", images / "text.exr"), "text.exr"),         # not an EXR
        (("--test", images / "ref.png"), "ref.png"),           # a PNG preview, not an EXR
    ]
    for extra, name in cases:
        code, _, err = cli("evaluate", "--ref", images / "ref.exr", "--test", images / "offset.exr", *extra, "-o", out)
        assert code == 2, (name, err)
        assert name in err and len(err.strip().splitlines()) == 1, err
    code, _, err = cli("evaluate", "--ref", images / "ref.exr", "-o", out)  # no test image
    assert code == 2 and "--test" in err
    code, _, err = cli("evaluate", "--ref", images / "ref.exr", "--test", images / "offset.exr",
                       "--sweep", images / "s.toml", "-o", out)  # two modes at once
    assert code == 2
    assert (out / "metrics.json").read_bytes() == before
    assert (out / "evaluation.zarr" / "zarr.json").read_bytes() == meta_before


def test_images_below_ssim_window_refused(cli, tmp_path):
    write_render(tmp_path / "a.exr", np.zeros((8, 8, 3), np.float32))
    write_render(tmp_path / "b.exr", np.zeros((8, 8, 3), np.float32))
    code, _, err = cli("evaluate", "--ref", tmp_path / "a.exr", "--test", tmp_path / "b.exr", "-o", tmp_path / "o")
    assert code == 2 and "11x11" in err


# ------------------------------------------------------------------------------------------------
# --table1: the memory-table rows come from pipeline.memory_table (another stage); a stand-in
# module with known rows checks the table's assembly, the render-time ratio and the image agreement.
def _fake_memory_table(monkeypatch, rows):
    import sys
    import types

    mod = types.ModuleType("pipeline.memory_table")
    mod.__file__ = "pipeline/memory_table.py"
    mod.table1_rows = lambda scenes: [dict(r, scene=s.stem) for r, s in zip(rows, scenes)]
    monkeypatch.setitem(sys.modules, "pipeline.memory_table", mod)


def test_table1_rows_times_and_agreement(cli, tmp_path, monkeypatch):
    rows = [{"full_total_bytes": 42_300_000_000, "full_regular_bytes": 42_200_000_000, "full_hair_bytes": 110_300_000,
             "full_loop_bytes": 36_800_000, "ours_total_bytes": 189_700_000, "ours_regular_bytes": 150_700_000,
             "ours_hair_bytes": 39_000_000, "ours_loop_bytes": 0},
            {"full_total_bytes": 1_000_000, "ours_total_bytes": 10_000}]
    _fake_memory_table(monkeypatch, rows)
    (tmp_path / "demo.toml").write_text("# scene\n")
    (tmp_path / "woven.toml").write_text("# scene\n")
    img = _scene_image(seed=4)
    write_render(tmp_path / "proc.exr", img)
    write_render(tmp_path / "real.exr", img + np.float32(0.01))
    _fake_render_artifact(tmp_path / "proc.exr", 5.0, 2_000_000)
    _fake_render_artifact(tmp_path / "real.exr", 6.0, 9_000_000)
    out = tmp_path / "t1"
    code, stdout, err = cli("evaluate", "--table1", "--scene", tmp_path / "demo.toml",
                            "--scene", tmp_path / "woven.toml",
                            "--procedural", tmp_path / "proc.exr", "--realized", tmp_path / "real.exr", "-o", out)
    assert code == 0, err
    got = json.loads((out / "table1.json").read_text())
    assert [r["scene"] for r in got] == ["demo", "woven"]
    assert got[0]["saving"] == pytest.approx(42_300_000_000 / 189_700_000)    # 223.0x, as in seed 000 Table 1
    assert got[1]["saving"] == pytest.approx(100.0)
    assert got[0]["procedural_time_s"] == 5.0 and got[0]["realized_time_s"] == 6.0
    assert got[0]["speed_ratio"] == pytest.approx(1.2)
    assert got[0]["procedural_vs_realized"]["rmse"] == pytest.approx(0.01, rel=1e-4)
    assert "procedural_time_s" not in got[1]
    md = (out / "report.md").read_text()
    assert "(223.0x)" in md and "42.3 GB" in md and "189.7 MB" in md and "(100.0x)" in md
    assert str(out / "report.md") in stdout


def test_table1_unrealized_scale_row(cli, tmp_path, monkeypatch):
    """A fabric too large to realize gets its procedural render alone (--unrealized, after the pairs'
    scenes): render and wall time, peak memory and that memory against the full realization."""
    _fake_memory_table(monkeypatch, [{"full_total_bytes": 1_000_000, "ours_total_bytes": 10_000},
                                     {"full_total_bytes": 80_000_000_000, "ours_total_bytes": 500_000_000}])
    for n in ("demo", "large"):
        (tmp_path / f"{n}.toml").write_text("# scene\n")
    img = _scene_image(seed=5)
    for n, t, m in (("proc", 5.0, 2_000_000), ("real", 6.0, 9_000_000), ("large", 80.0, 4_000_000_000)):
        write_render(tmp_path / f"{n}.exr", img)
        _fake_render_artifact(tmp_path / f"{n}.exr", t, m)
    out = tmp_path / "t1"
    code, _, err = cli("evaluate", "--table1", "--scene", tmp_path / "demo.toml", "--scene", tmp_path / "large.toml",
                       "--procedural", tmp_path / "proc.exr", "--realized", tmp_path / "real.exr",
                       "--unrealized", tmp_path / "large.exr", "-o", out)
    assert code == 0, err
    got = json.loads((out / "table1.json").read_text())
    assert got[1]["procedural_time_s"] == 80.0 and "realized_time_s" not in got[1]
    assert got[1]["procedural_peak_memory_bytes"] == 4_000_000_000
    assert got[1]["peak_over_full"] == pytest.approx(0.05)
    assert "1/20.0" in (out / "report.md").read_text()
    code, _, err = cli("evaluate", "--table1", "--scene", tmp_path / "demo.toml", "--procedural", tmp_path / "proc.exr",
                       "--realized", tmp_path / "real.exr", "--unrealized", tmp_path / "large.exr",
                       "-o", tmp_path / "o2")
    assert code == 2 and "--unrealized" in err


def test_table1_bad_inputs(cli, tmp_path, monkeypatch):
    import sys

    (tmp_path / "demo.toml").write_text("# scene\n")
    monkeypatch.setitem(sys.modules, "pipeline.memory_table", None)      # the module is absent
    code, _, err = cli("evaluate", "--table1", "--scene", tmp_path / "demo.toml", "-o", tmp_path / "o")
    assert code == 2 and "pipeline.memory_table" in err
    _fake_memory_table(monkeypatch, [{"full_total_bytes": 1, "ours_total_bytes": 1}])
    write_render(tmp_path / "p.exr", _scene_image())
    code, _, err = cli("evaluate", "--table1", "--scene", tmp_path / "demo.toml", "--procedural", tmp_path / "p.exr",
                       "-o", tmp_path / "o")
    assert code == 2 and "--realized" in err
    code, _, err = cli("evaluate", "--table1", "--scene", tmp_path / "demo.toml", "--procedural", tmp_path / "p.exr",
                       "--realized", tmp_path / "nope.exr", "-o", tmp_path / "o")
    assert code == 2 and "nope.exr" in err
    assert not (tmp_path / "o" / "report.md").exists()


def test_brightness_mismatch_noise_and_render_facts_are_reported(cli, tmp_path):
    """A test 1.5x as bright as the reference is flagged (ratio 1.5 per channel) and one 1.05x is not;
    with variance channels of pixel variance v each, the noise RMSE is sqrt(2 v) and noise dominates
    when it exceeds half the measured RMSE; resolution, spp, compile time and the render time
    (compilation excluded) come from the render artifact; the full images are shown side by side."""
    ref = _scene_image(seed=3)
    v = np.full(ref.shape[:2], 0.04 ** 2, np.float32)
    write_render(tmp_path / "ref.exr", ref, {"variance": v})
    write_render(tmp_path / "bright.exr", ref * np.float32(1.5), {"variance": v})
    write_render(tmp_path / "close.exr", ref * np.float32(1.05), {"variance": v})
    for name, t in (("ref", 12.0), ("bright", 3.0), ("close", 3.0)):
        _fake_render_artifact(tmp_path / f"{name}.exr", t + 5.0, 1)
        g = zarr.open_group(str(tmp_path / f"{name}.zarr"), mode="r+")
        g.attrs["summary"] = {**g.attrs["summary"], "render_time_s": t, "width": ref.shape[1], "height": ref.shape[0],
                              "paths": ref.shape[0] * ref.shape[1] * 20, "method_stats": {"compile_s": 5.0}}
    out = tmp_path / "eval"
    code, _, err = cli("evaluate", "--ref", tmp_path / "ref.exr", "--test", tmp_path / "bright.exr",
                       "--test", tmp_path / "close.exr", "-o", out)
    assert code == 0, err
    m = json.loads((out / "metrics.json").read_text())
    b, c = m["bright.exr"], m["close.exr"]
    assert b["brightness_ratio"] == pytest.approx([1.5] * 3, rel=1e-6) and b["brightness_mismatch"]
    assert c["brightness_ratio"] == pytest.approx([1.05] * 3, rel=1e-6) and not c["brightness_mismatch"]
    noise = np.sqrt(2 * 0.04 ** 2)
    assert b["noise_rmse"] == pytest.approx(noise, rel=1e-5) and c["noise_rmse"] == pytest.approx(noise, rel=1e-5)
    assert not b["noise_dominated"]          # RMSE 0.5 x mean ~ 0.25 >> noise
    assert c["noise_dominated"]              # RMSE 0.05 x mean ~ 0.025 < 2 x noise
    assert b["resolution"] == [ref.shape[1], ref.shape[0]] and b["samples_per_pixel"] == pytest.approx(20.0)
    assert b["compile_s"] == 5.0 and b["time_s"] == 3.0 and b["speedup_vs_reference"] == pytest.approx(4.0)
    md = (out / "report.md").read_text()
    assert "**Brightness mismatch**: bright.exr" in md and "close.exr differs" not in md
    assert "**Noise dominates** close.exr" in md and "](images.png)" in md
    assert (out / "images.png").stat().st_size > 0
