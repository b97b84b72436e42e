"""``precompute btf``: one repeat of a tiling fitted to seed 002's per-texel BRDFs (a ``btf`` artifact).

``run_btf`` takes exemplars of a tiling (woven repeats, or knitted ones: by default every exemplar its block map
uses, so a damask's texture holds both of its weaves; ``--exemplar`` picks), the fibre materials
the scene gives it (the same as ``fiberpath`` renders and ``precompute iirtf`` uses:
``pipeline.runners.precompute.tiling_materials``), and

1. **acquires** (seed 002 §4, ``stages.precompute.btf``) per texel of a res x res grid over the repeat's
   top face, per view cell of the view grid and per light cell of the light grid (``--directions cell``,
   the default: each sample's view and each path's lights uniform over their cells, so the table holds
   cell averages; ``grid``: the grid directions themselves, seed 002's point samples; ``--light-coords half``: the
   light cells in half-vector coordinates, ``stages.core.btf``) the radiance per unit
   irradiance r(l, v), the alpha of each view and the texel's average normal and tangent, path traced
   in the repeat repeated without end. One chunk task per exemplar and texel row (``pipeline.chunks``: here
   or on a Dask scheduler); each writes its row of ``samples`` (float16) and ``alpha`` into the artifact.
2. **fits** (seed 002 §5, ``stages.precompute.btf_fit``; half-vector cells read first on the FIT_LIGHT_GRID
   hemisphere grid from each grid view, ``stages.core.btf.half_to_hemisphere``) per texel and channel the diffuse
   term and 1-2 Lafortune lobes by Levenberg-Marquardt alternating with the lookup table T(v) of Eq. 4, and the
   mip levels from 2 x 2 groups of texels (§5.1) down to 1 x 1, each level's fit RMSE with and without
   the table (the paper's Fig. 5 point) recorded in the summary. The fit reads the stored (float16)
   samples and the level-0 frames as stored (float32), so a refit from the artifact reproduces it.
3. with ``--model tabulated``, **compresses** (``stages.precompute.btf_compress``: local PCA, ``--clusters`` x
   ``--components``) the table of every texel of every mip level -- the same alpha-weighted samples the fit
   sees -- into ``tabulated/`` (``cluster`` (E, T), ``mean`` (E, C, V, L, 3), ``basis`` (E, C, K, V, L, 3),
   ``weights`` (E, T, K), ``rel_rmse_by_components`` (E, K + 1); T the texels of every level, finest first);
   the summary's ``models`` lists what the artifact holds, ``table_bytes`` its size.

**Reusing an acquisition.** The summary records ``acquisition_key``: every parameter but the fit's and the
table's (``FIT_PARAMS``), the inputs' identities and the acquisition code's version. When the artifact at the
output path has the key of a new run, its samples, alpha and frames are taken instead of tracing them again
(said on the output; ``--force`` acquires anyway): a refit or an added table costs seconds, not minutes.

``--plane middle`` puts the texture on the middle plane of the exemplars' slab, ``--plane surface`` at the median
height of what the grid's views see of them (``surface_plane``; ``stages.precompute.btf``, "The texture's plane";
default ``top``, the paper's top face); the summary's ``plane_z`` is its height, where the renderer
puts a tiling's surface. ``--plane relief`` gives each texel its own plane (``relief_heights``: the median height of
what RELIEF_RAYS rays straight down through it meet; the slab's bottom where most pass through), written as
``heights`` (exemplars, res, res) in the exemplar's coordinates; ``plane_z`` is then the surface plane, where the
renderer puts the surface it marches the height field from (the field's heights are read relative to it).

With ``--light-domain sphere`` the samples' and the table's light axis is the hemisphere grid and then its mirror
below the fabric (``stages.core.btf.SPHERE``: 2 L lights); the summary says ``light_domain = "sphere"``, ``light_dirs``
is the hemisphere grid the fit reads (the Lafortune lobes are fitted to the lights above).

With half-vector cells the summary says ``light_coords = "half"``, ``light_grid`` is the cells' (nx, ny) (the samples'
and the table's light axis), ``fit_light_grid`` the fit's hemisphere grid, whose directions ``light_dirs`` holds;
``half_dirs`` (L, 3) the cells' centre half vectors; ``directions`` says whether the cells were averaged.

Every array but the direction grids has a leading exemplar axis (``samples`` (E, res, res, V, L, 3),
``alpha`` (E, res, res, V), ``level_l/rho`` (E, r, r, 3), ...), in the order of the summary's ``exemplars`` (the
tiling's exemplar indices) with ``exemplar_names`` and ``periods``; the fit statistics are over every exemplar's
texels, and per exemplar in ``per_exemplar``.

Defaults: 32 x 32 texels (the paper's), views and lights on 8 x 8 grids of equal solid angle (64 each,
the paper's 64-entry tables; ``--views 4x8`` gives the paper's 32), 16 samples per texel and view, two
lobes, threshold 0.1 (the paper's), paths of up to the full transport's depth (``FULL_TRANSPORT_DEPTH``); the
Lafortune model only (``--model tabulated``: 8 clusters x 8 components).
"""
from __future__ import annotations

