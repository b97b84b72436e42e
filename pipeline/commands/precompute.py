"""``loomlight precompute svf|iirtf TILING.zarr -o OUT.zarr``: seed 001 §4's precomputation per exemplar.

``svf``    segment visibility functions of every fibre segment (binary images, SSDF + PCA, sums of SGs)
``btf``    one exemplar as seed 002's fitted cloth texture (Lafortune lobes x view lookup table, mip levels)
``iirtf``  the mean free path, cells and per-cell SH transfer matrices A_C (with standard errors), and
           the BCSDF's SH table C_S of every fibre material the scene gives the tiling
Both cover every exemplar of the tiling (patterned cloth: one set per exemplar, §6.4) unless
``--exemplar`` picks some, run as chunk tasks (``pipeline.chunks``) and skip when up to date.
"""
from __future__ import annotations

from pathlib import Path
from typing import List

import typer

from ..limits import FULL_TRANSPORT_DEPTH
from .options import BUDGET, FORCE
from .scheduling import SCHEDULER, THREADS_PER_WORKER, WORKERS

app = typer.Typer(name="precompute", no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
                  help="Precompute the light transport of a tiling's exemplars for render --method prt "
                       "(Khungurn et al. 2017 §4: svf, then iirtf), or fit one exemplar as a cloth texture for render "
                       "--method btf (Daubert et al. 2001: btf).")


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="precompute")


_TILING = typer.Argument(..., help="A tiling artifact (loomlight tile).")
_OUT = typer.Option(..., "-o", "--out", help="Output artifact (directory ending in .zarr).")
_EXEMPLAR = typer.Option(None, "--exemplar", help="Exemplar index to precompute (repeatable; default: all).")
_THREADS = typer.Option(None, "--threads", help="numba threads (default: all cores); the bytes do not depend on it.")
_SCENE = typer.Option(None, "--scene", help="Scene giving the yarn materials (default: the scene the tiling names).")
_MAX_DEPTH = typer.Option(FULL_TRANSPORT_DEPTH, "--max-depth",
                          help="Largest number of scattering events on a path (default: the full transport).")
_RR_DEPTH = typer.Option(5, "--rr-depth", help="Russian roulette from this scattering event on.")
_BCSDF = typer.Option(None, "--bcsdf", metavar="<name | file.toml>",
                      help="BCSDF preset for yarn groups the scene names none for.")
_SET = typer.Option(None, "--set", metavar="<KEY=VALUE>", help="Material option KEY=VALUE (tint=yarn|none, as render).")


def _run(runner, tiling, out, params, describe, *, force, budget, threads, scheduler, workers, threads_per_worker,
         **where):
    """Run one precompute (its output already checked): the memory budget and the scheduler resolved, then
    'up to date' or ``describe(result)``."""
    from ..chunks import resolve_scheduler
    from ..memory import budget as memory_budget

    res = runner(tiling, out, params, force=force, budget=memory_budget(budget), threads=threads,
                 scheduler=resolve_scheduler(scheduler, None, workers, threads_per_worker), **where)
    typer.echo(f"{out} is up to date" if res["skipped"] else f"wrote {out} ({describe(res)})")


