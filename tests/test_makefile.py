"""The Makefile's contract with a newcomer (issue 23 item 6, issue 55 item 4), read from `make -n` (nothing
runs): `make demo` is every stage at small sizes and reduced precomputes, `make demo-full` the same commands at
the documented size in its own directory, the comparisons precompute their own inputs at demo-full's settings
(so the demo's settings never change what `make compare` measures), and pip's output goes to a log shown only on
failure; and, with real make in a scratch directory, that a precompute made with other arguments is rebuilt.
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


def _precompute(lines: list[str], kind: str) -> str:
    (cmd,) = [c for c in _commands(lines, "precompute") if f" {kind} " in c]
    return cmd


def test_demo_is_every_stage_small_and_demo_full_the_same_at_the_documented_size():
    demo = _dry_run("-B", "demo")
    full = _dry_run("-B", "demo-full")

    def sub(lines):
        return [line.split("loomlight ", 1)[1].split()[0] for line in lines if "bin/loomlight " in line]

    # every stage of the demo, no more and no fewer: the same loomlight subcommands in the same order
    assert sub(full) == sub(demo)
    for line in full:
        if "bin/loomlight " in line:
            assert "out/demo/" not in line and "out/demo-full/" in line, line
    for lines, size, refine in ((demo, "--width 160 --height 120", "--max-spp 0"),
                                (full, "--width 240 --height 180", "--max-spp 128")):
        main_renders = [r for r in _commands(lines, "render") if "/eval/" not in r]
        # volpath, fiberpath; damask: fiberpath, prt, btf's fit and table; knit: bysdf, fiberpath
        assert len(main_renders) == 8
        assert all(size in r for r in main_renders)
        assert all(refine in r for r in main_renders if "--max-spp" in r)
        # the main volpath picture: procedural lookups with the fibre cache (issue 21); the evaluation's
        # procedural render: lookups only, against the realized source
        (vol,) = [r for r in main_renders if "--method volpath" in r]
        assert "--source procedural" in vol and "--cache" not in vol
        (ev,) = [r for r in _commands(lines, "render") if "/eval/volpath-procedural" in r]
        assert "--cache 0" in ev
        assert "--exemplar" not in _precompute(lines, "btf")   # the damask's texture holds both satins
    assert "--resolution 32" in _precompute(demo, "svf") and "--paths 100" in _precompute(demo, "iirtf")
    assert "--resolution 64" in _precompute(full, "svf") and "--paths 200" in _precompute(full, "iirtf")
    assert "--resolution 16" in _precompute(full, "btf")
    readme = (ROOT / "README.md").read_text()
    assert "240×180" in readme and "make demo-full" in readme and "160×120" in readme


def test_the_comparisons_precompute_their_own_inputs_at_demo_full_settings():
    """make demo's reduced precomputes never reach make compare: the comparison files name the comparison's own
    precomputes and fits (out/compare/inputs), made with demo-full's arguments; fibres, tables and tilings,
    which take no settings, are the demo's."""
    full = _dry_run("-B", "demo-full")
    refs = _dry_run("-B", "references")
    for kind, out in (("svf", "out/compare/inputs/damask_svf.zarr"), ("iirtf", "out/compare/inputs/damask_iirtf.zarr"),
                      ("btf", "out/compare/inputs/damask_btf_fit.zarr")):
        (cmd,) = [c for c in _commands(refs, "precompute") if f"-o {out} " in c]
        assert cmd.split(f"-o {out} ", 1)[1] == _precompute(full, kind).split(" -o ", 1)[1].split(" ", 1)[1], kind
    fits = [c for c in _commands(refs, "fit-bysdf") if "out/compare/inputs/" in c]
    assert len(fits) == 2
    full_fit = _commands(full, "fit-bysdf")[0].split(".toml ", 2)[-1]
    assert all(c.endswith(full_fit) for c in fits)
    demo_made = ("damask_svf.zarr", "damask_iirtf.zarr", "damask_btf_fit.zarr", "bysdf_fit.toml", "knit_bysdf_fit.toml")
    for name in ("damask", "demo", "demo_delta", "knit"):
        text = (ROOT / "data" / "compare" / f"{name}.toml").read_text()
        assert not [f for f in demo_made if f"out/demo/{f}" in text], name
    assert "params=out/compare/inputs/bysdf_fit.toml" in (ROOT / "data/compare/demo.toml").read_text()


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
