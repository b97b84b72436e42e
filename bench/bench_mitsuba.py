"""fiberpath against Mitsuba 3 on the same explicit fibres: time, rays/s and image means (issue 24).

Three cases, all Lambertian capsule chains (albedo 0.75) under a constant environment (radiance 1),
no ground, 2 threads:

- ``small``: a 4 x 4 plain weave of cotton1 yarns (the agreement swatch's fabric, ~0.5 M capsule
  segments), 96 x 96 @ 256 spp, max depth 16 (the measurement of issue 24);
- ``thin``: the same fibres at a tenth of their radius, 96 x 96 @ 128 spp (a control with fewer overlaps);
- ``demo``: the realized demo swatch (``out/demo/fibers.zarr`` when ``make demo`` wrote it, else
  realized here from ``data/scenes/demo.toml``; ~1.5 M capsule segments), 96 x 72 @ 256 spp.

fiberpath renders each case twice: on Embree 4 (``--set accel=embree``, its default:
``stages.core.geometry.embree``) and on loomlight's own 4-wide BVH (``--set accel=bvh``); the ratio is
Mitsuba's time over fiberpath's on Embree (``bvh_speed_ratio`` on the BVH, ``embree_over_bvh`` the
speed-up), and ``embree_bvh_diff_in_standard_errors`` says whether the two fiberpath images agree.

Ray offsets: a Lambertian vertex's rays start off the surface along its normal. fiberpath's offset is
1e-3 of the fibre radius plus 1e-7 of the scene's size; Mitsuba's is (1 + max |p_i|) x 1500 x 2^-24 at
the hit p (its RayEpsilon), 1.25e-4 here: 13 % of a cotton fibre's radius (9.8e-4), so on realized
fibres, which touch and overlap, its rays start past whatever lies that close to the surface and
more of them escape.
That alone made Mitsuba's image 0.3 % brighter (6-9 standard errors); with Mitsuba's offset
fiberpath's mean is Mitsuba's within noise (0.52341 against 0.52346 on ``small``, Embree and BVH alike).
So the bench gives fiberpath Mitsuba's offset (``embree_kernels.mitsuba_offset``) for both its renders: the same
scene, the same rays, and means that must agree (``means_agree``) or the timing means nothing.

Both renderers get the same fibres: realized by ``loomlight realize`` and written for Mitsuba by
``loomlight export`` (curve text, loaded as ``linearcurve``: capsule chains, the shape fiberpath
traces), the same camera (``perspective``, horizontal fov, ``box`` filter, ``independent`` sampler),
the same albedo, light, spp and thread count (``drjit.set_thread_count``). Depth: fiberpath's
``max_depth`` counts scattering events, Mitsuba's ``max_depth`` counts path segments, so Mitsuba
gets one more (17 for 16; the same for Russian roulette: fiberpath ``rr_depth`` 4, Mitsuba 5; both
use survival min(0.95, max throughput channel)). Timings are of warm runs (each renderer compiles
first: numba loads or JITs its kernels, Dr.Jit traces and compiles its megakernel), ``ROUNDS`` of them
taken in turn (fiberpath on Embree, on the BVH, Mitsuba; again; five, since three-round medians swung
by ±0.05 between runs): the machine's speed drifts by ±10 % from one minute to the next, Mitsuba's
with it, so a ratio is only worth the median over rounds of renders made side by side (``speed_ratio``, its
spread in ``speed_ratio_range``). Builds are timed separately (fiberpath's Embree scene, and its SAH build and
4-wide collapse, from arrays in memory; Mitsuba's ``load_dict``: reading the curve text, Embree's scene build
and scene setup). Mitsuba's rays/s is estimated from fiberpath's ray count (a lower bound: Mitsuba also traces
the shadow rays of light samples below the surface, which fiberpath skips). ``means_agree``: |difference| < 4
standard errors per channel (Mitsuba reports no variance; one image's error is taken equal to fiberpath's, and
its mean is over the rounds' seeds). ``make bench`` also writes the README's table of the run
(``comparison_table``) to ``bench/results/mitsuba_table.md``.

The kernels alone (``kernel_case``, ``bench/embree_kernels.py``): fiberpath's Embree 4.4 (``embreex``)
and the Embree 3.13.4 inside Mitsuba's wheel trace the same curves and the same camera, bounce and
shadow rays of the ``small`` and ``demo`` cases, one ray per call on one thread (a second table).
Three quarters of a fiberpath render is Embree's, so this ratio is what fiberpath's own code has to
make up against Mitsuba's.

Mitsuba 3 is an optional, bench-only dependency (``pip install mitsuba``; its ``llvm`` variants need
LLVM >= 16, e.g. Debian's ``libllvm19``, found through ``DRJIT_LIBLLVM_PATH`` or the usual library
paths). Without it the benchmark reports ``skipped`` and the reason.
"""
from __future__ import annotations

