"""Precompute runner: seed 001 §4 per exemplar of a tiling (``svf`` and ``iirtf`` artifacts).

Both stages read a ``tiling`` artifact (stage ``tile``) and work in the flat fabric made of one
exemplar repeated without end (``stages.precompute.periodic``). Layout: one group ``exemplar_<k>`` per
exemplar k; every array that grows with the segments or the cells is chunked so that one chunk task
(``pipeline.chunks``) fills whole chunks, and tasks are seeded by their segment / cell ids, so the bytes
depend neither on the chunking nor on the thread count.

``svf``  (§4.1)  ``visibility`` (S, R*R/8) uint8 bit-packed images (rows theta from +z, columns phi),
                 ``ssdf_mean`` (D,), ``ssdf_basis`` (n, D), ``ssdf_coeffs`` (S, n) float32 (the PCA of
                 the SSDFs), ``sg_angle`` (S,) and ``sg_weights`` (S, Q) float32 (sums of SGs)
``iirtf`` (§4.2-4.3) only the cells holding a segment midpoint are stored, as rows: ``transfer`` (N, 3, n, n)
                 and ``transfer_se`` (N, 3, n, n) float32 (a_C [row, channel, j0 light, j1 incoming] and
                 its standard error, n = (L+1)^2; the incoming coefficients are c_T = a_C^T c_light),
                 ``row_cell`` (N,) int32 the row's cell index in the exemplar's grid (x fastest, then y,
                 then z, ``stages.precompute.iirtf``), ``row_segments`` (N,) int32 its segments,
                 ``cell_row`` (NX NY NZ,) int32 the row of every cell (-1: empty), ``seg_row`` (S,) int32
                 the row of every segment of the exemplar; at the root ``mat_of_fiber`` (F,) int32,
                 ``materials`` (M, MAT_SIZE) and ``bcsdf_sh`` (M, theta_o, n, 3) (C_S, §4.3)
Segments of exemplar k are the tiling's global segment ids ``segment_range[0] .. segment_range[1] - 1``
(fibre f's segment i is ``ex_offsets[f] - f + i``).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import LoomError
from ..limits import FULL_TRANSPORT_DEPTH, check_depth, largest_option
from ..memory import Estimate, budget as memory_budget, fmt_bytes

MAX_ORDER = 8
MIN_RESOLUTION = 8
# Bounds from time (``pipeline.limits.WorkEstimate``): rates no thread reaches, so a refused run could
# not have finished within the time limit either. A transfer path costs at least one periodic ray and
# an SH projection (measured: 2.7e4 paths/s a thread on the damask, README); the SG fit tests every
# visible pixel of every segment against every SG axis.
PATHS_PER_THREAD_S = 1e6
SG_TESTS_PER_THREAD_S = 1e11
CELL_BYTES = 40   # a cell's bookkeeping in ``build_cells`` and the writer (offsets, counts, cell_row)
MAX_CELLS = 10 ** 15   # past any memory (40 PB of cell grids); within it the memory budget decides


# ------------------------------------------------------------------------------------------------ parameters
SVF_RAY_START = "segment surface"  # the SVF's rays leave from the segment's side facing them
IIRTF_FIRST_RAY = "meets containing capsules"  # the IIRTF's first ray stops at a fibre containing the midpoint


@dataclass(frozen=True)
class SvfParams:
    resolution: int = 128          # R x R pixels over (theta, phi)
    components: int = 48           # PCA components
    sg_count: int = 48             # Q
    sg_sharpness: float = 128.0    # lambda_svf
    chunk: int = 1024              # segments per chunk task
    seed: int = 0

    def check(self) -> None:
        if not self.resolution >= MIN_RESOLUTION:
            raise LoomError(None, "--resolution",
                            f"visibility resolution must be at least {MIN_RESOLUTION}, got {self.resolution}")
        if self.resolution % 8:
            raise LoomError(None, "--resolution",
                            f"visibility resolution must be a multiple of 8 (bit-packed rows), got {self.resolution}")
        if self.resolution > 1024:
            raise LoomError(None, "--resolution",
                            f"visibility resolution above 1024 is not supported, got {self.resolution}")
        if not self.components >= 1:
            raise LoomError(None, "--components", f"must be at least 1, got {self.components}")
        if not self.sg_count >= 1:
            raise LoomError(None, "--sg-count", f"must be at least 1, got {self.sg_count}")
        if self.sg_count > self.resolution ** 2:
            raise LoomError(None, "--sg-count", f"{self.sg_count} SGs exceed the {self.resolution}x{self.resolution} = "
                            f"{self.resolution ** 2} visibility pixels: an SG's weight is the solid angle of the "
                            "pixels nearest its axis, so SGs past the pixel count get none; lower --sg-count")
        if not (math.isfinite(self.sg_sharpness) and self.sg_sharpness > 0):
            raise LoomError(None, "--sg-sharpness", f"must be a positive number, got {self.sg_sharpness}")
        if not self.chunk >= 1:
            raise LoomError(None, "--chunk", f"must be at least 1, got {self.chunk}")


# ell is the exemplar's, not the transfer matrices' Monte Carlo: traced with one fixed seed whatever --seed
# is, so the cell grid (cell_factor * ell) is the same for every seed (issue 53 item 3: with the seed, one
# patch got 24,000 or 25,600 cells); its precision is the reported standard error (--mfp-paths)
MFP_SEED = 0


@dataclass(frozen=True)
class IirtfParams:
    order: int = 4
    cell_factor: float = 1.0
    paths: int = 50000
    mfp_paths: int = 20000
    max_depth: int = FULL_TRANSPORT_DEPTH   # at 32 the damask's prt kept 0.74-0.94 of the fibres' light per channel
    rr_depth: int = 5
    light_sampling: str = "uniform"   # "uniform" (the paper's estimator) or "mis" (same integral, less variance)
    light_domain: str = "hemisphere"  # "hemisphere" (the paper's: light from above) or "sphere" (both sides, §4.2)
    layer_paths: int = 4000           # per cos theta bin and side of the layer transmittance (stages.precompute.layer)
    layer_bins: int = 8
    theta_samples: int = 512
    chunk: int = 16
    seed: int = 0
    material: dict = field(default_factory=dict)   # {"tint": ..., "bcsdf": ...}

    def check(self) -> None:
        if not 0 <= self.order <= MAX_ORDER:
            raise LoomError(None, "--order", f"SH order must be in 0..{MAX_ORDER}, got {self.order}")
        if not (math.isfinite(self.cell_factor) and self.cell_factor > 0):
            raise LoomError(None, "--cell-factor", f"must be a positive number, got {self.cell_factor}")
        for name, v, lo in (("--paths", self.paths, 2), ("--mfp-paths", self.mfp_paths, 2),
                            ("--layer-paths", self.layer_paths, 2), ("--layer-bins", self.layer_bins, 1),
                            ("--max-depth", self.max_depth, 1), ("--rr-depth", self.rr_depth, 1),
                            ("--theta-samples", self.theta_samples, 2), ("--chunk", self.chunk, 1)):
            if not v >= lo:
                raise LoomError(None, name, f"must be at least {lo}, got {v}")
        check_depth(self.max_depth, "--max-depth")
        check_depth(self.rr_depth, "--rr-depth")
        if self.light_sampling not in ("uniform", "mis"):
            raise LoomError(None, "--light-sampling",
                            f"unknown estimator {self.light_sampling!r} (known: mis, uniform)")
        if self.light_domain not in ("hemisphere", "sphere"):
            raise LoomError(None, "--light-domain",
                            f"unknown light domain {self.light_domain!r} (known: hemisphere, sphere)")


def parse_material_options(settings, bcsdf=None) -> dict:
    """``--set tint=yarn|none`` (as ``render --method fiberpath``) and ``--bcsdf``."""
    out = {"tint": "yarn"}
    for kv in settings:
        if "=" not in kv:
            raise LoomError(None, "--set", f"expected KEY=VALUE, got {kv!r}")
        k, v = (s.strip() for s in kv.split("=", 1))
        if k != "tint":
            raise LoomError(None, f"--set {k}", f"precompute has no setting {k!r} (known: tint)")
        if v not in ("yarn", "none"):
            raise LoomError(None, "--set tint", f"unknown tint {v!r} (known: none, yarn)")
        out["tint"] = v
    if bcsdf:
        out["bcsdf"] = bcsdf
    return out


# ------------------------------------------------------------------------------------------------ the tiling
def pick_exemplars(art, chosen, where) -> list[int]:
    K = int(art.summary.get("exemplars", 0))
    if K < 1 or len(art["ex_fibers"]) < 2:
        raise LoomError(where, None, "the tiling has no exemplar to precompute")
    if not chosen:
        return list(range(K))
    bad = [k for k in chosen if not 0 <= k < K]
    if bad:
        raise LoomError(None, "--exemplar", f"exemplar {bad[0]} does not exist (the tiling has {K}: 0..{K - 1})")
    return sorted(set(int(k) for k in chosen))


_SCENES: dict = {}


def periodic_scenes(tiling_path, content_hash: str):
    """The tiling's ``ShellScene`` (built once per process: chunk tasks of one run share it)."""
    from .tile import load_tiling

    key = (str(Path(tiling_path).resolve()), content_hash)  # a chunk task's path is absolute
    if key not in _SCENES:
        _SCENES.clear()
        sc, art = load_tiling(tiling_path)
        _SCENES[key] = (sc, art)
    return _SCENES[key]


