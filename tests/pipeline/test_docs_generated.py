"""The generated documentation (issue 54, ``pipeline/docs_gen.py``, ``loomlight docs``).

References: the schemas themselves (every key of every user-written file appears in ``docs/scenes.md``,
found by a walk of the raw JSON independent of the generator's), the renderer registry (every method and
``--set`` key appears in its page's settings block), the committed pages against a fresh generation
(``loomlight docs --check``), and synthetic benchmark and comparison results with known numbers
(``docs/measurements.md`` reports them, and says "not measured" where there are none).
"""
from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import pytest

from pipeline import docs_gen
from pipeline.renderers import METHODS
from tests.helpers import ROOT

DOCS = ROOT / "docs"


def _section(text: str, anchor: str) -> str:
    """The part of scenes.md from a schema's anchor to the next schema's."""
    start = text.index(f'<a id="{anchor}"></a>')
    ends = [text.find(f'<a id="{a}"></a>', start + 1) for _, a, _, _ in docs_gen.SCHEMA_DOCS]
    ends = [e for e in ends if e > start]
    return text[start:min(ends) if ends else len(text)]


def _property_names(node, out: set) -> set:
    """Every property name anywhere in a JSON Schema (raw JSON walk, $defs included)."""
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "properties" and isinstance(value, dict):
                out.update(k for k, v in value.items() if v is not True)
            _property_names(value, out)
    elif isinstance(node, list):
        for v in node:
            _property_names(v, out)
    return out


def test_committed_docs_are_current(cli):
    """`loomlight docs --check`: docs/scenes.md and every method page's settings block are what the schemas,
    the registry and the commands' options give (run `make docs` after changing those)."""
    code, out, err = cli("docs", "--check")
    assert code == 0, out + err


def test_check_exits_1_when_stale(cli, monkeypatch):
    """`--check` on stale docs names them and exits with code 1 (make test and CI rely on the code; the CLI once
    returned 0 here, because click hands a command's typer.Exit back instead of raising it)."""
    monkeypatch.setattr(docs_gen, "check", lambda root=None: ["docs/scenes.md: 1 line(s) differ"])
    code, out, err = cli("docs", "--check")
    assert code == 1 and "docs/scenes.md" in out and "stale" in err, (code, out, err)


@pytest.mark.parametrize("name,anchor", [(n, a) for n, a, _, _ in docs_gen.SCHEMA_DOCS])
def test_every_schema_key_is_in_scenes_md(name, anchor):
    schema = json.loads((ROOT / "schemas" / f"{name}.schema.json").read_text())
    if name == "scene":   # the [render] table comes from the registry
        from pipeline.renderers import render_schema

        schema["properties"]["render"] = render_schema()
    section = _section((DOCS / "scenes.md").read_text(), anchor)
    keys = _property_names(schema, set())
    assert keys
    missing = [k for k in sorted(keys) if not re.search(r"\| `(?:[^`|]*\.)?" + re.escape(k) + r"` \|", section)]
    assert not missing, f"keys of schemas/{name}.schema.json not documented in docs/scenes.md#{anchor}: {missing}"
    for line in section.splitlines():   # and every row says what the key means
        if line.startswith("| `"):
            assert line.rstrip().rsplit("|", 2)[-2].strip(), line


@pytest.mark.parametrize("name", [n for n, _, _, _ in docs_gen.SCHEMA_DOCS])
def test_every_schema_key_has_a_description(name):
    """The schema files describe every key themselves (scenes.md takes the meaning from there)."""
    schema = json.loads((ROOT / "schemas" / f"{name}.schema.json").read_text())
    bare = []

    def walk(node):
        if isinstance(node, dict):
            for key, value in node.get("properties", {}).items():
                if (isinstance(value, dict) and not value.get("description")
                        and not (name == "scene" and key == "render")):
                    bare.append(key)
            for key, value in node.items():
                if key != "if":   # an if's properties are conditions, not keys
                    walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(schema)
    assert not bare, f"schemas/{name}.schema.json: keys without a description: {sorted(set(bare))}"


def test_every_registered_method_and_setting_is_documented():
    covered = {m for page in docs_gen.PAGES.values() for m in page.methods}
    assert covered == set(METHODS), "a render method without a docs/methods page (pipeline/docs_gen.py: PAGES)"
    for page in docs_gen.PAGES.values():
        block = docs_gen.read_block((DOCS / "methods" / f"{page.name}.md").read_text(), "settings")
        for name in page.methods:
            m = METHODS[name]
            assert f"--method {name}`" in block
            for s in m.settings:
                assert f"| `{s.key}` |" in block, (name, s.key)
            for src in m.sources:
                assert f"`{src.name}`" in block, (name, src.name)


