"""``loomlight render SCENE --method M -o out.exr``: render a scene with one of the render methods.

Writes the linear float32 EXR (RGB plus the method's extra channels: alpha ``A``, ``depth``,
``variance``), an sRGB PNG preview beside it, and a ``render`` artifact ``<out stem>.zarr`` beside
them holding the image (chunked) and the statistics: wall time, render time, spp, paths/s, rays/s,
peak memory, thread count. Size, spp and seed default to the scene's camera and [render] table.
"""
from __future__ import annotations

import os
import resource
import time
from pathlib import Path

import typer


def _positive(value, name):
    from ..errors import LoomError

    if value is not None and value <= 0:
        raise LoomError(None, name, f"must be a positive integer, got {value}")


def run_render(scene_path, method=None, out=None, width=None, height=None, spp=None, seed=None, source=None,
               fibers=None, tables=None, grid=None, bcsdf=None, material=None, max_depth=None, threads=None, exposure=0.0, settings=()):
    """Render and publish; returns the lines to print (output paths and statistics)."""
    import numpy as np

    from ..artifacts import ArtifactWriter
    from ..errors import LoomError
    from ..images import write_render
    from ..renderers import RenderResult, renderer
    from ..scene import load_scene

    for v, name in ((width, "--width"), (height, "--height"), (spp, "--spp"), (max_depth, "--max-depth"), (threads, "--threads")):
        _positive(v, name)
    if seed is not None and seed < 0:
        raise LoomError(None, "--seed", f"must be >= 0, got {seed}")
    out = Path(out)
    if out.suffix.lower() != ".exr":
        raise LoomError(out, "-o", "the output image must end in .exr")
    scene = load_scene(scene_path)
    method = method or scene.render.get("method")
    if not method:
        raise LoomError(scene.path, "render.method", "no render method: pass --method")
    mod = renderer(method)
    cam = scene.camera or {}
    extra = {}
    for kv in settings:
        if "=" not in kv:
            raise LoomError(None, "--set", f"expected KEY=VALUE, got {kv!r}")
        k, v = kv.split("=", 1)
        extra[k.strip()] = v.strip()
    options = {
        "width": int(width or cam.get("width", 320)), "height": int(height or cam.get("height", 240)),
        "spp": int(spp or scene.render.get("spp", 16)),
        "seed": int(seed if seed is not None else scene.render.get("seed", scene.seed)),
        "source": source, "fibers": str(fibers) if fibers else None,
        "tables": str(tables) if tables else extra.get("tables"), "grid": str(grid) if grid else extra.get("grid"),
        "bcsdf": bcsdf, "material": material, "max_depth": max_depth, "threads": threads, "extra": extra,
    }
    if threads:
        import numba

        numba.set_num_threads(min(int(threads), numba.config.NUMBA_NUM_THREADS))
    t0 = time.perf_counter()
    result: RenderResult = mod.render(scene, options)
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
        "peak_memory_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "mean_rgb": [float(x) for x in rgb.reshape(-1, 3).mean(axis=0)],
        "exr": str(out), "png": str(out.with_suffix(".png")),
    }
    stats["paths_per_s"] = stats["paths"] / render_s
    stats["rays_per_s"] = stats["rays"] / render_s
    stats["method_stats"] = {k: v for k, v in st.items() if k not in ("rays", "paths", "render_s")}
    inputs = {"scene": scene.path}
    for key in ("fibers", "tables", "grid"):
        if options[key]:
            inputs[key] = options[key]
    params = {k: v for k, v in options.items() if k != "threads"}
    params["method"] = method
    exr, png = write_render(out, rgb, result.extra, exposure=exposure)
    art_path = out.with_suffix(".zarr")
    with ArtifactWriter(art_path, kind="render", stage="render", params=params, inputs=inputs) as w:
        H, W = rgb.shape[:2]
        w.write("image", rgb, chunks=(min(H, 128), min(W, 128), 3), dimension_names=("y", "x", "c"))
        for name, ch in result.extra.items():
            w.write(f"channels/{name}", np.ascontiguousarray(ch, dtype=np.float32), chunks=(min(H, 128), min(W, 128)),
                    dimension_names=("y", "x"))
        w.summary.update(stats)
    return [f"image    : {exr}", f"preview  : {png}", f"artifact : {art_path}",
            f"{method}: {stats['width']}x{stats['height']} @ {stats['spp']} spp in {wall:.2f} s "
            f"(render {render_s:.2f} s, {stats['paths_per_s']:.3g} paths/s, {stats['rays_per_s']:.3g} rays/s, "
            f"{stats['threads']} threads, peak {stats['peak_memory_bytes'] / 2**20:.0f} MiB)"]


def register(app: typer.Typer) -> None:
    @app.command("render")
    def render(scene: Path = typer.Argument(..., help="Scene file (TOML)."),
               method: str = typer.Option(None, "--method", "-m", help="Render method (a module in pipeline/renderers); default: the scene's render.method."),
               out: Path = typer.Option(..., "--out", "-o", help="Output EXR path (PNG preview and .zarr artifact go beside it)."),
               width: int = typer.Option(None, "--width", help="Image width in pixels (default: camera.width)."),
               height: int = typer.Option(None, "--height", help="Image height in pixels (default: camera.height)."),
               spp: int = typer.Option(None, "--spp", help="Samples per pixel (default: render.spp)."),
               seed: int = typer.Option(None, "--seed", help="Random seed (default: render.seed)."),
               source: str = typer.Option(None, "--source", help="Where the method takes its geometry from (method-specific, e.g. realized, procedural)."),
               fibers: Path = typer.Option(None, "--fibers", help="A fibers artifact (realized fibres) for fibre renderers, or a tiling artifact (shell-mapped exemplars)."),
               tables: Path = typer.Option(None, "--tables", help="volpath --source procedural: the procedural tables artifact."),
               grid: Path = typer.Option(None, "--grid", help="volpath --source grid: the voxel grid artifact."),
               bcsdf: str = typer.Option(None, "--bcsdf", help="BCSDF preset for yarn groups whose scene entry names none (data/bcsdf/)."),
               material: str = typer.Option(None, "--material", help="fiberpath: bcsdf (default) or lambert."),
               max_depth: int = typer.Option(None, "--max-depth", help="Maximum scattering events per path (default: render.max_depth)."),
               threads: int = typer.Option(None, "--threads", help="numba threads (default: all cores); the image does not depend on it."),
               exposure: float = typer.Option(0.0, "--exposure", help="PNG preview exposure in stops."),
               set_: list[str] = typer.Option(None, "--set", help="Method-specific setting KEY=VALUE (repeatable).")):
        """Render SCENE to an EXR + PNG preview + render artifact with statistics."""
        result = run_render(scene, method=method, out=out, width=width, height=height, spp=spp, seed=seed,
                            source=source, fibers=fibers, tables=tables, grid=grid, bcsdf=bcsdf, material=material, max_depth=max_depth,
                            threads=threads, exposure=exposure, settings=set_ or [])
        for line in result:
            typer.echo(line)