def start_precompute(p, threads) -> None:
    """What every precompute does first: compilation notices on, its parameters checked (``p.check()``),
    ``--threads`` applied (refused below 1; None: all cores)."""
    from .. import compilation

    compilation.watch()
    p.check()
    if threads is not None:
        import numba

        if threads < 1:
            raise LoomError(None, "--threads", f"must be at least 1, got {threads}")
        numba.set_num_threads(min(int(threads), numba.config.NUMBA_NUM_THREADS))


def open_tiling(tiling, exemplars) -> tuple[Path, object, list[int]]:
    """(path, the tiling ``Artifact``, the exemplars to precompute: ``exemplars`` checked, else all)."""
    tiling = Path(tiling)
    art = tiling_input(tiling)
    return tiling, art, pick_exemplars(art, exemplars, tiling)


def _segments(art, k):
    from stages.precompute.svf import exemplar_segments

    return exemplar_segments(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"],
                             art["ex_period"], k)


def _chunks(n: int, size: int) -> list[tuple[int, int]]:
    return [(a, min(n, a + size)) for a in range(0, n, size)]


def tiling_input(tiling):
    from ..artifacts import Artifact

    return Artifact(tiling, kind="tiling")


# ------------------------------------------------------------------------------------------------ svf
def svf_estimate(S_max: int, S_all: int, p: SvfParams, hold: bool) -> Estimate:
    from stages.precompute.svf import packed_bytes, svf_memory_estimate

    R = p.resolution
    est = Estimate("loomlight precompute svf")
    est.add("tiling scene", 400.0 * S_all, f"{S_all:,} segments and their BVH")
    est.add("PCA of one exemplar", svf_memory_estimate(S_max, R, R, p.components, hold=hold, chunk=p.chunk),
            f"{S_max:,} segments x {R}x{R} SSDF pixels" + (" held" if hold else " streamed"))
    est.add("visibility chunk", p.chunk * (packed_bytes(R, R) + 4 * p.sg_count + 8 * R * R), f"{p.chunk} segments")
    return est