import glob
import math
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
THREADS = 2
ROUNDS = 5   # interleaved renders per renderer and case (the machine's speed drifts by ±10 % between runs)
ALBEDO = 0.75
ENV = 1.0

SMALL = """
[scene]
name = "mitsuba-bench-small"
seed = 5

[fabric]
source = "generator"

[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 4
picks = 4
spacing = 0.1
yarn_radius = 0.045
crimp = 1.0
samples_per_cell = 4

[yarns.default]
preset = "cotton1"
radius = 0.045

[camera]
origin = [0.16, -0.28, 0.26]
target = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40.0
"""

CASES = {
    # name: (width, height, spp, max_depth, fibre radius scale)
    "small": (96, 96, 256, 16, 1.0),
    "demo": (96, 72, 256, 16, 1.0),
    # control: the small swatch's fibres at a tenth of their radius, so no fibre overlaps another
    "thin": (96, 96, 128, 16, 0.1),
}


def _llvm_16_or_newer() -> str | None:
    """Path of a shared LLVM >= 16 library (Dr.Jit's llvm backend crashes on 15 here), or None."""
    import re

    found = []
    for cand in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
        m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(cand))
        if m and int(m.group(1)) >= 16:
            found.append((int(m.group(1)), cand))
    return max(found)[1] if found else None


