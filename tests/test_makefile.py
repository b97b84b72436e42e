"""The Makefile's contract with a newcomer (issue 23 item 6), read from `make -n` (nothing runs):
`make demo-quick` is the whole demo at small sizes and reduced precomputes in its own directory,
`make demo` renders at the documented demo size, and pip's output goes to a log shown only on failure; and, with
real make in a scratch directory, that a precompute made with other arguments is rebuilt.
"""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")


def _dry_run(*args: str) -> list[str]:
    out = subprocess.run(["make", "-n", "--no-print-directory", *args], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout
    return [line for line in out.replace("\\\n", " ").splitlines() if line.strip()]


def _commands(lines: list[str], word: str) -> list[str]:
    return [line for line in lines if f"loomlight {word} " in line]


def test_demo_quick_is_the_whole_demo_small_in_its_own_directory():
    quick = _dry_run("-B", "demo-quick")
    demo = _dry_run("-B", "demo")
    # every stage of the demo, no more and no fewer: the same loomlight subcommands in the same order
    def sub(lines):
        return [line.split("loomlight ", 1)[1].split()[0] for line in lines if "bin/loomlight " in line]

    assert sub(quick) == sub(demo)
    for line in quick:
        if "bin/loomlight " in line:
            assert "out/demo" not in line, line
    renders = _commands(quick, "render")
    assert len(renders) >= 6
    main_renders = [r for r in renders if "/eval/" not in r]
    assert main_renders and all("--width 160 --height 120" in r for r in main_renders)
    assert all("--max-spp 0" in r for r in main_renders if "--max-spp" in r)
    (svf,) = [c for c in _commands(quick, "precompute") if " svf " in c]
    assert "--resolution 32" in svf
    (iirtf,) = [c for c in _commands(quick, "precompute") if " iirtf " in c]
    assert "--paths 100" in iirtf


def test_demo_renders_at_the_documented_size_and_precompute():
    demo = _dry_run("-B", "demo")
    main_renders = [r for r in _commands(demo, "render") if "/eval/" not in r]
    # volpath, fiberpath; damask: fiberpath, prt, btf's fit and table; knit: bysdf, fiberpath
    assert len(main_renders) == 8
    assert all("--width 240 --height 180" in r for r in main_renders)
    # the main volpath picture: procedural lookups with the fibre cache (issue 21); the evaluation's
    # procedural render: lookups only, against the realized source
    (vol,) = [r for r in main_renders if "--method volpath" in r]
    assert "--source procedural" in vol and "--cache" not in vol
    (ev,) = [r for r in _commands(demo, "render") if "/eval/volpath-procedural" in r]
    assert "--cache 0" in ev
    (btf,) = [c for c in _commands(demo, "precompute") if " btf " in c]
    assert "--exemplar" not in btf and "--resolution 16" in btf   # the damask's texture holds both satins
    readme = (ROOT / "README.md").read_text()
    assert "240×180" in readme and "make demo-quick" in readme
    (svf,) = [c for c in _commands(demo, "precompute") if " svf " in c]
    assert "--resolution 64" in svf


def test_pip_output_goes_to_a_log_shown_on_failure():
    lines = _dry_run("-B", ".venv/.installed")
    (pip,) = [line for line in lines if "pip" in line and "install" in line and "-e" in line]
    assert "> .venv/pip.log 2>&1" in pip
    assert "cat .venv/pip.log" in pip and "exit 1" in pip
    assert "--disable-pip-version-check" in pip


def test_changed_precompute_arguments_rebuild_their_artifact_and_nothing_else(tmp_path):
    """An artifact made with other arguments is rebuilt (an upgrade that changes IIRTF_ARGS must not leave the
    old IIRTF in place), and the same arguments rebuild nothing: the rule's argument file is rewritten only
    when the arguments differ. Real make, in a scratch OUT, with the command runner replaced by `true`."""
    out = tmp_path / "demo"

    def make(*args: str) -> str:
        return subprocess.run(["make", "--no-print-directory", f"OUT={out}", "LL=true", *args], cwd=ROOT,
                              capture_output=True, text=True, check=True).stdout

    args = out / ".args" / "damask_iirtf.args"
    make(str(args))
    default = args.read_text()
    assert "--light-domain sphere" in default
    for name in ("damask_tiling", "damask_iirtf"):          # artifacts newer than everything they depend on
        (out / f"{name}.zarr").mkdir(parents=True)
        (out / f"{name}.zarr" / "zarr.json").write_text("{}")
    target = str(out / "damask_iirtf.zarr" / "zarr.json")
    stamp = args.stat().st_mtime_ns
    assert "precompute iirtf" not in make(target)            # same arguments: nothing to do
    assert args.stat().st_mtime_ns == stamp
    rebuilt = make(target, "IIRTF_ARGS=--order 3")
    assert "true precompute iirtf" in rebuilt and "--order 3" in rebuilt and "precompute svf" not in rebuilt
    assert args.read_text() == "--order 3\n"
