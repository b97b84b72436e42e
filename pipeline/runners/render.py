"""Render runner: resolve the options of a registered method, render, publish EXR + PNG + artifact.

``run_render`` takes the command line's values (None where not given), resolves them against the
scene (``[camera]``, ``[render]``) and the registry's ``COMMON_DEFAULTS`` (``pipeline.renderers``),
checks the ``--set`` keys and the artifact inputs against the method's declaration, runs the method
and writes the linear float32 EXR (RGB plus the extra channels), an sRGB PNG preview beside it and
a ``render`` artifact ``<out stem>.zarr`` holding the image (chunked) and the statistics: wall time,
render time, spp, paths/s, rays/s, peak memory, thread count. The three are published as one set
(``ArtifactWriter`` companions): a render killed at any moment leaves the previous EXR, PNG and
artifact, or the new ones, never a mix, and the artifact records the EXR's and PNG's sha256. The
artifact's inputs are the scene and every artifact the method's source read; the outputs are
checked (not an input, not a file or directory in the way) before anything is rendered.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..bcsdf_presets import check_bcsdf_names
from ..errors import LoomError
from ..limits import check_depth
from ..memory import BUDGET_ENV, Estimate, budget as memory_budget, peak_rss_bytes

PIXEL_BYTES = 256          # the film's per-pixel sums, the image and its channels, the EXR and PNG encodings
VERTEX_BYTES = 300         # a realized fibre vertex: the fibres read, capsule segments and their BVH
# the bound from time on --spp / --max-spp (``pipeline.limits.WorkEstimate``): camera paths a thread traces
# in a second, a rate no method reaches (measured: 2-6e4 fiberpath and volpath paths a thread-second, README)
PATHS_PER_THREAD_S = 1e7


def render_work(options: dict, sched, method: str):
    """The least time of a render's camera paths (``WorkEstimate``: every pixel's spp, at most max_spp more
    each), on this process's threads or a LocalCluster's; None on a running scheduler (its workers are not
    known before connecting)."""
    from ..limits import WorkEstimate

    if sched is not None and sched.kind == "address":
        return None
    if sched is not None and sched.kind == "processes":
        threads = sched.workers * sched.threads_per_worker
    else:
        import numba

        threads = numba.get_num_threads()
    W, H, spp, more = options["width"], options["height"], options["spp"], options.get("max_spp") or 0
    est = WorkEstimate(f"loomlight render --method {method}", threads)
    est.add("camera paths", float(W) * H * spp, PATHS_PER_THREAD_S, f"{W} x {H} pixels x {spp:,} spp (--spp)")
    if more:
        est.add("adaptive paths (at most)", float(W) * H * more, PATHS_PER_THREAD_S,
                f"{W} x {H} pixels x {more:,} more (--max-spp)")
    return est


def render_estimate(options: dict, inputs: dict, scene=None) -> Estimate:
    """A render's peak from its size and the artifacts it reads: the film, realized fibres (or a tiling's
    exemplars) with their BVH, procedural tables with what loading them derives, a voxel grid, the scene's
    meshes (``render_setup.meshes_estimate``: their OBJ files' vertex and triangle counts)."""
    from ..artifacts import Artifact
    from .tables import accel_estimate

    est = Estimate("loomlight render")
    W, H = options["width"], options["height"]
    est.add("film", float(PIXEL_BYTES) * W * H, f"{W} x {H} pixels")
    if scene is not None and scene.meshes:
        from ..render_setup import meshes_estimate

        est.add("meshes and their BVH", *meshes_estimate(scene))
    for key, (path, _) in inputs.items():
        if key == "scene":
            continue
        art = Artifact(path)
        if art.kind == "tables":
            est.extend(accel_estimate(art, est.what)).add("majorant grid", _majorant_bytes(art))
            from ..fibre_cache import default_cache_mib

            mib = float(default_cache_mib() if options.get("cache") is None else options["cache"])
            est.add("fibre cache (at most its budget)", mib * 2**20, f"--cache {mib:g} MiB")
            if mib > 0:
                from ..fibre_cache import MAX_FINE_BYTES

                est.add("refined majorant cells (at most)", float(MAX_FINE_BYTES), "where the grid is capped")
        elif art.kind in ("fibers", "tiling"):
            points = art.arrays()["points" if art.kind == "fibers" else "ex_points"]
            est.add(f"{art.kind} and their BVH", VERTEX_BYTES * points.shape[0] + 2 * art.nbytes(),
                    f"{points.shape[0]:,} vertices")
        else:
            est.add(f"{art.kind} arrays", 3 * art.nbytes(), art.path.name)
    return est


def _majorant_bytes(art) -> float:
    """volpath's procedural majorant grid over the tables' curves box grown by the largest extent."""
    import numba
    import numpy as np

    from ..renderers.volpath import procedural_majorant_bytes

    pts, ext = np.asarray(art["curves/points"]), np.asarray(art["yarn_extent"])
    if not len(pts) or not len(ext):
        return 0.0
    return procedural_majorant_bytes(pts.min(0) - ext.max(), pts.max(0) + ext.max(), float(ext.mean()),
                                     numba.get_num_threads())


def _positive(value, name):
    if value is not None and value <= 0:
        raise LoomError(None, name, f"must be a positive integer, got {value}")


def parse_settings(settings, m) -> dict:
    """``--set KEY=VALUE`` pairs checked against the method's declared settings."""
    from ..renderers import did_you_mean

    extra = {}
    known = [s.key for s in m.settings]
    for kv in settings:
        if "=" not in kv:
            raise LoomError(None, "--set", f"expected KEY=VALUE, got {kv!r}")
        k, v = kv.split("=", 1)
        k, v = k.strip(), v.strip()
        if k not in known:
            raise LoomError(None, f"--set {k}", f"{m.name} has no setting {k!r} (known: {', '.join(known) or 'none'})"
                            + did_you_mean(k, known))
        choices = next(s.choices for s in m.settings if s.key == k)
        if choices and v not in choices:
            raise LoomError(None, f"--set {k}", f"{m.name}: unknown {k} {v!r} (known: {', '.join(choices)})"
                            + did_you_mean(v, choices))
        extra[k] = v
    return extra


@dataclass(frozen=True)
class RenderRequest:
    """What a render is asked for on top of its scene, as ``loomlight render`` takes it: a field left None is
    the scene's (``[camera]`` width and height, ``[render]`` spp, seed, max_depth, max_spp, cache), else the
    method's default (``resolve_options``). ``fibers``, ``tables``, ``grid``: artifact paths; ``extra``:
    the method's ``--set`` settings, parsed (``parse_settings``); ``threads``: numba threads (the image
    does not depend on them); ``cache``: volpath's fibre cache budget in MiB."""
    width: int | None = None
    height: int | None = None
    spp: int | None = None
    seed: int | None = None
    source: str | None = None
    fibers: str | Path | None = None
    tables: str | Path | None = None
    grid: str | Path | None = None
    bcsdf: str | None = None
    material: str | None = None
    max_depth: int | None = None
    threads: int | None = None
    max_spp: int | None = None
    cache: float | None = None
    extra: dict = field(default_factory=dict)


def resolve_options(scene, m, request: RenderRequest = RenderRequest()) -> dict:
    """The render's options: ``request``'s choices over the scene's over the method ``m``'s defaults, the
    artifacts its sources read, checked (positive sizes, a material the method knows)."""
    from ..renderers import COMMON_DEFAULTS

    r = request
    width, height, spp, seed, source = r.width, r.height, r.spp, r.seed, r.source
    fibers, tables, grid, bcsdf, material = r.fibers, r.tables, r.grid, r.bcsdf, r.material
    max_depth, threads, max_spp, cache = r.max_depth, r.threads, r.max_spp, r.cache
    extra = r.extra or {}
    cam = scene.camera or {}
    rs = scene.render

    raw_render = (getattr(scene, "raw", None) or {}).get("render", {})

    def pick(cli, table, key):
        v = cli if cli is not None else table.get(key)
        if cli is None and table is rs and key not in raw_render and key in dict(m.defaults):
            v = None   # the scene did not set it: the method's own default
        return int(v if v is not None else m.default(key))

    options = {
        "width": pick(width, cam, "width"), "height": pick(height, cam, "height"), "spp": pick(spp, rs, "spp"),
        "seed": int(seed if seed is not None else rs.get("seed", scene.seed)),
        "max_depth": pick(max_depth, rs, "max_depth"), "rr_depth": pick(None, rs, "rr_depth"),
        "tile_size": pick(None, rs, "tile_size"), "max_spp": pick(max_spp, rs, "max_spp"),
        "target_error": float(rs.get("target_error", COMMON_DEFAULTS["target_error"])),
        "source": source, "fibers": str(fibers) if fibers else extra.get("tiling"),
        "tables": str(tables) if tables else extra.get("tables"), "grid": str(grid) if grid else extra.get("grid"),
        "bcsdf": bcsdf, "material": material, "threads": threads, "extra": extra,
        "cache": _cache_budget(cache, rs),
    }
    from ..renderers import CLI_INPUTS

    for inp in {i.option for src in m.sources for i in src.inputs} - set(CLI_INPUTS):
        options[inp] = extra.get(inp)   # artifacts render has no option for: --set KEY=PATH.zarr
    for key, name in (("width", "--width"), ("height", "--height"), ("spp", "--spp")):
        _positive(options[key], name)
    if material is not None and m.materials and material not in m.materials:
        from ..renderers import did_you_mean

        raise LoomError(None, "--material", f"unknown fibre material {material!r} (known: {', '.join(m.materials)})"
                        + did_you_mean(material, m.materials))
    return options


def _cache_budget(cli, rs):
    """The fibre cache budget in MiB (``--cache``, else ``render.cache``, else None: the default),
    checked and clamped to the available memory (``pipeline.fibre_cache.cache_budget_mib``)."""
    from ..fibre_cache import cache_budget_mib

    if cli is not None:
        return cache_budget_mib(cli, "--cache")
    if rs.get("cache") is not None:
        return cache_budget_mib(rs["cache"], "render.cache")
    return None


def render_source(scene, m, options):
    """The method's source: ``--source``, else the scene's ``render.source`` where the method has it, else
    the method's default."""
    scene_source = scene.render.get("source")
    return m.source(options["source"] or (scene_source if scene_source in m.source_names else None))


def check_inputs(scene, m, options) -> None:
    """The method's source exists and every artifact it reads was given."""
    src = render_source(scene, m, options)
    for inp in src.inputs:
        if not options.get(inp.option):
            via = f"{m.name} --source {src.name}" if len(m.sources) > 1 else m.name
            from ..renderers import CLI_INPUTS

            how = f"--{inp.option} PATH.zarr" if inp.option in CLI_INPUTS else f"--set {inp.option}=PATH.zarr"
            raise LoomError(None, f"--{inp.option}" if inp.option in CLI_INPUTS else f"--set {inp.option}",
                            f"{via} needs {inp.what}: pass {how}")
    check_bcsdf_names(scene, options)
    check_set_artifacts(options)
    from ..render_setup import check_scene_matches

    for key in ("fibers", "tables", "yarns"):
        if options.get(key):
            check_scene_matches(scene, options[key], key if key != "yarns" else "set yarns")


def check_set_artifacts(options) -> None:
    """Every ``--set KEY=PATH.zarr`` names an artifact of a kind KEY reads (the registry's
    ``input_kinds``), and none is passed over: ``--set tiling=`` names the tiling ``--fibers`` names, if
    both are given."""
    from ..artifacts import read_meta
    from ..renderers import TILING, input_kinds

    kinds = {**input_kinds(), "tiling": TILING.kinds}   # --set tiling= is --fibers TILING.zarr's other name
    extra = options.get("extra") or {}
    for key, value in sorted(extra.items()):
        want = kinds.get(key)
        if want is None or not str(value).endswith(".zarr"):
            continue   # not an artifact setting (a tiling config .toml is built from by --build)
        found = read_meta(value).get("kind")
        if found not in want:
            raise LoomError(value, f"--set {key}", f"expected a {' or '.join(repr(k) for k in want)} artifact, found a "
                            f"{found!r} artifact")
    tiling, fibers = extra.get("tiling"), options.get("fibers")
    if tiling and fibers and os.path.realpath(tiling) != os.path.realpath(fibers):
        raise LoomError(None, "--set tiling", f"names {tiling} while --fibers names {fibers}; give the tiling once")


def run_render(scene_path, out, request: RenderRequest = RenderRequest(), method=None, settings=(), exposure=0.0,
               budget=None, scheduler=None, workers=None, threads_per_worker=None, build=False, cache_dir=None,
               say=print):
    """Render ``scene_path`` as ``request`` asks (``settings``: the ``--set KEY=VALUE`` strings, parsed
    against ``method``'s) into ``out`` and publish; returns the lines to print (output paths and
    statistics). ``build``: build
    the inputs no option gave into the cache (``pipeline.autobuild``; ``cache_dir``, else beside ``out``),
    saying what was built or reused through ``say``; otherwise they are refused. ``budget``
    (``pipeline.memory.budget``, default a fraction of the available memory): refuse before rendering
    when the estimated peak memory exceeds it. ``scheduler``: where the tile tasks run (``--scheduler``;
    ``pipeline.chunks``), with ``workers`` and ``threads_per_worker`` for a LocalCluster."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    import numpy as np

    from ..artifacts import FILE, ArtifactWriter
    from ..chunks import resolve_scheduler, session
    from ..images import write_render
    from ..renderers import RenderResult, input_kinds, method as registered
    from ..scene import load_scene

    r = request
    for v, name in ((r.width, "--width"), (r.height, "--height"), (r.spp, "--spp"), (r.max_depth, "--max-depth"),
                    (r.threads, "--threads")):
        _positive(v, name)
    if r.max_depth is not None:
        check_depth(r.max_depth, "--max-depth")
    if r.seed is not None and r.seed < 0:
        raise LoomError(None, "--seed", f"must be >= 0, got {r.seed}")
    out = Path(out)
    if out.suffix.lower() != ".exr":
        raise LoomError(out, "-o", "the output image must end in .exr")
    scene = load_scene(scene_path)
    sched = resolve_scheduler(scheduler, scene, workers, threads_per_worker)
    method = method or scene.render.get("method")
    if not method:
        raise LoomError(scene.path, "render.method", "no render method: pass --method")
    m = registered(method)
    m.check_scene(scene)      # a scene this method cannot render whole: refused before anything is built
    options = resolve_options(scene, m, replace(request, extra=parse_settings(settings, m)))
    from .. import compilation

    compilation.watch()
    if build:
        from ..autobuild import build_missing

        check_bcsdf_names(scene, options)   # bad names first: nothing is built for a render that would be refused
        build_missing(scene, m, render_source(scene, m, options), options, out, cache_dir, budget, sched, say)
    check_inputs(scene, m, options)
    if r.threads:
        import numba

        numba.set_num_threads(min(int(r.threads), numba.config.NUMBA_NUM_THREADS))
    inputs = {"scene": (scene.path, FILE)}
    kinds = input_kinds()
    for key in sorted({inp.option for src in m.sources for inp in src.inputs}):
        if options[key]:
            inputs[key] = (options[key], kinds[key])
    params = {k: v for k, v in options.items() if k != "threads"}
    params["method"] = method
    art_path = out.with_suffix(".zarr")
    writer = ArtifactWriter(art_path, kind="render", stage="render", params=params, inputs=inputs,
                            companions=(out, out.with_suffix(".png")), started=t_start)
    # render has no --budget option: its budget is $LOOMLIGHT_MEMORY_BUDGET's (or a share of what is free)
    render_estimate(options, inputs, scene).check(budget or memory_budget(), scene.path,
                                                  remedy=f"set {BUDGET_ENV} (MiB) higher or make the input smaller")
    work = render_work(options, sched, method)
    if work is not None:
        top = max(work.parts, key=lambda part: part[1])[2]
        work.check(None, "--max-spp" if "--max-spp" in top else "--spp", "lower --spp or --max-spp")
    options["out"] = str(out)  # where a distributed render puts its scratch film (not a parameter)
    t0 = time.perf_counter()
    from ..progress import status

    with session(sched) as dask, compilation.group(f"{method} render"), status(f"{method}: setup and render"):
        result: RenderResult = m.run(scene, options)
        workers = dask.workers() if dask is not None else 0
    wall = time.perf_counter() - t0
    rgb = np.ascontiguousarray(result.rgb, dtype=np.float32)
    if rgb.shape != (options["height"], options["width"], 3):
        raise RuntimeError(f"renderer {method} returned an image of shape {rgb.shape}")
    st = dict(result.stats)
    render_s = float(st.get("render_s", wall)) or wall
    import numba

    stats = {
        "kind": "render", "method": method, "width": options["width"], "height": options["height"],
        "spp": options["spp"], "seed": options["seed"], "wall_time_s": wall, "render_time_s": render_s,
        "paths": int(st.get("paths", rgb.shape[0] * rgb.shape[1] * options["spp"])),
        "rays": int(st.get("rays", 0)), "threads": int(numba.get_num_threads()),
        "scheduler": sched.address or sched.kind, "workers": workers,
        "peak_memory_bytes": peak_rss_bytes(),
        "mean_rgb": [float(x) for x in rgb.reshape(-1, 3).mean(axis=0)],
        "exr": str(out), "png": str(out.with_suffix(".png")),
    }
    stats["paths_per_s"] = stats["paths"] / render_s
    stats["rays_per_s"] = stats["rays"] / render_s
    stats["method_stats"] = {k: v for k, v in st.items() if k not in ("rays", "paths", "render_s")}
    with writer as w:
        write_render(out, rgb, result.extra, exposure=exposure, into=w.companion)
        H, W = rgb.shape[:2]
        w.write("image", rgb, chunks=(min(H, 128), min(W, 128), 3), dimension_names=("y", "x", "c"))
        for name, ch in result.extra.items():
            w.write(f"channels/{name}", np.ascontiguousarray(ch, dtype=np.float32), chunks=(min(H, 128), min(W, 128)),
                    dimension_names=("y", "x"))
        w.summary.update(stats)
    exr, png = out, out.with_suffix(".png")
    return [f"image    : {exr}", f"preview  : {png}", f"artifact : {art_path}",
            f"{method}: {stats['width']}x{stats['height']} @ {stats['spp']} spp in {wall:.2f} s "
            f"(render {render_s:.2f} s, {stats['paths_per_s']:.3g} paths/s, {stats['rays_per_s']:.3g} rays/s, "
            + (f"{workers} Dask workers" if workers else f"{stats['threads']} threads")
            + f", peak {stats['peak_memory_bytes'] / 2**20:.0f} MiB)"]