def svf_render_estimate(S_all: int, K: int, p: SvfParams) -> Estimate:
    """What ``render --method prt`` holds of this SVF (``pipeline.renderers.prt.load_prt``): every
    segment's PCA coefficients and SG weights, every exemplar's mean and basis."""
    D = p.resolution * p.resolution
    est = Estimate("loomlight render --method prt on this SVF", kernels=False)
    est.add("SG weights", 4.0 * S_all * p.sg_count, f"{S_all:,} segments x {p.sg_count:,} SGs (--sg-count)")
    est.add("PCA coefficients", 4.0 * S_all * p.components, f"{S_all:,} segments x {p.components} (--components)")
    est.add("PCA bases", 4.0 * K * (p.components + 1) * D, f"{K} exemplar(s) x {p.components} x {D:,} pixels")
    return est


def svf_work(S: int, p: SvfParams, threads: int):
    """The least time of the visibility images and the SG fit of S segments (``WorkEstimate``)."""
    from ..limits import WorkEstimate

    D = p.resolution * p.resolution
    est = WorkEstimate("loomlight precompute svf", threads)
    est.add("SG fit", float(S) * D * p.sg_count, SG_TESTS_PER_THREAD_S,
            f"{S:,} segments x {D:,} pixels x {p.sg_count:,} SGs (--sg-count)")
    est.add("visibility images", float(S) * D, 1e8, f"{S:,} segments x {D:,} rays (--resolution)")
    return est


def _svf_visibility_task(tiling, tiling_hash, store, k, a, b, p: dict):
    """Chunk task: visibility images and sums of SGs of exemplar k's segments a..b-1."""
    from stages.precompute.periodic import periodic_scene
    from stages.precompute.svf import sg_fit, visibility_images

    from ..chunks import open_for_chunk

    sc, art = periodic_scenes(tiling, tiling_hash)
    seg = _segments(art, k)
    R = p["resolution"]
    t0 = time.perf_counter()
    packed = visibility_images(periodic_scene(sc, k), k, seg.z_lo, seg.z_hi, seg.mids[a:b], seg.fibre[a:b], R, R,
                               capsules=seg.capsules[a:b])
    t1 = time.perf_counter()
    angle, weights = sg_fit(packed, seg.ids[a:b], R, R, p["sg_count"], p["seed"])
    g = f"exemplar_{k}/"
    open_for_chunk(store, g + "visibility")[a:b] = packed
    open_for_chunk(store, g + "sg_angle")[a:b] = angle
    open_for_chunk(store, g + "sg_weights")[a:b] = weights
    return {"visibility_s": t1 - t0, "sg_s": time.perf_counter() - t1, "rays": (b - a) * R * R}