import math
import time
from collections import namedtuple
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import LoomError
from ..limits import FULL_TRANSPORT_DEPTH, MAX_PATH_DEPTH, largest_option
from ..memory import Estimate, budget as memory_budget

DIRECTIONS = ("cell", "grid")
LIGHT_COORDS = ("hemisphere", "half")   # the light grid: equal-area rings and azimuths, or half-vector cells
LIGHT_DOMAINS = ("hemisphere", "sphere")   # lights above the fabric, or the grid and its mirror below it too
# the texture's plane: the exemplars' top face (the paper's), their slab's middle, the median height of what the views
# see, or one per texel (stages.precompute.btf)
PLANES = ("top", "middle", "surface", "relief")
SURFACE_RAYS = 256   # --plane surface: rays per grid view and exemplar whose first hits' median height is the plane
RELIEF_RAYS = 64     # --plane relief: rays straight down per texel whose first hits' median height is its plane
RELIEF_COVERED = 0.5  # --plane relief: a texel where fewer of them hit is a pit to the slab's bottom (a hole)
DEFAULT_LIGHTS = {"hemisphere": (8, 8), "half": (15, 15)}   # --lights when not given (half: a cell at h = 0)
FIT_LIGHT_GRID = (8, 8)   # half-vector acquisitions: the hemisphere grid the Lafortune fit (and the renderer's
                          # quadrature) reads them on (stages.core.btf.half_to_hemisphere)
MODELS = ("lafortune", "tabulated")   # what the artifact holds beside the samples: the fit, or the fit and the table
# parameters that change the fit or the table, not the acquisition: an artifact at the output path acquired with
# the same other parameters from the same inputs lends its samples (``reusable_acquisition``)
FIT_PARAMS = ("lobes", "threshold", "max_rounds", "model", "clusters", "components")
# Bounds of the count options. Memory (``btf_estimate``: the samples grow with texels x views x lights) and
# time (``btf_work``, ``pipeline.limits.WorkEstimate``, at rates no thread reaches: every sample casts a camera
# ray, and with ``--directions cell`` draws a direction in each light's cell; measured on a small tiling: about
# 4e3 samples and 7e4 light terms a thread-second) refuse a run, with the estimate, before any work starts.
# --max-depth and --rr-depth cap a path and --max-rounds the fit's alternations (each stops earlier on its
# own), so they have plain caps: past them a number is a typo, not a setting.
SAMPLES_PER_THREAD_S = 1e7
LIGHT_DIRECTIONS_PER_THREAD_S = 1e9
MAX_RESOLUTION = 256
MAX_GRID_DIRECTIONS = 4096
MAX_ROUNDS = 1_000