def _mitsuba():
    """(mitsuba, drjit) with the llvm_ad_rgb variant, or raise ImportError / RuntimeError with the reason."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        lib = _llvm_16_or_newer()
        if lib is None:
            raise RuntimeError("no LLVM >= 16 shared library found (e.g. Debian's libllvm19); "
                               "set DRJIT_LIBLLVM_PATH")
        os.environ["DRJIT_LIBLLVM_PATH"] = lib
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    return mi, dr


def _realize(scene_text: str | None, scene_path: Path | None, work: Path) -> Path:
    from pipeline.cli import main

    if scene_path is None:
        scene_path = work / "scene.toml"
        scene_path.write_text(scene_text)
    yarns, fibers = work / "yarns.zarr", work / "fibers.zarr"
    for args in (("ingest", scene_path, "-o", yarns), ("realize", yarns, "-o", fibers)):
        if main([str(a) for a in args]) != 0:
            raise RuntimeError(f"loomlight {args[0]} failed on {scene_path}")
    return fibers


def _export(fibers: Path, work: Path) -> Path:
    from pipeline.cli import main

    txt = work / "fibers.txt"
    if main(["export", str(fibers), "-o", str(txt)]) != 0:
        raise RuntimeError(f"loomlight export failed on {fibers}")
    return txt


class FiberpathRenderer:
    """fiberpath on one case's fibres, built once (``build_s``: the Embree scene, or the SAH BVH and its
    4-wide collapse, from arrays in memory) and compiled; ``render()`` renders the image anew (a fresh
    film) and returns its seconds, the last image's statistics in ``stats``."""

    def __init__(self, fibers: Path, camera: dict, W, H, spp, max_depth, rr_depth=4, radius_scale=1.0,
                 accel="embree", eps=None):
        import numba
        from embree_kernels import mitsuba_offset

        from pipeline.render_setup import load_fibers, pack_lights
        from pipeline.scene import camera_array
        from stages.core.geometry.bvh import build_fiber_bvh
        from stages.core.geometry.embree import EmbreeScene
        from stages.core.shading.material import pack_material_lambert
        from stages.render.film import new_film, tile_grid
        from stages.render.integrators.fiberpath import FiberpathIntegrator
        from stages.render.meshes import no_meshes
        from stages.render.tiles import render_tiles

        numba.set_num_threads(THREADS)
        f = load_fibers(fibers)
        radius = f.point_radius * radius_scale
        self.keep = None
        if accel == "embree":
            EmbreeScene(f.points[:64], np.array([0, 64]), radius[:64]).close()  # load the library and kernels
            t = time.perf_counter()
            self.keep = EmbreeScene(f.points, f.fiber_offsets, radius, THREADS)
            bvh = self.keep.fibers
        else:
            build_fiber_bvh(f.points[:64], np.array([0, 64]), radius[:64])  # compile / load the builder
            t = time.perf_counter()
            bvh, _ = build_fiber_bvh(f.points, f.fiber_offsets, radius)
        self.build_s = time.perf_counter() - t
        self.segments = int(len(bvh.seg_a))
        self.cam = camera_array(camera, W, H)
        lights = pack_lights([{"type": "constant", "radiance": ENV}])
        mats = np.stack([pack_material_lambert(np.full(3, ALBEDO))])
        mof = np.zeros(len(f.fiber_offsets) - 1, np.int32)
        extent = float(np.linalg.norm(f.points.max(0) - f.points.min(0)))
        self.integ = FiberpathIntegrator(bvh, mof, mats, pack_material_lambert(np.zeros(3)), lights.table(),
                                         np.zeros(4), False, no_meshes(), max_depth, rr_depth, 1 << 40,
                                         1e-7 * extent if eps is None else
                                         mitsuba_offset(f.points) if eps == "mitsuba" else eps)
        self.tiles = tile_grid(W, H, 16)
        self.W, self.H, self.spp = W, H, spp
        render_tiles(self.integ, self.cam, 1, 1, 0, 1, self.tiles[:1], new_film(W, H), THREADS)  # compile / load
        self.stats = None

    def render(self) -> float:
        from stages.render.film import F_RAYS, new_film
        from stages.render.tiles import render_tiles

        W, H, spp = self.W, self.H, self.spp
        film = new_film(W, H)
        t = time.perf_counter()
        render_tiles(self.integ, self.cam, 1, spp, 0, spp, self.tiles, film, THREADS)
        render_s = time.perf_counter() - t
        rgb = film[..., :3] / spp
        var = (film[..., 3:6] / spp - rgb ** 2) / max(spp - 1, 1)
        self.stats = {"rays": float(film[..., F_RAYS].sum()), "mean": rgb.reshape(-1, 3).mean(0),
                      "se": np.sqrt(var.reshape(-1, 3).sum(0)) / (W * H)}
        return render_s

    def close(self):
        if self.keep is not None:
            self.keep.close()
            self.keep = None