def _svf_project_task(store, k, a, b, R):
    """Chunk task: PCA coefficients of exemplar k's segments a..b-1 (and the error partials)."""
    from stages.precompute.svf import ssdf_project

    from ..chunks import open_for_chunk

    g = f"exemplar_{k}/"
    packed = open_for_chunk(store, g + "visibility")[a:b]
    mean = open_for_chunk(store, g + "ssdf_mean")[...]
    basis = open_for_chunk(store, g + "ssdf_basis")[...]
    coeffs, partials = ssdf_project(packed, R, R, mean, basis)
    open_for_chunk(store, g + "ssdf_coeffs")[a:b] = coeffs
    return partials


def _svf_warm_up(tiling, tiling_hash, k, seg, p: SvfParams) -> float:
    """Compile (or load) every svf kernel on one segment at 8 x 8 pixels; returns the seconds it took
    (reported apart from the timings)."""
    from stages.precompute.periodic import periodic_scene
    from stages.precompute.svf import sg_fit, ssdf_pca, ssdf_project, visibility_images

    t0 = time.perf_counter()
    sc, _ = periodic_scenes(tiling, tiling_hash)
    packed = visibility_images(periodic_scene(sc, k), k, seg.z_lo, seg.z_hi, seg.mids[:1], seg.fibre[:1], 8, 8,
                               capsules=seg.capsules[:1])
    sg_fit(packed, seg.ids[:1], 8, 8, 2, 0)
    pca = ssdf_pca(packed, 8, 8, 1, 0, chunk=1, hold=True)
    ssdf_project(packed, 8, 8, pca.mean, pca.basis)
    return time.perf_counter() - t0


def run_svf(tiling, out, p: SvfParams, exemplars=None, force=False, budget=None, threads=None, scheduler=None) -> dict:
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from stages.precompute.svf import packed_bytes, pca_error_report, ssdf_pca

    from ..artifacts import ArtifactWriter
    from ..chunks import ChunkTask, open_for_chunk, run_tasks, session
    from ..progress import status

    start_precompute(p, threads)
    tiling, art, ks = open_tiling(tiling, exemplars)
    # ray_start: where a segment's visibility rays start (stages.precompute.periodic, "Rays from a segment");
    # artifacts without it were made from the midpoint, and the renderer says so
    w = ArtifactWriter(out, kind="svf", stage="precompute svf",
                       params={**asdict(p), "exemplars": ks, "ray_start": SVF_RAY_START},
                       inputs={"tiling": (tiling, "tiling")}, started=t_start)
    if not force and w.up_to_date():
        return {"skipped": True}
    segs = {k: _segments(art, k) for k in ks}
    R = p.resolution
    D = R * R
    for k in ks:
        S = len(segs[k].ids)
        if S < 1:
            raise LoomError(tiling, f"exemplar {k}", "has no fibre segments")
        if p.components > min(S, D):
            raise LoomError(None, "--components", f"{p.components} PCA components exceed what exemplar {k} allows "
                            f"(min of {S} segments and {D} pixels)")
    S_max = max(len(s.ids) for s in segs.values())
    S_all = int(art.summary["segments"])
    limit = budget or memory_budget()
    S_ks = sum(len(s.ids) for s in segs.values())
    import numba

    work = svf_work(S_ks, p, numba.get_num_threads())
    work.check(None, largest_option(work, "--resolution"), "lower --sg-count or --resolution")
    rest = svf_render_estimate(S_ks, len(ks), p)
    rest.check(limit, None, largest_option(rest, "--sg-count"))
    hold = svf_estimate(S_max, S_all, p, True).total <= 0.5 * limit.nbytes
    svf_estimate(S_max, S_all, p, hold).check(limit, tiling)
    tiling_hash = art.meta["content_hash"]
    compile_s = _svf_warm_up(tiling, tiling_hash, ks[0], segs[ks[0]], p)
    info = []
    t_start = time.perf_counter()
    rays = vis_s = 0.0
    with session(scheduler), w:
        store = w.store_path
        for k in ks:
            S = len(segs[k].ids)
            g = f"exemplar_{k}/"
            ch = min(p.chunk, S)
            w.create(g + "visibility", (S, packed_bytes(R, R)), np.uint8, (ch, packed_bytes(R, R)))
            w.create(g + "sg_angle", (S,), np.float32, (ch,))
            w.create(g + "sg_weights", (S, p.sg_count), np.float32, (ch, p.sg_count))
            w.create(g + "ssdf_coeffs", (S, p.components), np.float32, (ch, p.components))
            w.write(g + "segment_ids", segs[k].ids, chunks=(max(ch, 1 << 16),))
        pdict = asdict(p)
        tasks = [ChunkTask(_svf_visibility_task, (str(tiling.resolve()), tiling_hash, str(store), k, a, b, pdict))
                 for k in ks for a, b in _chunks(len(segs[k].ids), p.chunk)]
        for r in run_tasks(tasks, "svf: visibility images"):
            rays += r["rays"]
            vis_s += r["visibility_s"]
        for k in ks:
            S = len(segs[k].ids)
            g = f"exemplar_{k}/"
            t0 = time.perf_counter()
            packed = open_for_chunk(store, g + "visibility")[...]
            with status(f"svf: PCA of the SSDFs, exemplar {k} ({S:,} segments)"):
                pca = ssdf_pca(packed, R, R, p.components, p.seed, chunk=p.chunk, hold=hold)
            del packed
            w.write(g + "ssdf_mean", pca.mean)
            w.write(g + "ssdf_basis", pca.basis, chunks=(min(8, p.components), D))
            w.write(g + "pca_eigenvalues", pca.eigenvalues)
            pca_s = time.perf_counter() - t0
            parts = run_tasks([ChunkTask(_svf_project_task, (str(store), k, a, b, R))
                               for a, b in _chunks(S, p.chunk)], f"svf: PCA coefficients, exemplar {k}")
            err = pca_error_report(np.sum(np.stack(parts), axis=0) if len(parts) > 1 else parts[0])
            nbytes = sum(int(np.prod(open_for_chunk(store, g + n).shape)) * np.dtype(dt).itemsize for n, dt in
                         (("visibility", np.uint8), ("sg_angle", np.float32), ("sg_weights", np.float32),
                          ("ssdf_coeffs", np.float32), ("ssdf_mean", np.float32), ("ssdf_basis", np.float32)))
            info.append({"exemplar": k, "name": art.summary["exemplar_names"][k], "segments": S,
                         "segment_range": [int(segs[k].ids[0]), int(segs[k].ids[-1]) + 1],
                         "pca_rms_error": err["rms_error"], "pca_rel_error": err["rel_error"],
                         "pca_sign_error": err["sign_error"],
                         "pca_sign_error_outside_band": err["sign_error_outside_band"],
                         "visible_fraction": err["visible_fraction"], "pca_s": pca_s, "bytes": int(nbytes),
                         "slab": [segs[k].z_lo, segs[k].z_hi], "period": list(segs[k].period)})
        total_s = time.perf_counter() - t_start
        w.summary.update(kind="svf", tiling=str(tiling), exemplars=info, resolution=[R, R], components=p.components,
                         sg_count=p.sg_count, sg_sharpness=p.sg_sharpness, seed=p.seed,
                         segments=int(sum(i["segments"] for i in info)), rays=int(rays),
                         rays_per_s=rays / max(vis_s, 1e-9),
                         segments_per_s=sum(i["segments"] for i in info) / max(total_s, 1e-9),
                         time_s=total_s, compile_s=compile_s)
    return {"skipped": False, "exemplars": len(ks), "segments": int(sum(i["segments"] for i in info)),
            "rays_per_s": rays / max(vis_s, 1e-9), "pca_rel_error": max(i["pca_rel_error"] for i in info)}


