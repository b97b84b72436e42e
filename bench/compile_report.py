"""The compile report: what numba compiles on a cold cache, for whom, and how long it takes.

    python bench/compile_report.py [--demo demo|full|none] [--tests heavy|all|none|FILE ...]
                                   [--out bench/results/compile.json]

(``make compile-report``.) Runs ``make demo``'s commands (``--demo demo``, the default; ``full`` runs
``make demo-full``'s, the same commands at larger sizes) and then the test suite's heaviest files
(``--tests heavy``, the default; ``all`` is ``make test``'s whole suite), each on an empty numba cache of
its own in a scratch directory, with ``LOOMLIGHT_COMPILE_LOG`` set: every compilation of every process
appends a line to a log (``pipeline/compilation.py``: the kernel, the signature it was typed with, its
seconds with and without the kernels compiled inside it, and who asked). Nothing of the checkout's own
cache or ``out/`` is touched.

Writes ``bench/results/compile.json`` (``loomlight docs --only measurements`` puts it on the measurements
page): per part (demo, tests) the compile time summed over processes (core-seconds: every process compiles on
one core) and the part's wall time; per kernel its self seconds (without the kernels it compiled), its
signatures with the seconds of each, how many times each was compiled per part (more than once: two processes
of the part compiled it, each paying), and who asked. Kernels typed more than one way come first, then kernels
compiled more than once with the same signature, then the rest by seconds.
Timings are the machine's: run it alone (it uses both cores for the demo's ``-j2``).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

# the test files that compile the most (make test on a cold cache; the procedural lookups, the volume
# integrators, fiberpath's scene classes, the BTF tile loop and the PRT)
HEAVY_TESTS = (
    "tests/procedural/test_tables_lookup.py",
    "tests/render/test_volpath.py",
    "tests/render/test_realized_medium.py",
    "tests/render/test_fiberpath.py",
    "tests/render/test_prt.py",
    "tests/render/test_bysdf_render.py",
    "tests/precompute/test_btf_acquire.py",
    "tests/hostile/test_hostile.py",
)


def _run_part(name: str, cmd: list[str], work: Path, extra_env: dict | None = None) -> dict:
    """Run ``cmd`` on an empty cache with the compile log on; return the part's records and wall time."""
    cache = work / f"{name}-cache"
    log = work / f"{name}-compile.jsonl"
    shutil.rmtree(cache, ignore_errors=True)
    log.unlink(missing_ok=True)
    env = dict(os.environ, LOOMLIGHT_NUMBA_CACHE_ROOT=str(cache), LOOMLIGHT_COMPILE_LOG=str(log),
               LOOMLIGHT_PROGRESS="0", **(extra_env or {}))
    env.pop("NUMBA_CACHE_DIR", None)
    if Path(cmd[0]).name == "make":   # the Makefile sets the cache root; a command-line variable overrides it
        cmd = [*cmd, f"LOOMLIGHT_NUMBA_CACHE_ROOT={cache}"]
    print(f"compile report: {name}: {' '.join(cmd)}", flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"compile report: {name} failed (exit {proc.returncode}): {' '.join(cmd)}")
    records = [json.loads(ln) for ln in log.read_text().splitlines() if ln.strip()] if log.is_file() else []
    print(f"compile report: {name}: {len(records)} compilations, wall {wall:.0f} s", flush=True)
    return {"records": records, "wall_s": wall}


def summarize(parts: dict[str, dict]) -> dict:
    """The report of ``parts`` ({name: {"records", "wall_s"}}): totals per part and the kernel table."""
    totals = {}
    for name, part in parts.items():
        recs = part["records"]
        totals[name] = {
            "compile_core_s": round(sum(r["self_s"] for r in recs), 1),
            "wall_s": round(part["wall_s"], 1),
            "compilations": len(recs),
            "processes": len({r["pid"] for r in recs}),
            "kernels": len({r["kernel"] for r in recs}),
        }
    by_kernel: dict[str, dict] = defaultdict(lambda: {"self_s": 0.0, "signatures": defaultdict(
        lambda: {"self_s": 0.0, "compiled": defaultdict(int), "asked_by": set()})})
    for name, part in parts.items():
        for r in part["records"]:
            k = by_kernel[r["kernel"]]
            k["self_s"] += r["self_s"]
            s = k["signatures"][r["signature"]]
            s["self_s"] += r["self_s"]
            s["compiled"][name] += 1   # per part: each part has a cache of its own, so one compile per part is due
            who = f"kernel {r['parent']}" if r.get("parent") else r.get("caller") or "?"
            s["asked_by"].add(f"{name}: {r['context']}: {who}")
    kernels = []
    for key, k in by_kernel.items():
        sigs = [{"signature": sig, "self_s": round(s["self_s"], 2), "compiled": dict(s["compiled"]),
                 "asked_by": sorted(s["asked_by"])} for sig, s in k["signatures"].items()]
        sigs.sort(key=lambda s: -s["self_s"])
        kernels.append({"kernel": key, "self_s": round(k["self_s"], 2), "signatures": len(sigs),
                        "recompiled": sum(n - 1 for s in sigs for n in s["compiled"].values()), "by_signature": sigs})
    # typed two ways first, then compiled twice with one signature, then by time
    kernels.sort(key=lambda k: (k["signatures"] < 2, k["recompiled"] < 1, -k["self_s"]))
    return {"totals": totals, "kernels": kernels}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--demo", choices=("demo", "full", "none"), default="demo")
    ap.add_argument("--tests", nargs="*", default=["heavy"],
                    help="heavy (the default), all (make test's suite), none, or test files")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "compile.json")
    ap.add_argument("--keep", type=Path, default=None, help="scratch directory to keep (default: a temporary one)")
    a = ap.parse_args(argv)
    work = a.keep or Path(tempfile.mkdtemp(prefix="loomlight-compile-"))
    work.mkdir(parents=True, exist_ok=True)
    python = str(Path(sys.executable))
    parts: dict[str, dict] = {}
    try:
        if a.demo != "none":
            target = "demo" if a.demo == "demo" else "demo-full"
            out = work / "demo-out"
            shutil.rmtree(out, ignore_errors=True)
            var = "OUT" if a.demo == "demo" else "FULL_OUT"
            parts["demo"] = _run_part("demo", ["make", "--no-print-directory", target, f"{var}={out}"], work)
        tests = a.tests
        if tests and tests != ["none"]:
            if tests == ["heavy"]:
                files = list(HEAVY_TESTS)
            elif tests == ["all"]:
                files = []
            else:
                files = tests
            cmd = [python, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "2", "--dist", "loadfile",
                   "-m", "not slow", *files]
            parts["tests"] = _run_part("tests", cmd, work)
    finally:
        if a.keep is None:
            shutil.rmtree(work, ignore_errors=True)
    report = summarize(parts)
    report["machine"] = {"python": platform.python_version(), "cpus": os.cpu_count(),
                         "date": time.strftime("%Y-%m-%d %H:%M:%S"), "demo": a.demo,
                         "tests": a.tests}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=1))
    for name, t in report["totals"].items():
        print(f"{name}: {t['compile_core_s'] / 60:.2f} core-minutes of compilation in {t['processes']} processes, "
              f"{t['kernels']} kernels, wall {t['wall_s']:.0f} s")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
