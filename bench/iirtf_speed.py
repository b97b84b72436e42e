"""IIRTF precompute speed on a tiling (default: the demo's damask): the mean free path of every exemplar,
its cells at a few cell factors, paths/s and cells/s measured on a random sample of non-empty cells, and
the projected cost of whole precomputes (cell factor, paths per cell, SH order). Prints JSON.

    python bench/iirtf_speed.py [--tiling out/demo/damask_tiling.zarr] [--preset cotton] [--orders 2,4,8]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LOOMLIGHT_NUMBA_CACHE_ROOT", str(ROOT / ".numba_cache"))

import numba  # noqa: E402  (after sys.path and cache env set-up)
import numpy as np  # noqa: E402  (after sys.path and cache env set-up)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tiling", default=str(ROOT / "out/demo/damask_tiling.zarr"))
    ap.add_argument("--preset", default="cotton")
    ap.add_argument("--sample", type=int, default=3, help="chunks timed per exemplar")
    ap.add_argument("--chunk", type=int, default=8, help="non-empty cells per timed chunk")
    ap.add_argument("--paths", type=int, default=1000, help="paths per timed cell")
    ap.add_argument("--orders", default="2,4,8")
    ap.add_argument("--mfp-paths", type=int, default=4000)
    ap.add_argument("--factors", default="1,1.5,2,3,4")
    ap.add_argument("--light-sampling", default="uniform,mis")
    a = ap.parse_args(argv)

    from pipeline.bcsdf_presets import load_bcsdf_preset
    from pipeline.runners.tile import load_tiling
    from stages.core.shading.material import pack_material_bcsdf
    from stages.precompute.iirtf import build_cells, exemplar_slabs, iirtf_chunk, mean_free_path

    sc, art = load_tiling(a.tiling)
    P, R, O, Fb = (np.asarray(art[n]) for n in ("ex_points", "ex_radius", "ex_offsets", "ex_fibers"))
    period, nblocks, bs = np.asarray(art["ex_period"]), np.asarray(art["ex_nblocks"]), np.asarray(art["block_size"])
    K = len(Fb) - 1
    slabs = exemplar_slabs(P, R, O, Fb)
    mats = pack_material_bcsdf(load_bcsdf_preset(a.preset))[None]
    mof = np.zeros(len(O) - 1, np.int32)
    out = {"tiling": a.tiling, "preset": a.preset, "threads": numba.get_num_threads(),
           "segments": int(len(P) - (len(O) - 1)), "exemplars": []}
    # warm up the kernels (compilation is not throughput)
    mean_free_path(sc, 0, *slabs[0], period[0], mof, mats, n_paths=4, max_depth=2)
    cells1 = build_cells(P, O, Fb, period, nblocks, bs, slabs, 0.1)
    for L in (int(x) for x in a.orders.split(",")):
        for ls in a.light_sampling.split(","):
            iirtf_chunk(sc, cells1, 0, 1, mof, mats, order=L, n_paths=2, light_sampling=ls)

    ells = []
    for k in range(K):
        t = time.perf_counter()
        ell, se, nseg = mean_free_path(sc, k, *slabs[k], period[k], mof, mats, n_paths=a.mfp_paths)
        dt = time.perf_counter() - t
        ells.append(ell)
        out["exemplars"].append({"k": k, "slab": slabs[k].tolist(), "mean_free_path": ell, "mean_free_path_se": se,
                                 "free_path_segments": nseg, "mean_free_path_s": dt})
    ells = np.array(ells)

    # throughput at factor 1 on contiguous chunks of cells (as the runner splits them) starting at random
    # non-empty cells, so the cells' depths spread over the slab; threads take cells one at a time
    cells = build_cells(P, O, Fb, period, nblocks, bs, slabs, ells)
    cnt = np.diff(cells.cell_offsets)
    rng = np.random.default_rng(0)
    timing = {}
    for L in (int(x) for x in a.orders.split(",")):
        for ls in a.light_sampling.split(","):
            secs, cpu, paths, rays, rel = 0.0, 0.0, 0, 0, []
            for k in range(K):
                ids = np.flatnonzero(cnt[cells.ex_cells[k]:cells.ex_cells[k + 1]] > 0) + cells.ex_cells[k]
                for start in rng.choice(len(ids) - a.chunk, size=a.sample, replace=False):
                    c0, c1 = int(ids[start]), int(ids[start + a.chunk - 1]) + 1
                    t, tc = time.perf_counter(), time.process_time()
                    r = iirtf_chunk(sc, cells, c0, c1, mof, mats, order=L, n_paths=a.paths, light_sampling=ls)
                    secs += time.perf_counter() - t
                    cpu += time.process_time() - tc
                    paths += a.paths * int((cnt[c0:c1] > 0).sum())
                    rays += int(r.rays.sum())
                    full = cnt[c0:c1] > 0
                    rel.extend((r.se[full, :, 0, 0] / np.maximum(r.a[full, :, 0, 0], 1e-300)).mean(axis=1))
            timing[f"L{L}_{ls}"] = {
                "paths_per_s": paths / secs, "rays_per_s": rays / secs, "rays_per_path": rays / paths,
                "paths_per_cpu_s": paths / cpu, "cells_per_s_at_1000_paths": paths / secs / 1000.0,
                "median_relative_se_a00": float(np.median(rel)), "paths_per_cell_timed": a.paths}
    out["timing"] = timing

    # whole precomputes: cells at each factor, projected seconds for a few paths-per-cell
    proj = []
    for f in (float(x) for x in a.factors.split(",")):
        cf = build_cells(P, O, Fb, period, nblocks, bs, slabs, f * ells)
        ne = int((np.diff(cf.cell_offsets) > 0).sum())
        row = {"cell_factor": f, "cells": int(cf.ex_cells[-1]), "non_empty_cells": ne,
               "block_cells": cf.block_cells.tolist(), "cell_size": cf.cell_size.tolist(), "seconds": {},
               "seconds_2_cores": {}}
        for key, tm in timing.items():
            for n in (250, 500, 1000, 2000, 50000):
                # wall seconds at the measured rate, and on 2 free cores (twice the per-CPU-second rate)
                row["seconds"][f"{key}_n{n}"] = ne * n / tm["paths_per_s"]
                row["seconds_2_cores"][f"{key}_n{n}"] = ne * n / (2.0 * tm["paths_per_cpu_s"])
        proj.append(row)
    out["projections"] = proj
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=1))