def test_check_finds_stale_docs_and_generate_repairs_them(tmp_path):
    """A stale scenes.md, a stale settings block and a missing page are reported; generating rewrites
    only the generated parts: the prose around the markers is kept byte for byte."""
    (tmp_path / "docs" / "methods").mkdir(parents=True)
    (tmp_path / "docs" / "scenes.md").write_text("# old\n")
    prose_before, prose_after = "# prt\n\nHand-written prose.\n\n", "\n\nMore prose | with a pipe.\n"
    begin, end = "<!-- BEGIN GENERATED: settings -->", "<!-- END GENERATED: settings -->"
    (tmp_path / "docs" / "methods" / "prt.md").write_text(f"{prose_before}{begin}\nold\n{end}{prose_after}")
    problems = docs_gen.check(tmp_path)
    text = "\n".join(problems)
    assert "scenes.md" in text and "prt.md (settings block)" in text
    assert all(f"{p}.md: missing" in text for p in docs_gen.PAGES if p != "prt")

    changed = docs_gen.generate(tmp_path, parts=("scenes", "methods"))
    assert docs_gen.check(tmp_path) == []
    assert {p.name for p in changed} == {"scenes.md", *(f"{p}.md" for p in docs_gen.PAGES)}
    prt = (tmp_path / "docs" / "methods" / "prt.md").read_text()
    assert prt.startswith(prose_before + begin) and prt.endswith(end + prose_after)
    assert docs_gen.read_block(prt, "settings") == docs_gen.settings_block(docs_gen.PAGES["prt"])
    new = (tmp_path / "docs" / "methods" / "btf.md").read_text()   # a new page: title and both blocks
    assert new.startswith("# btf") and docs_gen.read_block(new, "measurements") is not None
    assert docs_gen.generate(tmp_path, parts=("scenes", "methods")) == []   # nothing left to change


def test_broken_markers_are_an_error_naming_the_page(tmp_path):
    from pipeline.errors import LoomError

    page = tmp_path / "x.md"
    with pytest.raises(LoomError, match="settings block"):
        docs_gen.replace_block("<!-- END GENERATED: settings -->\n<!-- BEGIN GENERATED: settings -->\n",
                               "settings", "x", page)


def test_unknown_part_is_refused(cli):
    code, _, err = cli("docs", "--only", "scene")
    assert code == 2 and "--only" in err and "scenes" in err


# ------------------------------------------------------------------------------------------------ measurements
def _synthetic(tmp_path: Path):
    bench_dir = tmp_path / "bench"
    bench_dir.mkdir()
    (bench_dir / "bench_prtspeed.py").write_text('"""prt render speed: paths per second."""\n')
    (bench_dir / "bench_idle.py").write_text('"""A benchmark that has not run."""\n')
    results = tmp_path / "results"
    results.mkdir()
    (results / "prtspeed.json").write_text(json.dumps(
        {"bench_wall_s": 12.5, "paths_per_s": 12345.678, "setup": {"tiles": 4}, "fps_target": 10.0,
         "image": "64x48"}))
    (results / "broken.json").write_text("{not json")
    (results / "summary.md").write_text("# loomlight benchmarks\n\nMachine: python 3.11, cpus 2\n")
    compare = tmp_path / "compare"
    (compare / "flat").mkdir(parents=True)
    def lv(t, b=""):
        return {"time_s": t, "bound": b, "floor_blocks": False}

    doc = {"comparison": "flat", "description": "a flat patch", "scene": "x.toml",
           "reference": {"method": "fiberpath", "spp": 512, "batches": 8, "render_time_s": 42.0,
                         "mean_error": 0.0012, "targets_met": True},
           "levels": [0.3, 0.1],
           "methods": {"fiberpath": {"method": "fiberpath", "floor": 0.0, "floor_se": 0.01,
                                     "levels": {"0.3": lv(2.0), "0.1": lv(18.0)},
                                     "speedup_at_equal_error": {"level": 0.1, "value": 1.0, "bound": ""},
                                     "peak_memory_bytes": 3 * 2**30},
                       "prt": {"method": "prt", "floor": 0.25, "floor_se": 0.02,
                               "levels": {"0.3": lv(0.5), "0.1": {"time_s": 4.0, "bound": ">", "floor_blocks": True}},
                               "speedup_at_equal_error": {"level": 0.3, "value": 4.0, "bound": ""}}},
           "targets": [{"method": "prt", "target": 10.0, "met": False, "why": "its bias floor 0.25 is above 0.1"}]}
    (compare / "flat" / "convergence.json").write_text(json.dumps(doc))
    return bench_dir, results, compare


