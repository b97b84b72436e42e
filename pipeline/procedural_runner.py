"""Runner of the procedural stage: yarn types, tables (``tables`` artifact), realization (``fibers``).

The tables artifact is self-contained for rendering: besides the ``Tables`` arrays
(stages/procedural/tables.py) it carries a copy of the yarn-curve arrays under ``curves/`` whose
segment grid is padded by each yarn's fibre-extent bound (hairs reach beyond the yarn radius), so
``load_tables(path)`` gives the (Curves, Tables) pair the lookup kernels take.
"""
from __future__ import annotations


import numpy as np

from .artifacts import Artifact, ArtifactWriter
from .errors import LoomError
from .presets import pack, resolve_yarn_types
from .yarns import CURVE_ARRAYS, curves_from_group

DEFAULT_SPACING = 0.002       # cm between realized vertices along the yarn (z_step_size / 5)
DEFAULT_BUDGET = 2 << 30      # bytes a realization may occupy
FIBER_VERTEX_BYTES = 16       # float32 xyz + float32 radius
FIBER_BYTES = 8 + 4 + 2 + 1 + 4  # offset, yarn, ply, kind, index


def yarn_types_of(yarns: Artifact, preset: str | None, radius: float | None):
    """(type dicts, packed tparams (T, NPARAM), yarn_type (Y,), albedo (Y, 3)) of a yarns artifact."""
    types = yarns.summary.get("yarn_types") or [{}]
    ytype = np.asarray(yarns["yarn_type"], np.int32)
    rad = np.asarray(yarns["radius"], np.float64)
    type_radius = [float(np.median(rad[ytype == t] if (ytype == t).any() else rad)) for t in range(len(types))]
    dicts = resolve_yarn_types(types, type_radius, preset=preset, radius=radius, file=yarns.path)
    tparams = np.stack([pack(d) for d in dicts])
    albedo = np.asarray([dicts[t]["albedo"] for t in ytype], np.float64).reshape(-1, 3)
    return dicts, tparams, ytype, albedo


def padded_curves(get, extent):
    """Curves with the segment grid rebuilt, padded by each yarn's extent bound + delta."""
    from stages.ingest.spline_process import build_grid

    cv = curves_from_group(get)
    pad = np.ascontiguousarray(extent + cv.delta, np.float64)
    glo, gcell, gdims, gstart, gitems = build_grid(cv, pad)
    return cv._replace(grid_lo=np.asarray(glo, np.float64), grid_cell=np.array([gcell], np.float64),
                       grid_dims=np.asarray(gdims, np.int64), grid_cell_start=np.asarray(gstart, np.int64),
                       grid_items=np.asarray(gitems, np.int32), grid_pad=pad)


def build(yarns_path, preset=None, radius=None, seed=0, nbins=32, hair_mode="hybrid", derive=True):
    """(cv, tab, info, type dicts, yarns artifact) for a yarns artifact; derive: also the lookups'
    load-time structures (tables.derive_lookup_accel)."""
    from stages.procedural.tables import build_tables
    from stages.core.yarn.accel import derive_lookup_accel
    from stages.core.yarn.model import extent_bound

    yarns = Artifact(yarns_path, kind="yarns")
    dicts, tparams, ytype, albedo = yarn_types_of(yarns, preset, radius)
    ext = np.array([extent_bound(tparams[t]) for t in ytype])
    cv = padded_curves(lambda n: yarns[n], ext)
    mode = {"hybrid": 0, "free": 1}[hair_mode]
    tab, info = build_tables(cv, tparams, ytype, albedo, int(seed), nbins=int(nbins), hair_mode=mode)
    if derive:
        tab = derive_lookup_accel(cv, tab)
    return cv, tab, info, dicts, yarns


def check_options(preset, radius, nbins=None, spacing=None, budget=None):
    from .presets import load_preset

    if preset is not None:
        load_preset(preset)
    if radius is not None and not radius > 0:
        raise LoomError(None, "--radius", f"yarn radius must be positive, got {radius}")
    if nbins is not None and nbins < 1:
        raise LoomError(None, "--bins", f"need at least one azimuth bin, got {nbins}")
    if spacing is not None and not spacing > 0:
        raise LoomError(None, "--spacing", f"sample spacing must be positive, got {spacing}")
    if budget is not None and not budget > 0:
        raise LoomError(None, "--budget", f"memory budget must be positive, got {budget}")


