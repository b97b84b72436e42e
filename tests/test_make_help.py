"""`make help` lists every target a user calls, each with one line (issue 54 item 4).

Reference: the makefiles' own text. Every rule in Makefile and make/*.mk that has a recipe and is not a
file or pattern rule (no `$`, `/` or `%` in its name, not a special `.TARGET`) must appear in `make help`'s
output with a description (from its `## ...` comment), and every target `make help` lists must exist. The
main targets stay up front in Makefile, the experiments in make/experiments.mk; no comment states a timing
(those live in docs/measurements.md, generated), nor does docs/architecture.md.
"""
from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from tests.helpers import ROOT

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
MAKEFILES = [ROOT / "Makefile", *sorted((ROOT / "make").glob("*.mk"))]
MAIN = {"help", "setup", "demo", "demo-full", "test", "test-all", "bench", "references", "compare", "docs", "clean"}
EXPERIMENTS = {"table1", "sweep", "agreement", "prt-sweep", "prt-study", "btf-sweep"}
# a number with a unit of time ("~4 min", "7 s", "10 minutes"): measured timings, never in comments or prose
TIMING = re.compile(r"\b\d[\d,.]*\s*(?:ms|s|sec|seconds?|min|mins|minutes?|h|hours?)\b")


def _logical_lines(path):
    """The file's lines with backslash continuations joined."""
    out, cur = [], ""
    for line in path.read_text().splitlines():
        if line.endswith("\\"):
            cur += line[:-1] + " "
            continue
        out.append(cur + line)
        cur = ""
    return out


def _targets(path) -> dict[str, bool]:
    """{target: has a recipe} of the rules a user can call by name in one makefile."""
    lines = _logical_lines(path)
    found = {}
    for i, line in enumerate(lines):
        if line.startswith(("\t", "#")) or not line.strip():
            continue
        m = re.match(r"^([^:#=\s][^:#=]*?)\s*:(?![:=])", line)
        if not m or re.match(r"^\S+\s*[?+:!]?=", line):
            continue
        rest = lines[i + 1:]
        nxt = next((ln for ln in rest if ln.strip() and not ln.startswith("#")), "")
        for t in m.group(1).split():
            if t.startswith(".") or any(c in t for c in "$/%"):
                continue
            found[t] = found.get(t, False) or nxt.startswith("\t")
    return found


def _help() -> dict[str, str]:
    out = subprocess.run(["make", "--no-print-directory", "help"], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout
    listed = {}
    for line in out.splitlines():
        m = re.match(r"^  make (\S+)\s+(.*)$", line)
        if m:
            assert m.group(1) not in listed, f"listed twice: {m.group(1)}"
            listed[m.group(1)] = m.group(2).strip()
    return listed


def test_help_lists_every_target_with_a_recipe():
    listed = _help()
    defined = {}
    for path in MAKEFILES:
        defined.update(_targets(path))
    with_recipe = {t for t, recipe in defined.items() if recipe}
    assert MAIN | EXPERIMENTS <= with_recipe | {"setup"}
    missing = sorted(with_recipe - set(listed))
    assert not missing, f"targets with a recipe that `make help` does not list (add `## what it does`): {missing}"
    assert all(listed[t] for t in listed), listed
    unknown = sorted(set(listed) - set(defined))
    assert not unknown, f"`make help` lists targets that do not exist: {unknown}"


def test_help_is_the_default_goal():
    plain = subprocess.run(["make", "--no-print-directory"], cwd=ROOT, capture_output=True, text=True, check=True)
    assert "  make demo " in plain.stdout and "  make table1 " in plain.stdout


def test_main_targets_up_front_and_experiments_apart():
    main = _targets(ROOT / "Makefile")
    experiments = _targets(ROOT / "make" / "experiments.mk")
    assert MAIN <= set(main), MAIN - set(main)
    assert EXPERIMENTS <= set(experiments) and not EXPERIMENTS & set(main)
    text = (ROOT / "Makefile").read_text()
    assert "\ninclude make/experiments.mk" in text
    first_file_rule = text.index("\n$(")   # the user's targets come before the artifact rules
    assert all(re.search(rf"^{re.escape(t)}:", text[:first_file_rule], re.M) for t in MAIN), MAIN


def test_bench_and_compare_regenerate_the_measurements():
    """`make bench` and `make compare` end by rewriting docs/measurements.md (`loomlight docs`); read from
    `make -n` (nothing runs; compare's references are taken as made)."""
    for args in (["bench"], ["-o", "references", "compare"]):
        out = subprocess.run(["make", "-n", "--no-print-directory", *args], cwd=ROOT, capture_output=True,
                             text=True, check=True).stdout.replace("\\\n", " ")
        docs = [ln for ln in out.splitlines() if "loomlight docs --only measurements" in ln]
        assert docs, out
        assert out.rstrip().splitlines()[-1] in docs or "exit $status" in docs[-1], out


def test_no_timings_in_makefile_comments_or_architecture():
    bad = []
    for path in MAKEFILES:
        for n, line in enumerate(path.read_text().splitlines(), 1):
            comment = line.split("#", 1)[1] if line.lstrip().startswith("#") or " ## " in line else ""
            if TIMING.search(comment):
                bad.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    for n, line in enumerate((ROOT / "docs" / "architecture.md").read_text().splitlines(), 1):
        if TIMING.search(line):
            bad.append(f"docs/architecture.md:{n}: {line.strip()}")
    assert not bad, "timings belong in docs/measurements.md (make bench, make compare):\n" + "\n".join(bad)
