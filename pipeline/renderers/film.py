"""Run the shared tile loop (``stages.render.tiles``) over an image with a progress bar.

``render_film(label, integ, cam, width, height, sampling, seed, tile_size, variance, threads)``
compiles (or loads from numba's cache) the integrator's tile loop on an empty tile first, so the
render time excludes compilation (reported apart as ``compile_s``), renders the image in batches of
tiles (one progress step per tile) and finishes the film (``stages.render.film.finalize``). Returns
a ``FilmRun``: rgb, extra channels ``A``/``depth``/``variance``, the ``FilmImage`` (ray and lookup
totals), render and compile seconds, samples traced and pixels refined.

Adaptive sampling (``Sampling``: ``spp``, ``max_spp``, ``target_error``). Every pixel first takes
``spp`` samples. With ``max_spp`` > 0, a second pass gives pixel i up to ``max_spp`` more
(``refine_counts``): n_i new samples, so that spp + n_i reaches the count its neighbourhood asks for,
max over the eight neighbours j of s_j^2 / (target_error * max(m_j, floor_i))^2, with m_j and s_j^2 the
mean and per-sample variance of neighbour j's luminance in the first pass and floor_i 1 % of the
image's mean luminance without pixel i. Pixel i's value is the mean of all its spp + n_i samples
(sample numbers after the first pass's for the new ones): n_i is a function of *other* pixels'
samples only, independent of pixel i's, so the estimate stays unbiased, and no sample is thrown
away. (Deciding from a pixel's own first pass and keeping those samples would bias it: a pixel whose
first samples missed a rare bright path would stop early, low; ``tests/pipeline/test_adaptive.py``
measures that bias and shows this rule has none.) The neighbourhood's max pools eight first passes,
so glints, which cluster along fibres, are found even where a pixel's own first samples missed them.
This is what converges the fireflies of sharp BCSDF lobes under delta lights, which no sampling
strategy can remove (a directional light is only reached by next-event estimation).

On a Dask scheduler (``pipeline.chunks``; ``remote`` given) each pass is a list of chunk tasks, one per
band of ``tile_size`` image rows: a worker rebuilds the integrator and camera once per command
(``RemoteFilm``: the renderer module's ``film_setup(scene, options)``, then the empty-tile compile),
renders its band's tiles into a band of the film and writes it to a scratch zarr array beside the
output (removed afterwards); the driver reads the film back and finishes it as above. Every pixel
depends only on its own random numbers, so the image is the same bytes as a local render.

Paged procedural tables (``pager``: ``stages.core.yarn.frame_pool``): a pixel whose lookups needed a yarn's
frame samples before they were resident takes its samples again once they are (``stages.render.tiles``); a
local render first runs a pilot pass, one sample in every PILOT_STRIDE^2 pixels, thrown away, that pages in
the yarns the view's paths reach in a few rounds over the whole image. Its time is part of the render's.
"""
from __future__ import annotations

import json
import os
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..progress import progress, status


@dataclass(frozen=True)
class Sampling:
    spp: int
    max_spp: int | None = None       # the most samples a pixel takes in the second pass; None or 0: no second pass
    target_error: float = 0.05

    @property
    def adaptive(self) -> bool:
        return self.max_spp is not None and self.max_spp > 0


@dataclass
class FilmRun:
    rgb: np.ndarray
    extra: dict
    image: object          # stages.render.film.FilmImage
    render_s: float
    compile_s: float
    samples: int
    refined_pixels: int
    target_error: float = 0.05

    def stats(self) -> dict:
        """The statistics every method reports: rays, paths (samples), render and compile seconds,
        pixels refined and the ``convergence`` of the image (``convergence``)."""
        return {"rays": self.image.rays, "paths": self.samples, "render_s": self.render_s,
                "compile_s": self.compile_s, "refined_pixels": self.refined_pixels,
                "convergence": convergence(self.rgb, self.extra["variance"], self.target_error)}


def relative_error(rgb, variance) -> np.ndarray:
    """Per pixel the relative standard error of its mean, sqrt(variance channel) / max(luminance,
    1 % of the image's mean luminance): how far the pixel may still move with more samples."""
    lum = rgb[..., 0] * 0.2126 + rgb[..., 1] * 0.7152 + rgb[..., 2] * 0.0722
    floor = max(0.01 * float(lum.mean()), 1e-6)
    return np.sqrt(np.maximum(np.asarray(variance, np.float64), 0.0)) / np.maximum(lum, floor)