def _type_summary(dicts):
    keep = ("name", "scale", "ply_num", "fiber_num", "yarn_radius", "fiber_radius", "density", "roughness", "albedo")
    return [{k: d[k] for k in keep if k in d} for d in dicts]


def run_tables(yarns_path, out, preset=None, radius=None, seed=0, nbins=32, hair_mode="hybrid", force=False):
    from stages.core.yarn.tables import STORED_FIELDS, table_bytes

    check_options(preset, radius, nbins)
    if hair_mode not in ("hybrid", "free"):
        raise LoomError(None, "--hair-mode", f"must be 'hybrid' or 'free', got {hair_mode!r}")
    params = {"preset": preset, "radius": radius, "seed": int(seed), "bins": int(nbins), "hair_mode": hair_mode}
    w = ArtifactWriter(out, kind="tables", stage="tables", params=params, inputs={"yarns": yarns_path})
    if w.up_to_date() and not force:
        return {"skipped": True}
    cv, tab, info, dicts, yarns = build(yarns_path, preset, radius, seed, nbins, hair_mode, derive=False)
    parts = table_bytes(tab)
    with w:
        for name in STORED_FIELDS:
            w.write(name, np.asarray(getattr(tab, name)))
        w.group.create_group("curves")
        for name in CURVE_ARRAYS:
            w.write(f"curves/{name}", np.asarray(getattr(cv, _cv_field(name))))
        curve_bytes = int(sum(np.asarray(getattr(cv, _cv_field(n))).nbytes for n in CURVE_ARRAYS))
        folded = int(np.sum(info["folded"]))
        w.summary.update({
            "kind": "tables", "yarns": int(len(tab.yarn_type)), "yarn_types": _type_summary(dicts),
            "hair_mode": hair_mode, "bins": int(nbins), "seed": int(seed),
            "regular_fibers": int(len(tab.fib_R)), "hairs": int(tab.hair_count.sum()),
            "bytes": {"tables": int(sum(parts.values())), "regular": parts["regular"], "hair": parts["hair"],
                      "loop": parts["loop"], "per_yarn": parts["per_yarn"], "curves": curve_bytes},
            "folded_yarns": folded,
            "curvature_max": float(np.max(info["curvature_max"])) if len(info["curvature_max"]) else 0.0,
            "exact": folded == 0,
        })
    return {"skipped": False, "yarns": int(len(tab.yarn_type)), "folded": folded}


def _cv_field(name):
    return "offsets" if name == "curve_offsets" else name


def load_tables(path):
    """(Curves, Tables, Artifact) of a tables artifact (self-contained: curves from its copy)."""
    from stages.core.yarn.tables import STORED_FIELDS, Tables, empty_accel
    from stages.core.yarn.accel import derive_lookup_accel

    art = Artifact(path, kind="tables")
    missing = [f for f in STORED_FIELDS if f not in art]
    if missing:
        raise LoomError(art.path, missing[0], "array missing from the tables artifact (rebuild it with loomlight tables)")
    stored = {f: np.ascontiguousarray(art[f]) for f in STORED_FIELDS}
    tab = Tables(**stored, **dict(zip([f for f in Tables._fields if f not in stored],
                                      empty_accel(len(stored["yarn_type"])))))
    cv = curves_from_group(lambda n: art[f"curves/{n}"])
    return cv, derive_lookup_accel(cv, tab), art


# ------------------------------------------------------------------------------------------------
# realization
def realized_size(tab, curve_length, spacing):
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
    return nv * FIBER_VERTEX_BYTES + nf * FIBER_BYTES, nv, nf, per_kind, fibres_kind


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
            "yarn_types": _type_summary(dicts),
        })
    return {"skipped": False, "fibers": int(nfib), "vertices": int(verts), "bytes": int(nbytes)}
