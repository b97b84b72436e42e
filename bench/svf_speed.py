"""SVF precompute speed on a tiling (default: the demo's damask): visibility rays/s, SSDF, PCA, projection
and sum-of-SG times measured on an evenly spaced sample of one exemplar's segments, extrapolated to
every segment of every exemplar. Prints JSON. Not run by tests or ``bench/run.py``.

    python bench/svf_speed.py [--tiling out/demo/damask_tiling.zarr] [--exemplar 0] [--sample 2000]
                              [--res 128,96,64] [--components 48]
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


def _timed(f, *args, **kw):
    t = time.perf_counter()
    r = f(*args, **kw)
    return r, time.perf_counter() - t


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tiling", default=str(ROOT / "out/demo/damask_tiling.zarr"))
    ap.add_argument("--exemplar", type=int, default=0)
    ap.add_argument("--sample", type=int, default=2000)
    ap.add_argument("--res", default="128,96,64")
    ap.add_argument("--components", type=int, default=48)
    ap.add_argument("--sg", type=int, default=48)
    ap.add_argument("--power-iters", type=int, default=2)
    ap.add_argument("--stream", action="store_true", help="also time the PCA streamed in chunks of 1024")
    a = ap.parse_args(argv)

    from pipeline.runners.tile import load_tiling
    from stages.precompute import svf
    from stages.precompute.periodic import periodic_scene

    sc, art = load_tiling(a.tiling)
    arrays = [np.asarray(art[n]) for n in ("ex_points", "ex_radius", "ex_offsets", "ex_fibers", "ex_period")]
    K = len(arrays[3]) - 1
    total = sum(len(svf.exemplar_segments(*arrays, k).ids) for k in range(K))
    k = a.exemplar
    seg = svf.exemplar_segments(*arrays, k)
    psc = periodic_scene(sc, k)
    S = len(seg.ids)
    idx = np.linspace(0, S - 1, min(a.sample, S)).astype(np.int64)
    n = len(idx)
    out = {"tiling": a.tiling, "exemplar": k, "threads": numba.get_num_threads(), "exemplars": K,
           "segments_exemplar": S, "segments_total": total, "sample": n, "components": a.components,
           "sg": a.sg, "power_iters": a.power_iters, "resolutions": {}}
    # compile outside the timings
    p0 = svf.visibility_images(psc, k, seg.z_lo, seg.z_hi, seg.mids[:4], seg.fibre[:4], 8, 8, capsules=seg.capsules[:4])
    svf.ssdf_images(p0, 8, 8)
    pc = svf.ssdf_pca(p0, 8, 8, 2, hold=True)
    svf.ssdf_project(p0, 8, 8, pc.mean, pc.basis)
    svf.sg_fit(p0, seg.ids[:4], 8, 8, a.sg)

    for R in (int(x) for x in a.res.split(",")):
        D = R * R
        wall0, cpu0 = time.perf_counter(), time.process_time()
        packed, t_vis = _timed(svf.visibility_images, psc, k, seg.z_lo, seg.z_hi, seg.mids[idx], seg.fibre[idx], R, R,
                                capsules=seg.capsules[idx])
        img = svf.unpack_images(packed, R, R)
        vis_frac = img.mean(axis=(1, 2))
        _, t_ssdf = _timed(svf.ssdf_images, packed, R, R)
        pca, t_pca = _timed(svf.ssdf_pca, packed, R, R, a.components, power_iters=a.power_iters, hold=True)
        (_, parts), t_proj = _timed(svf.ssdf_project, packed, R, R, pca.mean, pca.basis)
        _, t_sg = _timed(svf.sg_fit, packed, seg.ids[idx], R, R, a.sg)
        row = {
            "rays_per_s": n * D / t_vis,
            "visibility_segments_per_s": n / t_vis,
            "ssdf_ms_per_segment": 1e3 * t_ssdf / n,
            "pca_s_sample": t_pca,
            "projection_ms_per_segment": 1e3 * t_proj / n,
            "sg_ms_per_segment": 1e3 * t_sg / n,
            "visible_fraction": float(img.mean()),
            "segments_all_occluded": float((vis_frac == 0).mean()),
            "segments_upper_hemisphere_half_visible": float((img[:, :R // 2].mean(axis=(1, 2)) > 0.5).mean()),
            "pca_error": svf.pca_error_report(parts),
            "memory_hold_bytes_exemplar": svf.svf_memory_estimate(S, R, R, a.components, hold=True),
            "memory_stream_bytes_exemplar": svf.svf_memory_estimate(S, R, R, a.components, hold=False),
        }
        # CPU seconds per wall second of this resolution's timings: below the thread count when other
        # processes share the cores (the timings are then pessimistic)
        row["effective_cores"] = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
        if a.stream:
            _, row["pca_stream_s_sample"] = _timed(svf.ssdf_pca, packed, R, R, a.components,
                                                   power_iters=a.power_iters, hold=False)
        # whole precompute: per-segment work scales with all segments, the PCA with each exemplar's
        per_seg = t_vis / n + t_proj / n + t_sg / n
        row["projected_s"] = {
            "visibility": total * t_vis / n,
            "pca_hold": t_pca * total / n,
            "projection": total * t_proj / n,
            "sg": total * t_sg / n,
            "all": total * per_seg + t_pca * total / n,
        }
        out["resolutions"][f"{R}x{R}"] = row
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=1))
