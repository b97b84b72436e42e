"""Realize runner: every fibre of a yarns artifact as a fabric-space polyline (``fibers`` artifact).

``run_realize`` builds the tables (``pipeline.runners.tables.build``: the same random numbers as
``loomlight tables``, so both describe one fabric), counts the full realization before building it
(``realized_size``: 16 bytes a vertex, 19 bytes a fibre), then realizes regular, loop and hair fibres
(``stages.procedural.realize``) and publishes them with radius, yarn, ply, kind and index per fibre.

The vertices are chunk tasks (``pipeline.chunks``), one per chunk of ``VERTEX_CHUNK`` vertices of the
stored arrays: a task realizes the pieces (fibres) that overlap its vertex range (float64, converted
to the stored float32), writes its range of ``points`` and ``point_radius`` straight into the artifact
under construction and returns its chord error and bounds. A piece that straddles two chunks is
realized by both tasks, identically. The tasks run here or on a Dask scheduler (``--scheduler``); a
worker rebuilds the tables once (the same random numbers), the driver never holds the vertices.

Memory: before anything is built the peak is estimated from the yarns artifact, the yarn types and
the spacing (``realization_estimate``: the tables build plus the expected vertices and pieces) and
refused past the budget; once the tables exist the exact counts (``realized_size``, the plan's
per-yarn capacities) are checked again before the plan and the vertices are allocated.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..artifacts import ArtifactWriter
from ..memory import Estimate, budget as memory_budget
from .tables import build, check_options, prepare, slot_hairs, tables_estimate
from .yarn_types import type_summary

DEFAULT_SPACING = 0.002       # cm between realized vertices along the yarn (z_step_size / 5)
FIBER_VERTEX_BYTES = 16       # float32 xyz + float32 radius
FIBER_BYTES = 8 + 4 + 2 + 1 + 4  # offset, yarn, ply, kind, index
PLAN_BYTES = 47               # yarn_plan's columns per piece of capacity (ply, index, kind, a0, a1, hair z1/ze, nv)
PIECE_BYTES = 2 * PLAN_BYTES + 4 + FIBER_BYTES  # the concatenated plan beside the per-yarn buffers,
                                                # + the stored columns
BLOCK_VERTICES = 1 << 19      # vertices realized (float64) and measured (chord_error) per block (estimates)
VERTEX_CHUNK = 1 << 18        # vertices per stored chunk of points / point_radius, and per chunk task
BLOCK_BYTES = BLOCK_VERTICES * (32 + 150)  # a block's float64 vertices and radii, chord_error's temporaries


class RealizedSize(NamedTuple):
    nbytes: int               # bytes of the whole realization
    vertices: int
    fibers: int
    vertices_by_kind: dict    # {1 regular, 2 loop, 3 hair: vertices}
    fibers_by_kind: dict      # {1 regular, 2 loop, 3 hair: fibres}


def realized_size(tab, curve_length, spacing) -> RealizedSize:
    """(bytes, vertices, fibres, vertices by kind {1, 2, 3}, fibres by kind) of the full realization,
    counted yarn by yarn without listing pieces or building geometry."""
    from stages.procedural.realize import yarn_counts

    verts = np.zeros(4, np.int64)
    pieces = np.zeros(4, np.int64)
    for c in range(len(tab.yarn_type)):
        v, p = yarn_counts(tab, c, float(curve_length[c]), float(spacing))
        verts += v
        pieces += p
    per_kind = {k: int(verts[k]) for k in (1, 2, 3)}
    fibres_kind = {k: int(pieces[k]) for k in (1, 2, 3)}
    nv, nf = int(verts.sum()), int(pieces.sum())
    return RealizedSize(nv * FIBER_VERTEX_BYTES + nf * FIBER_BYTES, nv, nf, per_kind, fibres_kind)


def _plan_capacity(tp, length, hairs) -> np.ndarray:
    """yarn_plan's buffer capacity (pieces) for yarns of one type with these lengths and hair counts."""
    from stages.core.yarn import model as M

    length = np.asarray(length, np.float64)
    ncyc = np.floor(length * tp[M.S_MIG] / tp[M.ALPHA]) + 4 if tp[M.USE_MIGRATION] else np.full(len(length), 3.0)
    return float(tp[M.PLY_NUM]) * float(tp[M.FIBER_NUM]) * (2 * ncyc + 2) + hairs + 1


