"""Studies of the precomputed-light-transport renderer (``--method prt``, seed 001 §6.1 and §6.3).

``loomlight study prt-params STUDY.toml -o DIR`` (``run_params``): seed 001 §6.1's two parameter studies
on one exemplar, each variant against ``fiberpath`` on the same view and light:

- cell size (Fig. 8): one IIRTF per target cell length ``factors`` x the mean free path, rendered at SH
  order ``[cell_size] order``;
- SH order (Fig. 9): one IIRTF at the largest order, cut to each order L of ``[sh_order] orders``
  (``truncate_iirtf``: real SH are hierarchical, so the order-L transfer matrices and BCSDF tables are the
  leading (L+1)^2 rows and columns of the order-5 ones, every entry the same Monte Carlo estimate).

The study file (TOML; paths relative to it)::

    [study]
    name = "prt-params"
    tiling = "../tilings/flat_plain_study.toml"   # a tiling configuration: tiled into DIR/tiling.zarr
    scene = "../scenes/flat_satin.toml"          # optional: camera, materials (default: the tiling's scene)
    camera = { width = 96, height = 72 }         # merged into the scene's [camera]
    lights = [{ type = "sg", axis = [0.5, -0.5, 0.7071], sharpness = 100.0, power = 3.0 }]
    reference = { spp = 64, max_depth = 32, rr_depth = 5 }   # fiberpath: merged into the scene's [render]
    prt = { spp = 16 }                                       # prt: likewise
    svf = ["--resolution", "64"]                 # extra arguments of loomlight precompute svf
    iirtf = ["--paths", "300", "--light-sampling", "mis"]   # ... of precompute iirtf (not --order/--cell-factor)

    [cell_size]
    factors = [0.5, 1.0, 1.5, 2.0]               # --cell-factor values
    order = 5

    [sh_order]
    orders = [0, 1, 2, 3, 4, 5]
    cell_factor = 1.0                            # the IIRTF the orders are cut from

Outputs: DIR/tiling.zarr, svf.zarr, iirtf_c<f>.zarr (order max of both studies), iirtf_c<f>_L<l>.zarr (cut),
DIR/renders/<name>.exr (+ png, render artifact), the strips DIR/cell_size.png and DIR/sh_order.png (images
over error maps, each titled with its mean-intensity ratios to fiberpath), DIR/study.json, DIR/report.md/.html.

``loomlight study prt-terms SWEEP.toml --sweep-dir D -o DIR`` (``run_terms``): which term of prt holds a
sweep's error. From the sweep's methods ``fiberpath`` and ``prt`` it derives DIR/terms_sweep.toml with
``fiberpath_single`` (the same render, ``max_depth = 1``: direct light only, i.e. single scattering),
``prt_single`` (``--set terms=single``), ``prt_multi`` (``--set terms=multi``) and ``prt_hits`` (``--set
terms=hits``: eye rays only, whose time bounds prt's speed-up at equal spp), renders it through the
sweep machinery (``pipeline.runners.sweep``, its report in DIR/report.md compares prt_single with
fiberpath_single), then reads the full renders' mean intensities from D/sweep.json and writes
DIR/terms.json and DIR/attribution.md/.html: per configuration the ratios prt/fiberpath,
prt_single/fiberpath_single and (prt - prt_single)/(fiberpath - fiberpath_single) -- prt's multiple
scattering without what both term renders carry (misses that see the light, the ground; prt_multi holds it
too) -- and the RMSE of mean intensity split into its single and multiple scattering parts (``attribute``).

Renders of prt-params are reused while a stamp beside each records the same scene text, method, arguments,
content hashes of its input artifacts and loomlight's code hash (``pipeline.artifacts.code_hash``); the
precomputes skip by their own up-to-date check. ``force`` redoes everything.
"""
from __future__ import annotations

import copy
import hashlib
import json
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import LoomError
from ..toml_file import dumps_toml, read_toml

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


# ------------------------------------------------------------------------------------------------ study file
@dataclass
class Study:
    path: Path
    name: str
    tiling_config: Path
    scene: Path | None
    camera: dict
    lights: list
    reference: dict
    prt: dict
    svf_args: list[str]
    iirtf_args: list[str]
    cell_factors: list[float]
    cell_order: int
    orders: list[int]
    order_cell_factor: float

    @property
    def max_order(self) -> int:
        return max([self.cell_order, *self.orders])

    @property
    def iirtf_factors(self) -> list[float]:
        return sorted(set(self.cell_factors) | {self.order_cell_factor})