@app.command("svf")
def svf(
    tiling: Path = _TILING,
    out: Path = _OUT,
    resolution: int = typer.Option(128, "--resolution", help="Visibility image size: RES x RES pixels over "
                                                             "(theta, phi) (§4.1: 128); at least 8."),
    components: int = typer.Option(48, "--components", help="PCA components of the SSDFs (§4.1: 48)."),
    sg_count: int = typer.Option(48, "--sg-count", help="Q, spherical Gaussians per segment (§4.1: 48)."),
    sg_sharpness: float = typer.Option(128.0, "--sg-sharpness", help="lambda_svf of the visibility SGs (§4.1: 128)."),
    chunk: int = typer.Option(1024, "--chunk", help="Segments per chunk task."),
    seed: int = typer.Option(0, "--seed", help="Seed of the per-segment SG rotations and the PCA sketch."),
    exemplar: List[int] = _EXEMPLAR,
    force: bool = FORCE,
    budget: float = BUDGET,
    threads: int = _THREADS,
    scheduler: str = SCHEDULER,
    workers: int = WORKERS,
    threads_per_worker: int = THREADS_PER_WORKER,
):
    """Compute the segment visibility functions of every fibre segment (Khungurn et al. 2017 §4.1).

    Per fibre segment: the binary visibility image of the sky from its
    midpoint in the exemplar repeated without end, its spherical signed distance function (SSDF) compressed
    by PCA over the exemplar, and the sum-of-SGs representation."""
    from ..outputs import ARTIFACT, check_output
    from ..runners.precompute import SvfParams, run_svf

    check_output(out, "-o", ARTIFACT, inputs=[tiling])
    p = SvfParams(resolution=resolution, components=components, sg_count=sg_count, sg_sharpness=sg_sharpness,
                  chunk=chunk, seed=seed)
    _run(run_svf, tiling, out, p, lambda res: f"{res['exemplars']} exemplars, {res['segments']:,} segments, "
         f"{res['rays_per_s'] / 1e6:.2f} M rays/s, PCA relative error {res['pca_rel_error']:.3f}",
         force=force, budget=budget, threads=threads, scheduler=scheduler, workers=workers,
         threads_per_worker=threads_per_worker, exemplars=exemplar or None)


@app.command("iirtf")
def iirtf(
    tiling: Path = _TILING,
    out: Path = _OUT,
    scene: Path = _SCENE,
    order: int = typer.Option(4, "--order", help="SH order L of the transfer matrices (§6.1: 4 or 5), 0..8."),
    cell_factor: float = typer.Option(1.0, "--cell-factor", help="Target cell side in mean free paths (§6.1: 1-2)."),
    paths: int = typer.Option(50000, "--paths", help="Monte Carlo paths per cell (§4.2: 50,000)."),
    mfp_paths: int = typer.Option(20000, "--mfp-paths", help="Paths traced to estimate the mean free path."),
    layer_paths: int = typer.Option(4000, "--layer-paths",
                                    help="Paths per angle and side for the exemplar's layer transmittance (how much "
                                         "light crosses the cloth; prt's shadow rays through other folds)."),
    layer_bins: int = typer.Option(8, "--layer-bins", help="Incidence angles (bins of cos theta) of the layer "
                                                           "transmittance."),
    max_depth: int = _MAX_DEPTH,
    rr_depth: int = _RR_DEPTH,
    light_sampling: str = typer.Option("uniform", "--light-sampling", metavar="<uniform | mis>",
                                       help="Estimator of the light integral: uniform (§4.2: light directions "
                                            "uniform on the hemisphere) or mis (the same integral, a path "
                                            "tracer lit by the SH sky with multiple importance sampling; "
                                            "much less variance for sharp BCSDFs)."),
    light_domain: str = typer.Option("hemisphere", "--light-domain", metavar="<hemisphere | sphere>",
                                     help="Light directions the matrices hold: hemisphere (§4.2: light from "
                                          "above) or sphere (§4.2's extension to the bottom surface: light "
                                          "from below crosses the cloth too, e.g. a drape's hanging sides "
                                          "under a low light; the renderer then lights the cloth from both "
                                          "sides). Same paths per cell, spread over twice the directions."),
    theta_samples: int = typer.Option(512, "--theta-samples",
                                      help="theta_o values of the BCSDF table C_S (§4.3: 512)."),
    bcsdf: str = _BCSDF,
    chunk: int = typer.Option(16, "--chunk", help="Cells per chunk task."),
    seed: int = typer.Option(0, "--seed", help="Seed of the transfer matrices' Monte Carlo (the mean free path, "
                                                 "hence the cell grid, uses a fixed one)."),
    set_: List[str] = _SET,
    exemplar: List[int] = _EXEMPLAR,
    force: bool = FORCE,
    budget: float = BUDGET,
    threads: int = _THREADS,
    scheduler: str = SCHEDULER,
    workers: int = WORKERS,
    threads_per_worker: int = THREADS_PER_WORKER,
):
    """Compute the incoming indirect radiance transfer functions of every exemplar (Khungurn et al. 2017 §4.2-4.3).

    The exemplar cut into cells of about a mean free
    path, and per cell the SH matrix A_C taking light to the indirect incoming radiance at the cell's
    segments, estimated by path tracing the fibre BCSDF, with its standard error; plus the BCSDF's SH table
    C_S (§4.3) of every material and the exemplar's layer transmittance (the light that crosses it)."""
    from ..outputs import ARTIFACT, check_output
    from ..runners.precompute import IirtfParams, parse_material_options, run_iirtf

    check_output(out, "-o", ARTIFACT, inputs=[tiling, scene])
    p = IirtfParams(order=order, cell_factor=cell_factor, paths=paths, mfp_paths=mfp_paths, max_depth=max_depth,
                    rr_depth=rr_depth, light_sampling=light_sampling, light_domain=light_domain,
                    layer_paths=layer_paths, layer_bins=layer_bins, theta_samples=theta_samples, chunk=chunk,
                    seed=seed, material=parse_material_options(set_ or [], bcsdf))
    _run(run_iirtf, tiling, out, p, lambda res: f"{res['exemplars']} exemplars, {res['cells']:,} cells, mean free "
         f"path {', '.join(f'{m:.4g}' for m in res['mean_free_path'])}, {res['paths_per_s'] / 1e3:.1f} k paths/s",
         force=force, budget=budget, threads=threads, scheduler=scheduler, workers=workers,
         threads_per_worker=threads_per_worker, scene=scene, exemplars=exemplar or None)


