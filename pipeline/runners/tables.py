"""Tables runner: seed 000's realization-minimizing tables of a yarns artifact (``tables`` artifact).

The tables artifact is self-contained for rendering: besides the ``Tables`` arrays
(stages/procedural/tables.py) it carries a copy of the yarn-curve arrays under ``curves/`` whose
segment grid is padded by each yarn's fibre-extent bound (hairs reach beyond the yarn radius), so
``load_tables(path)`` gives the (Curves, Tables) pair the lookup kernels take. ``build`` makes the
same (Curves, Tables) in memory from a yarns artifact (the realize runner and Table 1 use it);
``check_options`` checks the options the tables and realize commands share.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..artifacts import Artifact, ArtifactWriter
from ..errors import LoomError
from ..limits import check_positive
from ..yarns import CURVE_ARRAYS, curves_from_group
from .yarn_types import type_summary, yarn_types_of


class BuiltTables(NamedTuple):
    cv: object        # Curves, segment grid padded by the fibre extent
    tab: object       # Tables
    info: dict        # build_tables' diagnostics (folded, curvature_max)
    dicts: list       # resolved yarn-type dicts
    yarns: Artifact   # the yarns artifact read


def padded_curves(get, extent):
    """Curves with the segment grid rebuilt, padded by each yarn's extent bound + delta."""
    from stages.ingest.spline_process import build_grid

    cv = curves_from_group(get)
    pad = np.ascontiguousarray(extent + cv.delta, np.float64)
    glo, gcell, gdims, gstart, gitems = build_grid(cv, pad)
    return cv._replace(grid_lo=np.asarray(glo, np.float64), grid_cell=np.array([gcell], np.float64),
                       grid_dims=np.asarray(gdims, np.int64), grid_cell_start=np.asarray(gstart, np.int64),
                       grid_items=np.asarray(gitems, np.int32), grid_pad=pad)


def build(yarns_path, preset=None, radius=None, seed=0, nbins=32, hair_mode="hybrid", derive=True) -> BuiltTables:
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
    return BuiltTables(cv, tab, info, dicts, yarns)


def check_options(preset, radius, nbins=None, spacing=None, budget=None):
    from ..presets import load_preset

    if preset is not None:
        load_preset(preset)
    check_positive(radius, "--radius")
    if nbins is not None and nbins < 1:
        raise LoomError(None, "--bins", f"need at least one azimuth bin, got {nbins}")
    check_positive(spacing, "--spacing")
    check_positive(budget, "--budget", upper=math.inf)


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
            "kind": "tables", "yarns": int(len(tab.yarn_type)), "yarn_types": type_summary(dicts),
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