def test_measurements_report_synthetic_results(tmp_path):
    bench_dir, results, compare = _synthetic(tmp_path)
    data = docs_gen.load_measurements(results, compare, bench_dir=bench_dir, compare_files=[Path("flat.toml"),
                                                                                           Path("other.toml")],
                                      now="2027-01-01 00:00 UTC", host="test CPU, 2 cores", revision="abc123")
    md = docs_gen.measurements_md(data)
    assert "- Generated: 2027-01-01 00:00 UTC" in md and "test CPU, 2 cores" in md and "abc123" in md
    assert "python 3.11, cpus 2" in md   # the benchmarks' own record of their machine
    for page in docs_gen.PAGES:   # every method page can link measurements.md#<page>
        assert f'<a id="{page}"></a>' in md
    # the benchmark: every (flattened) number, the docstring's first line, the one that did not run
    assert '<a id="bench-prtspeed"></a>' in md and "prt render speed: paths per second." in md
    assert "| `paths_per_s` | 1.235e+04 |" in md and "| `setup.tiles` | 4 |" in md
    idle = md.split('<a id="bench-idle"></a>')[1].split("<a id=")[0]
    assert "Not measured in this run" in idle
    # the comparison: floors, times to each level, speed-up, memory, targets; the missing one says so
    flat = md.split('<a id="compare-flat"></a>')[1].split("<a id=")[0]
    assert "| prt | prt | 0.250 ± 0.020 | 30%: 0.5 s; 10%: > 4 s (floor) | 4× at 30% | - |" in flat
    assert "| fiberpath | fiberpath | 0.000 ± 0.010 | 30%: 2 s; 10%: 18 s | reference method | 3 GiB |" in flat
    assert "prt ≥ 10× at equal error: not met: its bias floor 0.25 is above 0.1" in flat
    other = md.split('<a id="compare-other"></a>')[1]
    assert "Not measured in this run" in other
    # the prt page's block quotes the comparison row
    block = docs_gen.measurements_block(docs_gen.PAGES["prt"], data)
    assert "[flat](../measurements.md#compare-flat)" in block and "4× at 30%" in block
    assert "../measurements.md#prt" in block


def test_measurements_without_results(tmp_path):
    """No results directory and no comparisons: every section says it was not measured; nothing fails."""
    data = docs_gen.load_measurements(tmp_path / "nothing", tmp_path / "none", bench_dir=ROOT / "bench",
                                      now="2027-01-01 00:00 UTC", host="h", revision="r")
    md = docs_gen.measurements_md(data)
    benches = sorted(p.stem[len("bench_"):] for p in (ROOT / "bench").glob("bench_*.py"))
    assert benches
    for b in benches:
        assert "Not measured in this run" in md.split(f'<a id="bench-{b}"></a>')[1].split("<a id=")[0]
    for page in docs_gen.PAGES.values():
        block = docs_gen.measurements_block(page, data)
        assert "Not measured in this run" in block


def test_measurements_rewrite_keeps_the_file_when_only_the_header_changes(tmp_path):
    bench_dir, results, compare = _synthetic(tmp_path)
    root = tmp_path / "repo"
    shutil.copytree(DOCS / "methods", root / "docs" / "methods")

    def run(now):
        data = docs_gen.load_measurements(results, compare, bench_dir=bench_dir, compare_files=[],
                                          now=now, host="h", revision="r")
        return docs_gen.generate(root, parts=("measurements",), data=data)

    assert root / "docs" / "measurements.md" in run("2027-01-01 00:00 UTC")
    assert run("2027-01-02 00:00 UTC") == []
    assert "2027-01-01" in (root / "docs" / "measurements.md").read_text()
    (results / "prtspeed.json").write_text(json.dumps({"paths_per_s": 1.0}))
    assert root / "docs" / "measurements.md" in run("2027-01-03 00:00 UTC")


def test_a_run_without_benchmarks_keeps_the_pages_benchmark_numbers(tmp_path):
    """``make compare`` alone regenerates the page: the benchmarks it did not run keep the numbers and date
    the page had (round trip through the page's own tables), marked as kept; comparisons are never kept."""
    bench_dir, results, compare = _synthetic(tmp_path)
    first = docs_gen.load_measurements(results, compare, bench_dir=bench_dir, compare_files=[Path("flat.toml")],
                                       now="2027-01-01 00:00 UTC", host="h", revision="r")
    page = tmp_path / "measurements.md"
    page.write_text(docs_gen.measurements_md(first))
    again = docs_gen.load_measurements(tmp_path / "nothing", tmp_path / "none", bench_dir=bench_dir,
                                       compare_files=[Path("flat.toml")], now="2027-01-02 00:00 UTC", host="h",
                                       revision="r", previous=page)
    md = docs_gen.measurements_md(again)

    def section(text, anchor):
        return text.split(f'<a id="{anchor}"></a>')[1].split("<a id=")[0]

    old, new = section(page.read_text(), "bench-prtspeed"), section(md, "bench-prtspeed")
    mark = f"{docs_gen.KEPT} (on h)"   # the machine the page's header named
    assert new.replace(mark, "") == old and mark in new
    assert "Not measured in this run" in section(md, "bench-idle")
    assert "Not measured in this run" in section(md, "compare-flat")
    prt = dataclasses.replace(docs_gen.PAGES["prt"], benchmarks=("prtspeed",))
    assert "| [prtspeed](../measurements.md#bench-prtspeed) | `paths_per_s` | 1.235e+04 |" in \
        docs_gen.measurements_block(prt, again)
    # kept twice, on another machine: the mark does not pile up and still names the machine that measured
    page.write_text(md)
    third = docs_gen.load_measurements(tmp_path / "nothing", tmp_path / "none", bench_dir=bench_dir,
                                       compare_files=[], now="2027-01-03 00:00 UTC", host="elsewhere",
                                       revision="r", previous=page)
    assert section(docs_gen.measurements_md(third), "bench-prtspeed") == new
