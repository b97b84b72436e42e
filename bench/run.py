"""Run every ``bench/bench_*.py`` (each defines ``run(out_dir) -> dict``) and write the results.

    python bench/run.py --out bench/results [--only fiberpath,volpath]

Writes ``<out>/<name>.json`` per benchmark (name = file name without ``bench_``) and
``<out>/summary.md``: the machine, one table per benchmark, and a side-by-side table of the
throughput numbers the benchmarks report (every key ending in ``paths_per_s``, ``rays_per_s`` or
``rays_per_s_per_core``, e.g. fiberpath's next to volpath's).
Benchmarks hold performance targets; tests never time anything.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LOOMLIGHT_NUMBA_CACHE_ROOT", str(ROOT / ".numba_cache"))
# before numba reads its configuration: stages sets NUMBA_CACHE_DIR to the directory keyed by the kernel
# sources (a benchmark that imports numba first would use __pycache__ beside the sources, where machine
# code compiled from older callees is not invalidated)
import stages  # noqa: E402,F401  (before numba: NUMBA_CACHE_DIR, see above)

# isort: split

COMPARE = ("paths_per_s", "rays_per_s", "rays_per_s_per_core")


def _throughput_keys(r: dict) -> list[str]:
    return [k for k in r if k.endswith(COMPARE) and isinstance(r[k], (int, float))]


def _load(path: Path):
    # imported by its own name from bench/ (numba's cache needs an importable module)
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    return importlib.import_module(path.stem)


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, dict)):
        return json.dumps(v)
    return str(v)


def machine() -> dict:
    import numba

    return {"python": platform.python_version(), "platform": platform.platform(), "cpus": os.cpu_count(),
            "numba_threads": numba.config.NUMBA_NUM_THREADS, "date": time.strftime("%Y-%m-%d %H:%M:%S")}


def write_summary(out: Path, results: dict[str, dict], info: dict) -> Path:
    lines = ["# loomlight benchmarks", "", "Machine: " + ", ".join(f"{k} {v}" for k, v in info.items()), ""]
    rows = [(n, k, r[k]) for n, r in sorted(results.items()) for k in _throughput_keys(r)]
    if rows:
        lines += ["## Throughput side by side", "", "| benchmark | quantity | value |", "|---|---|---|"]
        for n, k, v in rows:
            lines.append(f"| {n} | {k} | {_fmt(v)} |")
        lines.append("")
    for n, r in sorted(results.items()):
        lines += [f"## {n}", "", "| quantity | value |", "|---|---|"]
        for k, v in r.items():
            lines.append(f"| {k} | {_fmt(v)} |")
        lines.append("")
    path = out / "summary.md"
    path.write_text("\n".join(lines))
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "results"))
    ap.add_argument("--only", default="", help="comma-separated benchmark names")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    results = {}
    for p in sorted(out.glob("*.json")):  # keep earlier results of benchmarks not re-run
        try:
            results[p.stem] = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            pass
    failed = 0
    for path in sorted(HERE.glob("bench_*.py")):
        name = path.stem[len("bench_"):]
        if only and name not in only:
            continue
        print(f"[bench] {name} ...", flush=True)
        t0 = time.perf_counter()
        try:
            mod = _load(path)
            res = mod.run(out)
        except Exception:
            traceback.print_exc()
            failed += 1
            continue
        res = {"bench_wall_s": time.perf_counter() - t0, **res}
        (out / f"{name}.json").write_text(json.dumps(res, indent=2, default=float))
        results[name] = res
        print(f"[bench] {name}: " + ", ".join(f"{k}={_fmt(res[k])}" for k in _throughput_keys(res)), flush=True)
    s = write_summary(out, results, machine())
    print(f"[bench] summary: {s}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