@app.command("btf")
def btf(
    tiling: Path = _TILING,
    out: Path = _OUT,
    exemplar: List[int] = typer.Option(None, "--exemplar",
                                       help="An exemplar (repeat) of the tiling to fit (repeatable; default: every "
                                            "exemplar the tiling's block map uses)."),
    scene: Path = _SCENE,
    resolution: int = typer.Option(32, "--resolution", help="Texels a side of the finest level (a power of two; "
                                                            "Daubert et al. 2001: 32)."),
    views: str = typer.Option("8x8", "--views", help="View grid THETAxPHI: rings of equal solid angle x azimuths "
                                                    "(8x8 = the paper's 64 table entries; 4x8 its 32)."),
    lights: str = typer.Option(None, "--lights", help="Light grid THETAxPHI, as --views (default 8x8); with "
                                                      "--light-coords half NXxNY cells of the half vector's (x, y) "
                                                      "square (default 15x15)."),
    light_coords: str = typer.Option("hemisphere", "--light-coords", metavar="<hemisphere | half>",
                                     help="hemisphere: light cells of equal solid angle (Daubert et al. 2001); half: "
                                          "cells of the half vector between light and view, where fibre glints stay "
                                          "put as the view moves (the tabulated model reads them sharper)."),
    light_domain: str = typer.Option("hemisphere", "--light-domain", metavar="<hemisphere | sphere>",
                                     help="hemisphere: lights above the fabric (Daubert et al. 2001: a reflectance); "
                                          "sphere: the light grid and its mirror below the fabric too, so the "
                                          "tabulated model lets light through the cloth (a sky below a knit, a "
                                          "curtain against a window; twice the lights to acquire). The Lafortune "
                                          "fit reads the lights above only."),
    plane: str = typer.Option("top", "--plane", metavar="<top | middle | surface | relief>",
                              help="The texture's plane: top (Daubert et al. 2001: the repeat's top face), middle "
                                   "(the middle of its fibres' slab: what lies deep in a thick knit blurs half as "
                                   "much between view directions), surface (the median height of what the "
                                   "views see) or relief (a plane per texel, the height of what it shows from "
                                   "above, holes down to the bottom; the renderer marches that height field)."),
    spp: int = typer.Option(16, "--spp", help="Rays per texel and view (super-sampled alpha and radiance)."),
    lobes: int = typer.Option(2, "--lobes", help="Lafortune lobes per texel: 1 or 2."),
    threshold: float = typer.Option(0.1, "--threshold", help="Stop alternating lobes and table when the table's "
                                                             "mean change is below this (Daubert et al. 2001: 0.1)."),
    max_rounds: int = typer.Option(10, "--max-rounds", help="At most this many lobe/table alternations."),
    model: str = typer.Option("lafortune", "--model", metavar="<lafortune | tabulated>",
                              help="lafortune: seed 002's fit (the btf renderer's default); tabulated: the fit and "
                                   "the acquired table itself, compressed by local PCA (render with --set "
                                   "model=tabulated)."),
    clusters: int = typer.Option(8, "--clusters", help="Tabulated: clusters of texels, each with its own mean and "
                                                       "components (1: plain PCA)."),
    components: int = typer.Option(8, "--components", help="Tabulated: principal components per cluster."),
    directions: str = typer.Option("cell", "--directions", metavar="<cell | grid>",
                                   help="cell: each sample's view and light uniform over its grid cell (the texture "
                                        "holds cell averages, so fibre glints between grid directions are not lost "
                                        "or aliased); grid: the grid directions themselves (the point samples of "
                                        "Daubert et al. 2001)."),
    max_depth: int = _MAX_DEPTH,
    rr_depth: int = _RR_DEPTH,
    bcsdf: str = _BCSDF,
    seed: int = typer.Option(0, "--seed", help="Seed of the Monte Carlo estimates."),
    set_: List[str] = _SET,
    force: bool = FORCE,
    budget: float = BUDGET,
    threads: int = _THREADS,
    scheduler: str = SCHEDULER,
    workers: int = WORKERS,
    threads_per_worker: int = THREADS_PER_WORKER,
):
    """Fit the exemplars of a tiling as view-dependent cloth textures (Daubert et al. 2001 §4-§5).

    Per exemplar: radiance samples of the repeat over view x light grids, path traced on its explicit
    fibres with its copies all around, alpha and average normals per texel; per texel diffuse + Lafortune
    lobes times a view lookup table, and mip levels down to 1 x 1. The btf renderer dresses a tiling with
    each exemplar's texture where its block map places that exemplar."""
    from ..outputs import ARTIFACT, check_output
    from ..runners.precompute import parse_material_options
    from ..runners.precompute_btf import DEFAULT_LIGHTS, BtfParams, parse_grid, run_btf

    check_output(out, "-o", ARTIFACT, inputs=[tiling, scene])
    grid = parse_grid(lights, "--lights") if lights is not None else DEFAULT_LIGHTS.get(light_coords, (8, 8))
    p = BtfParams(resolution=resolution, views=parse_grid(views, "--views"), lights=grid, light_coords=light_coords,
                  light_domain=light_domain, plane=plane, spp=spp, lobes=lobes, threshold=threshold,
                  max_rounds=max_rounds, directions=directions,
                  model=model, clusters=clusters, components=components,
                  max_depth=max_depth,
                  rr_depth=rr_depth, seed=seed, material=parse_material_options(set_ or [], bcsdf))
    _run(run_btf, tiling, out, p, lambda res: f"{res['exemplars']} exemplar(s), "
         f"{res['resolution']}x{res['resolution']} texels, {res['views']} "
         f"views x {res['lights']} lights, {res['levels']} levels, {res['fit_bytes'] / 2**20:.2f} MiB fitted; "
         f"acquisition {res['acquire_s']:.1f} s, fit {res['fit_s']:.1f} s; fit RMSE level 0 "
         f"{res['fit_rmse'][0]:.4g} (without the table {res['fit_rmse_no_table'][0]:.4g})"
         + (f"; tabulated {res['table_bytes'] / 2**20:.2f} MiB, relative RMSE {res['table_rel_rmse']:.3f}, "
            f"compression {res['compress_s']:.1f} s" if res["table_bytes"] else "")
         + ("; acquisition reused" if res["acquisition_reused"] else ""),
         force=force, budget=budget, threads=threads, scheduler=scheduler, workers=workers,
         threads_per_worker=threads_per_worker, scene=scene, exemplars=exemplar or None)
