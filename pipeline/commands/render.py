"""``loomlight render SCENE --method M -o out.exr``: render a scene with one of the render methods.

Writes the linear float32 EXR (RGB plus the method's extra channels: alpha ``A``, ``depth``,
``variance``), an sRGB PNG preview beside it, and a ``render`` artifact ``<out stem>.zarr`` beside
them holding the image (chunked) and the statistics (``pipeline.runners.render``). Size, spp and seed
default to the scene's camera and [render] table. The methods, their sources and settings come from
the renderer registry (``pipeline.renderers``). The artifacts a method reads that no option gives
(``--fibers``, ``--tables``, ``--set KEY=PATH``) are built into a cache beside the output and reused
(``pipeline.autobuild``; ``--cache-dir``, ``--no-build``); one line says what was built or reused.
"""
from __future__ import annotations

from pathlib import Path

import typer

from ..renderers import (
    COMMON_DEFAULTS,
    material_help,
    material_metavar,
    method_help,
    method_metavar,
    settings_help,
    source_help,
    source_metavar,
)
from .scheduling import SCHEDULER, THREADS_PER_WORKER, WORKERS


def register(app: typer.Typer) -> None:
    @app.command("render")
    def render(scene: Path = typer.Argument(..., help="Scene file (TOML)."),
               method: str = typer.Option(None, "--method", "-m", metavar=method_metavar(), help=method_help()),
               out: Path = typer.Option(..., "--out", "-o",
                                        help="Output EXR path (PNG preview and .zarr artifact go beside it)."),
               width: int = typer.Option(None, "--width",
                                         help="Image width in pixels (default: camera.width, else "
                                              f"{COMMON_DEFAULTS['width']})."),
               height: int = typer.Option(None, "--height",
                                          help="Image height in pixels (default: camera.height, else "
                                               f"{COMMON_DEFAULTS['height']})."),
               spp: int = typer.Option(None, "--spp",
                                       help=f"Samples per pixel (default: render.spp, else {COMMON_DEFAULTS['spp']})."),
               seed: int = typer.Option(None, "--seed",
                                        help=f"Random seed (default: render.seed, else {COMMON_DEFAULTS['seed']})."),
               source: str = typer.Option(None, "--source", metavar=source_metavar(), help=source_help()),
               fibers: Path = typer.Option(None, "--fibers",
                                           help="A fibers artifact (realized fibres) for fibre renderers, or a tiling "
                                                "artifact (shell-mapped exemplars)."),
               tables: Path = typer.Option(None, "--tables",
                                           help="volpath --source procedural: the procedural tables artifact."),
               grid: Path = typer.Option(None, "--grid", help="volpath --source grid: the voxel grid artifact."),
               bcsdf: str = typer.Option(None, "--bcsdf", metavar="<name | file.toml>",
                                         help="BCSDF preset (a name in data/bcsdf/ or a preset file) for yarn groups "
                                              "whose scene entry names none."),
               material: str = typer.Option(None, "--material", metavar=material_metavar(), help=material_help()),
               max_depth: int = typer.Option(None, "--max-depth",
                                             help="Maximum scattering events per path (default: render.max_depth, else "
                                                  f"{COMMON_DEFAULTS['max_depth']})."),
               max_spp: int = typer.Option(None, "--max-spp", min=0,
                                           help="Adaptive sampling: a second pass gives each pixel up to this many "
                                                "more samples, as many as its neighbours' relative error after --spp "
                                                "samples asks for to reach render.target_error (default 0.05) "
                                                "(default: render.max_spp, else 0 = off)."),
               cache: float = typer.Option(None, "--cache", metavar="MiB",
                                           help="volpath --source procedural: the render-time fibre cache budget in "
                                                "MiB: the fibres of the bricks the camera sees, realized into a "
                                                "capsule BVH; 0 = every lookup procedural (default: render.cache, else "
                                                "2048; clamped to the available memory)."),
               threads: int = typer.Option(None, "--threads",
                                           help="numba threads (default: all cores); the image does not depend on it."),
               exposure: float = typer.Option(0.0, "--exposure",
                                              help="PNG preview exposure in stops (finite, within +-64)."),
               set_: list[str] = typer.Option(None, "--set", metavar="<KEY=VALUE>", help=settings_help()),  # noqa: B008 (help text, built once at registration)
               cache_dir: Path = typer.Option(None, "--cache-dir", help="Where the artifacts no option gives are built "
                                              "and reused (default: .loomlight-cache beside -o; "
                                              "docs/one-command-render.md)."),
               no_build: bool = typer.Option(False, "--no-build", help="Refuse a render whose method reads an "
                                             "artifact no option gives, instead of building it (by default ingest, "
                                             "tables or realize, tile and precompute build it at their defaults into "
                                             "--cache-dir, and it is reused while the scene and code are unchanged)."),
               scheduler: str = SCHEDULER, workers: int = WORKERS, threads_per_worker: int = THREADS_PER_WORKER):
        """Render a scene to a linear EXR, an sRGB PNG preview and a render artifact with statistics."""
        from ..errors import LoomError, check_name
        from ..outputs import ARTIFACT, check_output
        from ..renderers import all_sources, method as registered
        from ..runners.render import RenderRequest, run_render

        if method is not None:  # the names first: before the outputs are checked or the scene is read
            m = registered(method)
            if source is not None:
                m.source(source)
        elif source is not None:
            check_name(source, all_sources(), None, "--source", "render source")
        if not -64.0 <= exposure <= 64.0:
            raise LoomError(None, "--exposure", f"must be a finite number of stops within +-64, got {exposure}")
        check_output(out, "-o", suffixes=(".exr",))
        check_output(out.with_suffix(".png"), "-o")
        check_output(out.with_suffix(".zarr"), "-o", ARTIFACT)
        request = RenderRequest(width=width, height=height, spp=spp, seed=seed, source=source, fibers=fibers,
                                tables=tables, grid=grid, bcsdf=bcsdf, material=material, max_depth=max_depth,
                                threads=threads, max_spp=max_spp, cache=cache)
        result = run_render(scene, out, request, method=method, settings=set_ or [], exposure=exposure,
                            scheduler=scheduler, workers=workers, threads_per_worker=threads_per_worker,
                            build=not no_build, cache_dir=cache_dir, say=typer.echo)
        for line in result:
            typer.echo(line)