_RENDER_KEYS = ("spp", "max_depth", "rr_depth", "seed")
_RESERVED = {"--order", "--cell-factor", "--exemplar", "-o", "--out", "--force"}


def _need(path, table: dict, key: str, kind, where: str):
    if key not in table:
        raise LoomError(path, f"{where}.{key}", "missing")
    v = table[key]
    if not isinstance(v, kind) or isinstance(v, bool):
        raise LoomError(path, f"{where}.{key}", f"expected {getattr(kind, '__name__', 'a value')}, got {v!r}")
    return v


def _render_table(path, v, where) -> dict:
    if not isinstance(v, dict):
        raise LoomError(path, where, f"expected a table, got {v!r}")
    for k, x in v.items():
        if k not in _RENDER_KEYS:
            raise LoomError(path, f"{where}.{k}", f"unknown key (known: {', '.join(_RENDER_KEYS)})")
        if not isinstance(x, int) or isinstance(x, bool) or x < (0 if k == "seed" else 1):
            raise LoomError(path, f"{where}.{k}", f"expected a positive integer, got {x!r}")
    return dict(v)


def _args(path, v, where) -> list[str]:
    if not isinstance(v, list) or not all(isinstance(a, str) for a in v):
        raise LoomError(path, where, "expected a list of strings (command-line arguments)")
    bad = [a for a in v if a.split("=")[0] in _RESERVED]
    if bad:
        raise LoomError(path, where, f"{bad[0]} is set by the study itself")
    return list(v)


def load_study(path: str | Path) -> Study:
    """Read and check a study file (one ``LoomError`` line naming the key on bad input)."""
    path = Path(path)
    raw = read_toml(path, what="study file")
    for k in raw:
        if k not in ("study", "cell_size", "sh_order"):
            raise LoomError(path, k, "unknown table (known: study, cell_size, sh_order)")
    st = raw.get("study")
    if not isinstance(st, dict):
        raise LoomError(path, "study", "missing [study] table")
    def rel(p):
        return (path.parent / p).resolve() if not Path(p).is_absolute() else Path(p)
    tiling = rel(_need(path, st, "tiling", str, "study"))
    if not tiling.is_file():
        raise LoomError(path, "study.tiling", f"tiling configuration {tiling} not found")
    scene = rel(st["scene"]) if "scene" in st else None
    if scene is not None and not scene.is_file():
        raise LoomError(path, "study.scene", f"scene file {scene} not found")
    lights = _need(path, st, "lights", list, "study")
    if not lights or not all(isinstance(l, dict) and "type" in l for l in lights):
        raise LoomError(path, "study.lights", "expected a non-empty list of light tables with a 'type'")
    cs = raw.get("cell_size", {})
    so = raw.get("sh_order", {})
    factors = [float(f) for f in cs.get("factors", [])]
    orders = [int(o) for o in so.get("orders", [])]
    if not factors and not orders:
        raise LoomError(path, "cell_size.factors", "the study has neither cell sizes nor SH orders to compare")
    if any(not (f > 0) for f in factors):
        raise LoomError(path, "cell_size.factors", "cell factors must be > 0")
    if any(not 0 <= o <= 8 for o in orders):
        raise LoomError(path, "sh_order.orders", "SH orders must lie in 0..8")
    cell_order = int(cs.get("order", 4))
    if not 0 <= cell_order <= 8:
        raise LoomError(path, "cell_size.order", "SH order must lie in 0..8")
    ocf = float(so.get("cell_factor", factors[0] if factors else 1.0))
    if not ocf > 0:
        raise LoomError(path, "sh_order.cell_factor", "must be > 0")
    cam = st.get("camera", {})
    if not isinstance(cam, dict):
        raise LoomError(path, "study.camera", "expected a table")
    return Study(path, str(st.get("name", path.stem)), tiling, scene, dict(cam), copy.deepcopy(lights),
                 _render_table(path, st.get("reference", {}), "study.reference"),
                 _render_table(path, st.get("prt", {}), "study.prt"),
                 _args(path, st.get("svf", []), "study.svf"), _args(path, st.get("iirtf", []), "study.iirtf"),
                 factors, cell_order, orders, ocf)


