"""The compile report and ahead-of-time compilation (issue 55 items 1 and 5; ``pipeline/compilation.py``'s
compile log, ``bench/compile_report.py``, ``pipeline/warmup.py``).

References: numba's own ``numba:compile`` events (a function compiled in this test has never been
compiled before: ``cache=False``), a hand-made log for the report's ordering, and the CLI's own parser for
the warmup plan's commands."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT


@pytest.fixture
def compile_log(monkeypatch, tmp_path):
    from pipeline import compilation

    log = tmp_path / "compile.jsonl"
    monkeypatch.setattr(compilation, "_log_path", str(log))
    monkeypatch.setattr(compilation, "context", "a test")
    monkeypatch.setattr(compilation, "times_file", lambda: tmp_path / "compile_times.json")
    compilation.watch()
    return log


def test_every_compilation_is_logged_with_who_asked(compile_log):
    """Two fresh kernels, one calling the other: two lines; the callee asked for by the caller kernel, the
    caller by this test file's line; self seconds never above the total, the caller's without the callee's."""
    from numba import njit

    @njit(cache=False)
    def callee_for_the_log(x):
        return x + 1.0

    @njit(cache=False)
    def caller_for_the_log(x):
        return callee_for_the_log(x) * 2.0

    assert caller_for_the_log(1.0) == 4.0
    recs = [json.loads(ln) for ln in compile_log.read_text().splitlines()]
    by = {r["kernel"].rsplit(".", 1)[-1]: r for r in recs}
    assert set(by) == {"callee_for_the_log", "caller_for_the_log"}, recs
    caller, callee = by["caller_for_the_log"], by["callee_for_the_log"]
    assert callee["parent"] == caller["kernel"] and callee["caller"] is None
    assert caller["parent"] is None and caller["caller"].startswith("tests/pipeline/test_compile_report.py:")
    assert caller["signature"] == "float64" and caller["context"] == "a test"
    for r in recs:
        assert 0 <= r["self_s"] <= r["total_s"]
    assert caller["self_s"] <= caller["total_s"] - callee["total_s"] + 1e-3
    assert caller_for_the_log(2.0) == 6.0                      # compiled: nothing more logged
    assert caller_for_the_log(2) == 6.0                        # a new typing: one line more, the caller only
    recs2 = [json.loads(ln) for ln in compile_log.read_text().splitlines()]
    assert len(recs2) >= 3 and recs2[2]["signature"] == "int64"


def test_report_lists_duplicate_signatures_first():
    sys.path.insert(0, str(ROOT / "bench"))
    from compile_report import summarize

    def rec(kernel, sig, s, pid, parent=None):
        return {"kernel": kernel, "signature": sig, "self_s": s, "total_s": s, "pid": pid, "parent": parent,
                "caller": None if parent else "pipeline/x.py:1 (f)", "context": "loomlight render"}

    recs = [rec("big", "float64", 30.0, 1), rec("twice", "int64", 2.0, 1), rec("twice", "float64", 1.0, 1),
            rec("again", "int64", 3.0, 1), rec("again", "int64", 3.5, 2), rec("inner", "int64", 5.0, 1, "big")]
    report = summarize({"demo": {"records": recs, "wall_s": 60.0}})
    assert [k["kernel"] for k in report["kernels"]] == ["twice", "again", "big", "inner"]
    t = report["totals"]["demo"]
    assert t["compile_core_s"] == 44.5 and t["processes"] == 2 and t["kernels"] == 4 and t["compilations"] == 6
    again = report["kernels"][1]
    assert again["signatures"] == 1 and again["recompiled"] == 1 and again["by_signature"][0]["compiled"] == {"demo": 2}
    assert report["kernels"][3]["by_signature"][0]["asked_by"] == ["demo: loomlight render: kernel big"]
    # a part has a cache of its own: the same signature compiled once in each of two parts is no repeat
    two = summarize({"demo": {"records": [rec("k", "int64", 1.0, 1)], "wall_s": 1.0},
                     "tests": {"records": [rec("k", "int64", 1.0, 7)], "wall_s": 1.0}})
    assert (two["kernels"][0]["recompiled"] == 0
            and two["kernels"][0]["by_signature"][0]["compiled"] == {"demo": 1, "tests": 1})


def test_warmup_plan_runs_each_step_once_and_parses(cli, monkeypatch):
    """Every method's plan: no step twice, every option of every command one its command has."""
    from pipeline.warmup import METHODS, plan

    monkeypatch.setenv("COLUMNS", "240")   # rich wraps the help at the console width

    steps = plan(METHODS)
    assert len(steps) == len(set(steps))
    assert [s.name for s in plan(["fiberpath", "volpath"])][:2] == ["ingest the demo swatch", "realize its fibres"]
    helps = {}
    for s in steps:
        words = s.args[:2] if s.args[0] == "precompute" else s.args[:1]
        if words not in helps:
            code, out, _ = cli(*words, "--help")
            assert code == 0
            helps[words] = out
        for a in s.args:
            if a.startswith("--"):
                assert a in helps[words], (s.name, a)
        for a in s.args:
            if a.endswith(".toml") and "{d}" not in a:
                assert (ROOT / a).is_file() or Path(a).is_file(), a


def test_warmup_rejects_an_unknown_method(cli):
    code, out, err = cli("warmup", "--methods", "volpath,raytrace")
    assert code == 2 and "--methods" in err and "raytrace" in err and "volpath" in err


@pytest.mark.slow
def test_after_warmup_a_render_compiles_nothing(tmp_path):
    """``warmup --methods btf`` on an empty cache of its own, then the demo's btf chain at a few pixels
    compiles no kernel (the compile log of the second process is empty)."""
    import os

    env = dict(os.environ, LOOMLIGHT_NUMBA_CACHE_ROOT=str(tmp_path / "cache"), LOOMLIGHT_PROGRESS="plain")
    env.pop("NUMBA_CACHE_DIR", None)
    ll = [sys.executable, "-m", "pipeline.cli"]
    r = subprocess.run([*ll, "warmup", "--methods", "btf"], env=env, cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "warmup: done in" in r.stdout
    log = tmp_path / "compile.jsonl"
    from pipeline.warmup import METHOD_STEPS

    d = tmp_path / "work"
    d.mkdir()
    for step in METHOD_STEPS["btf"]:
        args = [a.replace("{d}", str(d)) for a in step.args]
        r = subprocess.run([*ll, *args], env=dict(env, LOOMLIGHT_COMPILE_LOG=str(log)), cwd=ROOT,
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    assert not log.exists() or log.read_text().strip() == "", log.read_text()[:2000]
