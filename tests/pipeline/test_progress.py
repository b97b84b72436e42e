"""No silent minutes (issue 54 item 7, ``pipeline/progress.py``, ``pipeline/compilation.py``): off a terminal
long work prints plain lines; a numba compilation says so while it runs and how long it took, and the time
is kept for the next estimate.

References: numba's own ``numba:compile`` event (fired only when numba compiles; a function compiled in
this test has never been compiled before), and the clock (the plain lines' interval)."""
import json
import time

import pytest


@pytest.fixture
def plain(monkeypatch, tmp_path):
    """Plain progress lines; compile times kept under tmp_path (not the project's numba cache)."""
    from pipeline import compilation

    monkeypatch.setenv("LOOMLIGHT_PROGRESS", "plain")
    monkeypatch.setattr(compilation, "times_file", lambda: tmp_path / "numba" / "compile_times.json")
    monkeypatch.setattr(compilation, "DELAY_S", 0.0)
    monkeypatch.setattr(compilation, "RECORD_MIN_S", 0.0)
    return tmp_path


def test_modes(monkeypatch):
    from pipeline.progress import mode

    for flag, want in (("0", "off"), ("", "off"), ("no", "off"), ("plain", "plain"), ("1", "live")):
        monkeypatch.setenv("LOOMLIGHT_PROGRESS", flag)
        assert mode() == want, flag
    monkeypatch.delenv("LOOMLIGHT_PROGRESS")
    assert mode() == "plain"   # pytest's captured stderr is not a terminal


def test_plain_lines_for_long_work_only(plain, monkeypatch, capsys):
    from pipeline.progress import progress, status

    monkeypatch.setenv("LOOMLIGHT_PROGRESS_INTERVAL", "1")
    with progress("quick", 3) as advance:
        advance(3)
    assert capsys.readouterr().err == ""          # shorter than the interval: nothing
    with progress("tiles", 4) as advance:
        advance()
        time.sleep(1.6)
        advance(3)
    err = capsys.readouterr().err.splitlines()
    assert any(line.startswith("tiles: 1/4 (25 %), ") and "elapsed" in line for line in err), err
    assert err[-1].startswith("tiles: 4/4 done in "), err
    with status("building"):
        time.sleep(1.6)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("building: ") and err[0].endswith("elapsed"), err
    assert err[-1].startswith("building: done in "), err


def test_compilation_is_announced_timed_and_recorded(plain, capsys):
    """A kernel compiled for the first time: one line when it starts (with no time known yet), one when
    it ends, its time recorded; a new typing of it later is announced with that time; a call that
    compiles nothing says nothing."""
    from numba import njit

    from pipeline import compilation

    compilation.watch()

    @njit(cache=False)
    def fresh_kernel_for_this_test(x):
        return x * 2 + 1

    with compilation.group("test kernels"):
        assert fresh_kernel_for_this_test(3) == 7
    err = capsys.readouterr().err.splitlines()
    assert err[0] == ("compiling test kernels: test_compilation_is_announced_timed_and_recorded.<locals>."
                      "fresh_kernel_for_this_test (first run of this code on this machine; can take minutes)"), err
    assert err[-1].startswith("compiled test kernels: ") and " in " in err[-1], err
    times = json.loads((plain / "numba" / "compile_times.json").read_text())
    key = [k for k in times if k.endswith("fresh_kernel_for_this_test")]
    assert len(key) == 1 and times[key[0]] > 0

    assert fresh_kernel_for_this_test(4) == 9     # compiled already: no event, no line
    assert capsys.readouterr().err == ""

    fresh_kernel_for_this_test(2.5)                # a new typing compiles again: the estimate is the last time
    err = capsys.readouterr().err.splitlines()
    assert "last time)" in err[0] and err[0].startswith("compiling tests."), err


def test_progress_off_says_nothing(monkeypatch, capsys):
    from numba import njit

    from pipeline import compilation
    from pipeline.progress import progress

    monkeypatch.setenv("LOOMLIGHT_PROGRESS", "0")
    monkeypatch.setattr(compilation, "DELAY_S", 0.0)
    compilation.watch()

    @njit(cache=False)
    def another_fresh_kernel(x):
        return x - 1

    with progress("tiles", 2) as advance:
        assert another_fresh_kernel(1) == 0
        advance(2)
    assert capsys.readouterr().err == ""