# ------------------------------------------------------------------------------------------------ SH order cut
def truncate_iirtf(src: str | Path, order: int, out: str | Path, tiling: str | Path, force: bool = False) -> Path:
    """The IIRTF artifact ``src`` cut to SH order ``order`` (at most its own) into ``out``: transfer matrices
    and their standard errors keep their leading (order+1)^2 rows and columns, the BCSDF tables C_S their
    leading (order+1)^2 coefficients; everything else is copied. ``tiling`` is the tiling ``src`` was
    precomputed from (recorded as the input, so prt accepts the result with that tiling)."""
    t_start = time.perf_counter()  # wall_time_s: the whole stage, imports and input reading too
    from ..artifacts import Artifact, ArtifactWriter

    src, out = Path(src), Path(out)
    a = Artifact(src, kind="iirtf")
    L0 = int(a.summary["order"])
    if not 0 <= order <= L0:
        raise LoomError(src, "order", f"cannot cut an IIRTF of SH order {L0} to order {order}")
    J0, J = (L0 + 1) ** 2, (order + 1) ** 2
    w = ArtifactWriter(out, kind="iirtf", stage="study: iirtf cut to a lower SH order",
                       params={"order": order, "source_order": L0},
                       inputs={"tiling": (Path(tiling), "tiling"), "iirtf": (src, "iirtf")}, started=t_start)
    if not force and w.up_to_date():
        return out
    with w:
        for name in a.arrays():
            x = a[name]
            leaf = name.rsplit("/", 1)[-1]
            if leaf in ("transfer", "transfer_se"):
                x = x[:, :, :J, :J]
            elif name == "bcsdf_sh":
                x = x[:, :, :J, :]
            w.write(name, np.ascontiguousarray(x))
        summary = copy.deepcopy(dict(a.summary))
        for e in summary["exemplars"]:
            n = int(e["stored_cells"])
            e["bytes"] = int(e["bytes"]) - 2 * n * 3 * (J0 * J0 - J * J) * 4
        summary.update(order=order, sh_coefficients=J, cut_from_order=L0, cut_from=str(src))
        w.summary.update(summary)
    return out


# ------------------------------------------------------------------------------------------------ renders
@dataclass
class RenderJob:
    name: str
    method: str
    args: list[str]
    exr: Path
    scene_file: Path
    scene_text: str
    inputs: list[Path] = field(default_factory=list)


def _render_text(table: dict) -> str:
    return " ".join(f"{k} {v}" for k, v in table.items())


def _job_key(job: RenderJob) -> str:
    from .. import __version__
    from ..artifacts import code_hash, content_hash

    doc = {"scene": job.scene_text, "method": job.method, "args": job.args, "version": __version__, "code": code_hash(),
           "inputs": {str(p): content_hash(p) for p in job.inputs}}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def run_render(job: RenderJob, force: bool) -> bool:
    """Render ``job`` unless its stamp holds; True when it rendered."""
    from ..report import write_text
    from .sweep import cli_render

    stamp = job.exr.with_suffix(".stamp.json")
    key = _job_key(job)
    if not force and job.exr.exists():
        try:
            if json.loads(stamp.read_text()).get("key") == key:
                return False
        except (OSError, ValueError):
            pass
    stamp.unlink(missing_ok=True)
    job.exr.parent.mkdir(parents=True, exist_ok=True)
    cli_render(job.scene_file, job.method, job.exr, list(job.args))
    write_text(stamp, json.dumps({"key": key, "method": job.method, "args": job.args}, indent=2) + "\n")
    return True


def _cli(args: list[str], what: Path) -> None:
    from ..cli import main

    rc = main([str(a) for a in args])
    if rc != 0:
        raise LoomError(what, None, f"loomlight {' '.join(str(a) for a in args[:2])} failed with exit code {rc}")


# ------------------------------------------------------------------------------------------------ comparison
def compare(test: np.ndarray, ref: np.ndarray) -> dict:
    """Mean-intensity ratios per channel (test / reference), their relative RMS error, and the image metrics
    (``pipeline.runners.evaluate.image_metrics``: RMSE, relMSE, SSIM, ΔE00) against the reference."""
    from .evaluate import image_metrics

    e = image_metrics(test, ref)
    mt = np.asarray(e["mean_intensity"], float)
    mr = np.asarray(ref, float).reshape(-1, 3).mean(axis=0)
    ratio = mt / np.maximum(mr, 1e-12)
    e["reference_mean_intensity"] = mr.tolist()
    e["ratio"] = ratio.tolist()
    e["luminance_ratio"] = float(mt @ LUMINANCE / max(float(mr @ LUMINANCE), 1e-12))
    e["mean_intensity_rel_error"] = float(np.sqrt(np.mean((mt - mr) ** 2))
                                          / max(float(np.sqrt(np.mean(mr ** 2))), 1e-12))
    return e