@dataclass
class BtfParams:
    resolution: int = 32
    views: tuple = (8, 8)            # (n_theta, n_phi) of the view grid
    lights: tuple = (8, 8)           # (n_theta, n_phi) of the light grid; (nx, ny) with light_coords "half"
    spp: int = 16
    lobes: int = 2
    threshold: float = 0.1
    max_rounds: int = 10
    directions: str = "cell"         # cell: view and light uniform over each grid cell (averages); grid: the grid's
    light_coords: str = "hemisphere"  # half: light cells in half-vector coordinates (stages.core.btf)
    light_domain: str = "hemisphere"  # sphere: the light grid's mirror below the fabric too (stages.core.btf SPHERE)
    plane: str = "top"               # middle: the texture on the slab's middle plane (stages.precompute.btf)
    max_depth: int = FULL_TRANSPORT_DEPTH   # at 16 the damask's ground-satin texture held 0.55 / 0.66 / 0.75 of
    rr_depth: int = 5                       # its red / green / blue light at 256 (64 x 48 render, 8 spp)
    seed: int = 0
    material: dict = field(default_factory=dict)
    model: str = "lafortune"         # tabulated: the compressed table too (stages.precompute.btf_compress)
    clusters: int = 8                # the table's local PCA: clusters of texels ...
    components: int = 8              # ... and components per cluster

    def check(self) -> None:
        r = self.resolution
        if r < 1 or r & (r - 1) or r > MAX_RESOLUTION:
            raise LoomError(None, "--resolution", f"must be a power of two from 1 to {MAX_RESOLUTION}, got {r}")
        for name, g in (("--views", self.views), ("--lights", self.lights)):
            if len(g) != 2 or min(g) < 1 or g[0] * g[1] > MAX_GRID_DIRECTIONS:
                raise LoomError(None, name, f"must be THETAxPHI with positive counts, at most {MAX_GRID_DIRECTIONS} "
                                            f"directions; got {g}")
        for name, v in (("--spp", self.spp), ("--max-depth", self.max_depth), ("--rr-depth", self.rr_depth),
                        ("--max-rounds", self.max_rounds)):
            if v < 1:
                raise LoomError(None, name, f"must be a positive integer, got {v}")
        caps = (("--max-depth", self.max_depth, MAX_PATH_DEPTH,
                 "scattering events on a path (Russian roulette from --rr-depth ends paths long before)"),
                ("--rr-depth", self.rr_depth, MAX_PATH_DEPTH, "scattering events before Russian roulette"),
                ("--max-rounds", self.max_rounds, MAX_ROUNDS,
                 "lobe/table alternations (the fit stops earlier, at --threshold)"))
        for name, v, cap, what in caps:
            if v > cap:
                raise LoomError(None, name, f"{v:,} is past the cap of {cap:,} {what}; lower it")
        if self.directions not in DIRECTIONS:
            raise LoomError(None, "--directions", f"must be one of {', '.join(DIRECTIONS)}, got {self.directions!r}")
        if self.light_coords not in LIGHT_COORDS:
            raise LoomError(None, "--light-coords", f"must be one of {', '.join(LIGHT_COORDS)}, got "
                                                    f"{self.light_coords!r}")
        if self.light_domain not in LIGHT_DOMAINS:
            raise LoomError(None, "--light-domain", f"must be one of {', '.join(LIGHT_DOMAINS)}, got "
                                                    f"{self.light_domain!r}")
        if self.light_domain == "sphere" and self.light_coords != "hemisphere":
            raise LoomError(None, "--light-domain", "sphere mirrors the hemisphere grid below the fabric; it does not "
                                                    "take --light-coords half")
        if self.plane not in PLANES:
            raise LoomError(None, "--plane", f"must be one of {', '.join(PLANES)}, got {self.plane!r}")
        if self.model not in MODELS:
            raise LoomError(None, "--model", f"must be one of {', '.join(MODELS)}, got {self.model!r}")
        if self.model == "tabulated":
            self.check_table()
        if self.lobes not in (1, 2):
            raise LoomError(None, "--lobes", f"must be 1 or 2 (Daubert et al. 2001 §7), got {self.lobes}")
        if not (math.isfinite(self.threshold) and self.threshold > 0):
            raise LoomError(None, "--threshold", f"must be a positive number, got {self.threshold}")

    def light_count(self) -> int:
        """The acquisition's and the table's lights: the grid's cells, twice with ``light_domain`` sphere."""
        return self.lights[0] * self.lights[1] * (2 if self.light_domain == "sphere" else 1)

    def check_table(self) -> None:
        """The tabulated model's counts: components within the table's rank bound, clusters within its texels."""
        from stages.precompute.btf_compress import rank_bound

        rows = texel_rows(self.resolution)
        dims = self.views[0] * self.views[1] * self.light_count() * 3
        if not 1 <= self.components <= rank_bound(rows, dims):
            raise LoomError(None, "--components", f"must be from 1 to {rank_bound(rows, dims):,}, the rank bound of "
                            f"the table's {rows:,} texels (every mip level) x {dims:,} values; got {self.components}")
        if not 1 <= self.clusters <= rows:
            raise LoomError(None, "--clusters", f"must be from 1 to {rows:,} (the texels of every mip level), got "
                            f"{self.clusters}")


def texel_rows(res: int) -> int:
    """Texels of every mip level of a res x res texture: res^2 + (res/2)^2 + ... + 1."""
    return sum((int(res) >> lv) ** 2 for lv in range(int(res).bit_length()))


def parse_grid(text: str, option: str) -> tuple[int, int]:
    """``8x8`` -> (8, 8): rings of equal solid angle x azimuths."""
    parts = str(text).lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise LoomError(None, option, f"expected THETAxPHI (e.g. 8x8), got {text!r}")
    return int(parts[0]), int(parts[1])