class MitsubaRenderer:
    """Mitsuba 3 on one case's curve text, loaded once (``build_s``: reading the text, Embree's build and
    scene setup) and warmed up (Dr.Jit traces and compiles its megakernel); ``render()`` renders with the
    next seed and returns its seconds; ``stats`` holds the mean of its images."""

    def __init__(self, txt: Path, camera: dict, W, H, spp, max_depth, rr_depth=5):
        mi, dr = _mitsuba()
        dr.set_thread_count(THREADS)
        T = mi.ScalarTransform4f
        scene_dict = {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": max_depth + 1, "rr_depth": rr_depth},
            "sensor": {
                "type": "perspective", "fov": float(camera["fov"]), "fov_axis": "x",
                "to_world": T().look_at(origin=list(map(float, camera["origin"])),
                                        target=list(map(float, camera["target"])), up=list(map(float, camera["up"]))),
                "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                "sampler": {"type": "independent", "sample_count": spp},
            },
            "env": {"type": "constant", "radiance": {"type": "rgb", "value": [ENV] * 3}},
            "fibres": {"type": "linearcurve", "filename": str(txt),
                       "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [ALBEDO] * 3}}},
        }
        t = time.perf_counter()
        self.scene = mi.load_dict(scene_dict)
        self.build_s = time.perf_counter() - t
        self.mi, self.spp, self.seed = mi, spp, 0
        np.asarray(mi.render(self.scene, spp=spp, seed=0))  # warm-up: traces and compiles the kernel
        self.means = []

    def render(self) -> float:
        self.seed += 1
        t = time.perf_counter()
        img = np.array(self.mi.render(self.scene, spp=self.spp, seed=self.seed))
        render_s = time.perf_counter() - t
        self.means.append(img.reshape(-1, 3).mean(0))
        return render_s

    @property
    def stats(self):
        """The mean of the images rendered so far (each round's seed is new), and how many."""
        return {"mean": np.mean(self.means, axis=0), "images": len(self.means)}

    def close(self):
        self.scene = None


def _export_scaled(fibers: Path, work: Path, scale: float) -> Path:
    """The fibres as Mitsuba curve text (what ``loomlight export`` writes) with radii times ``scale``."""
    from pipeline.io.mitsuba_txt import write_mitsuba_txt
    from pipeline.render_setup import load_fibers

    f = load_fibers(fibers)
    txt = work / f"fibers_r{scale:g}.txt"
    write_mitsuba_txt(txt, f.points, f.point_radius * scale, f.fiber_offsets)
    return txt


def run_case(name, fibers: Path, txt: Path, camera: dict) -> dict:
    """The three renderers on one case, built once each, then ``ROUNDS`` rounds of one render each in turn
    (so a slow spell of the machine falls on all three alike); times are per-round medians and the
    ratios the medians of the rounds' ratios, with their range across rounds."""
    W, H, spp, depth, scale = CASES[name]
    fp = FiberpathRenderer(fibers, camera, W, H, spp, depth, radius_scale=scale, eps="mitsuba")
    fb = FiberpathRenderer(fibers, camera, W, H, spp, depth, radius_scale=scale, accel="bvh", eps="mitsuba")
    mi = MitsubaRenderer(txt, camera, W, H, spp, depth)
    try:
        times = np.array([[fp.render(), fb.render(), mi.render()] for _ in range(ROUNDS)])
    finally:
        for r in (fp, fb, mi):
            r.close()
    t_fp, t_fb, t_mi = np.median(times, axis=0)
    ratio = times[:, 2] / times[:, 0]
    bvh_ratio = times[:, 2] / times[:, 1]
    f, b, m = fp.stats, fb.stats, mi.stats
    diff = np.abs(f["mean"] - m["mean"])
    # Mitsuba reports no variance: one of its images is taken to have fiberpath's standard error, and
    # its mean over the rounds' seeds 1 / sqrt(rounds) of it (fiberpath's rounds repeat its one seed)
    se = f["se"] * math.sqrt(1.0 + 1.0 / m["images"])
    tol = 4.0 * se
    p = f"{name}_"
    return {
        p + "image": f"{W}x{H} @ {spp} spp, max depth {depth}" + (f", fibre radii x {scale:g}" if scale != 1.0 else ""),
        p + "segments": fp.segments, p + "rounds": ROUNDS,
        p + "fiberpath_render_s": float(t_fp), p + "mitsuba_render_s": float(t_mi),
        p + "speed_ratio": float(np.median(ratio)),
        p + "speed_ratio_range": [round(float(ratio.min()), 3), round(float(ratio.max()), 3)],
        p + "fiberpath_rays_per_s": f["rays"] / t_fp,
        p + "mitsuba_rays_per_s_estimated": f["rays"] / t_mi,
        p + "fiberpath_build_s": fp.build_s, p + "mitsuba_load_s": mi.build_s,
        p + "build_ratio": mi.build_s / fp.build_s,
        p + "fiberpath_mean": [round(float(v), 5) for v in f["mean"]],
        p + "mitsuba_mean": [round(float(v), 5) for v in m["mean"]],
        p + "mean_rel_diff": float(np.max(diff / np.maximum(m["mean"], 1e-12))),
        p + "mean_diff_in_standard_errors": float(np.max(diff / np.maximum(se, 1e-300))),
        p + "means_agree": bool(np.all(diff < tol)),
        # loomlight's own BVH (--set accel=bvh) on the same image
        p + "fiberpath_bvh_render_s": float(t_fb), p + "bvh_speed_ratio": float(np.median(bvh_ratio)),
        p + "embree_over_bvh": float(np.median(times[:, 1] / times[:, 0])),
        p + "fiberpath_bvh_build_s": fb.build_s,
        p + "fiberpath_bvh_mean": [round(float(v), 5) for v in b["mean"]],
        p + "embree_bvh_diff_in_standard_errors": float(np.max(np.abs(f["mean"] - b["mean"])
                                                               / np.maximum(math.sqrt(2.0) * f["se"], 1e-300))),
    }


def kernel_case(name, fibers: Path, camera: dict) -> dict:
    """The two ray-tracing kernels alone on one case's rays (``embree_kernels``: Embree 4.4 under
    fiberpath, Embree 3.13.4 under Mitsuba), or the reason they could not be compared."""
    import embree_kernels
    from embree_kernels import mitsuba_offset

    from pipeline.render_setup import load_fibers

    W, H = CASES[name][:2]
    try:
        f = load_fibers(fibers)
        res = embree_kernels.compare(f, camera, W, H, mitsuba_offset(f.points))
    except (OSError, KeyError, RuntimeError, subprocess.SubprocessError) as e:   # no libembree3 / nm, other symbols
        return {f"{name}_kernels_skipped": f"{type(e).__name__}: {e}".splitlines()[0]}
    return {f"{name}_kernels": res}


def run(out_dir) -> dict:
    try:
        _mitsuba()
    except Exception as e:  # ImportError, or a variant that cannot start without LLVM
        return {"skipped": f"Mitsuba 3 (llvm_ad_rgb) unavailable: {type(e).__name__}: {e}".splitlines()[0]}
    from pipeline.scene import load_scene

    res = {"threads": THREADS}
    only = os.environ.get("LOOMLIGHT_BENCH_MITSUBA_CASES", "small,thin,demo").split(",")
    with tempfile.TemporaryDirectory(prefix="bench-mitsuba-") as tmp:
        work = Path(tmp)
        if "small" in only:
            d = work / "small"
            d.mkdir()
            fibers = _realize(SMALL, None, d)
            camera = load_scene(d / "scene.toml").camera
            res.update(run_case("small", fibers, _export(fibers, d), camera))
            res.update(kernel_case("small", fibers, camera))
            if "thin" in only:
                res.update(run_case("thin", fibers, _export_scaled(fibers, d, CASES["thin"][4]), camera))
        if "demo" in only:
            d = work / "demo"
            d.mkdir()
            demo = ROOT / "data" / "scenes" / "demo.toml"
            fibers = ROOT / "out" / "demo" / "fibers.zarr"
            if not (fibers / "zarr.json").exists():
                fibers = _realize(None, demo, d)
            res.update(run_case("demo", fibers, _export(fibers, d), load_scene(demo).camera))
            res.update(kernel_case("demo", fibers, load_scene(demo).camera))
    if out_dir is not None:
        (Path(out_dir) / "mitsuba_table.md").write_text(comparison_table(res))
    return res


CASE_LABELS = {"small": "4×4 plain weave, 96×96 @ 256 spp",
               "thin": "same fibres, radii × 0.1 (control), 96×96 @ 128 spp",
               "demo": "realized demo swatch, 96×72 @ 256 spp"}


def comparison_table(res: dict) -> str:
    """The README's table (Status, *Rendering*) of one run: per case, fiberpath on Embree and on
    loomlight's BVH against Mitsuba 3, builds and means."""
    lines = ["| case (Lambertian fibres, constant sky, max depth 16, 2 threads) | fiberpath (Embree) | "
             "fiberpath (`accel=bvh`) | Mitsuba 3 | ratio (≥ 1: loomlight faster; median of the rounds, range) | "
             "build: Embree / BVH / Mitsuba load | "
             "means: fiberpath / Mitsuba (SE) | Embree vs BVH (SE) |",
             "|---|---|---|---|---|---|---|---|"]
    for c, label in CASE_LABELS.items():
        if f"{c}_speed_ratio" not in res:
            continue
        def g(k, c=c):
            return res[f"{c}_{k}"]
        lines.append(
            f"| {label}, {g('segments') / 1e6:.2f} M segments | {g('fiberpath_render_s'):.2f} s, "
            f"{g('fiberpath_rays_per_s') / 1e6:.2f} M rays/s | {g('fiberpath_bvh_render_s'):.2f} s | "
            f"{g('mitsuba_render_s'):.2f} s | **{g('speed_ratio'):.2f}** ({g('speed_ratio_range')[0]:.2f}-"
            f"{g('speed_ratio_range')[1]:.2f}; BVH {g('bvh_speed_ratio'):.2f}) | "
            f"{g('fiberpath_build_s'):.2f} / {g('fiberpath_bvh_build_s'):.2f} / {g('mitsuba_load_s'):.2f} s | "
            f"{g('fiberpath_mean')[0]:.5f} / {g('mitsuba_mean')[0]:.5f} ({g('mean_diff_in_standard_errors'):.1f}) | "
            f"{g('embree_bvh_diff_in_standard_errors'):.2f} |")
    kernels = [(c, res[f"{c}_kernels"]) for c in CASE_LABELS if f"{c}_kernels" in res]
    if kernels:
        lines += ["", "| the ray-tracing kernels alone, one thread (`bench/embree_kernels.py`) | "
                  "rays: camera / bounce / shadow | "
                  "Embree 4.4 (fiberpath), ns per ray | Embree 3.13.4 (Mitsuba), ns per ray | "
                  "Embree 3 / Embree 4 (< 1: Mitsuba's faster) | builds: Embree 4 / 3 | "
                  "camera rays: same segment (other: its chain neighbour) | "
                  "rays from inside a capsule meeting a surface: Embree 4 / 3 |",
                  "|---|---|---|---|---|---|---|---|"]
        for c, k in kernels:
            def ns(e, k=k):
                return " / ".join(f"{k[f'{x}_ns_per_ray'][e]:.0f}" for x in ("camera", "bounce", "shadow"))
            lines.append(
                f"| {CASE_LABELS[c].split(',')[0]} | {' / '.join(str(v) for v in k['rays'].values())} | "
                f"{ns('embree4')} | "
                f"{ns('embree3')} | {k['camera_embree3_over_embree4']:.2f} / {k['bounce_embree3_over_embree4']:.2f} / "
                f"{k['shadow_embree3_over_embree4']:.2f}; all rays **{k['all_rays_embree3_over_embree4']:.2f}** | "
                f"{k['embree4_build_s']:.2f} / {k['embree3_build_s']:.2f} s | {100 * k['camera_same_segment']:.2f} % "
                f"(chain neighbour {100 * k['camera_chain_neighbour']:.2f} %) | "
                f"{100 * k['inside_rays_meeting_a_surface']['embree4']:.0f} / "
                f"{100 * k['inside_rays_meeting_a_surface']['embree3']:.0f} % |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    import json
    import sys

    sys.path.insert(0, str(ROOT))
    print(json.dumps(run(None), indent=1, default=str))