def convergence(rgb, variance, target_error: float = 0.05) -> dict:
    """How converged an image is: the median, 95th percentile and maximum relative standard error of
    its pixels (``relative_error``), the fraction of pixels within ``target_error``, and the relative
    variance of the image's mean luminance (sum of the pixel variances / N^2, over the mean^2)."""
    err = relative_error(rgb, variance)
    lum = rgb[..., 0] * 0.2126 + rgb[..., 1] * 0.7152 + rgb[..., 2] * 0.0722
    n = err.size
    mean = float(lum.mean())
    return {"rel_error_p50": float(np.median(err)), "rel_error_p95": float(np.percentile(err, 95)),
            "rel_error_max": float(err.max()), "within_target": float(np.mean(err <= target_error)),
            "target_error": float(target_error),
            "mean_rel_variance": float(np.sum(variance, dtype=np.float64) / n / n / max(mean * mean, 1e-30))}


@dataclass(frozen=True)
class FilmSetup:
    """What a renderer module's ``film_setup(scene, options)`` returns: the integrator and camera the
    tile loop takes, the progress label, the variance mode and the statistics known before rendering."""
    label: str
    integ: object
    cam: np.ndarray
    variance: str
    stats: dict = field(default_factory=dict)
    keep: tuple = ()   # what the integrator's handles point into (an Embree scene): alive while rendering
    pager: object = None  # a FramePool whose tables the integrator holds (stages.core.yarn.frame_pool), or None


PILOT_STRIDE = 4  # paged frame samples: the pilot pass takes one sample in every PILOT_STRIDE^2 pixels


@dataclass(frozen=True)
class RemoteFilm:
    """How a Dask worker rebuilds a render's ``FilmSetup``: ``<module>.film_setup(scene, options)``."""
    module: str
    scene_path: str
    options: dict
    out: str          # the output EXR: the scratch film lies beside it
    token: str = field(default_factory=lambda: uuid.uuid4().hex)  # one command: its workers' cache key

    def build(self):
        import importlib

        from stages.render.tiles import load_tile_kernel

        from ..scene import load_scene

        t0 = time.perf_counter()
        s = importlib.import_module(self.module).film_setup(load_scene(self.scene_path), self.options)
        t1 = time.perf_counter()
        load_tile_kernel(s.integ, s.cam)
        return s, t1 - t0, time.perf_counter() - t1

    def key(self) -> str:
        return json.dumps([self.module, self.scene_path, self.token, self.options], sort_keys=True, default=str)


def remote_film(module: str, scene, options: dict) -> RemoteFilm:
    """The ``RemoteFilm`` of a render, its paths made absolute (a worker's directory is not ours)."""
    def absolute(v):
        return str(Path(v).resolve()) if isinstance(v, str) and v and Path(v).exists() else v

    opts = dict(options)
    for k in ("fibers", "tables", "grid", "bcsdf"):
        opts[k] = absolute(opts.get(k))
    opts["extra"] = {k: absolute(v) for k, v in (options.get("extra") or {}).items()}
    out = options.get("out") or ""
    return RemoteFilm(module, str(Path(scene.path).resolve()), opts, str(Path(out).resolve()) if out else "")


def _band_task(remote: RemoteFilm, seed, stride, first, counts, r0, tile_size, width, store, name):
    """Chunk task: render the image rows r0 .. r0 + len(counts) - 1 (tiles of ``tile_size``) with the
    band's sample counts and write the band of the film to the scratch array ``name``."""
    from stages.render.film import new_film, tile_grid
    from stages.render.tiles import render_tiles

    from ..chunks import open_for_chunk, worker_cache

    built = []
    s, setup_s, compile_s = worker_cache(remote.key(), lambda: built.append(1) or remote.build())
    rows = counts.shape[0]
    tiles = tile_grid(width, rows, tile_size)
    tiles[:, 0] += r0
    tiles[:, 2] += r0
    tiles = tiles[[counts[t[0] - r0:t[2] - r0, t[1]:t[3]].any() for t in tiles]]
    band = new_film(width, rows)
    t0 = time.perf_counter()
    render_tiles(s.integ, s.cam, seed, stride, first, counts, tiles, band, None, r0, s.pager)
    render_s = time.perf_counter() - t0
    open_for_chunk(store, name)[r0:r0 + rows] = band
    return {"render_s": render_s, "setup_s": setup_s if built else 0.0, "compile_s": compile_s if built else 0.0}


