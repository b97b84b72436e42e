"""Build the render-time fibre cache of ``volpath --source procedural`` (``--cache MiB``).

The design is in ``stages.render.media.fibre_cache`` (bricks, samples, pilot, ranking) and
docs/architecture.md ("Fibre cache"). This module glues the stages: it ranks the bricks, picks the
prefix that fits the budget, realizes the needed windows of the yarns with the realization's own
kernels (``stages.procedural.realize``: the same pieces, random numbers and vertex floats as
``loomlight realize`` at ``spacing``), rounds them to float32 as a fibers artifact stores them, and
puts them in a capsule BVH (``stages.core.geometry.bvh``) of which only the 4-wide nodes are kept.

Memory: ``CACHE_VERTEX_BYTES`` per cached vertex is the peak of the build (float64 vertices and
radii, segment arrays, the SAH build's boxes and the wide nodes), measured on the demo swatch
(``bench/bench_volpath.py`` reports the measured bytes next to the estimate). The budget is compared
with that estimate before anything is realized: bricks are taken while their estimated bytes fit.
"""
from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from .errors import LoomError
from .progress import warn

CACHE_VERTEX_BYTES = 320   # peak bytes of a cached vertex during the build (see the module doc)
DEFAULT_CACHE_MIB = 2048   # --cache default (render.cache in the scene), at most a quarter of the available memory
DEFAULT_SPACING = 0.002    # cm between cached vertices: ``loomlight realize``'s default
MAX_FINE_K = 16            # a refined majorant cell holds at most 16^3 sub-cells (``cached_majorant``)
MAX_FINE_BYTES = 64 * 2**20  # the refined cells' sub-cell majorants hold at most this (k shrinks to fit)


class CacheBuild(NamedTuple):
    medium: object            # stages.render.media.fibre_cache.FibreCacheMedium
    majorant: object          # its MajorantGrid: inside cached bricks from the cached capsules
    info: dict                # statistics for the render artifact


def default_cache_mib() -> float:
    """The default budget: DEFAULT_CACHE_MIB, or a quarter of the available memory when that is less."""
    from .memory import available_bytes

    return float(min(DEFAULT_CACHE_MIB, np.floor(available_bytes() / 4 / 2**20)))


def cache_budget_mib(value, place: str = "--cache") -> float:
    """The budget in MiB: a finite number >= 0 (0: no cache, lookups only); past the available memory
    it is clamped to it with a warning."""
    from .memory import available_bytes

    try:
        mib = float(value)
    except (TypeError, ValueError):
        raise LoomError(None, place, f"the fibre cache budget must be a number of MiB, got {value!r}") from None
    if not np.isfinite(mib) or mib < 0:
        raise LoomError(None, place,
                        f"the fibre cache budget must be a finite number of MiB >= 0 (0: no cache), got {value}")
    free = available_bytes() / 2**20
    if mib > free:
        warn(f"{place} {mib:g} MiB is more than the available memory ({free:.0f} MiB): using {free:.0f} MiB")
        mib = float(np.floor(free))
    return mib


def _medium(cv, tab, grid, cached, bvh, fibre_yarn, fibre_id):
    from stages.core.yarn.model import DENSITY, ROUGHNESS
    from stages.render.media.fibre_cache import FibreCacheMedium
    from stages.render.media.procedural_medium import ProceduralMedium

    tp = tab.tparams[tab.yarn_type]
    return FibreCacheMedium(ProceduralMedium(cv, tab), grid.lo, np.full(3, 1.0 / grid.size), grid.res, cached, bvh,
                            fibre_yarn, fibre_id, np.ascontiguousarray(tp[:, DENSITY]),
                            np.ascontiguousarray(tab.yarn_albedo),
                            np.ascontiguousarray(tp[:, ROUGHNESS]), bvh.wide_box, bvh.wide_child, bvh.prims,
                            bvh.seg_fiber, bvh.points, bvh.seg_a)


def empty_cache(cv, tab, grid):
    """A ``FibreCacheMedium`` that caches no brick: every lookup is the exact procedural one, through the
    brick test (one array read). A render without a cache uses it rather than the bare ``ProceduralMedium``
    so that the volpath integrator is compiled for one medium type whatever the budget (its compilation
    takes about a minute on a cold cache); the pictures are the same bytes (``tests/render/test_fibre_cache``)."""
    from stages.core.geometry.bvh import empty_fiber_bvh

    cached = np.zeros(int(np.prod(grid.res)), np.uint8)
    return _medium(cv, tab, grid, cached, empty_fiber_bvh(), np.zeros(0, np.int32), np.zeros(0, np.int64))