# ------------------------------------------------------------------------------------------------ iirtf
def materials_scene(tiling: Path, art, scene):
    from ..scene import load_scene, one_fabric

    path = scene or art.summary.get("scene")
    if not path:
        raise LoomError(tiling, "scene", "the tiling names no scene for the yarn materials; pass --scene SCENE.toml")
    if not Path(path).exists():
        raise LoomError(None, "--scene" if scene else f"{tiling}: scene", f"file not found: {path}")
    return Path(path), one_fabric(load_scene(path), None if scene else tiling, "--scene" if scene else "scene")


def tiling_materials(scene, art, material: dict):
    """(mat_of_fiber (F,) int32, materials (M, MAT_SIZE)): the fibre materials the fiberpath renderer gives
    the tiling under ``scene`` (``pipeline.renderers.fiberpath``), so the precompute and the reference agree."""
    from ..bcsdf_presets import check_bcsdf_names
    from ..renderers.fiberpath import fiber_materials, tiling_fibers

    options = {"material": "bcsdf", "bcsdf": material.get("bcsdf"), "extra": {"tint": material.get("tint", "yarn")}}
    check_bcsdf_names(scene, options)
    fibers = tiling_fibers(scene, art)
    mof, mats = fiber_materials(scene, fibers, options)
    return np.ascontiguousarray(mof, np.int32), np.ascontiguousarray(mats, np.float64)


_CELLS: dict = {}