def btf_estimate(res, V, L, segments, exemplars=1, p: "BtfParams | None" = None) -> Estimate:
    """Peak memory of the acquisition and the fit: one exemplar's samples (float16 stored, float32 read, float64
    in the fit: the exemplars are fitted one after the other) and the tables and lobes of every level of every
    exemplar; with the tabulated model, one exemplar's rows of every level and their reconstruction (float32) and
    every exemplar's compressed table; each part names the option it grows with."""
    est = Estimate("loomlight precompute btf")
    est.add("tiling scene", 520.0 * segments, f"{segments:,} segments")
    grows = "--resolution" if res * res >= V * L else _grid_option(V, L)
    est.add("samples", float(res) * res * V * L * 3 * (2 + 4 + 8), f"{res}x{res} texels x {V:,} views x {L:,} lights "
            f"(float16 stored, float32 read, float64 fit) ({grows})")
    est.add("fit", float(res) * res * V * 4 * 8 * 6 * exemplars,
            f"tables and lobes of every level of {exemplars} exemplar(s) (--resolution, --exemplar)")
    if p is not None and p.model == "tabulated":
        rows, D = texel_rows(res), V * L * 3
        est.add("table rows", float(rows) * D * (4 + 4 + 4), f"{rows:,} texels of every level x {D:,} values "
                f"(rows, reconstruction, clusters' rows) ({grows})")
        est.add("compressed table", exemplars * (p.clusters * (p.components + 1) * D + rows * p.components) * 4.0,
                f"{exemplars} exemplar(s) x {p.clusters} clusters x {p.components} components (--clusters, "
                "--components)")
    return est


def _grid_option(V, L) -> str:
    return "--views" if V >= L else "--lights"


def btf_work(res, V, L, p: "BtfParams", threads: int, exemplars: int = 1):
    """The least time of the acquisition (``WorkEstimate``): every sample of every texel and view of every
    exemplar casts a camera ray, and with cell averages (the default) draws one direction in each light's cell."""
    from ..limits import WorkEstimate

    samples = float(res) * res * V * p.spp * exemplars
    what = f"{exemplars} exemplar(s) x {res}x{res} texels x {V:,} views x {p.spp:,} samples"
    est = WorkEstimate("loomlight precompute btf", threads)
    est.add("camera rays", samples, SAMPLES_PER_THREAD_S, f"{what} (--spp)")
    if p.directions == "cell":
        est.add("light directions", samples * L, LIGHT_DIRECTIONS_PER_THREAD_S,
                f"{what} x {L:,} lights "
                f"({'--spp' if p.spp >= max(V, L) else _grid_option(V, L)})")
    return est


def direction_grids(p: dict) -> tuple:
    """(view_grid, light_grid, light_coords) for ``acquire_texels``: the grids with ``directions = "cell"`` (averages
    over each grid cell), (0, 0) each with "grid" (the grid directions themselves) -- but a half-vector light grid
    always, its cells being seen from each view (``stages.core.btf.half_cell_direction``)."""
    from stages.core.btf import HALF, HEMISPHERE, SPHERE

    half = p.get("light_coords", "hemisphere") == "half"
    lights = tuple(int(x) for x in p["lights"])
    coords = HALF if half else SPHERE if p.get("light_domain", "hemisphere") == "sphere" else HEMISPHERE
    if p.get("directions", "cell") == "grid":
        return (0, 0), lights if half else (0, 0), coords
    return tuple(int(x) for x in p["views"]), lights, coords


def light_cells(p: "BtfParams"):
    """(the acquisition's light directions (L, 3), the fit's (M, 3)): the hemisphere grid of ``--lights`` twice (with
    ``light_domain`` sphere the acquisition's followed by its mirror image below the fabric); for half-vector cells,
    the cells' centre half vectors (h_z 0 off the unit disk: what ``half_dirs`` stores; the acquisition takes only
    their count) and the hemisphere grid of FIT_LIGHT_GRID."""
    from stages.core.btf import half_grid, hemisphere_grid, sphere_grid

    if p.light_coords != "half":
        grid = hemisphere_grid(*p.lights)
        return (sphere_grid(*p.lights) if p.light_domain == "sphere" else grid), grid
    return half_grid(*p.lights), hemisphere_grid(*FIT_LIGHT_GRID)


