"""``--method prt``: precomputed light transport on a shell-mapped tiling (seed 001 §5-§6, CPU version).

Inputs: the tiling (``--fibers TILING.zarr`` or ``--set tiling=``), its segment visibility functions
(``--set svf=SVF.zarr``, ``loomlight precompute svf``) and its IIRTF (``--set iirtf=IIRTF.zarr``,
``loomlight precompute iirtf``); both must have been computed from this very tiling (their recorded
input identity equals the tiling's) and cover every exemplar its block map uses, and the IIRTF's fibre
materials must be the ones the scene gives the tiling now (the yarn BCSDFs and colours), since single
scattering shades with them and multiple scattering was precomputed with them.

Settings (``--set``): ``terms`` all (default) | single | multi | hits (fibre hits left black: the eye rays
walk to their first fibre hit and no more, which times the walk every prt sample pays); ``sg`` mc (default:
SG lights sampled into directions, the paper's CPU version) | analytic (§5.2.2's Gamma, sum of SGs and
erf-smoothed SSDF);
``sigma_glo`` the standard deviation of the Gaussian that filters the global visibility of multiple
scattering, in flat-fabric units (default: the tiling's exemplar thickness, the depth over which light
spreads sideways inside the cloth); ``sh_window`` none (default) | hann | lanczos: multiplies band l of
both SH sides of every transfer matrix (the light's and the BCSDF's) by w_l, Hann 0.5 (1 + cos(pi l /
(L + 1))) or Lanczos sinc(pi l / (L + 1)) (L the IIRTF's order), the classic cure for the ringing of a
truncated SH expansion (Sloan 2008, "Stupid Spherical Harmonics Tricks" §8), traded against blur of
multiple scattering's angular detail. Integrator: ``stages.render.integrators.prt``.
"""
from __future__ import annotations

import time

import numpy as np

from ..errors import LoomError, unknown
from . import RenderResult
from .settings import number_setting

TERMS = {"all": 3, "single": 1, "multi": 2, "hits": 0}
SH_WINDOWS = ("none", "hann", "lanczos")


def sh_window(kind: str, order: int) -> np.ndarray:
    """w_l per SH coefficient j (band l = floor(sqrt(j))) of an expansion of ``order``: 1 for "none"."""
    if kind not in SH_WINDOWS:
        raise LoomError(None, "--set sh_window", unknown("SH window", kind, SH_WINDOWS))
    band = np.floor(np.sqrt(np.arange((order + 1) ** 2))).astype(float)
    x = np.pi * band / (order + 1)
    if kind == "hann":
        return 0.5 * (1.0 + np.cos(x))
    if kind == "lanczos":
        return np.sinc(x / np.pi)
    return np.ones_like(x)
SG_MODES = {"mc": 0, "analytic": 1}
MS_INCIDENCE = {"local": False, "filtered": True}
MS_INCIDENCE_DEFAULT = "filtered"   # flat cloth renders the same bytes either way (tests/render/test_prt.py)


def _check_precompute(art_path, kind, tiling_path, tiling_id):
    from ..artifacts import Artifact

    a = Artifact(art_path, kind=kind)
    rec = (a.meta.get("inputs") or {}).get("tiling") or {}
    if rec.get("sha256") != tiling_id:
        raise LoomError(art_path, "inputs.tiling", f"was precomputed from another tiling ({rec.get('path')}, identity "
                        f"{str(rec.get('sha256'))[:12]}) than {tiling_path} (identity {tiling_id[:12]}); run loomlight "
                        f"precompute {kind} on it")
    return a


def _used_exemplars(art) -> list[int]:
    bm = art["block_map"]
    return sorted(int(k) for k in np.unique(bm) if k >= 0)