def _cells(art, key, targets):
    from stages.precompute.iirtf import build_cells, exemplar_slabs

    k = ((str(Path(key[0]).resolve()), key[1]), tuple(float(t) for t in targets))  # a task's path is absolute
    if k not in _CELLS:
        _CELLS.clear()
        slabs = exemplar_slabs(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"])
        _CELLS[k] = build_cells(art["ex_points"], art["ex_offsets"], art["ex_fibers"], art["ex_period"],
                                art["ex_nblocks"], art["block_size"], slabs, np.asarray(targets))
    return _CELLS[k]


def _iirtf_task(tiling, tiling_hash, store, k, r0, r1, targets, mof, mats, p: dict):
    """Chunk task: A_C and its standard error for exemplar k's stored rows r0..r1-1 (non-empty cells)."""
    from stages.precompute.iirtf import iirtf_chunk

    from ..chunks import open_for_chunk

    sc, art = periodic_scenes(tiling, tiling_hash)
    cells = _cells(art, (tiling, tiling_hash), targets)
    base = int(cells.ex_cells[k])
    rows = _nonempty(cells, k)[r0:r1]          # local cell ids of the rows; empty cells between cost nothing
    c0, c1 = base + int(rows[0]), base + int(rows[-1]) + 1
    t0 = time.perf_counter()
    res = iirtf_chunk(sc, cells, c0, c1, mof, mats, order=p["order"], n_paths=p["paths"],
                      seed=p["seed"], max_depth=p["max_depth"], rr_depth=p["rr_depth"],
                      light_sampling=p["light_sampling"], light_domain=p["light_domain"])
    pick = rows - (c0 - base)
    g = f"exemplar_{k}/"
    open_for_chunk(store, g + "transfer")[r0:r1] = res.a[pick].astype(np.float32)
    open_for_chunk(store, g + "transfer_se")[r0:r1] = res.se[pick].astype(np.float32)
    return {"s": time.perf_counter() - t0, "paths": int(p["paths"]) * (r1 - r0), "rays": int(res.rays.sum())}


def _nonempty(cells, k):
    """Local cell ids (ascending) of exemplar k's cells that hold a segment midpoint."""
    base = int(cells.ex_cells[k])
    n = int(cells.ex_cells[k + 1]) - base
    return np.flatnonzero(np.diff(cells.cell_offsets[base:base + n + 1]) > 0)


def iirtf_work(p: IirtfParams, n_exemplars: int, stored_cells: int, threads: int):
    """The least time of the mean free paths, the layer transmittance and the transfer matrices
    (``WorkEstimate``); before the cells are known, ``stored_cells`` = the exemplars (each stores at least
    one cell)."""
    from ..limits import WorkEstimate

    est = WorkEstimate("loomlight precompute iirtf", threads)
    est.add("transfer matrices", float(p.paths) * stored_cells, PATHS_PER_THREAD_S,
            f"{p.paths:,} paths per cell x {stored_cells:,} cells holding segments (--paths)")
    est.add("mean free paths", float(p.mfp_paths) * n_exemplars, PATHS_PER_THREAD_S,
            f"{p.mfp_paths:,} paths x {n_exemplars} exemplar(s) (--mfp-paths)")
    est.add("layer transmittance", 2.0 * p.layer_bins * p.layer_paths * n_exemplars, PATHS_PER_THREAD_S,
            f"{p.layer_paths:,} paths x {p.layer_bins} angles x 2 sides x {n_exemplars} exemplar(s) (--layer-paths)")
    return est


def cell_counts(art, targets, ks) -> dict[int, int]:
    """Cells of each exemplar k in ``ks`` at target length ``targets[k]`` (``build_cells``' grids), counted
    in Python integers before any cell is allocated."""
    from stages.precompute.iirtf import cells_per_side, exemplar_slabs

    slabs = exemplar_slabs(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"])
    bs, nb = art["block_size"], art["ex_nblocks"]
    out = {}
    for k in ks:
        try:
            n = [cells_per_side(float(side), float(targets[k])) for side in (bs[0], bs[1], slabs[k, 1] - slabs[k, 0])]
        except (ValueError, OverflowError):
            n = None
        cells = None if n is None else int(nb[k, 0]) * n[0] * int(nb[k, 1]) * n[1] * n[2]
        if cells is None or cells > MAX_CELLS:
            raise LoomError(None, "--cell-factor", f"cells of {float(targets[k]):.3g} (the factor times exemplar {k}'s "
                            f"mean free path) make {'too many' if cells is None else f'{cells:.3g}'} cells, over "
                            f"{MAX_CELLS:.0e} ({fmt_bytes(CELL_BYTES * MAX_CELLS)} of cell grids); "
                            "nothing was started: raise --cell-factor")
        out[k] = cells
    return out


def iirtf_estimate(S_all: int, C_max: int, p: IirtfParams, n_mats: int, cells: int = 0) -> Estimate:
    J = (p.order + 1) ** 2
    est = Estimate("loomlight precompute iirtf")
    est.add("tiling scene and cells", 520.0 * S_all, f"{S_all:,} segments")
    if cells:
        est.add("cell grids", float(CELL_BYTES) * cells, f"{cells:,} cells (--cell-factor)")
    est.add("transfer chunk", 2 * 8 * 3 * J * J * min(p.chunk, C_max) + 4 * 3 * J * J * 2 * C_max,
            f"{C_max:,} cells x 3 x {J}x{J}")
    est.add("C_S tables", 8.0 * n_mats * p.theta_samples * J * 3 * 2, f"{n_mats} materials x {p.theta_samples} theta_o")
    return est


def run_iirtf(tiling, out, p: IirtfParams, scene=None, exemplars=None, force=False, budget=None, threads=None,
              scheduler=None) -> dict:
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from stages.core.shading.bcsdf_sh import bcsdf_sh_table
    from stages.core.shading.material import MAT_BCSDF
    from stages.precompute.iirtf import exemplar_slabs, mean_free_path
    from stages.precompute.layer import layer_transmittance

    from ..artifacts import FILE, ArtifactWriter
    from ..chunks import ChunkTask, run_tasks, session
    from ..progress import progress, status

    start_precompute(p, threads)
    tiling, art, ks = open_tiling(tiling, exemplars)
    import numba

    work = iirtf_work(p, len(ks), len(ks), numba.get_num_threads())
    work.check(None, largest_option(work, "--paths"), "lower --paths or --mfp-paths")
    scene_path, sc_obj = materials_scene(tiling, art, scene)
    mof, mats = tiling_materials(sc_obj, art, p.material)
    # first_ray: how the paths leave a segment's midpoint (stages.precompute.periodic, "Rays from a segment")
    w = ArtifactWriter(out, kind="iirtf", stage="precompute iirtf",
                       params={**asdict(p), "exemplars": ks, "first_ray": IIRTF_FIRST_RAY},
                       inputs={"tiling": (tiling, "tiling"), "scene": (scene_path, FILE)}, started=t_start)
    if not force and w.up_to_date():
        return {"skipped": True}
    tiling_hash = art.meta["content_hash"]
    sc, _ = periodic_scenes(tiling, tiling_hash)
    slabs = exemplar_slabs(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"])
    periods = art["ex_period"]
    S_all = int(art.summary["segments"])
    iirtf_estimate(S_all, 1, p, len(mats)).check(budget or memory_budget(), tiling)
    # mean free path per exemplar (§4.2; the first call compiles the kernels: timed apart)
    t0 = time.perf_counter()
    mean_free_path(sc, ks[0], slabs[ks[0], 0], slabs[ks[0], 1], periods[ks[0]], mof, mats, n_paths=2, seed=MFP_SEED,
                   max_depth=2)
    layer_transmittance(sc, ks[0], slabs[ks[0], 0], slabs[ks[0], 1], periods[ks[0]], mof, mats, n_bins=1, n_paths=2,
                        max_depth=2)
    compile_s = time.perf_counter() - t0
    mfp = {}
    t0 = time.perf_counter()
    with progress(f"iirtf: mean free path ({p.mfp_paths:,} paths per exemplar)", len(ks)) as advance:
        for k in ks:
            ell, se, n = mean_free_path(sc, k, slabs[k, 0], slabs[k, 1], periods[k], mof, mats, n_paths=p.mfp_paths,
                                        seed=MFP_SEED, max_depth=p.max_depth)
            if not (n > 0 and math.isfinite(ell) and ell > 0):
                raise LoomError(tiling, f"exemplar {k}", "no path scattered twice inside the fabric, so it has no mean "
                                f"free path (are its fibres black, or is it empty?); measured {n} free paths")
            mfp[k] = (ell, se, n)
            advance()
    mfp_s = time.perf_counter() - t0
    # the layer transmittance per exemplar (prt's shadow rays through other folds; its own fixed seed, as ell's)
    t0 = time.perf_counter()
    layer = {}
    with progress(f"iirtf: layer transmittance ({p.layer_paths:,} paths per angle and side)", len(ks)) as advance:
        for k in ks:
            layer[k] = layer_transmittance(sc, k, slabs[k, 0], slabs[k, 1], periods[k], mof, mats, n_bins=p.layer_bins,
                                           n_paths=p.layer_paths, seed=MFP_SEED, max_depth=p.max_depth,
                                           rr_depth=p.rr_depth)
            advance()
    layer_s = time.perf_counter() - t0
    bs = art["block_size"]
    targets = np.array([p.cell_factor * mfp[k][0] if k in mfp else max(bs[0], bs[1]) for k in range(len(periods))])
    # every exemplar's cells are built (``_cells``), not only those of ks
    counted = cell_counts(art, targets, range(len(periods)))
    iirtf_estimate(S_all, 1, p, len(mats), sum(counted.values())).check(budget or memory_budget(), None,
                                                                          "--cell-factor")
    cells = _cells(art, (str(tiling), tiling_hash), targets)
    C = {k: int(cells.ex_cells[k + 1] - cells.ex_cells[k]) for k in ks}
    rows = {k: _nonempty(cells, k) for k in ks}
    N = {k: len(rows[k]) for k in ks}
    est = iirtf_estimate(S_all, max(N.values()), p, len(mats), sum(counted.values()))
    est.check(budget or memory_budget(), tiling)
    work = iirtf_work(p, len(ks), sum(N.values()), numba.get_num_threads())
    work.check(None, largest_option(work, "--paths"), "lower --paths or raise --cell-factor")
    J = (p.order + 1) ** 2
    info = []
    t_start = time.perf_counter()
    with session(scheduler), w:
        store = w.store_path
        for k in ks:
            g = f"exemplar_{k}/"
            ch = min(p.chunk, N[k])
            w.create(g + "transfer", (N[k], 3, J, J), np.float32, (ch, 3, J, J))
            w.create(g + "transfer_se", (N[k], 3, J, J), np.float32, (ch, 3, J, J))
            base = int(cells.ex_cells[k])
            cell_row = np.full(C[k], -1, np.int32)
            cell_row[rows[k]] = np.arange(N[k], dtype=np.int32)
            seg0, seg1 = (int(art["ex_offsets"][f]) - f
                          for f in (int(art["ex_fibers"][k]), int(art["ex_fibers"][k + 1])))
            w.write(g + "cell_row", cell_row)
            w.write(g + "row_cell", rows[k].astype(np.int32))
            w.write(g + "row_segments", np.diff(cells.cell_offsets[base:base + C[k] + 1])[rows[k]].astype(np.int32))
            w.write(g + "seg_row", cell_row[cells.seg_cell[seg0:seg1] - base])
            w.write(g + "layer_tau", layer[k][0])
            w.write(g + "layer_tau_se", layer[k][1])
        w.write("mat_of_fiber", mof)
        w.write("materials", mats)
        tabs = np.zeros((len(mats), p.theta_samples, J, 3))
        t0 = time.perf_counter()
        with status(f"iirtf: BCSDF SH tables C_S of {len(mats)} material(s)"):
            for m, row in enumerate(mats):
                if int(row[0]) == MAT_BCSDF:
                    tabs[m] = bcsdf_sh_table(row[1:11], p.order, p.theta_samples)
        cs_s = time.perf_counter() - t0
        w.write("bcsdf_sh", tabs)
        pdict = {k: v for k, v in asdict(p).items() if k != "material"}
        tasks = [ChunkTask(_iirtf_task,
                           (str(tiling.resolve()), tiling_hash, str(store), k, a, b, targets, mof, mats, pdict))
                 for k in ks for a, b in _chunks(N[k], p.chunk)]
        res = run_tasks(tasks, "iirtf: transfer matrices")
        task_s = sum(r["s"] for r in res)
        paths = sum(r["paths"] for r in res)
        for k in ks:
            S_k = int(art["ex_offsets"][int(art["ex_fibers"][k + 1])] - art["ex_fibers"][k + 1]
                      - art["ex_offsets"][int(art["ex_fibers"][k])] + art["ex_fibers"][k])
            nbytes = 2 * N[k] * 3 * J * J * 4 + 4 * (C[k] + 2 * N[k] + S_k)
            info.append({"exemplar": k, "name": art.summary["exemplar_names"][k], "mean_free_path": mfp[k][0],
                         "mean_free_path_se": mfp[k][1], "free_paths": int(mfp[k][2]), "cells": C[k],
                         "stored_cells": N[k], "empty_cells": C[k] - N[k],
                         "cell_grid": [int(v) for v in cells.ex_grid[k]],
                         "cell_size": [float(v) for v in cells.cell_size[k]],
                         "cells_per_block": [int(v) for v in cells.block_cells[k]],
                         "segments": S_k, "slab": [float(v) for v in slabs[k]], "bytes": int(nbytes),
                         "layer_transmittance_near_normal": [float(v) for v in layer[k][0][0, -1]]})
        total_s = time.perf_counter() - t_start
        w.summary.update(kind="iirtf", tiling=str(tiling), scene=str(scene_path), exemplars=info, order=p.order,
                         sh_coefficients=J, cell_factor=p.cell_factor, paths=p.paths, materials=int(len(mats)),
                         theta_samples=p.theta_samples, seed=p.seed, light_sampling=p.light_sampling,
                         light_domain=p.light_domain, layer_bins=p.layer_bins, layer_paths=p.layer_paths,
                         cells=int(sum(C.values())), stored_cells=int(sum(N.values())), paths_total=int(paths),
                         paths_per_s=paths / max(task_s, 1e-9),
                         cells_per_s=sum(N.values()) / max(task_s, 1e-9), mean_free_path_s=mfp_s,
                         bcsdf_sh_s=cs_s, layer_transmittance_s=layer_s, time_s=total_s, compile_s=compile_s)
    return {"skipped": False, "exemplars": len(ks), "cells": int(sum(C.values())),
            "mean_free_path": [mfp[k][0] for k in ks], "paths_per_s": paths / max(task_s, 1e-9)}