def _distributed_pass(label, remote, seed, stride, first, counts, tile_size, film, scratch, name):
    """One pass on the session's scheduler: a task per band of ``tile_size`` rows that has samples to
    take; the bands come back into ``film``. Returns the tasks' summed seconds (setup, compile)."""
    import zarr

    from stages.render.film import FILM_CHANNELS

    from ..chunks import ChunkTask, run_tasks

    H, W = counts.shape
    zarr.create_array(str(scratch), name=name, shape=(H, W, FILM_CHANNELS), dtype=np.float64,
                      chunks=(tile_size, W, FILM_CHANNELS), fill_value=0.0)
    bands = [(r0, min(r0 + tile_size, H)) for r0 in range(0, H, tile_size)]
    bands = [(a, b) for a, b in bands if counts[a:b].any()]
    tasks = [ChunkTask(_band_task, (remote, int(seed), int(stride), int(first), np.ascontiguousarray(counts[a:b]), a,
                                    int(tile_size), W, str(scratch), name)) for a, b in bands]
    res = run_tasks(tasks, label)
    arr = zarr.open_array(str(scratch), path=name, mode="r")
    for a, b in bands:
        film[a:b] = arr[a:b]
    return {k: sum(r[k] for r in res) for k in ("setup_s", "compile_s")}


def _pass(label, integ, cam, seed, stride, first, counts, tiles, film, threads, pager=None):
    from stages.render.tiles import render_tiles

    batch = max(1, 4 * (os.cpu_count() or 1))
    with progress(label, len(tiles)) as advance:
        if pager is not None:   # paged: the rounds that render pixels again run over the whole pass at once
            render_tiles(integ, cam, seed, stride, first, counts, tiles, film, threads, pager=pager, advance=advance)
            return
        for b0 in range(0, len(tiles), batch):
            b1 = min(b0 + batch, len(tiles))
            render_tiles(integ, cam, seed, stride, first, counts, tiles[b0:b1], film, threads, pager=pager)
            advance(b1 - b0)


def refine_counts(film, spp, sampling) -> np.ndarray:
    """New samples each pixel takes in the second pass, from its eight neighbours' first passes only
    (module doc): int64 (H, W), 0 for a pixel whose neighbourhood is converged."""
    from stages.render.film import F_Y, F_YY

    n = float(spp)
    mean = film[..., F_Y] / n
    H, W = mean.shape
    if spp > 1:
        var = np.maximum(film[..., F_YY] / n - mean * mean, 0.0) * (n / (n - 1.0))
    else:
        var = np.full(mean.shape, np.inf)
    # floor_i: 1 % of the image's mean luminance without pixel i (so nothing of pixel i enters its count)
    floor = np.maximum(0.01 * (mean.sum() - mean) / max(mean.size - 1, 1), 1e-6)
    pm = np.pad(mean, 1, constant_values=np.inf)   # outside the image: no neighbour (0 relative variance)
    pv = np.pad(var, 1, constant_values=0.0)
    need = np.zeros(mean.shape)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr == 0 and dc == 0:
                continue
            mj = pm[1 + dr:1 + dr + H, 1 + dc:1 + dc + W]
            vj = pv[1 + dr:1 + dr + H, 1 + dc:1 + dc + W]
            with np.errstate(invalid="ignore"):
                rel = np.where(vj > 0.0, vj / np.maximum(mj, floor) ** 2, 0.0)
            np.maximum(need, rel, out=need)
    want = np.ceil(np.minimum(need / sampling.target_error ** 2, 1e18)) - spp
    return np.clip(want, 0, sampling.max_spp).astype(np.int64)


def add_pass(film, counts, film2, more):
    """The film and per-pixel counts after a second pass ``film2`` of ``more`` samples per pixel: the
    film's sums add up, so each pixel's mean is over all its samples."""
    return film + film2, counts + more


