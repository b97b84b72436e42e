"""Realize runner: every fibre of a yarns artifact as a fabric-space polyline (``fibers`` artifact).

``run_realize`` builds the tables (``pipeline.runners.tables.build``: the same random numbers as
``loomlight tables``, so both describe one fabric), counts the full realization before building it
(``realized_size``: 16 bytes a vertex, 19 bytes a fibre) and refuses one over the memory budget,
then realizes regular, loop and hair fibres (``stages.procedural.realize``) and publishes them with
radius, yarn, ply, kind and index per fibre.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..artifacts import ArtifactWriter
from ..errors import LoomError
from .tables import build, check_options
from .yarn_types import type_summary

DEFAULT_SPACING = 0.002       # cm between realized vertices along the yarn (z_step_size / 5)
DEFAULT_BUDGET = 2 << 30      # bytes a realization may occupy
FIBER_VERTEX_BYTES = 16       # float32 xyz + float32 radius
FIBER_BYTES = 8 + 4 + 2 + 1 + 4  # offset, yarn, ply, kind, index


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


def run_realize(yarns_path, out, preset=None, radius=None, seed=0, spacing=DEFAULT_SPACING,
                budget=DEFAULT_BUDGET, force=False):
    from stages.procedural.realize import chord_error, realize_fill

    check_options(preset, radius, spacing=spacing, budget=budget)
    params = {"preset": preset, "radius": radius, "seed": int(seed), "spacing": float(spacing)}
    w = ArtifactWriter(out, kind="fibers", stage="realize", params=params, inputs={"yarns": yarns_path})
    if w.up_to_date() and not force:
        return {"skipped": True}
    cv, tab, info, dicts, yarns = build(yarns_path, preset, radius, seed, hair_mode="hybrid")
    nbytes, verts, nfib, per_kind, fib_kind = realized_size(tab, cv.curve_length, spacing)
    if nbytes > budget:
        raise LoomError(out, "--budget", f"the realization would take {nbytes / 2**20:.1f} MiB ({verts} vertices, "
                        f"{nfib} fibres), over the budget of {budget / 2**20:.1f} MiB; raise --budget or --spacing")
    from stages.procedural.realize import realize_plan

    yarn, ply, idx, kind, a0, a1, hz1, hze, nv = realize_plan(tab, cv.curve_length, spacing)
    assert int(nv.sum()) == verts and len(nv) == nfib
    offsets = np.zeros(len(nv) + 1, np.int64)
    np.cumsum(nv, out=offsets[1:])
    pts = np.empty((verts, 3))
    rad = np.empty(verts)
    realize_fill(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, offsets, pts, rad)
    pts32 = pts.astype(np.float32)
    del pts
    sag, turn = chord_error(pts32, offsets)
    with w:
        w.write("points", pts32, dimension_names=("point", "xyz"))
        w.write("point_radius", rad.astype(np.float32))
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
            "bounds": [pts32.min(axis=0).tolist(), pts32.max(axis=0).tolist()] if verts else [[0, 0, 0], [0, 0, 0]],
            "yarn_types": type_summary(dicts),
        })
    return {"skipped": False, "fibers": int(nfib), "vertices": int(verts), "bytes": int(nbytes)}