def _vertex_parts(est: Estimate, vertices: float, pieces: float, capacity: float) -> Estimate:
    est.add("realized fibres", vertices * FIBER_VERTEX_BYTES + pieces * PIECE_BYTES + capacity * PLAN_BYTES
            + min(vertices, BLOCK_VERTICES) / BLOCK_VERTICES * BLOCK_BYTES,
            f"{int(vertices):,} vertices, {int(pieces):,} fibres")
    return est


def realization_estimate(prep, spacing: float) -> Estimate:
    """The realization's memory from the yarn types and lengths alone (expected counts): per regular
    fibre its length over the spacing plus one vertex per piece (two more pieces per loop), per hair
    its expected yarn-space length over the spacing, the plan's per-yarn buffers."""
    from stages.core.yarn import model as M

    est = Estimate("loomlight realize")
    verts = pieces = cap = 0.0
    for t, tp in enumerate(prep.types.tparams):
        L = prep.curve_length[prep.types.yarn_type == t]
        if not len(L):
            continue
        P, N = float(tp[M.PLY_NUM]), float(tp[M.FIBER_NUM])
        loops = (tp[M.P_LOOP] * (L * tp[M.S_MIG] / tp[M.ALPHA] + 2) if tp[M.USE_FLYAWAYS] and tp[M.USE_MIGRATION]
                 else 0 * L)
        fib_pieces = P * N * (1 + 2 * loops)
        verts += float(np.sum(P * N * L / spacing + fib_pieces))
        pieces += float(np.sum(fib_pieces))
        n = slot_hairs(tp, L)
        rm = tp[M.HAIR_RMAX] + tp[M.PLY_RADIUS]
        def rms(mu, sig, tp=tp):
            return float(np.hypot(tp[mu], tp[sig]))
        speed = (rms(M.ZE_MU, M.ZE_SIG) * (1 + rm * 2 * np.pi / tp[M.YARN_ALPHA]) + rms(M.RE_MU, M.RE_SIG)
                 + tp[M.HAIR_RMAX] * rms(M.PE_MU, M.PE_SIG))
        verts += float(np.sum(P * n * (speed / spacing + 2)))
        pieces += float(np.sum(P * n))
        cap += float(np.sum(_plan_capacity(tp, L, P * n)))
    return _vertex_parts(est, verts, pieces, cap)


def _tables_key(yarns_path, yarns_hash, preset, radius, seed):
    return ("realize-tables", str(yarns_path), yarns_hash, preset, radius, int(seed))


def _realize_task(yarns_path, yarns_hash, preset, radius, seed, store, v0, v1, plan, offsets):
    """Chunk task: the vertices v0..v1-1 of the realization; ``plan`` the pieces overlapping them (the
    plan's columns), ``offsets`` their vertex offsets (absolute, one more than pieces)."""
    from stages.procedural.realize import chord_error, realize_fill

    from ..chunks import open_for_chunk, worker_cache

    def tables():
        b = build(yarns_path, preset, radius, seed, hair_mode="hybrid", derive=False)
        return b.cv, b.tab

    cv, tab = worker_cache(_tables_key(yarns_path, yarns_hash, preset, radius, seed), tables)
    lo, hi = int(offsets[0]), int(offsets[-1])
    pts = np.empty((hi - lo, 3))
    rad = np.empty(hi - lo)
    realize_fill(cv, tab, *plan, offsets - lo, pts, rad)
    pts32 = pts[v0 - lo:v1 - lo].astype(np.float32)
    sag, turn = chord_error(pts.astype(np.float32), offsets - lo)
    open_for_chunk(store, "points")[v0:v1] = pts32
    open_for_chunk(store, "point_radius")[v0:v1] = rad[v0 - lo:v1 - lo].astype(np.float32)
    return {"sag": float(sag), "turn": float(turn), "lo": pts32.min(axis=0), "hi": pts32.max(axis=0)}


