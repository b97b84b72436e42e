"""Tables runner: seed 000's realization-minimizing tables of a yarns artifact (``tables`` artifact).

The tables artifact is self-contained for rendering: besides the ``Tables`` arrays
(stages/procedural/tables.py) it carries a copy of the yarn-curve arrays under ``curves/`` whose
segment grid is padded by each yarn's fibre-extent bound (hairs reach beyond the yarn radius), so
``load_tables(path)`` gives the (Curves, Tables) pair the lookup kernels take. ``build`` makes the
same (Curves, Tables) in memory from a yarns artifact (the realize runner and Table 1 use it);
``check_options`` checks the options the tables and realize commands share.

Memory: ``tables_estimate`` counts the build's peak from the yarns artifact and the packed yarn types
alone (plies x fibres x bins, hairs and loops per unit length times the yarn lengths, per-ply
bookkeeping), so ``run_tables`` (and ``run_realize``) refuse an oversized build before it starts
(and past the time limit, ``bins_work``; ``check_bins`` names ``--bins`` as the place when the bins
are at fault);
``accel_estimate`` counts what loading a tables artifact derives (frame samples, chord grid) from its
small per-yarn arrays, for the stages that load tables.
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from ..artifacts import Artifact, ArtifactWriter
from ..errors import LoomError
from ..limits import check_positive
from ..memory import Estimate, budget as memory_budget
from ..yarns import CURVE_ARRAYS, curves_from_group
from .yarn_types import YarnTypes, type_summary, yarn_types_of

FOLD_CAP = 0.5             # build_tables' cap on kappa x extent: g_min >= 1 - FOLD_CAP
SLOT_BYTES = 1200          # per (yarn, ply): the dozen small arrays and list entries the build keeps
BIN_ENTRIES_PER_THREAD_S = 1e10   # (bin, fibre) entries of the regular tables a thread fills: none reaches it
DEFAULT_BINS = 32          # azimuth bins of the regular-fibre tables (``loomlight tables --bins``)
PY_ARRAY_BYTES = 150       # a small numpy array in a Python list (header, list slot, bin start)


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


class Prepared(NamedTuple):
    yarns: Artifact
    types: YarnTypes
    curve_length: np.ndarray   # (Y,) arc length of every yarn


def prepare(yarns_path, preset=None, radius=None) -> Prepared:
    """The yarns artifact and its resolved yarn types: what the estimates and the build start from."""
    yarns = Artifact(yarns_path, kind="yarns")
    types = yarn_types_of(yarns, preset, radius)
    return Prepared(yarns, types, np.asarray(yarns["curve_length"], np.float64))


def build(yarns_path, preset=None, radius=None, seed=0, nbins=DEFAULT_BINS, hair_mode="hybrid", derive=True,
          prepared: Prepared | None = None) -> BuiltTables:
    """(cv, tab, info, type dicts, yarns artifact) for a yarns artifact; derive: also the lookups'
    load-time structures (tables.derive_lookup_accel)."""
    from stages.core.yarn.accel import derive_lookup_accel
    from stages.core.yarn.model import extent_bound
    from stages.procedural.tables import build_tables

    yarns, (dicts, tparams, ytype, albedo), _ = prepared or prepare(yarns_path, preset, radius)
    ext = np.array([extent_bound(tparams[t]) for t in ytype])
    cv = padded_curves(lambda n: yarns[n], ext)
    mode = {"hybrid": 0, "free": 1}[hair_mode]
    tab, info = build_tables(cv, tparams, ytype, albedo, int(seed), nbins=int(nbins), hair_mode=mode)
    if derive:
        tab = derive_lookup_accel(cv, tab)
    return BuiltTables(cv, tab, info, dicts, yarns)


def _rms(tp, mu, sig):
    return float(np.hypot(tp[mu], tp[sig]))


def slot_hairs(tp, length) -> np.ndarray:
    """Hairs per ply of yarns of these lengths (tables.hair_count's rule), as floats (no overflow)."""
    from stages.core.yarn import model as M

    return (np.round(tp[M.HAIR_DENSITY] * np.asarray(length, np.float64)) if tp[M.USE_FLYAWAYS]
            else np.zeros(len(length)))


def _bin_fraction(tp, nbins: int) -> float:
    """Mean fraction of a ply's azimuth bins a regular fibre is listed in (regular_tables' rule, with the
    largest reach factor the fold cap allows and fibre radii spread uniformly over the disc)."""
    from stages.core.yarn import model as M
    from stages.core.yarn.tables import PAD_FRACTION

    K = M.reach_factor(M.transverse_speed_bound(tp), 1.0 - FOLD_CAP)
    m = K * tp[M.FIBER_RADIUS] * (1.0 + PAD_FRACTION) / min(tp[M.E_SHORT], tp[M.E_LONG])
    R = tp[M.R_MAX] * np.sqrt((np.arange(64) + 0.5) / 64.0)
    lo = (tp[M.RHO_MIN] if tp[M.USE_MIGRATION] else 1.0) * R
    reach = np.where(lo > m, np.arcsin(np.minimum(1.0, m / np.maximum(lo, 1e-300))), np.pi)
    return float(np.mean(np.minimum(1.0, reach / np.pi + 2.0 / nbins)))


def tables_estimate(prep: Prepared, nbins: int, hair_mode: str, what: str = "loomlight tables") -> Estimate:
    """Peak memory of ``build(..., derive=False)`` from the yarns artifact and yarn types alone: the
    curves with their padded grid, per type the regular fibres and their azimuth bins (regular_tables:
    (bins x fibres) float temporaries per ply, one small array per bin), per (yarn, ply) the hybrid hairs
    (stored z extents, shapes and bin lists, twice while concatenated, plus the slot's Python shape
    list), the loops and their z-bins, and the per-ply bookkeeping."""
    from stages.core.yarn import model as M

    est = Estimate(what)
    yarns, types, length = prep
    est.add("yarn curves", 3 * yarns.nbytes(), f"{len(length)} yarns")
    B = int(nbins)
    for t, tp in enumerate(types.tparams):
        P, N = float(tp[M.PLY_NUM]), float(tp[M.FIBER_NUM])
        items = P * N * B * _bin_fraction(tp, B)
        nbytes = 96 * P * N + 25 * B * N + (PY_ARRAY_BYTES + 16) * P * B + 8 * items
        est.add(f"regular fibres of {types.dicts[t].get('name', t)}", nbytes,
                f"{int(P)} plies x {int(N)} fibres x {B} bins")
    hairs = loops = slots = slot_peak = 0.0
    for t, tp in enumerate(types.tparams):
        L = length[types.yarn_type == t]
        if not len(L):
            continue
        P, N = float(tp[M.PLY_NUM]), float(tp[M.FIBER_NUM])
        slots += P * len(L)
        if hair_mode == "hybrid":
            n = slot_hairs(tp, L)
            overlap = 1.0 + 2.0 * tp[M.HAIR_DENSITY] * (_rms(tp, M.ZE_MU, M.ZE_SIG) + 2.2 * tp[M.FIBER_RADIUS])
            hairs += P * float(n.sum()) * (2 * (80 + 4 * overlap) + 32)
            slot_peak = max(slot_peak, 256.0 * float(n.max()))
        if tp[M.USE_FLYAWAYS] and tp[M.USE_MIGRATION] and tp[M.P_LOOP] > 0:
            loops += P * float(np.sum(tp[M.P_LOOP] * N * (L * tp[M.S_MIG] / tp[M.ALPHA] + 2))) * 96
        zbin = 0.5 * tp[M.ALPHA] / max(tp[M.S_MIG], 1e-12)
        loops += P * float(np.sum(np.ceil(L / zbin) + 1)) * 64
    est.add("hairs", hairs + slot_peak, "hybrid z extents, shapes and z-bins")
    est.add("loops", loops, "mutated cycles and their z-bins")
    est.add("per-ply bookkeeping", SLOT_BYTES * slots, f"{int(slots)} (yarn, ply) slots")
    return est


def accel_estimate(art: Artifact, what: str) -> Estimate:
    """Memory of loading a tables artifact: its stored arrays (curves included) plus what
    derive_lookup_accel builds (``stages.core.yarn.accel``), counted from the artifact's curve and
    per-yarn arrays without loading the tables: the frame samples of every yarn at its first-guess
    step between its breakpoints (``frame_sample_count``, +10 % for a refinement round), the coarse
    knots (index, arc length, position, sag, gate), the chord grid's cells and runs (cells as
    derive_lookup_accel sizes them, runs per yarn length / cell x (2 r / cell + 1.2)^2 for r its extent),
    the fringe bits and the per-hair, per-fibre and per-loop-bin bounds. Within 10-25 % of the measured
    peak on the 1,000-yarn cloth (README, "Scale")."""
    from stages.core.yarn.accel import chord_grid_cell
    from stages.core.yarn.frame_samples import FRAME_COLS
    from stages.core.yarn.tables import FO_WORDS, FO_ZBIN_EXTENTS

    est = Estimate(what)
    est.add("stored tables", art.nbytes(), art.path.name)
    ytype = art["yarn_type"]
    length, ext = (np.asarray(art[k], np.float64) for k in ("yarn_length", "yarn_extent"))
    Y = len(ytype)
    if Y == 0:
        return est
    first, step = first_guess_frame_samples(art)
    samples = 1.1 * first
    est.add("frame samples", (8 + 8 * FRAME_COLS) * samples,
            f"{int(samples):,} samples (at most: a paged volpath render holds the yarns its rays reach)")
    stride = max(1, int(0.5 * float(ext.min()) / float(np.mean(step))))
    knots = samples / stride + 2 * Y
    pts = np.asarray(art["curves/points"])
    box = pts.max(0) - pts.min(0) + 2 * ext.max()
    cell = chord_grid_cell(box, float(ext.max()))
    cells = float(np.prod(np.ceil(box / cell)))
    runs = float(np.sum((length / cell + 1) * (2 * ext / cell + 1.2) ** 2))
    est.add("chord grid", 28 * cells + 12 * runs + 56 * knots, f"{int(cells):,} cells, ~{int(runs):,} runs")
    zbins = float(np.sum(np.ceil(length / (FO_ZBIN_EXTENTS * ext)) + 1))
    est.add("fringe and bounds", 8 * (2 * FO_WORDS + 3) * zbins + 16 * len(art["hair_z1"]) + 8 * len(art["fib_R"])
            + 16 * len(art["lz_start"]), f"{int(zbins):,} fringe z-bins")
    return est


def first_guess_frame_samples(art: Artifact):
    """(frame samples of every yarn at its first-guess step, those steps (Y,)): ``accel.frame_steps`` from the
    artifact's per-yarn arrays, counted by ``frame_sample_count`` (loading the tables refines the steps: about
    10 % more)."""
    from stages.core.yarn import model as M
    from stages.core.yarn.accel import frame_steps

    tp, ytype = art["tparams"], art["yarn_type"]
    ext, kap = (np.asarray(art[k], np.float64) for k in ("yarn_extent", "yarn_kappa"))
    radius = np.asarray(art["curves/radius"][:len(ytype)], np.float64)
    step = frame_steps(kap, ext, radius, tp[ytype, M.FIBER_RADIUS])
    return frame_sample_count(art, step), step


def frame_sample_count(art: Artifact, step: np.ndarray) -> float:
    """The frame samples ``stages.core.yarn.frame_samples.sample_all`` makes at ``step`` per yarn
    (``sample_counts``), from the artifact's curve arrays alone."""
    from stages.core.yarn.frame_samples import sample_counts

    def get(name, dtype):
        return np.ascontiguousarray(art[f"curves/{name}"], dtype)
    counts = sample_counts(get("curve_offsets", np.int64), get("closed", np.bool_), get("seg_arclen", np.float64),
                           get("frame_offsets", np.int64), get("frame_s", np.float64),
                           get("curve_length", np.float64), np.ascontiguousarray(step, np.float64))
    return float(counts.sum())


def bins_work(prep: Prepared, nbins: int, threads: int):
    """The least time of the regular-fibre tables (``pipeline.limits.WorkEstimate``): every ply of every
    yarn type fills a (bins x fibres) table, at a rate no thread reaches (``BIN_ENTRIES_PER_THREAD_S``)."""
    from stages.core.yarn import model as M

    from ..limits import WorkEstimate

    entries = sum(float(tp[M.PLY_NUM]) * float(tp[M.FIBER_NUM]) for tp in prep.types.tparams) * float(nbins)
    return WorkEstimate("loomlight tables", threads).add(
        "regular-fibre bins", entries, BIN_ENTRIES_PER_THREAD_S,
        f"{len(prep.types.tparams)} yarn type(s), plies x fibres x {int(nbins):,} bins (--bins)")


def check_bins(prep: Prepared, nbins: int, hair_mode: str, limit) -> None:
    """Refuse a build past the time limit (``bins_work``) or the memory budget ``limit``
    (``tables_estimate``), naming the yarns artifact, and ``--bins`` as the place when the bins are at
    fault: more than ``DEFAULT_BINS``, which would have passed."""
    import numba

    from ..limits import time_limit

    threads = numba.get_num_threads()
    more = int(nbins) > DEFAULT_BINS
    work = bins_work(prep, nbins, threads)
    if work.seconds > time_limit()[0]:
        place = "--bins" if more and bins_work(prep, DEFAULT_BINS, threads).seconds <= time_limit()[0] else None
        work.check(prep.yarns.path, place, "lower --bins" if place else "make the input smaller")
    est = tables_estimate(prep, nbins, hair_mode)
    if est.total > limit.nbytes:
        place = "--bins" if more and tables_estimate(prep, DEFAULT_BINS, hair_mode).total <= limit.nbytes else None
        est.check(limit, prep.yarns.path, place, "lower --bins, or raise --budget" if place else
                  "raise --budget or make the input smaller")


def check_options(preset, radius, nbins=None, spacing=None, budget=None):
    from ..presets import load_preset

    if preset is not None:
        load_preset(preset)
    check_positive(radius, "--radius")
    if nbins is not None and nbins < 1:
        raise LoomError(None, "--bins", f"need at least one azimuth bin, got {nbins}")
    check_positive(spacing, "--spacing")
    check_positive(budget, "--budget", upper=math.inf)


def run_tables(yarns_path, out, preset=None, radius=None, seed=0, nbins=DEFAULT_BINS, hair_mode="hybrid",
               force=False, budget=None):
    """Build (or skip when up to date) the tables artifact; ``budget`` (``pipeline.memory.budget``):
    refuse before building when the estimated peak memory exceeds it."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from stages.core.yarn.tables import STORED_FIELDS, table_bytes

    from .. import compilation

    compilation.watch()

    check_options(preset, radius, nbins)
    if hair_mode not in ("hybrid", "free"):
        raise LoomError(None, "--hair-mode", f"must be 'hybrid' or 'free', got {hair_mode!r}")
    params = {"preset": preset, "radius": radius, "seed": int(seed), "bins": int(nbins), "hair_mode": hair_mode}
    w = ArtifactWriter(out, kind="tables", stage="tables", params=params, inputs={"yarns": (yarns_path, "yarns")},
                       started=t_start)
    if w.up_to_date() and not force:
        return {"skipped": True}
    prep = prepare(yarns_path, preset, radius)
    check_bins(prep, nbins, hair_mode, budget or memory_budget())
    from ..progress import status

    with status(f"tables: {len(prep.curve_length):,} yarns"):
        cv, tab, info, dicts, yarns = build(yarns_path, preset, radius, seed, nbins, hair_mode, derive=False,
                                            prepared=prep)
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
            "ingest_identity": yarns.summary.get("ingest_identity"),
        })
    return {"skipped": False, "yarns": int(len(tab.yarn_type)), "folded": folded}


def _cv_field(name):
    return "offsets" if name == "curve_offsets" else name


def load_tables(path, paged: bool = False):
    """(Curves, Tables, Artifact) of a tables artifact (self-contained: curves from its copy). ``paged``: keep
    no frame samples (``stages.core.yarn.frame_pool``: a render pages them in as its rays reach each yarn)."""
    from stages.core.yarn.accel import derive_lookup_accel
    from stages.core.yarn.tables import STORED_FIELDS, Tables, empty_accel

    art = Artifact(path, kind="tables")
    missing = [f for f in STORED_FIELDS if f not in art]
    if missing:
        raise LoomError(art.path, missing[0],
                        "array missing from the tables artifact (rebuild it with loomlight tables)")
    stored = {f: np.ascontiguousarray(art[f]) for f in STORED_FIELDS}
    tab = Tables(**stored, **dict(zip([f for f in Tables._fields if f not in stored],
                                      empty_accel(len(stored["yarn_type"])))))
    cv = curves_from_group(lambda n: art[f"curves/{n}"])
    return cv, derive_lookup_accel(cv, tab, paged=paged), art