def _vertices_per_length(tab, curve_length, spacing) -> np.ndarray:
    from stages.procedural.realize import yarn_counts

    out = np.zeros(len(curve_length))
    for c, L in enumerate(curve_length):
        v, _ = yarn_counts(tab, c, float(L), float(spacing))
        out[c] = float(v.sum()) / max(float(L), 1e-12)
    return out


def build_fibre_cache(cv, tab, maj, cam, width, height, budget_mib, spacing=DEFAULT_SPACING,
                      fine_cell=None) -> CacheBuild:
    """The ``FibreCacheMedium`` of the procedural source ``(cv, tab)`` seen by ``cam`` at width x height,
    within ``budget_mib``; where nothing is cached (budget 0, too small for one brick, or tables of the
    realization-free hair mode, whose hairs are never stored: ``info["cache_skipped"]`` says so) a cache
    of no bricks (``empty_cache``), whose every lookup is the procedural one. A partial cache is kept however
    little of the view it holds: every brick it holds answers faster than the lookups, and an uncached
    lookup through it costs what a bare one does (``bench_volpath``'s budget curve). ``fine_cell``: refine
    the majorant's cells inside cached bricks to about this size (``cached_majorant``; None: never)."""
    from stages.core.geometry.bvh import build_fiber_bvh
    from stages.procedural.realize import realize_fill_window, window_pieces, yarn_plan
    from stages.render.camera import camera_ray
    from stages.render.media.fibre_cache import (
        PILOT_DEPTH,
        brick_grid,
        brick_order,
        brick_samples,
        choose_bricks,
        fibre_ids,
        occupied_bricks,
        pilot_bricks,
        windows,
        yarn_samples,
    )

    t0 = time.perf_counter()
    Y = len(tab.yarn_type)
    # a capped majorant grid (a large cloth, fine_cell given) has its box from the yarns' extent tubes: centred
    # bricks split the cloth at its middle
    grid = brick_grid(maj.lo, maj.hi, float(np.max(tab.yarn_extent)) if Y else 1.0, centred=fine_cell is not None)
    budget = float(budget_mib) * 2**20
    info = {"cache_budget_mib": float(budget_mib), "cache_bricks": [int(v) for v in grid.res],
            "cache_brick_size": float(grid.size), "cache_spacing": float(spacing)}

    def bare(**why):
        """Nothing cached: a cache of no bricks, every lookup procedural (``empty_cache``)."""
        info.update({"cache_bricks_cached": 0, "cache_fibres": 0, "cache_segments": 0, "cache_bytes": 0,
                     "cache_estimate_bytes": 0, **why, "cache_build_s": time.perf_counter() - t0})
        return CacheBuild(empty_cache(cv, tab, grid), maj, info)

    if budget <= 0 or Y == 0:
        return bare()
    if int(tab.hair_mode[0]) != 0:
        # realization-free hairs are drawn from the implicit quad-tree at each lookup; the tables store none,
        # so the cache could not realize them (yarn_plan would read hair arrays that are empty)
        return bare(cache_skipped="hair mode free: the tables store no hairs to realize")

    occ = occupied_bricks(maj, grid.lo, grid.size, grid.res)
    stride = max(1, max(int(width), int(height)) // 128)
    steps, seen = pilot_bricks(maj, cam, int(width), int(height), stride, grid.lo, grid.size, grid.res, PILOT_DEPTH)
    eye, _ = camera_ray(cam, 0.5 * height, 0.5 * width, 0.0, 0.0)
    order = brick_order(occ, steps, seen, grid.lo, grid.size, grid.res, eye)
    samples = yarn_samples(cv, tab, 0.5 * grid.size, float(spacing))
    off, items = brick_samples(samples, grid.lo, grid.size, grid.res)
    vpl = _vertices_per_length(tab, cv.curve_length, spacing)
    sample_bytes = vpl[samples.yarn] * (samples.s1 - samples.s0) * CACHE_VERTEX_BYTES
    cached, need, est = choose_bricks(order, off, items, sample_bytes, budget)
    share = float(steps[cached == 1].sum()) / max(float(steps.sum()), 1.0)
    if not cached.any():
        return bare(cache_seen_share=share)
    need = need.astype(bool)

    cols = {k: [] for k in ("yarn", "ply", "idx", "kind", "a0", "a1", "hz1", "hze", "first", "nfull", "count")}
    for c, (w0, w1) in enumerate(windows(samples, need, Y)):
        if not len(w0):
            continue
        L = float(cv.curve_length[c])
        ply, idx, kind, a0, a1, hz1, hze, nv = yarn_plan(tab, c, L, float(spacing))
        piece, first, count = window_pieces(kind, a0, a1, hz1, hze, nv, w0, w1, float(spacing), L,
                                            L if cv.closed[c] else 0.0)
        for k, v in (("ply", ply), ("idx", idx), ("kind", kind), ("a0", a0), ("a1", a1), ("hz1", hz1), ("hze", hze),
                     ("nfull", nv)):
            cols[k].append(v[piece])
        cols["yarn"].append(np.full(len(piece), c, np.int32))
        cols["first"].append(first)
        cols["count"].append(count)
    if not cols["yarn"]:
        return bare()
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    offsets = np.zeros(len(cat["yarn"]) + 1, np.int64)
    np.cumsum(cat["count"], out=offsets[1:])
    V = int(offsets[-1])
    points = np.empty((V, 3))
    radius = np.empty(V)
    realize_fill_window(cv, tab, cat["yarn"], cat["ply"], cat["idx"], cat["kind"], cat["a0"], cat["a1"], cat["hz1"],
                        cat["hze"], cat["first"], cat["nfull"], offsets, points, radius)
    # the fibers artifact's float32 vertices and radii: the same capsules as the realized source
    points[...] = points.astype(np.float32)
    radius[...] = radius.astype(np.float32)
    del cat["first"], cat["count"], cat["a0"], cat["a1"], cat["hz1"], cat["hze"], cat["nfull"]
    bvh, _ = build_fiber_bvh(points, offsets, radius, keep_binary=False)  # queries walk the wide nodes only
    del points, radius
    ids = fibre_ids(cat["yarn"], cat["ply"], cat["kind"], cat["idx"])
    med = _medium(cv, tab, grid, cached, bvh, cat["yarn"], ids)
    held = sum(int(np.asarray(a).nbytes) for a in bvh) + cached.nbytes + ids.nbytes + cat["yarn"].nbytes
    info.update({"cache_bricks_cached": int(cached.sum()), "cache_bricks_occupied": int(np.sum(occ)),
                 "cache_bricks_seen": int(np.sum(steps > 0)), "cache_fibres": int(len(ids)), "cache_vertices": V,
                 "cache_segments": int(len(bvh.seg_a)), "cache_bytes": held, "cache_estimate_bytes": float(est),
                 "cache_complete": bool(cached.sum() == len(order)), "cache_seen_share": share,
                 "cache_build_s": time.perf_counter() - t0})
    majorant, fine_info = cached_majorant(med, maj, fine_cell)
    info.update(fine_info)
    return CacheBuild(med, majorant, info)


def cached_majorant(med, maj, fine_cell=None):
    """``maj`` with the cells inside cached bricks bounded by the cached capsules (tighter than the
    procedural tubes: as many null collisions as the realized source), and, where ``maj``'s cells are
    coarser than ``fine_cell`` (a large cloth's grid is capped at MAX_MAJORANT_CELLS), those cells
    refined into k^3 sub-cells of about ``fine_cell`` (k <= MAX_FINE_K; ``stages.render.media.tracking``):
    (MajorantGrid, info)."""
    from stages.render.media.fibre_cache import cells_in_cached_bricks
    from stages.render.media.tracking import fine_majorants_from_prims, majorants_from_prims, make_majorant_grid

    inner = cells_in_cached_bricks(maj, med.brick_lo, 1.0 / med.brick_inv[0], med.brick_res, med.cached)
    mu = majorants_from_prims(med.prims, med.seg_fiber, med.fibre_yarn, med.yarn_density, maj.lo, maj.hi, maj.res)
    mu = np.where(inner, mu, maj.mu)
    cs = float(np.max((maj.hi - maj.lo) / maj.res))
    refine = inner & (mu > 0)
    blocks = int(refine.sum())
    k = min(MAX_FINE_K, int(np.ceil(cs / fine_cell - 1e-9))) if fine_cell else 1
    while k > 1 and blocks * k ** 3 * 8 > MAX_FINE_BYTES:
        k -= 1
    if k < 2 or blocks == 0:
        return make_majorant_grid(maj.lo, maj.hi, maj.res, mu), {"majorant_fine_k": 1, "majorant_fine_cells": 0}
    fine = np.full(refine.shape, -1, np.int32)
    fine[refine] = np.arange(blocks, dtype=np.int32)
    fine_mu = fine_majorants_from_prims(med.prims, med.seg_fiber, med.fibre_yarn, med.yarn_density, maj.lo, maj.hi,
                                        maj.res, fine, blocks, k)
    info = {"majorant_fine_k": k, "majorant_fine_cells": blocks * k ** 3,
            "majorant_fine_occupied": float(np.mean(fine_mu > 0))}
    return make_majorant_grid(maj.lo, maj.hi, maj.res, mu, fine, fine_mu), info