def _btf_row_task(tiling, tiling_hash, store, e, k, iy, mof, mats, view_dirs, light_dirs, p: dict, z_plane=None):
    """Chunk task: texel row iy of exemplar k (the artifact's exemplar e) -- samples and alpha into the artifact;
    returns normal sums and timings. ``z_plane``: the texture's plane (None: the exemplar's top face; an array
    (res^2,): each texel's own, ``--plane relief``)."""
    from stages.precompute.btf import acquire_texels
    from stages.precompute.iirtf import exemplar_slabs
    from stages.precompute.periodic import periodic_scene

    from ..chunks import open_for_chunk
    from .precompute import periodic_scenes

    sc, art = periodic_scenes(tiling, tiling_hash)
    slab = exemplar_slabs(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"])[k]
    W, H = (float(v) for v in art["ex_period"][k])
    res = p["resolution"]
    t0 = time.perf_counter()
    rad, alpha, nsum, rays = acquire_texels(periodic_scene(sc, k), float(slab[0]), float(slab[1]), W, H, mof, mats,
                                            res, iy * res, (iy + 1) * res, view_dirs, light_dirs, p["spp"], p["seed"],
                                            p["max_depth"], p["rr_depth"], _max_dist(W, H, slab), _eps(W, H, slab),
                                            *direction_grids(p), z_plane)
    open_for_chunk(store, "samples")[e, iy] = rad.astype(np.float16)
    open_for_chunk(store, "alpha")[e, iy] = alpha
    return {"normal": nsum, "rays": int(rays.sum()), "s": time.perf_counter() - t0}


def _max_dist(W, H, slab) -> float:
    """How far a ray may run inside the slab (grazing rays stop after this many periods)."""
    return 64.0 * max(W, H, float(slab[1] - slab[0]))


def _eps(W, H, slab) -> float:
    return 1e-7 * (max(W, H) + abs(float(slab[0])) + abs(float(slab[1])))


def _probe_paths(sc, k, slab, W, H, mof, mats):
    """Exemplar k's periodic fabric for first-hit probes (``hit_heights``: no path past the first hit)."""
    from stages.precompute.periodic import PeriodicPaths, periodic_scene

    return PeriodicPaths(periodic_scene(sc, k), float(slab[0]), float(slab[1]), W, H, mof, mats, 1, 1,
                         _max_dist(W, H, slab), _eps(W, H, slab))


def surface_plane(sc, ks, slabs, periods, mof, mats, view_dirs, seed) -> float:
    """``--plane surface``: the median height of the first fibre hits of SURFACE_RAYS rays per grid view into every
    exemplar of ``ks`` (``stages.precompute.btf.hit_heights``), pooled."""
    from stages.precompute.btf import hit_heights

    z = [hit_heights(_probe_paths(sc, k, slabs[k], W, H, mof, mats), view_dirs, SURFACE_RAYS, seed).ravel()
         for k, (W, H) in zip(ks, periods)]
    z = np.concatenate(z)
    z = z[np.isfinite(z)]
    return float(np.median(z)) if len(z) else 0.5 * (float(slabs[ks[0]][0]) + float(slabs[ks[0]][1]))


def relief_heights(sc, ks, slabs, periods, mof, mats, res, seed) -> np.ndarray:
    """``--plane relief``: (exemplars, res, res) float32 each texel's plane, the median height of the first fibre hits
    of RELIEF_RAYS rays straight down through its footprint (``stages.precompute.btf.hit_heights`` on the texel
    grid); the slab's bottom where fewer than RELIEF_COVERED of them hit (a hole is a pit: a ray into it meets the
    yarns around it, or what lies deeper, where they are)."""
    from stages.precompute.btf import hit_heights

    down = np.array([[0.0, 0.0, 1.0]])
    out = []
    for k, (W, H) in zip(ks, periods):
        slab = slabs[k]
        z = hit_heights(_probe_paths(sc, k, slab, W, H, mof, mats), down, RELIEF_RAYS, seed, res)[0]
        hit = np.isfinite(z)
        covered = hit.mean(axis=1) >= RELIEF_COVERED
        med = np.full(len(z), float(slab[0]))
        med[covered] = np.nanmedian(z[covered], axis=1)
        out.append(med.reshape(res, res))
    return np.stack(out).astype(np.float32)


def used_exemplars(art) -> list[int]:
    """The exemplars a tiling's block map places somewhere (all of them when the map is empty)."""
    used = sorted(int(k) for k in np.unique(np.asarray(art["block_map"])) if k >= 0)
    return used or list(range(int(art.summary["exemplars"])))


def _fit_record(levels, res, V, K) -> list[dict]:
    """Per level, the arrays one exemplar's fit writes (``level_l/...``, without the exemplar axis), finest first."""
    out = []
    for lev, f in enumerate(levels):
        r = res >> lev
        out.append({"rho": f.rho.reshape(r, r, 3), "lobes": f.lobes.reshape(r, r, K, 3, 4),
                    "table": f.table.reshape(r, r, V, 4), "frame": f.frames.reshape(r, r, 2, 3),
                    "rmse": f.rmse.reshape(r, r, 3)})
    return out


Reused = namedtuple("Reused", ["samples", "alpha", "frames", "rays", "acquire_s"])
Reused.__doc__ = """An earlier artifact's acquisition: samples (E, res, res, V, L, 3) float16, alpha (E, res, res, V),
level-0 frames (E, res, res, 2, 3) float32, its rays and acquisition seconds."""


def acquisition_key(w, p: BtfParams) -> str:
    """What the acquisition depends on: every parameter but ``FIT_PARAMS``, the inputs' identities and the code the
    acquisition runs (``pipeline.source_graph.code_version`` of the acquisition kernel and of the runner that
    turns the scene into fibre materials, with the bundled yarn and BCSDF presets)."""
    import hashlib
    import json

    from ..source_graph import code_version

    params = {k: v for k, v in w.params.items() if k not in FIT_PARAMS}
    code = code_version(Path(__file__).resolve().parents[2], ("stages.precompute.btf", "pipeline.runners.precompute"),
                        ("data/yarns", "data/bcsdf"))
    doc = {"params": params, "inputs": w.input_identities(), "code": code}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def reusable_acquisition(out, key: str) -> Reused | None:
    """The acquisition of the btf artifact at ``out`` when its summary's ``acquisition_key`` is ``key`` (a refit,
    or a table added, from the same samples), read and checked; else None."""
    from ..artifacts import Artifact

    try:
        art = Artifact(out, kind="btf")
        if art.summary.get("acquisition_key") != key:
            return None
        return Reused(np.asarray(art["samples"], np.float16), np.asarray(art["alpha"], np.float32),
                      np.asarray(art["level_0/frame"], np.float32), int(art.summary["rays"]),
                      float(art.summary["acquire_s"]))
    except (LoomError, KeyError):
        return None


def level_rows(samples, alpha, frames, res) -> np.ndarray:
    """(T, V L 3) float32: the texels of every mip level (``btf_fit.group_level``: the alpha-weighted means the fit
    sees), finest level first, each row-major -- the table's rows, in the renderer's order within an exemplar."""
    from stages.precompute.btf_fit import group_level

    rows = []
    for lv in range(int(res).bit_length()):
        g = group_level(samples, alpha, frames, res, lv)
        rows.append(np.asarray(g.samples, np.float32).reshape(len(g.samples), -1))
    return np.ascontiguousarray(np.concatenate(rows))


def write_tables(w, tables, V, L) -> int:
    """The exemplars' compressed tables into ``tabulated/`` (every array with a leading exemplar axis) and their shape
    and size into the summary (``table_clusters``, ``table_components``, ``table_bytes``); their bytes."""
    E = len(tables)
    C, K, _ = tables[0].basis.shape
    arrays = {"cluster": np.stack([t.cluster for t in tables]),
              "mean": np.stack([t.mean for t in tables]).reshape(E, C, V, L, 3),
              "basis": np.stack([t.basis for t in tables]).reshape(E, C, K, V, L, 3),
              "weights": np.stack([t.weights for t in tables]),
              "rel_rmse_by_components": np.stack([t.rel_rmse_by_components for t in tables])}
    for name, a in arrays.items():
        w.write(f"tabulated/{name}", np.ascontiguousarray(a))
    size = sum(a.nbytes for n, a in arrays.items() if n != "rel_rmse_by_components")
    w.summary.update(table_clusters=int(C), table_components=int(K), table_bytes=int(size))
    return size


def _rms(parts) -> float:
    return float(np.sqrt(np.mean(np.concatenate([np.square(np.asarray(a, np.float64)).ravel() for a in parts]))))


def run_btf(tiling, out, p: BtfParams, scene=None, exemplars=None, force=False, budget=None, threads=None,
            scheduler=None) -> dict:
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from stages.core.btf import half_cell_geometry, half_to_hemisphere, hemisphere_grid
    from stages.precompute.btf import acquire_texels, texel_frames
    from stages.precompute.btf_compress import compress_texels
    from stages.precompute.btf_fit import fit_levels
    from stages.precompute.iirtf import exemplar_slabs
    from stages.precompute.periodic import periodic_scene

    from ..artifacts import FILE, ArtifactWriter
    from ..chunks import ChunkTask, run_tasks, session
    from ..progress import info, status
    from .precompute import materials_scene, open_tiling, periodic_scenes, start_precompute, tiling_materials

    start_precompute(p, threads)
    import numba

    tiling, art, ks = open_tiling(tiling, exemplars)
    if not exemplars:
        ks = used_exemplars(art)
    E = len(ks)
    V, L = p.views[0] * p.views[1], p.light_count()
    work = btf_work(p.resolution, V, L, p, numba.get_num_threads(), E)
    work.check(None, largest_option(work, "--spp"), "lower it (or --resolution, --views, --lights, --exemplar)")
    scene_path, sc_obj = materials_scene(tiling, art, scene)
    mof, mats = tiling_materials(sc_obj, art, p.material)
    w = ArtifactWriter(out, kind="btf", stage="precompute btf", params={**asdict(p), "exemplars": ks},
                       inputs={"tiling": (tiling, "tiling"), "scene": (scene_path, FILE)}, started=t_start)
    if not force and w.up_to_date():
        return {"skipped": True}
    res = p.resolution
    view_dirs = hemisphere_grid(*p.views)
    light_dirs, fit_dirs = light_cells(p)
    half = p.light_coords == "half"
    V, L = len(view_dirs), len(light_dirs)
    limit = budget or memory_budget()
    est = btf_estimate(res, V, L, int(art.summary["segments"]), E, p)
    est.check(limit, None, largest_option(est, "--resolution"), "lower it, or raise --budget")
    tiling_hash = art.meta["content_hash"]
    tiling_abs = str(tiling.resolve())  # chunk tasks may run in another directory
    sc, _ = periodic_scenes(tiling_abs, tiling_hash)
    slabs = exemplar_slabs(art["ex_points"], art["ex_radius"], art["ex_offsets"], art["ex_fibers"])
    periods = [[float(v) for v in art["ex_period"][k]] for k in ks]
    k0, (W, H) = ks[0], periods[0]
    slab = slabs[k0]
    top, bottom = max(float(slabs[k][1]) for k in ks), min(float(slabs[k][0]) for k in ks)
    z_plane = {"top": None, "middle": 0.5 * (top + bottom)}.get(p.plane)   # top: each exemplar's own top face
    heights = None
    if p.plane in ("surface", "relief"):
        z_plane = surface_plane(sc, ks, slabs, periods, mof, mats, hemisphere_grid(*p.views), p.seed)
    if p.plane == "relief":
        with status(f"btf: the relief's heights ({res}x{res} texels x {RELIEF_RAYS} rays)"):
            heights = relief_heights(sc, ks, slabs, periods, mof, mats, res, p.seed)
    acq_key = acquisition_key(w, p)
    reused = None if force else reusable_acquisition(out, acq_key)
    compile_s = 0.0
    if reused is None:
        t0 = time.perf_counter()  # compile (or load) the acquisition kernel on one texel, one view, one light
        acquire_texels(periodic_scene(sc, k0), float(slab[0]), float(slab[1]), W, H, mof, mats, res, 0, 1,
                       view_dirs[:1], light_dirs[:1], 1, p.seed, 2, 2, _max_dist(W, H, slab), _eps(W, H, slab),
                       *direction_grids(asdict(p)))   # the grids the chunk tasks pass: the same specialisation
        compile_s = time.perf_counter() - t0
    pdict = {key: v for key, v in asdict(p).items() if key != "material"}
    names = [str(art.summary["exemplar_names"][k]) for k in ks]
    with session(scheduler), w:
        store = w.store_path
        w.write("view_dirs", view_dirs)
        w.write("light_dirs", fit_dirs)     # the fit's light grid (the acquisition's with hemisphere coordinates)
        if half:
            w.write("half_dirs", light_dirs)
            valid = half_cell_geometry(p.views[0], p.views[1], p.lights[0], p.lights[1], p.directions == "cell").valid
        if reused is None:
            w.create("samples", (E, res, res, V, L, 3), np.float16, (1, 1, res, V, L, 3),
                     dimension_names=("exemplar", "y", "x", "view", "light", "c"))
            w.create("alpha", (E, res, res, V), np.float32, (1, 1, res, V),
                     dimension_names=("exemplar", "y", "x", "view"))
            t0 = time.perf_counter()
            tasks = [ChunkTask(_btf_row_task, (tiling_abs, tiling_hash, str(store), e, k, iy, mof, mats, view_dirs,
                                               light_dirs, pdict,
                                               z_plane if heights is None else heights[e].astype(np.float64).ravel()))
                     for e, k in enumerate(ks)
                     for iy in range(res)]
            parts = run_tasks(tasks, f"btf: acquisition, {E} exemplar(s) x {res}x{res} texels x {V} views x "
                                     f"{L} lights")
            acquire_s = time.perf_counter() - t0
            rays = sum(r["rays"] for r in parts)
            normals = [np.concatenate([r["normal"] for r in parts[e * res:(e + 1) * res]]) for e in range(E)]
            # rounded as stored (level_0/frame), so a refit from the artifact fits the same frames
            frames_all = [texel_frames(n).reshape(res, res, 2, 3).astype(np.float32) for n in normals]
        else:
            info(f"btf: the acquisition of {out} reused (same tiling, scene and acquisition parameters; "
                        "--force acquires again)")
            w.write("samples", reused.samples, chunks=(1, 1, res, V, L, 3),
                    dimension_names=("exemplar", "y", "x", "view", "light", "c"))
            w.write("alpha", reused.alpha, chunks=(1, 1, res, V), dimension_names=("exemplar", "y", "x", "view"))
            frames_all = list(reused.frames)
            rays, acquire_s = reused.rays, reused.acquire_s
        fits, fit_s, per_exemplar, no_table, unconverged = [], 0.0, [], [], 0
        tables, compress_s = [], 0.0
        for e, k in enumerate(ks):
            frames = frames_all[e].astype(np.float64)
            samples = w.group["samples"][e].astype(np.float32)
            alpha = w.group["alpha"][e]
            t0 = time.perf_counter()
            fit_samples = samples
            if p.light_domain == "sphere":   # the Lafortune lobes are a reflectance: the lights above only
                fit_samples = samples[:, :, :, :len(fit_dirs)]
            mean_e = float(np.mean(fit_samples))   # the radiance of the lights above (what the fit's RMSE is over)
            if half:   # the fit's lobes take the lights of a hemisphere grid: the table read there from each view
                fit_samples = half_to_hemisphere(samples.reshape(res * res, V, L, 3), valid, p.lights[0], p.lights[1],
                                                 view_dirs, fit_dirs).reshape(res, res, V, len(fit_dirs), 3)
            with status(f"btf: fitting {res}x{res} texels of '{names[e]}' and their mip levels"):
                levels = fit_levels(fit_samples, alpha, frames, view_dirs, fit_dirs, p.lobes, p.threshold,
                                    max_rounds=p.max_rounds)
            fit_s += time.perf_counter() - t0
            fits.append(_fit_record(levels, res, V, p.lobes))
            per_exemplar.append({"exemplar": k, "name": names[e], "mean_radiance": mean_e,
                                 "fit_rmse": [_rms([f.rmse]) for f in levels], "alpha_mean": float(np.mean(alpha))})
            no_table.append([f.rmse_no_table for f in levels])
            unconverged += sum(int(np.count_nonzero(~np.asarray(f.converged))) for f in levels)
            if p.model == "tabulated":
                t0 = time.perf_counter()
                with status(f"btf: compressing the table of '{names[e]}' ({p.clusters} clusters x "
                            f"{p.components} components)"):
                    tables.append(compress_texels(level_rows(samples, alpha, frames, res), p.clusters, p.components,
                                                  p.seed))
                compress_s += time.perf_counter() - t0
                per_exemplar[-1]["table_rel_rmse"] = float(tables[-1].rel_rmse)
                per_exemplar[-1]["table_rel_rmse_by_components"] = [float(x) for x in
                                                                    tables[-1].rel_rmse_by_components]
            del samples
        n_levels = len(fits[0])
        fit_bytes = 0
        for lev in range(n_levels):
            for name in ("rho", "lobes", "table", "frame", "rmse"):
                a = np.ascontiguousarray(np.stack([f[lev][name] for f in fits]), np.float32)
                w.write(f"level_{lev}/{name}", a)
                if name != "rmse":
                    fit_bytes += a.nbytes
        table_bytes = write_tables(w, tables, V, L) if tables else 0
        if heights is not None:
            w.write("heights", heights, dimension_names=("exemplar", "y", "x"))
        rmse = [_rms([f[lev]["rmse"] for f in fits]) for lev in range(n_levels)]
        rmse_nt = [_rms([x[lev] for x in no_table]) for lev in range(n_levels)]
        mean_r = float(np.mean([x["mean_radiance"] for x in per_exemplar]))   # the exemplars hold as many samples each
        w.summary.update(kind="btf", source=str(tiling), source_hash=tiling_hash, scene=str(scene_path), exemplars=ks,
                         exemplar_names=names, periods=periods, per_exemplar=per_exemplar,
                         top=top, bottom=bottom, plane=p.plane, plane_z=top if z_plane is None else z_plane,
                         resolution=res,
                         levels=n_levels, lobes=p.lobes, view_grid=list(p.views), light_grid=list(p.lights),
                         light_coords=p.light_coords, light_domain=p.light_domain, directions=p.directions,
                         fit_light_grid=list(FIT_LIGHT_GRID if half else p.lights),
                         spp=p.spp, fit_rmse=rmse, fit_rmse_no_table=rmse_nt, fit_bytes=int(fit_bytes),
                         mean_radiance=mean_r, relative_fit_rmse=[x / max(mean_r, 1e-12) for x in rmse],
                         unconverged_texels=unconverged,
                         alpha_mean=float(np.mean(w.group["alpha"][...])), rays=int(rays),
                         rays_per_s=rays / max(acquire_s, 1e-9), acquire_s=acquire_s, fit_s=fit_s,
                         compile_s=compile_s, acquisition_key=acq_key, acquisition_reused=reused is not None,
                         models=["lafortune", "tabulated"] if tables else ["lafortune"])
        if tables:
            w.summary.update(table_rel_rmse=_rms([[x["table_rel_rmse"]] for x in per_exemplar]),
                             compress_s=compress_s)
    return {"skipped": False, "exemplars": E, "resolution": res, "views": V, "lights": L, "levels": n_levels,
            "fit_rmse": rmse, "fit_rmse_no_table": rmse_nt, "acquire_s": acquire_s, "fit_s": fit_s,
            "fit_bytes": int(fit_bytes), "mean_radiance": mean_r, "acquisition_reused": reused is not None,
            "table_bytes": int(table_bytes), "table_rel_rmse": w.summary.get("table_rel_rmse"),
            "compress_s": compress_s}