def load_prt(scene, tiling_path, svf_path, iirtf_path, options):
    """(ShellScene, tiling Artifact, integrator arrays dict) for ``PrtIntegrator``."""
    from stages.core.shell.top import build_top_surface

    from ..artifacts import input_identity
    from ..progress import warn
    from ..runners.precompute import IIRTF_FIRST_RAY, SVF_RAY_START, tiling_materials
    from ..runners.tile import load_tiling

    sc, art = load_tiling(tiling_path)
    tid = input_identity(tiling_path, "tiling")
    svf = _check_precompute(svf_path, "svf", tiling_path, tid)
    ii = _check_precompute(iirtf_path, "iirtf", tiling_path, tid)
    if (svf.meta.get("params") or {}).get("ray_start") != SVF_RAY_START:
        warn(f"{svf_path}: an SVF made before 2026-12-02, its rays from the segments' midpoints, which shadows "
             "light the segments' surfaces receive (single scattering ~5-10 % darker); run loomlight precompute "
             "svf again")
    if (ii.meta.get("params") or {}).get("first_ray") != IIRTF_FIRST_RAY:
        warn(f"{iirtf_path}: an IIRTF made before 2026-12-02, whose paths passed through the fibres containing "
             "a segment's midpoint (multiple scattering ~10-20 % darker); run loomlight precompute iirtf again")
    from stages.render.integrators.prt import MAX_SH_ORDER

    if not 0 <= int(ii.summary["order"]) <= MAX_SH_ORDER:
        raise LoomError(ii.path, "summary.order", f"SH order {ii.summary['order']} is outside 0..{MAX_SH_ORDER}")
    used = _used_exemplars(art)
    for a, what in ((svf, "svf"), (ii, "iirtf")):
        have = {e["exemplar"] for e in a.summary["exemplars"]}
        missing = [k for k in used if k not in have]
        if missing:
            raise LoomError(a.path, "exemplars", f"has no {what} data for exemplar {missing[0]} "
                            f"('{art.summary['exemplar_names'][missing[0]]}'), which the tiling's block map uses "
                            f"(it has {sorted(have)}); precompute it (loomlight precompute {what} without --exemplar)")
    extra = options.get("extra") or {}
    mof, mats = tiling_materials(scene, art, {"tint": extra.get("tint", "yarn"), "bcsdf": options.get("bcsdf")})
    if not (np.array_equal(mof, ii["mat_of_fiber"]) and np.array_equal(mats, ii["materials"])):
        raise LoomError(ii.path, "materials", "was precomputed with other fibre materials than the scene gives "
                        f"the tiling now ({scene.path}: yarn BCSDFs, colours, tint); run loomlight precompute iirtf "
                        "again with this scene")
    S = int(art.summary["segments"])
    K = int(art.summary["exemplars"])
    R, C = svf.summary["resolution"]
    n = int(svf.summary["components"])
    svf_row = np.full(S, -1, np.int64)
    seg_row = np.full(S, -1, np.int64)
    mean = np.zeros((K, R * C), np.float32)
    basis = np.zeros((K, n, R * C), np.float32)
    coeffs, angles, weights, transfer = [], [], [], []
    off = off2 = 0
    for e in svf.summary["exemplars"]:
        k = e["exemplar"]
        a, b = e["segment_range"]
        g = f"exemplar_{k}/"
        svf_row[a:b] = off + np.arange(b - a)
        off += b - a
        mean[k] = svf[g + "ssdf_mean"]
        basis[k] = svf[g + "ssdf_basis"]
        coeffs.append(svf[g + "ssdf_coeffs"])
        angles.append(svf[g + "sg_angle"])
        weights.append(svf[g + "sg_weights"])
    layer_tau = None   # an IIRTF made before 2026-12-07 has none: the paper's opaque shell
    for e in ii.summary["exemplars"]:
        k = e["exemplar"]
        g = f"exemplar_{k}/"
        if "layer_bins" in ii.summary:   # the shapes checked on reading (pipeline.artifact_checks)
            tau = ii[g + "layer_tau"]
            if layer_tau is None:
                layer_tau = np.ones((K, *tau.shape))
            layer_tau[k] = tau
        rows = ii[g + "seg_row"].astype(np.int64)
        f0, _f1 = int(art["ex_fibers"][k]), int(art["ex_fibers"][k + 1])
        a = int(art["ex_offsets"][f0]) - f0
        seg_row[a:a + len(rows)] = np.where(rows >= 0, rows + off2, -1)
        tr = ii[g + "transfer"]
        off2 += len(tr)
        transfer.append(tr)
    top = build_top_surface(art["base_uv"], art["base_triangles"], art["base_vertices"], art["base_normals"],
                            float(art.summary["thickness"]))
    arrays = dict(top=top, mat_of_fiber=mof, mats=mats, svf_row=svf_row, svf_mean=mean, svf_basis=basis,
                  svf_coeffs=np.ascontiguousarray(np.concatenate(coeffs)),
                  svf_res=np.array([R, C], np.int64), sg_angle=np.concatenate(angles),
                  sg_weights=np.ascontiguousarray(np.concatenate(weights)),
                  lam_svf=float(svf.summary["sg_sharpness"]), seg_row=seg_row,
                  transfer=np.ascontiguousarray(np.concatenate(transfer)), order=int(ii.summary["order"]),
                  cs_table=np.ascontiguousarray(ii["bcsdf_sh"]), mat_cs=np.arange(len(mats), dtype=np.int64),
                  below=ii.summary.get("light_domain", "hemisphere") == "sphere",
                  layer_tau=np.ascontiguousarray(layer_tau if layer_tau is not None else np.zeros((0, 2, 1, 3))))
    return sc, art, arrays