def strip_png(ref: np.ndarray, tests: list[np.ndarray], labels: list[str], metrics: list[dict], path: Path,
              title: str) -> Path:
    """One row of sRGB previews (the reference first) over one row of relative-error maps against the
    reference (``pipeline.report.relative_error``, log scale 1e-4..10 as the evaluation's maps)."""
    import os

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    from ..images import to_srgb8
    from ..report import ERR_RANGE, relative_error

    n = 1 + len(tests)
    h, w = ref.shape[:2]
    s = max(1.0, 240.0 / w)
    fig, axes = plt.subplots(2, n, figsize=(n * (w * s / 100 + 0.25), 2 * (h * s / 100) + 1.4), squeeze=False)
    im = None
    for c in range(n):
        img = ref if c == 0 else tests[c - 1]
        ax = axes[0][c]
        ax.imshow(to_srgb8(img), interpolation="nearest")
        if c == 0:
            m = np.asarray(ref, float).reshape(-1, 3).mean(axis=0)
            ax.set_title("fiberpath (reference)\nmean " + ", ".join(f"{v:.3f}" for v in m), fontsize=7)
        else:
            e = metrics[c - 1]
            ax.set_title(f"{labels[c - 1]}\nratio " + ", ".join(f"{v:.2f}" for v in e["ratio"])
                         + f"\nRMSE {e['rmse']:.3f}, SSIM {e['ssim']:.2f}", fontsize=7)
        ax2 = axes[1][c]
        if c > 0:
            err = np.clip(relative_error(img, ref), *ERR_RANGE)
            im = ax2.imshow(err, cmap="inferno", norm=LogNorm(*ERR_RANGE), interpolation="nearest")
        for a in (ax, ax2):
            a.set_xticks([])
            a.set_yticks([])
        if c == 0:
            ax2.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axes[1].tolist(), fraction=0.02, pad=0.01, label="relative squared error")
    fig.suptitle(title, fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}.png")
    try:
        fig.savefig(str(tmp), format="png", dpi=100, bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    return path


# ------------------------------------------------------------------------------------------------ prt-params
def _fmt_factor(f: float) -> str:
    return f"{f:g}"


def _scene_text(study: Study, scene_path: Path, method: str, render: dict) -> str:
    raw = read_toml(scene_path, what="scene file")
    base = scene_path.parent
    fab = raw.get("fabric", {})
    if "path" in fab and not Path(fab["path"]).is_absolute():
        fab["path"] = str((base / fab["path"]).resolve())
    raw["lights"] = copy.deepcopy(study.lights)
    if study.camera:
        raw["camera"] = {**raw.get("camera", {}), **study.camera}
    raw["render"] = {**raw.get("render", {}), **render, "method": method}
    return (f"# derived by loomlight study prt-params {study.path.name} from {scene_path}: {method}\n"
            + dumps_toml(raw))


@dataclass
class ParamsResult:
    out_dir: Path
    cell_size: list
    sh_order: list
    rendered: int
    report_md: Path


def run_params(study_path: str | Path, out_dir: str | Path, force: bool = False) -> ParamsResult:
    from .. import report as rp
    from ..artifacts import Artifact
    from ..schemas import validate
    from .evaluate import load_image, render_stats

    study = load_study(study_path)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise LoomError(out, None, "output path exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    f_ = ["--force"] if force else []
    timings: dict[str, float] = {}

    # precompute: tiling, SVF, one IIRTF per cell factor at the largest order, cuts to lower orders
    tiling = out / "tiling.zarr"
    _cli(["tile", study.tiling_config, "-o", tiling, *f_], study.path)
    scene_path = study.scene or Path(Artifact(tiling, kind="tiling").summary["scene"])
    svf = out / "svf.zarr"
    t0 = time.perf_counter()
    _cli(["precompute", "svf", tiling, "-o", svf, *study.svf_args, *f_], study.path)
    timings["svf"] = time.perf_counter() - t0
    iirtf: dict[float, Path] = {}
    for f in study.iirtf_factors:
        iirtf[f] = out / f"iirtf_c{_fmt_factor(f)}.zarr"
        t0 = time.perf_counter()
        _cli(["precompute", "iirtf", tiling, "-o", iirtf[f], "--order", study.max_order, "--cell-factor", f,
              "--scene", scene_path, *study.iirtf_args, *f_], study.path)
        timings[f"iirtf_c{_fmt_factor(f)}"] = time.perf_counter() - t0

    def at_order(f: float, L: int) -> Path:
        if L == study.max_order:
            return iirtf[f]
        return truncate_iirtf(iirtf[f], L, out / f"iirtf_c{_fmt_factor(f)}_L{L}.zarr", tiling, force)

    # renders: the reference and every variant, on one view and light (a derived scene per method)
    scenes = {}
    for method, render in (("fiberpath", study.reference), ("prt", study.prt)):
        text = _scene_text(study, scene_path, method, render)
        validate(tomllib.loads(text), "scene", study.path, prefix=f"derived {method} scene: ")
        scenes[method] = (rp.write_text(out / f"scene_{method}.toml", text), text)
    rdir = out / "renders"

    def prt_job(name: str, ii: Path) -> RenderJob:
        return RenderJob(name, "prt", ["--fibers", str(tiling), "--set", f"svf={svf}", "--set", f"iirtf={ii}"],
                         rdir / f"{name}.exr", *scenes["prt"], [tiling, svf, ii])

    ref = RenderJob("fiberpath", "fiberpath", ["--fibers", str(tiling)], rdir / "fiberpath.exr", *scenes["fiberpath"],
                    [tiling])
    cell_jobs = [(f, prt_job(f"prt_c{_fmt_factor(f)}", at_order(f, study.cell_order))) for f in study.cell_factors]
    oc = study.order_cell_factor
    order_jobs = [(L, prt_job(f"prt_c{_fmt_factor(oc)}_L{L}", at_order(oc, L))) for L in study.orders]
    jobs = {j.name: j for j in [ref] + [j for _, j in cell_jobs] + [j for _, j in order_jobs]}
    rendered = sum(run_render(j, force) for j in jobs.values())

    # compare
    ref_img = load_image(ref.exr)
    ref_stats = render_stats(ref.exr)

    def entry(job: RenderJob, ii: Path, extra: dict) -> dict:
        img = load_image(job.exr)
        e = compare(img, ref_img)
        st = render_stats(job.exr)
        a = Artifact(ii, kind="iirtf")
        ex = a.summary["exemplars"][0]
        # speed-up at equal samples per pixel: time per sample of fiberpath over prt's
        def per(x):
            return x["time_s"] / x["spp"] if x.get("time_s") and x.get("spp") else None
        e.update(extra, name=job.name, image=str(job.exr), time_s=st.get("time_s"), spp=st.get("spp"),
                 speedup=(per(ref_stats) / per(st)) if per(ref_stats) and per(st) else None,
                 iirtf=str(ii), sh_order=int(a.summary["order"]), mean_free_path=ex["mean_free_path"],
                 cell_grid=ex["cell_grid"], cell_size=ex["cell_size"], stored_cells=ex["stored_cells"],
                 iirtf_bytes=ex["bytes"], paths=int(a.summary["paths"]),
                 iirtf_time_s=a.summary.get("time_s"))
        return e, img

    cell_rows, cell_imgs = [], []
    for f, j in cell_jobs:
        e, img = entry(j, at_order(f, study.cell_order), {"cell_factor": f})
        cell_rows.append(e)
        cell_imgs.append(img)
    order_rows, order_imgs = [], []
    for L, j in order_jobs:
        e, img = entry(j, at_order(study.order_cell_factor, L), {"cell_factor": study.order_cell_factor})
        order_rows.append(e)
        order_imgs.append(img)
    # against the variant closest to the converged one (the smallest cells, the highest order): prt renders
    # share their random numbers, so these ratios show the IIRTF's effect without the reference's noise
    for rows, key in ((cell_rows, lambda e: e["cell_factor"]), (order_rows, lambda e: -e["sh_order"])):
        if rows:
            base = np.asarray(min(rows, key=key)["mean_intensity"], float)
            for e in rows:
                e["ratio_to_finest"] = (np.asarray(e["mean_intensity"], float) / np.maximum(base, 1e-12)).tolist()

    lights = "; ".join(", ".join(f"{k} {v}" for k, v in l.items()) for l in study.lights)
    rep = rp.Report(f"prt parameter study {study.name} (Khungurn et al. 2017 §6.1)")
    ex0 = (cell_rows or order_rows)[0]
    rep.paragraph(f"Study file {study.path}; tiling {study.tiling_config} (one exemplar, mean free path "
                  f"ℓ = {ex0['mean_free_path']:.5f}); scene {scene_path}; light: {lights}. Reference: fiberpath on the "
                  f"tiling's explicit fibres ({_render_text(study.reference)}); prt "
                  f"({_render_text(study.prt)}). SVF: {' '.join(study.svf_args) or 'defaults'}; IIRTF: "
                  f"{' '.join(study.iirtf_args) or 'defaults'}. Ratios: the prt image's mean intensity over "
                  "fiberpath's "
                  f"(R, G, B); relative error: RMS over channels of the mean-intensity difference over the RMS of "
                  f"fiberpath's means; vs finest: the mean intensity over the smallest cells' (the highest order's) "
                  f"prt image, which shares its random numbers. Times: render kernels, compilation apart.")
    rep.paragraph(f"fiberpath: {ref_stats.get('time_s', float('nan')):.2f} s at {ref_stats.get('spp')} spp, "
                  "mean intensity "
                  + ", ".join(f"{v:.4f}" for v in ref_img.reshape(-1, 3).mean(axis=0)))
    heads = ["variant", "cells (grid)", "cell side (cm)", "stored cells", "IIRTF bytes", "R, G, B ratio",
             "rel. error of mean", "image RMSE", "SSIM", "R, G, B vs finest", "time", "speed-up at equal spp"]

    def row(e, label):
        return [label, "x".join(str(v) for v in e["cell_grid"]), f"{e['cell_size'][0]:.4f}", e["stored_cells"],
                rp.fmt_bytes(e["iirtf_bytes"]), ", ".join(f"{v:.3f}" for v in e["ratio"]),
                f"{e['mean_intensity_rel_error']:.1%}", f"{e['rmse']:.4f}", f"{e['ssim']:.3f}",
                ", ".join(f"{v:.3f}" for v in e["ratio_to_finest"]),
                rp.fmt_seconds(e["time_s"]) if e["time_s"] is not None else "-",
                f"{e['speedup']:.1f}x" if e["speedup"] else "-"]

    if cell_rows:
        rep.heading("Cell size (Khungurn et al. 2017 Fig. 8)")
        rep.table(heads, [row(e, f"{e['cell_factor']:g} ℓ") for e in cell_rows],
                  caption=f"SH order {study.cell_order}; IIRTF precompute times: "
                          + ", ".join(f"{e['cell_factor']:g} ℓ {e['iirtf_time_s']:.0f} s" for e in cell_rows
                                      if e.get("iirtf_time_s") is not None))
        strip_png(ref_img, cell_imgs, [f"cells {e['cell_factor']:g} ℓ" for e in cell_rows], cell_rows,
                  out / "cell_size.png", f"IIRTF cell size (SH order {study.cell_order}) against fiberpath")
        rep.image("cell_size.png", "fiberpath, then prt at each cell size; below: relative squared error")
    if order_rows:
        rep.heading("SH order (Khungurn et al. 2017 Fig. 9)")
        rep.table(heads, [row(e, f"L = {e['sh_order']}") for e in order_rows],
                  caption=f"All cut from one IIRTF of order {study.max_order} with cells of "
                          f"{study.order_cell_factor:g} ℓ")
        strip_png(ref_img, order_imgs, [f"L = {e['sh_order']}" for e in order_rows], order_rows,
                  out / "sh_order.png", f"SH order (cells of {study.order_cell_factor:g} ℓ) against fiberpath")
        rep.image("sh_order.png", "fiberpath, then prt at each SH order; below: relative squared error")
    md, _ = rep.write(out)
    doc = {"study": study.name, "file": str(study.path), "tiling": str(tiling), "scene": str(scene_path),
           "reference": {"image": str(ref.exr), "time_s": ref_stats.get("time_s"),
                         "mean_intensity": ref_img.reshape(-1, 3).mean(axis=0).tolist()},
           "cell_size": cell_rows, "sh_order": order_rows, "precompute_wall_s": timings, "rendered": rendered}
    rp.write_text(out / "study.json", json.dumps(doc, indent=2) + "\n")
    return ParamsResult(out, cell_rows, order_rows, rendered, md)


# ------------------------------------------------------------------------------------------------ prt-terms
def attribute(fp: np.ndarray, fp1: np.ndarray, prt: np.ndarray, ps: np.ndarray, pm: np.ndarray) -> dict:
    """Split prt's error in mean intensity over configurations into single and multiple scattering.

    Arrays (C, 3) of mean intensities: fiberpath (full), fiberpath with max_depth 1 (single scattering),
    prt, prt single, prt multi. References: fp1 for single scattering, the remainder fp - fp1 for multiple
    scattering. prt's multiple scattering is taken as prt - ps: both term renders also carry what is not
    scattering by fibres (pixels that miss the cloth and see the light, the ground), which cancels there;
    ps + pm - prt measures it (``both``). Then prt - fp = (ps - fp1) + ((prt - ps) - (fp - fp1)) exactly.
    RMSEs are over configurations and channels; relative ones divide by the RMS of fp."""
    fp, fp1, prt, ps, pm = (np.asarray(a, float) for a in (fp, fp1, prt, ps, pm))
    rms = float(np.sqrt(np.mean(fp ** 2)))
    def r(d):
        return float(np.sqrt(np.mean(d ** 2)))
    d_all, d_s = prt - fp, ps - fp1
    d_m = (prt - ps) - (fp - fp1)
    def rel(x):
        return x / rms if rms > 0 else None
    return {"rmse": r(d_all), "rmse_single": r(d_s), "rmse_multi": r(d_m),
            "relative_rmse": rel(r(d_all)), "relative_rmse_single": rel(r(d_s)), "relative_rmse_multi": rel(r(d_m)),
            "mean_error": float(np.mean(d_all)), "mean_error_single": float(np.mean(d_s)),
            "mean_error_multi": float(np.mean(d_m)),
            "both_terms_mean": float(np.mean(ps + pm - prt)),
            "multi_share_reference": float(np.sum(fp - fp1) / max(float(np.sum(fp)), 1e-300))}


@dataclass
class TermsResult:
    out_dir: Path
    summary: dict
    rows: list
    report_md: Path


def run_terms(sweep_path: str | Path, sweep_dir: str | Path, out_dir: str | Path, reference: str = "fiberpath",
              prt: str = "prt", force: bool = False, renderer=None) -> TermsResult:
    """``renderer``: as ``pipeline.runners.sweep.run_sweep``'s (default: ``loomlight render`` in process)."""
    from .. import report as rp
    from .sweep import expand_args, run_sweep
    from .sweep_file import load_sweep

    sweep = load_sweep(sweep_path)
    sweep_dir, out = Path(sweep_dir), Path(out_dir)
    byname = {m.name: m for m in sweep.methods}
    for n in (reference, prt):
        if n not in byname:
            raise LoomError(sweep.path, "methods", f"has no method named {n!r} (has {', '.join(byname)})")
    full_json = sweep_dir / "sweep.json"
    if not full_json.is_file():
        raise LoomError(full_json, None, f"not found: run loomlight evaluate --sweep {sweep.path} -o {sweep_dir} first")
    full = json.loads(full_json.read_text())
    raw = read_toml(sweep.path, what="sweep file")
    fm, pm_ = byname[reference], byname[prt]
    fargs = expand_args(sweep, sweep_dir, fm.args)
    pargs = expand_args(sweep, sweep_dir, pm_.args)
    doc = {"sweep": {"name": f"{sweep.name}-terms", "description": f"terms of {sweep.name}: single and multiple "
                     f"scattering of {prt} against {reference} with max_depth 1 and the remainder",
                     "scene": str(sweep.scene_path), "reference": f"{reference}_single",
                     "render": dict(sweep.render), "camera": dict(sweep.camera)},
           "methods": [{"name": f"{reference}_single", "method": fm.method, "render": {**fm.render, "max_depth": 1},
                        "args": fargs},
                       {"name": f"{prt}_single", "method": pm_.method, "render": dict(pm_.render),
                        "args": [*pargs, "--set", "terms=single"]},
                       {"name": f"{prt}_multi", "method": pm_.method, "render": dict(pm_.render),
                        "args": [*pargs, "--set", "terms=multi"]},
                       {"name": f"{prt}_hits", "method": pm_.method, "render": dict(pm_.render),
                        "args": [*pargs, "--set", "terms=hits"]}]}
    for k in ("grid", "configurations"):
        if k in raw:
            doc[k] = raw[k]
    out.mkdir(parents=True, exist_ok=True)
    tpath = rp.write_text(out / "terms_sweep.toml", f"# derived by loomlight study prt-terms from {sweep.path}\n"
                          + dumps_toml(doc))
    run_sweep(tpath, out, force=force, renderer=renderer)
    terms = json.loads((out / "sweep.json").read_text())
    fullc = {c["name"]: c for c in full["configurations"]}
    rows, arrs = [], {k: [] for k in ("fp", "fp1", "prt", "ps", "pm")}
    for c in terms["configurations"]:
        fc = fullc.get(c["name"])
        mi, mf = c["mean_intensity"], (fc or {}).get("mean_intensity", {})
        vals = (mf.get(reference), mi.get(f"{reference}_single"), mf.get(prt), mi.get(f"{prt}_single"),
                mi.get(f"{prt}_multi"))
        if any(v is None for v in vals):
            continue
        fp, fp1, p, ps, pm = (np.asarray(v, float) for v in vals)
        for k, v in zip(arrs, (fp, fp1, p, ps, pm)):
            arrs[k].append(v)
        t = c.get("time_s", {})
        tf = (fc or {}).get("time_s", {})
        rows.append({"configuration": c["name"], "description": c["description"],
                     "ratio": (p / np.maximum(fp, 1e-12)).tolist(),
                     "single_ratio": (ps / np.maximum(fp1, 1e-12)).tolist(),
                     "multi_ratio": ((p - ps) / np.maximum(fp - fp1, 1e-12)).tolist(),
                     "multi_share": float(np.sum(fp - fp1) / max(float(np.sum(fp)), 1e-300)),
                     "both_terms": (ps + pm - p).tolist(),
                     "time_s": {reference: tf.get(reference), prt: tf.get(prt),
                                f"{reference}_single": t.get(f"{reference}_single"),
                                f"{prt}_single": t.get(f"{prt}_single"), f"{prt}_multi": t.get(f"{prt}_multi"),
                                f"{prt}_hits": t.get(f"{prt}_hits")}})
    if not rows:
        raise LoomError(sweep_dir, "sweep.json", "no configuration has all five renders")
    summary = attribute(*(np.array(arrs[k]) for k in ("fp", "fp1", "prt", "ps", "pm")))
    summary["configurations"] = len(rows)
    def mean_t(k):
        return float(np.mean([r["time_s"][k] for r in rows if r["time_s"].get(k) is not None] or [np.nan]))
    summary["time_per_image_s"] = tpi = {k: mean_t(k) for k in rows[0]["time_s"]}
    summary["speedup"] = full["methods"].get(prt, {}).get("speedup") or float("nan")   # the sweep's own
    summary["speedup_bound"] = tpi[reference] / tpi[f"{prt}_hits"]   # nan where a time is missing

    rep = rp.Report(f"Which term holds prt back: {sweep.name}")
    rep.paragraph(f"Sweep {sweep.path} (full renders in {sweep_dir}); term renders in {out}/renders. Single "
                  f"scattering: {prt} --set terms=single against {reference} with max_depth 1 (direct light only). "
                  f"Multiple scattering: {prt} - {prt}_single (which equals {prt} --set terms=multi less the light "
                  f"both term renders carry) against the remainder {reference} - {reference}_single. Ratios are "
                  f"mean intensities per channel (R, G, B).")
    rep.table(["configuration", f"{prt} / {reference}", "single / single", "multi / remainder",
               f"multi share of {reference}"],
              [[r["configuration"], ", ".join(f"{v:.3f}" for v in r["ratio"]),
                ", ".join(f"{v:.3f}" for v in r["single_ratio"]), ", ".join(f"{v:.3f}" for v in r["multi_ratio"]),
                f"{r['multi_share']:.0%}"] for r in rows])
    s = summary
    rep.table(["", "all", "single", "multi"],
              [["RMSE of mean intensity", rp.fmt_num(s["rmse"]), rp.fmt_num(s["rmse_single"]),
                rp.fmt_num(s["rmse_multi"])],
               ["relative (to RMS of the reference)", f"{s['relative_rmse']:.1%}", f"{s['relative_rmse_single']:.1%}",
                f"{s['relative_rmse_multi']:.1%}"],
               ["mean signed error", rp.fmt_num(s["mean_error"]), rp.fmt_num(s["mean_error_single"]),
                rp.fmt_num(s["mean_error_multi"])]],
              caption=f"prt - fiberpath = (single - single ref.) + (multi - remainder), prt's multiple scattering "
                      f"taken as prt - prt_single: light that both term renders carry (misses that see the light, "
                      f"the ground; mean {s['both_terms_mean']:.3g}) cancels there. Multiple scattering is "
                      f"{s['multi_share_reference']:.0%} of fiberpath's light.")
    rep.table(["render", "time per image"], [[k, rp.fmt_seconds(v)] for k, v in summary["time_per_image_s"].items()],
              caption=f"{prt}_hits (--set terms=hits) walks the eye rays to their first fibre hit and shades nothing: "
                      f"every {prt} sample pays that walk, so at equal spp {prt} cannot be more than "
                      f"{reference} / {prt}_hits = {s['speedup_bound']:.1f}x faster than {reference} here (it is "
                      f"{s['speedup']:.1f}x).")
    md, _ = rep.write(out, stem="attribution")
    rp.write_text(out / "terms.json", json.dumps({"sweep": str(sweep.path), "summary": summary, "configurations": rows},
                                                 indent=2) + "\n")
    return TermsResult(out, summary, rows, md)