def render_film(label, integ, cam, width, height, sampling: Sampling, seed, tile_size, variance,
                threads=None, remote: RemoteFilm | None = None, pager=None) -> FilmRun:
    """Render the image in one or two passes (module doc): here on ``threads`` threads, or as band
    tasks on the open Dask session when ``remote`` says how a worker rebuilds the integrator. On Dask,
    render_s is the passes' wall time less the workers' setup and compile seconds (summed over the
    workers, divided by their number) and compile_s the workers' compile seconds. ``pager``: the
    ``FramePool`` of paged procedural tables the integrator holds (``stages.render.tiles.render_tiles``;
    a Dask worker pages into its own)."""
    import shutil

    from stages.render.film import finalize, new_film, tile_grid

    from .. import chunks

    spp = int(sampling.spp)
    stride = spp + (int(sampling.max_spp) if sampling.adaptive else 0)
    counts = np.full((height, width), spp, np.int64)
    spent = {"setup_s": 0.0, "compile_s": 0.0}
    if remote is not None and chunks.distributed():
        from ..artifacts import temp_sibling

        # the scratch film lies beside the output (or, with none, in the working directory): workers see it
        scratch = temp_sibling(Path(remote.out or Path.cwd() / "loomlight-film").with_suffix(".zarr"), "tmp")

        def run_pass(text, first, cnt, film, name):
            r = _distributed_pass(text, remote, seed, stride, first, cnt, int(tile_size), film, scratch, name)
            for k in spent:
                spent[k] += r[k]

        def cleanup():
            shutil.rmtree(scratch, ignore_errors=True)
    else:
        from stages.render.tiles import load_tile_kernel

        tiles = tile_grid(width, height, int(tile_size))
        t0 = time.perf_counter()
        load_tile_kernel(integ, cam, seed, stride)
        spent["compile_s"] = time.perf_counter() - t0

        def run_pass(text, first, cnt, film, name):
            busy = np.array([cnt[r0:r1, c0:c1].any() for r0, c0, r1, c1 in tiles], bool)
            _pass(text, integ, cam, seed, stride, first, cnt, tiles[busy], film, threads, pager)

        def cleanup():
            pass
    film = new_film(width, height)
    refined = 0
    samples = int(counts.sum())
    try:
        t0 = time.perf_counter()
        if pager is not None and not (remote is not None and chunks.distributed()):
            # paged frame samples: a pilot of one sample every PILOT_STRIDE pixels each way pages in the yarns
            # the view's paths reach, so the passes' tiles seldom render again (its film is thrown away)
            from stages.render.tiles import render_tiles

            pilot = np.zeros_like(counts)
            pilot[PILOT_STRIDE // 2::PILOT_STRIDE, PILOT_STRIDE // 2::PILOT_STRIDE] = 1
            with status(f"{label}: paging in frame samples"):   # all tiles at once: rounds over them all
                render_tiles(integ, cam, seed, stride, 0, pilot, tiles, new_film(width, height), threads, pager=pager)
            pager.pilot_rounds, pager.pilot_pixels_again = pager.rounds, pager.pixels_again
        run_pass(f"{label} {width}x{height} @ {spp} spp", 0, counts, film, "pass0")
        if sampling.adaptive:
            more = refine_counts(film, spp, sampling)
            refined = int(np.count_nonzero(more))
            if refined:
                film2 = new_film(width, height)
                run_pass(f"{label}: {refined} pixels, up to {sampling.max_spp} more spp", spp, more, film2, "pass1")
                film, counts = add_pass(film, counts, film2, more)
                samples += int(more.sum())
        wall = time.perf_counter() - t0
    finally:
        cleanup()
    render_s = wall
    if remote is not None and chunks.distributed():
        render_s = max(wall - (spent["setup_s"] + spent["compile_s"]) / max(1, chunks.worker_count()), 1e-9)
    img = finalize(film, counts, variance)
    extra = {"A": img.alpha, "depth": img.depth, "variance": img.variance}
    return FilmRun(img.rgb, extra, img, render_s, spent["compile_s"], samples, refined, float(sampling.target_error))


def render_with_film(module: str, scene, options: dict):
    """(FilmSetup, FilmRun) of a render method whose module defines ``film_setup(scene, options)``."""
    import importlib

    s = importlib.import_module(module).film_setup(scene, options)
    run = render_film(s.label, s.integ, s.cam, options["width"], options["height"], sampling_of(options),
                      options["seed"], options["tile_size"], s.variance, options.get("threads"),
                      remote_film(module, scene, options), s.pager)
    return s, run


def sampling_of(options) -> Sampling:
    """The ``Sampling`` of resolved render options (``spp``, ``max_spp``, ``target_error``)."""
    max_spp = options.get("max_spp")
    return Sampling(int(options["spp"]), int(max_spp) if max_spp else None,
                    float(options.get("target_error") or 0.05))