def run_realize(yarns_path, out, preset=None, radius=None, seed=0, spacing=DEFAULT_SPACING,
                budget=None, force=False, scheduler=None):
    """Build (or skip when up to date) the fibers artifact; ``budget`` (``pipeline.memory.budget``, default
    a fraction of the available memory): refuse before building when the estimated peak exceeds it;
    ``scheduler`` (``pipeline.chunks``): where the vertex chunk tasks run."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from stages.procedural.realize import realize_plan

    from .. import compilation
    from ..chunks import ChunkTask, run_tasks, session, worker_cache

    compilation.watch()
    check_options(preset, radius, spacing=spacing)
    params = {"preset": preset, "radius": radius, "seed": int(seed), "spacing": float(spacing)}
    w = ArtifactWriter(out, kind="fibers", stage="realize", params=params, inputs={"yarns": (yarns_path, "yarns")},
                       started=t_start)
    if w.up_to_date() and not force:
        return {"skipped": True}
    limit = budget or memory_budget()
    prep = prepare(yarns_path, preset, radius)
    tables_estimate(prep, 32, "hybrid", what="loomlight realize").extend(realization_estimate(prep, spacing)).check(
        limit, prep.yarns.path)
    cv, tab, info, dicts, yarns = build(yarns_path, preset, radius, seed, hair_mode="hybrid", derive=False,
                                        prepared=prep)
    nbytes, verts, nfib, per_kind, fib_kind = realized_size(tab, cv.curve_length, spacing)
    hairs = np.add.reduceat(tab.hair_count, tab.yarn_ply_off[:-1]) if len(tab.yarn_type) else np.zeros(0)
    cap = sum(float(_plan_capacity(tab.tparams[t], cv.curve_length[c:c + 1], hairs[c])[0])
              for c, t in enumerate(tab.yarn_type))
    exact = Estimate("loomlight realize").add("tables", sum(np.asarray(a).nbytes for a in tab)
                                              + sum(np.asarray(a).nbytes for a in cv))
    _vertex_parts(exact, verts, nfib, cap).check(limit, yarns.path)

    yarn, ply, idx, kind, a0, a1, hz1, hze, nv = realize_plan(tab, cv.curve_length, spacing)
    assert int(nv.sum()) == verts and len(nv) == nfib
    offsets = np.zeros(len(nv) + 1, np.int64)
    np.cumsum(nv, out=offsets[1:])
    yarns_abs = str(Path(yarns_path).resolve())  # chunk tasks may run in another directory
    key = _tables_key(yarns_abs, yarns.meta["content_hash"], preset, radius, seed)
    plan = (yarn, ply, idx, kind, a0, a1, hz1, hze)
    with session(scheduler), w:
        worker_cache(key, lambda: (cv, tab))  # local tasks take the tables built above
        ch = (VERTEX_CHUNK, 3)
        w.create("points", (verts, 3), np.float32, ch, dimension_names=("point", "xyz"))
        w.create("point_radius", (verts,), np.float32, ch[:1])
        tasks = []
        for v0 in range(0, verts, VERTEX_CHUNK):
            v1 = min(v0 + VERTEX_CHUNK, verts)
            a = int(np.searchsorted(offsets, v0, side="right")) - 1
            b = int(np.searchsorted(offsets, v1, side="left"))
            tasks.append(ChunkTask(_realize_task, (yarns_abs, yarns.meta["content_hash"], preset, radius,
                                                   int(seed), str(w.store_path), v0, v1,
                                                   tuple(c[a:b] for c in plan), offsets[a:b + 1])))
        parts = run_tasks(tasks, f"realize {nfib:,} fibres")
        sag = max((r["sag"] for r in parts), default=0.0)
        turn = max((r["turn"] for r in parts), default=0.0)
        bounds = ([np.min([r["lo"] for r in parts], axis=0).tolist(), np.max([r["hi"] for r in parts], axis=0).tolist()]
                  if parts else [[0, 0, 0], [0, 0, 0]])
        w.write("fiber_offsets", offsets)
        w.write("fiber_yarn", yarn.astype(np.int32))
        w.write("fiber_ply", ply.astype(np.int16))
        w.write("fiber_kind", kind.astype(np.int8))
        w.write("fiber_index", idx.astype(np.int32))
        w.write("yarn_albedo", tab.yarn_albedo.astype(np.float32))
        w.summary.update({
            "kind": "fibers", "fibers": int(nfib), "vertices": int(verts), "yarns": int(len(tab.yarn_type)),
            "spacing": float(spacing), "max_chord_error": sag, "max_turn_rad": turn,
            "fibers_by_kind": {"regular": fib_kind[1], "loop": fib_kind[2], "hair": fib_kind[3]},
            "bytes": {"total": int(nbytes),
                      "regular": per_kind[1] * FIBER_VERTEX_BYTES + fib_kind[1] * FIBER_BYTES,
                      "loop": per_kind[2] * FIBER_VERTEX_BYTES + fib_kind[2] * FIBER_BYTES,
                      "hair": per_kind[3] * FIBER_VERTEX_BYTES + fib_kind[3] * FIBER_BYTES},
            "bounds": bounds,
            "yarn_types": type_summary(dicts),
            "ingest_identity": yarns.summary.get("ingest_identity"),
        })
    return {"skipped": False, "fibers": int(nfib), "vertices": int(verts), "bytes": int(nbytes)}

