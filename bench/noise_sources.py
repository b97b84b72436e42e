"""Where the noise of the demo's `fiberpath` picture comes from (issue 15 item 4), and whether stratified
pixel positions would remove it. Prints JSON. Not run by tests or ``bench/run.py``.

    python bench/noise_sources.py [--fibers out/bench_bysdf/fibers.zarr] [--scene data/scenes/demo.toml]
                                  [--size 120x90] [--spp 64] [--ref-spp 1024]

(``make bench`` leaves the demo swatch's fibres in ``out/bench_bysdf/``.)

1. **By light and by depth.** The scene rendered with all its lights, with each light alone, and with
   direct light only (max depth 1), at the same spp. For each, over the cloth's pixels (coverage 1 in the
   full render): the standard error of the pixel mean relative to the full picture's pixel value, and the
   same per sample (x sqrt(spp)), at the median and the 95th percentile. The terms add up to the full
   picture, so the largest relative error names the term that keeps the picture from converging.
2. **Stratified pixel positions.** The same integrator with the camera sample's two pixel dimensions
   drawn at random (loomlight's tile loop) or from a 2D Hammersley set rotated by a random shift per
   pixel (Cranley-Patterson: unbiased), every other dimension as before; per-pixel error of the
   luminance against a ``--ref-spp`` reference (random positions, another seed) over the cloth's
   pixels of 1, two
   seeds each. This is what quasi-Monte Carlo pixel sampling could give where the noise is the pixel's
   footprint (glints across a pixel); it gives little where the noise lies in later path dimensions.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LOOMLIGHT_NUMBA_CACHE_ROOT", str(ROOT / ".numba_cache"))
import stages  # noqa: E402,F401  (NUMBA_CACHE_DIR before numba loads)

# isort: split

import numpy as np  # noqa: E402  (after sys.path and stages set-up)
from numba import njit  # noqa: E402  (after sys.path and stages set-up)

from stages.core.geometry.stack import stack_vector3  # noqa: E402  (after sys.path and stages set-up)
from stages.core.rng import uniform, van_der_corput  # noqa: E402  (after sys.path and stages set-up)
from stages.render.camera import camera_ray_into  # noqa: E402  (after sys.path and stages set-up)
from stages.render.integrator import radiance  # noqa: E402  (after sys.path and stages set-up)

LUMA = np.array([0.2126, 0.7152, 0.0722])


def _render(scene, fibers, W, H, spp, depth):
    from pipeline.renderers import method
    from pipeline.runners.render import RenderRequest, resolve_options

    m = method("fiberpath")
    request = RenderRequest(width=W, height=H, spp=spp, max_depth=depth, fibers=str(fibers))
    return m.run(scene, resolve_options(scene, m, request))


def by_light_and_depth(scene, fibers, W, H, spp) -> dict:
    depth = int(scene.render.get("max_depth", 16))
    cases = [("all lights", scene.lights, depth), ("all lights, direct only (max depth 1)", scene.lights, 1)]
    for i, light in enumerate(scene.lights):
        cases.append((f"light {i} ({light.get('type')}) alone", [light], depth))
        cases.append((f"light {i} ({light.get('type')}) alone, direct only", [light], 1))
    out, full = {}, None
    for name, lights, d in cases:
        r = _render(dataclasses.replace(scene, lights=list(lights)), fibers, W, H, spp, d)
        lum = np.asarray(r.rgb, float) @ LUMA
        if full is None:
            full = lum
            cloth = np.asarray(r.extra["A"], float) > 0.99
        rel = np.sqrt(np.asarray(r.extra["variance"], float)[cloth]) / np.maximum(full[cloth], 1e-12)
        out[name] = {"mean_luminance": float(lum[cloth].mean()),
                     "rel_error_p50": float(np.percentile(rel, 50)), "rel_error_p95": float(np.percentile(rel, 95)),
                     "per_sample_p50": float(np.percentile(rel, 50) * np.sqrt(spp)),
                     "per_sample_p95": float(np.percentile(rel, 95) * np.sqrt(spp))}
    out["cloth_pixels"] = int(cloth.sum())
    return out, cloth


@njit(cache=True, nogil=True, _nrt=False)
def _rows(integ, cam, seed, spp, stratified, row0, row1, out):
    """Pixel means of rows [row0, row1): random or rotated-Hammersley pixel positions."""
    W = out.shape[1]
    o = stack_vector3()
    d = stack_vector3()
    for row in range(row0, row1):
        for col in range(W):
            pix = row * W + col
            sx = uniform(seed + 7, pix, 0)
            sy = uniform(seed + 7, pix, 1)
            r = 0.0
            g = 0.0
            b = 0.0
            for s in range(spp):
                index = pix * spp + s
                if stratified:
                    u = (s + 0.5) / spp + sx
                    v = van_der_corput(s) + sy
                    u -= np.floor(u)
                    v -= np.floor(v)
                else:
                    u = uniform(seed, index, 0)
                    v = uniform(seed, index, 1)
                camera_ray_into(cam, row, col, u, v, o, d)
                ps = radiance(integ, o, d, seed, index)
                r += ps.r
                g += ps.g
                b += ps.b
            out[row, col, 0] = r / spp
            out[row, col, 1] = g / spp
            out[row, col, 2] = b / spp


def stratified_pixels(scene, fibers, W, H, spp, ref_spp, cloth, threads=2) -> dict:
    from concurrent.futures import ThreadPoolExecutor

    from pipeline.renderers import method
    from pipeline.renderers.fiberpath import film_setup
    from pipeline.runners.render import RenderRequest, resolve_options

    request = RenderRequest(width=W, height=H, spp=spp, fibers=str(fibers))
    setup = film_setup(scene, resolve_options(scene, method("fiberpath"), request))

    def image(seed, n, stratified):
        out = np.zeros((H, W, 3))
        bands = [(r, min(H, r + 4)) for r in range(0, H, 4)]
        t0 = time.perf_counter()
        with ThreadPoolExecutor(threads) as ex:
            list(ex.map(lambda b: _rows(setup.integ, setup.cam, seed, n, stratified, b[0], b[1], out), bands))
        return out @ LUMA, time.perf_counter() - t0

    image(0, 1, False)   # compile (or load) apart
    image(0, 1, True)
    ref, ref_s = image(1000, ref_spp, False)
    res = {"reference_spp": ref_spp, "reference_s": ref_s}
    for name, strat in (("random", False), ("stratified", True)):
        rows = []
        for seed in (10, 11):
            img, _ = image(seed, spp, strat)
            e = np.abs(img - ref)[cloth] / ref[cloth]
            rows.append((np.percentile(e, 50), np.percentile(e, 95),
                         np.sqrt(np.mean((img - ref)[cloth] ** 2)) / ref[cloth].mean()))
        p50, p95, rmse = np.mean(rows, axis=0)
        res[name] = {"rel_error_p50": float(p50), "rel_error_p95": float(p95), "rel_rmse": float(rmse)}
    res["stratified_over_random_rmse"] = res["stratified"]["rel_rmse"] / res["random"]["rel_rmse"]
    return res


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fibers", default=str(ROOT / "out" / "bench_bysdf" / "fibers.zarr"))
    ap.add_argument("--scene", default=str(ROOT / "data" / "scenes" / "demo.toml"))
    ap.add_argument("--size", default="120x90")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--ref-spp", type=int, default=1024)
    args = ap.parse_args(argv)
    from pipeline.scene import load_scene

    W, H = (int(x) for x in args.size.split("x"))
    scene = load_scene(args.scene)
    terms, cloth = by_light_and_depth(scene, args.fibers, W, H, args.spp)
    res = {"image": f"{W}x{H} @ {args.spp} spp", "by_light_and_depth": terms,
           "stratified_pixels": stratified_pixels(scene, args.fibers, W, H, args.spp, args.ref_spp, cloth)}
    print(json.dumps(res, indent=2))
    return res


if __name__ == "__main__":
    main()