def film_setup(scene, options: dict):
    """The ``FilmSetup`` of a prt render (``pipeline.renderers.film``): integrator, camera, label."""
    from stages.core.sh import quarter_turn_x
    from stages.core.shading.material import pack_material_lambert
    from stages.render.film import VARIANCE_CHANNELS
    from stages.render.integrators.prt import PrtIntegrator

    from ..render_setup import ground_array, pack_lights, ray_eps
    from ..scene import camera_array
    from .film import FilmSetup

    extra = options.get("extra") or {}
    tiling = options.get("fibers") or extra.get("tiling")
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    lights = pack_lights(scene.lights, scene.path)
    if len(lights.lights) == 0:
        raise LoomError(scene.path, "lights", "the scene has no lights (the image would be black)")
    for key in ("svf", "iirtf"):
        if not extra.get(key):
            raise LoomError(None, f"--set {key}", f"prt needs the tiling's {key} artifact: pass --set "
                            f"{key}=PATH.zarr (loomlight precompute {key})")
    t0 = time.perf_counter()
    sc, art, arr = load_prt(scene, tiling, extra["svf"], extra["iirtf"], options)
    load_s = time.perf_counter() - t0
    terms = TERMS[extra.get("terms", "all")]
    sg_mode = SG_MODES[extra.get("sg", "mc")]
    window = extra.get("sh_window", "none")
    incidence = extra.get("ms_incidence", MS_INCIDENCE_DEFAULT)
    w = sh_window(window, arr["order"])
    if window != "none":
        arr["transfer"] = np.ascontiguousarray(arr["transfer"]
                                               * (w[:, None] * w[None, :]).astype(arr["transfer"].dtype))
    sigma = number_setting(extra, "sigma_glo", float(art.summary.get("exemplar_thickness", art.summary["thickness"])),
                           lo=0.0)
    ground, has_ground = ground_array(scene.render)
    cam = camera_array(scene.camera, options["width"], options["height"])
    flat_size = np.asarray(art.summary["flat_size"], np.float64)
    integ = PrtIntegrator(sc, arr["top"], arr["mat_of_fiber"], arr["mats"], lights.table(), ground, has_ground,
                          pack_material_lambert(ground[1:4]), arr["svf_row"], arr["svf_mean"], arr["svf_basis"],
                          arr["svf_coeffs"], arr["svf_res"], arr["sg_angle"], arr["sg_weights"], arr["lam_svf"],
                          arr["seg_row"], arr["transfer"], arr["order"], quarter_turn_x(arr["order"]),
                          arr["cs_table"], arr["mat_cs"],
                          flat_size, sigma, terms, sg_mode, ray_eps(*art.summary["bounds"]), arr["below"],
                          arr["layer_tau"], MS_INCIDENCE[incidence])
    stats = {"load_s": load_s, "terms": extra.get("terms", "all"), "sg": extra.get("sg", "mc"), "sh_window": window,
             "sigma_glo": sigma, "sh_order": arr["order"], "exemplars": int(art.summary["exemplars"]),
             "light_from_below": arr["below"], "ms_incidence": incidence,
             "translucent_layers": bool(arr["layer_tau"].shape[0] > 0)}
    return FilmSetup("prt", integ, cam, VARIANCE_CHANNELS, stats)


def render(scene, options: dict) -> RenderResult:
    from .film import render_with_film

    s, run = render_with_film(__name__, scene, options)
    return RenderResult(run.rgb, run.extra, {**run.stats(), **s.stats})
