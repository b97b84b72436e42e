"""Scale out (issue 22 item 5): one render and one precompute run in this process and on a 2-worker Dask
LocalCluster on the same machine (the overhead ratio), and a model of the cost at 100 workers from the
measured per-task time and bytes moved.

Render: ``fiberpath`` on the demo's realized fibres, 240 x 180 at 8 spp (no refinement), tiles of 16
(a task per band of 16 rows: 12 tasks). Precompute: ``precompute iirtf`` of the demo damask's exemplar 0
at 3 mean free paths, 200 paths per cell, chunks of 32 cells. Both run once first so every kernel is
compiled (numba's cache) and the workers load it from there; the times are whole commands
(``wall_s``: reading inputs, starting the cluster, the workers' setup, publication), the local one on
2 numba threads, the cluster one on 2 workers x 1 thread. Bytes are those the artifacts and the
scratch film record, not the network's counters.

The model (``model_speedup``): a job of N tasks of t seconds each (one core), b bytes moved per task
(arguments in, chunks out), a serial part s (the driver: inputs, setup, publication) and a per-worker
setup w (starting, loading the kernels and the scene), on P workers with a shared link of B bytes/s:

    T(P) = s + w + ceil(N / P) t + N b / B,   speed-up = (s + N t) / T(P)

with B = 1.25e9 (10 Gbit/s Ethernet). It is reported for the measured jobs and for the same work at
production size (a 3840 x 2160 frame: 135 bands; the paper's full damask IIRTF: the measured cells
times (3 / 1)^3 for cells of one mean free path, 50,000 paths each).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK_BYTES_PER_S = 1.25e9
FILM_CHANNELS = 12


def _ll(*args, env=None) -> float:
    exe = Path(sys.executable).parent / "loomlight"
    cmd = [str(exe) if exe.exists() else "loomlight", *map(str, args)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, env={**os.environ, **(env or {})}, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _summary(path) -> dict:
    return json.loads((Path(path) / "zarr.json").read_text())["attributes"]["summary"]


def model_speedup(n_tasks, t_task, bytes_task, serial_s, worker_setup_s, workers) -> float:
    t_p = serial_s + worker_setup_s + math.ceil(n_tasks / workers) * t_task + n_tasks * bytes_task / LINK_BYTES_PER_S
    return (serial_s + n_tasks * t_task) / t_p


def _inputs(out_dir: Path):
    demo = ROOT / "out/demo"
    fibers, tiling = demo / "fibers.zarr", demo / "damask_tiling.zarr"
    if not (fibers / "zarr.json").exists():
        fibers = out_dir / "fibers.zarr"
        _ll("ingest", ROOT / "data/scenes/demo.toml", "-o", out_dir / "yarns.zarr")
        _ll("realize", out_dir / "yarns.zarr", "-o", fibers)
    if not (tiling / "zarr.json").exists():
        tiling = out_dir / "damask_tiling.zarr"
        _ll("tile", ROOT / "data/tilings/damask.toml", "-o", tiling)
    return fibers, tiling


def run(out_dir) -> dict:
    out_dir = Path(out_dir) / "dask"
    out_dir.mkdir(parents=True, exist_ok=True)
    fibers, tiling = _inputs(out_dir)
    W, H, spp, tile = 240, 180, 8, 16
    render = ["render", ROOT / "data/scenes/demo.toml", "--method", "fiberpath", "--fibers", fibers, "--width", W,
              "--height", H, "--spp", spp, "--max-spp", 0, "--threads", 2]
    iirtf = ["precompute", "iirtf", tiling, "--exemplar", 0, "--order", 4, "--cell-factor", 3, "--paths", 200,
             "--light-sampling", "mis", "--chunk", 32, "--force"]
    cluster = ["--scheduler", "processes", "--workers", 2, "--threads-per-worker", 1]
    _ll(*render, "-o", out_dir / "warm.exr")                       # compile everything once
    _ll(*render, "-o", out_dir / "warm.exr", *cluster)
    r_local = _ll(*render, "-o", out_dir / "local.exr")
    r_dask = _ll(*render, "-o", out_dir / "dask.exr", *cluster)
    same_exr = (out_dir / "local.exr").read_bytes() == (out_dir / "dask.exr").read_bytes()
    rs = _summary(out_dir / "local.zarr")
    bands = math.ceil(H / tile)
    render_task_s = rs["render_time_s"] * rs["threads"] / bands          # one band on one core
    render_bytes = (2 * tile * W * FILM_CHANNELS * 8 + tile * W * 8)      # film band out + read back, counts in
    render_serial = max(r_local - rs["render_time_s"], 0.0)
    worker_setup = max(r_dask - r_local, 0.0)  # what the cluster adds: its start, each worker's setup

    _ll(*iirtf, "-o", out_dir / "warm_iirtf.zarr")
    i_local = _ll(*iirtf, "-o", out_dir / "iirtf_local.zarr")
    i_dask = _ll(*iirtf, "-o", out_dir / "iirtf_dask.zarr", *cluster)
    meta = [json.loads((out_dir / f"iirtf_{w}.zarr" / "zarr.json").read_text())["attributes"]["loomlight"]["arrays"]
            for w in ("local", "dask")]
    same_iirtf = {k: v["sha256"] for k, v in meta[0].items()} == {k: v["sha256"] for k, v in meta[1].items()}
    isum = _summary(out_dir / "iirtf_local.zarr")
    ex = isum["exemplars"][0]
    i_tasks = math.ceil(ex["stored_cells"] / 32)
    J = isum["sh_coefficients"]
    i_task_s = isum["stored_cells"] / isum["cells_per_s"] / i_tasks * 2  # cells_per_s is on 2 threads
    i_bytes = 32 * 3 * J * J * 4 * 2
    i_serial = max(i_local - isum["stored_cells"] / isum["cells_per_s"], 0.0)
    i_setup = max(i_dask - i_local, 0.0)

    res = {
        "render_local_s": r_local, "render_cluster_s": r_dask, "render_overhead_ratio": r_dask / r_local,
        "render_same_bytes": same_exr, "render_tasks": bands, "render_task_s": render_task_s,
        "render_bytes_per_task": render_bytes,
        "iirtf_local_s": i_local, "iirtf_cluster_s": i_dask, "iirtf_overhead_ratio": i_dask / i_local,
        "iirtf_same_bytes": same_iirtf, "iirtf_tasks": i_tasks, "iirtf_task_s": i_task_s,
        "iirtf_bytes_per_task": i_bytes,
    }
    jobs = {
        "render 240x180 @ 8 spp": (bands, render_task_s, render_bytes, render_serial, worker_setup),
        "render 3840x2160 @ 64 spp": (135, render_task_s * (3840 / W) * 64 / spp, 2 * tile * 3840 * FILM_CHANNELS * 8
                                      + tile * 3840 * 8, render_serial, worker_setup),
        "iirtf exemplar 0 (demo)": (i_tasks, i_task_s, i_bytes, i_serial, i_setup),
        "iirtf exemplar 0 (paper: 1 mfp, 50,000 paths)": (i_tasks * 27, i_task_s * 250, i_bytes, i_serial, i_setup),
    }
    res["model"] = {name: {"tasks": n, "task_s": t, "bytes_per_task": b,
                           "speedup_2": model_speedup(n, t, b, s, w, 2),
                           "speedup_100": model_speedup(n, t, b, s, w, 100)}
                    for name, (n, t, b, s, w) in jobs.items()}
    res["targets"] = {"same bytes": same_exr and same_iirtf}
    return res


if __name__ == "__main__":
    print(json.dumps(run(ROOT / "bench/results"), indent=1))
