"""The precompute of Khungurn et al. 2017 (issue 17 item 6): SVF and IIRTF of the demo damask's two
exemplars at settings near ``make demo-full``'s, as the paper's Table 1 columns per exemplar (fibres,
segments, fibre radius, mean free path, target cell length, SH order, IIRTF size and time, SSDF size,
sum-of-SGs size, visibility time), the throughputs (SVF rays/s and segments/s, IIRTF paths/s and
cells/s) and the cost of the paper's defaults extrapolated from the measured rates (128 x 128 pixels;
cells of one mean free path, 50,000 paths each).

Tiling: ``$LOOMLIGHT_BENCH_TILING`` or ``out/demo/damask_tiling.zarr`` (built from data/tilings/damask.toml
into the results directory when missing). Settings: ``$LOOMLIGHT_BENCH_SVF`` / ``$LOOMLIGHT_BENCH_IIRTF``
(CLI arguments), default SVF 64 x 64 with 48 components (FULL_SVF_ARGS), IIRTF of order 4 at cells of 3 mean
free paths with 500 paths each. Times exclude compilation (reported apart).
"""
from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEMO_SVF = "--resolution 64 --components 48"
DEMO_IIRTF = "--order 4 --cell-factor 3 --paths 500 --light-sampling mis"


def _makefile_args(var: str, default: str) -> str:
    for line in (ROOT / "Makefile").read_text().splitlines():
        if line.startswith(f"{var} ?="):
            return line.split("?=", 1)[1].strip()
    return default


def _ll(*args):
    exe = Path(sys.executable).parent / "loomlight"
    cmd = [str(exe) if exe.exists() else "loomlight", *map(str, args)]
    subprocess.run(cmd, check=True, cwd=ROOT)


def run(out_dir) -> dict:
    from pipeline.artifacts import Artifact

    out_dir = Path(out_dir)
    tiling = Path(os.environ.get("LOOMLIGHT_BENCH_TILING", ROOT / "out/demo/damask_tiling.zarr"))
    if not (tiling / "zarr.json").exists():
        tiling = out_dir / "damask_tiling.zarr"
        _ll("tile", ROOT / "data/tilings/damask.toml", "-o", tiling)
    svf_args = os.environ.get("LOOMLIGHT_BENCH_SVF", _makefile_args("SVF_ARGS", DEMO_SVF))
    iirtf_args = os.environ.get("LOOMLIGHT_BENCH_IIRTF", _makefile_args("IIRTF_ARGS", DEMO_IIRTF))
    work = out_dir / "precompute"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    _ll("precompute", "svf", tiling, "-o", work / "svf.zarr", *shlex.split(svf_args))
    _ll("precompute", "iirtf", tiling, "-o", work / "iirtf.zarr", *shlex.split(iirtf_args))
    t = Artifact(tiling, kind="tiling")
    svf = Artifact(work / "svf.zarr", kind="svf")
    ii = Artifact(work / "iirtf.zarr", kind="iirtf")
    s, i = svf.summary, ii.summary
    res = {"tiling": str(tiling), "svf_args": svf_args, "iirtf_args": iirtf_args,
           "svf_rays_per_s": s["rays_per_s"], "svf_segments_per_s": s["segments_per_s"], "svf_time_s": s["time_s"],
           "svf_compile_s": s["compile_s"], "iirtf_paths_per_s": i["paths_per_s"],
           "iirtf_cells_per_s": i["cells_per_s"], "iirtf_time_s": i["time_s"],
           "iirtf_mean_free_path_s": i["mean_free_path_s"], "iirtf_compile_s": i["compile_s"],
           "precompute_total_s": s["time_s"] + i["time_s"] + i["mean_free_path_s"]}
    O, F = t["ex_offsets"], t["ex_fibers"]
    R = t["ex_radius"]
    paper_svf_rays = 0
    paper_paths = 0
    for se, ie in zip(s["exemplars"], i["exemplars"]):
        k = se["exemplar"]
        g = f"exemplar_{k}/"
        ssdf = sum(svf.group[g + n].nbytes for n in ("ssdf_mean", "ssdf_basis", "ssdf_coeffs"))
        ssg = sum(svf.group[g + n].nbytes for n in ("sg_angle", "sg_weights"))
        vis = svf.group[g + "visibility"].nbytes
        tr = sum(ii.group[g + n].nbytes for n in ("transfer", "transfer_se"))
        p0, p1 = int(O[F[k]]), int(O[F[k + 1]])
        pre = f"ex{k}_"
        res.update({pre + "name": se["name"], pre + "fibers": int(F[k + 1] - F[k]), pre + "segments": se["segments"],
                    pre + "fiber_radius": float(R[p0:p1].mean()), pre + "mean_free_path": ie["mean_free_path"],
                    pre + "target_cell_length": float(i["cell_factor"] * ie["mean_free_path"]),
                    pre + "cells": ie["cells"], pre + "stored_cells": ie["stored_cells"], pre + "sh_order": i["order"],
                    pre + "iirtf_MB": tr / 1e6, pre + "ssdf_MB": ssdf / 1e6, pre + "sum_of_sgs_MB": ssg / 1e6,
                    pre + "visibility_images_MB": vis / 1e6, pre + "pca_rel_error": se["pca_rel_error"],
                    pre + "pca_sign_error": se["pca_sign_error"]})
        paper_svf_rays += se["segments"] * 128 * 128
        # the paper's cells: one mean free path; its stored-cell count is measured by the kernels' cell builder
        from stages.precompute.iirtf import build_cells, exemplar_slabs

        slabs = exemplar_slabs(t["ex_points"], R, O, F)
        cells = build_cells(t["ex_points"], O, F, t["ex_period"], t["ex_nblocks"], t["block_size"], slabs,
                            ie["mean_free_path"])
        base, n = int(cells.ex_cells[k]), int(cells.ex_cells[k + 1] - cells.ex_cells[k])
        paper_paths += 50000 * int((cells.cell_offsets[base + 1:base + n + 1]
                                    - cells.cell_offsets[base:base + n] > 0).sum())
    res["paper_defaults_svf_s_estimate"] = paper_svf_rays / res["svf_rays_per_s"]
    res["paper_defaults_iirtf_s_estimate"] = paper_paths / res["iirtf_paths_per_s"]
    res["target_s"] = 15 * 60
    res["meets_15_min_at_demo_settings"] = res["precompute_total_s"] <= 15 * 60
    return res
