"""``loomlight fit-bysdf``: match the BYSDF to explicit fibres (seed 004 §5's protocol).

The paper fits its few parameters so that its renders match its reference under three lights: front
only, back only, and both. Here the reference is ``fiberpath`` on the realized fibres of the same
yarns (the same yarn curves, the same procedural model: ``loomlight realize``), rendered with the
scene's camera under

- ``front``: one directional light travelling along the camera's view direction (lit from the viewer's side),
- ``back``: one travelling against it (lit from behind the cloth, seen through it),
- ``front+back``: both (not fitted: it checks that the fitted reflection and transmission add up),
- ``scene`` (``scene_lights=True``, the default when the scene has lights): the scene's own lights, not
  fitted either, compared over the pixels both methods cover (its environment lights the background),

each directional light of irradiance ``IRRADIANCE``, no environment in the first three (the background
stays black, so the image mean is the cloth's). Fitted, eight numbers with six constraints' worth of
freedom (front and back, per channel):

- the energy split (``stages.core.shading.bysdf``), as the body energy reflected at the entry point,
  x = (1 - spec_weight) reflect_weight, and the body energy transmitted to the exit point,
  y = (1 - spec_weight) (1 - reflect_weight); the specular lobes take the rest, spec_weight = 1 - x - y,
  fitted on the mean luminances (front, back) by Newton steps, the slopes measured every round by two
  more renders (``probed_jacobian``; the specular share crossing the yarn lights the back too, so the back's
  light does not simply follow y); x + y capped at 1 (no negative specular share; where a step would pass
  it, the point of that line the linear model fits best; a binding cap is reported);
- per-channel factors on the body colours that the yarn's colour gives (``body_r_scale`` for the
  reflection side, ``body_t_scale`` for the transmission side; ``pipeline.renderers.bysdf.bysdf_rows``),
  fitted on the chromaticity of the same setups: s_c <- s_c (ref_c / bysdf_c) / (L_ref / L_bysdf), x and y
  carrying the brightness; at a bound of the energies (the cap, or ``ENERGY_MIN``) the factors also take the
  level the energies cannot reach (the yarn's colour is calibrated under a white sky, not under these lights:
  its cloth may reflect or transmit more along them than the fibres do).

``reflect="scene"`` (``--fit-reflection scene``) fits the reflection side's numbers to the scene's own
lights instead of the front light (which becomes a prediction): the model's reflection does not follow
the fibres' as the light moves away from the view (docs/methods/bysdf.md, Limits), so a fit under the
lights a picture is rendered with is what keeps that picture's colour.

Each round (six renders) moves each number towards its target; where the uncoloured specular lobes make
most of a setup's light, the colour factors converge slowly and clip (colours at most 1): the report names
the setups left off.
Output: a TOML of parameters (``[default]``: ``spec_weight``, ``reflect_weight``, ``body_r_scale``,
``body_t_scale``) for ``--set params=`` and a JSON report with, per setup, the reference and fitted means
per channel, their relative errors and the SSIM of the two pictures (``stages.evaluate.metrics``); with
``--angles`` / ``--azimuths`` also bysdf / fiberpath under the front light turned towards the scene's key
(``angle_lights``) or about the camera's up axis (``azimuth_lights``), each with a plot beside the parameters.
"""
from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from ..errors import LoomError
from ..limits import FULL_TRANSPORT_DEPTH

IRRADIANCE = 3.0
# Both methods render the fit at this path depth, whatever the scene's render.max_depth (a picture's choice): the
# fit matches the models' full transport (``pipeline.limits.FULL_TRANSPORT_DEPTH``); bysdf's own paths are short
# (the demo swatch renders the same bytes at depth 16, 32 and 64).
FIT_MAX_DEPTH = FULL_TRANSPORT_DEPTH
SETUPS = ("front", "back", "front+back")
LUMA = np.array([0.2126, 0.7152, 0.0722])


def _view_direction(scene) -> np.ndarray:
    cam = scene.camera
    view = np.asarray(cam["target"], float) - np.asarray(cam["origin"], float)
    return view / np.linalg.norm(view)


def setup_lights(scene) -> dict:
    """The three light setups from the scene's camera."""
    view = _view_direction(scene)
    front = {"type": "directional", "direction": [float(x) for x in view], "irradiance": IRRADIANCE}
    back = {"type": "directional", "direction": [float(-x) for x in view], "irradiance": IRRADIANCE}
    return {"front": [front], "back": [back], "front+back": [front, back]}


ANGLE_MAX = 89.0     # degrees: the angle check's lights stay within a quarter turn of the view
PARALLEL_SINE = 1e-6  # |a x b| of unit vectors below which they count as parallel (no plane to turn in)


def angle_lights(scene, angles) -> dict:
    """The angle check's setups {"angle A": [light]}: the front light turned by A degrees (``angles``) from the
    view direction towards the scene's brightest directional light (its key), or, where the scene has none or
    it lies along the view, towards straight down (the light rises above the camera). Angle 0 is the front
    setup itself. The fibres' cloth and bysdf's part as the light leaves the view (docs/methods/bysdf.md,
    Limits): this measures by how much, on the fit's own renders."""
    view = _view_direction(scene)
    keys = [lt for lt in scene.lights if lt.get("type") == "directional"]
    towards = np.array([0.0, 0.0, -1.0])
    if keys:
        key = np.asarray(max(keys, key=lambda lt: float(np.mean(lt.get("irradiance", 1.0))))["direction"], float)
        towards = key / np.linalg.norm(key)
    axis = np.cross(view, towards)
    if np.linalg.norm(axis) < PARALLEL_SINE:      # the key lies along the view: rise towards straight down
        axis = np.cross(view, np.array([0.0, 0.0, -1.0]))
    if np.linalg.norm(axis) < PARALLEL_SINE:      # a camera looking straight down: any axis across the view
        axis = np.cross(view, np.array([1.0, 0.0, 0.0]))
    axis /= np.linalg.norm(axis)
    return {f"angle {a:g}": [_turned_light(view, axis, a)] for a in angles}


AZIMUTH_MAX = 360.0   # degrees (exclusive): the azimuth check's lights go once round the camera's up axis


def azimuth_lights(scene, azimuths) -> dict:
    """The azimuth check's setups {"azimuth A": [light]}: the front light turned by A degrees (``azimuths``) about
    the camera's up axis, so it keeps the view's elevation: on cloth facing up the irradiance stays the same and
    only where the light stands changes (0 is the front setup, 180 the view mirrored about the up axis): how
    both methods depend on the light's direction apart from its irradiance (docs/methods/bysdf.md, Limits:
    the light's cone)."""
    view = _view_direction(scene)
    up = np.asarray(scene.camera.get("up", (0.0, 0.0, 1.0)), float)
    up /= np.linalg.norm(up)
    return {f"azimuth {a:g}": [_turned_light(view, up, a)] for a in azimuths}


def _turned_light(view, axis, degrees) -> dict:
    """A directional light of the fit's irradiance along ``view`` turned by ``degrees`` about the unit ``axis``
    (Rodrigues' rotation)."""
    t = np.radians(degrees)
    d = view * np.cos(t) + np.cross(axis, view) * np.sin(t) + axis * (axis @ view) * (1.0 - np.cos(t))
    return {"type": "directional", "direction": [float(x) for x in d], "irradiance": IRRADIANCE}


class _Renderer:
    """One method's integrator, set up once (the fibres' BVH is the costly part), rendered under each light
    setup by swapping the integrator's light table."""

    def __init__(self, scene, method_name, options, extra):
        import importlib

        from ..renderers import method
        from ..runners.render import RenderRequest, resolve_options

        sc = dataclasses.replace(scene, lights=next(iter(setup_lights(scene).values())))
        m = method(method_name)
        m.check_scene(sc)
        self.scene = sc
        self.opts = resolve_options(sc, m, RenderRequest(
            width=options["width"], height=options["height"], spp=options["spp"], seed=options["seed"],
            fibers=options.get("fibers"), max_depth=options.get("max_depth"), threads=options.get("threads"),
            extra=dict(extra)))
        self.setup = importlib.import_module(f"pipeline.renderers.{m.module}").film_setup(sc, self.opts)

    def image(self, lights, **fields) -> tuple[np.ndarray, np.ndarray]:
        """(rgb (H, W, 3), coverage (H, W)) under ``lights``, with any other integrator ``fields`` replaced too."""
        from ..render_setup import pack_lights
        from ..renderers.film import render_film, sampling_of

        s, o = self.setup, self.opts
        integ = s.integ._replace(lights=pack_lights(lights, self.scene.path).table(), **fields)
        run = render_film(s.label, integ, s.cam, o["width"], o["height"], sampling_of(o), o["seed"], o["tile_size"],
                          s.variance, o.get("threads"), None)
        return np.asarray(run.rgb, np.float64), np.asarray(run.extra["A"], np.float64).reshape(run.rgb.shape[:2])


REFLECT_SETUPS = ("front", "scene")   # the setups the reflection side may be fitted to
SCALE_MIN, SCALE_MAX = 1e-3, 10.0   # the colour factors' range (a channel the fit cannot move stops there)


@dataclasses.dataclass
class FitState:
    """The fitted numbers: body energies x (reflected) and y (transmitted), per-channel colour factors."""
    x: float
    y: float
    scale_r: np.ndarray = dataclasses.field(default_factory=lambda: np.ones(3))
    scale_t: np.ndarray = dataclasses.field(default_factory=lambda: np.ones(3))
    capped: bool = False

    def table(self) -> dict:
        """The ``[default]`` table of the parameters file, as written (6 significant digits)."""
        def six(v):
            return float(f"{v:.6g}")
        return {**{k: six(v) for k, v in split(self.x, self.y).items()},
                "body_r_scale": [six(v) for v in self.scale_r], "body_t_scale": [six(v) for v in self.scale_t]}


def _mean(img, mask=None) -> np.ndarray:
    """Mean rgb of an (H, W, 3) picture over ``mask``'s pixels, or all of them."""
    return img[mask].mean(axis=0) if mask is not None else img.reshape(-1, 3).mean(axis=0)


def _ratio(ref, got):
    return np.asarray(ref, float) / np.maximum(np.asarray(got, float), 1e-12)


def _mean_errors(m_b, m_r) -> dict:
    """bysdf's mean rgb ``m_b`` against fiberpath's ``m_r``: both, and the relative errors per channel and of
    luminance."""
    return {"reference_rgb": m_r.tolist(), "bysdf_rgb": m_b.tolist(),
            "rel_error_rgb": (_ratio(m_b, m_r) - 1.0).tolist(),
            "rel_error_luminance": float(LUMA @ m_b / max(LUMA @ m_r, 1e-12) - 1.0)}


ENERGY_MIN = 1e-4            # the least body energy a side keeps
STEP_FACTOR = 4.0            # a round moves a body energy by at most this factor


def luminances(got: dict, reflect: str) -> np.ndarray:
    """(L of the ``reflect`` setup, L of the back setup) of {setup: mean rgb}."""
    return np.array([float(LUMA @ got[reflect]), float(LUMA @ got["back"])])


PROBE = 0.05                 # the finite-difference step on a body energy (absolute)


def probed_jacobian(render_means, st: "FitState", lum: np.ndarray, reflect: str) -> np.ndarray:
    """dL/d(x, y) at ``st`` by forward differences of ``PROBE`` (backwards where x + y would pass 1): the
    luminances are linear in the body energies for fixed colours (every lobe's weight is), and the renders
    share their random numbers, so two more renders per round measure the slopes with little noise."""
    J = np.zeros((2, 2))
    for k in range(2):
        h = PROBE if st.x + st.y + PROBE <= 1.0 else -min(PROBE, 0.5 * (st.x if k == 0 else st.y))
        probe = dataclasses.replace(st, x=st.x + h) if k == 0 else dataclasses.replace(st, y=st.y + h)
        J[:, k] = (luminances(render_means(probe, (reflect, "back")), reflect) - lum) / h
    return J


def fit_step(st: FitState, ref: dict, got: dict, reflect: str, J: np.ndarray) -> FitState:
    """One round (module doc): the body energies (x, y) by a Newton step on the luminances of the ``reflect``
    setup (front, or the scene's own lights) and the back setup, with ``J`` dL/d(x, y) (``probed_jacobian``;
    a singular one falls back to the proportional step x <- x L_ref / L, y <- y L_ref / L), each
    moved by at most ``STEP_FACTOR``; where the step would pass x + y = 1 (no negative specular share), the
    point of that line the same linear model fits best instead; at that line or at ``ENERGY_MIN`` the colour
    factors take the level the energies leave besides their chromaticity (else chromaticity alone)."""
    lum = luminances(got, reflect)
    target = luminances(ref, reflect)
    v = np.array([st.x, st.y])
    try:
        dv = np.linalg.solve(J, target - lum)
    except np.linalg.LinAlgError:
        dv = np.full(2, np.nan)
    if not np.all(np.isfinite(dv)):
        dv = v * (target / np.maximum(lum, 1e-12) - 1.0)
    nv = np.clip(v + dv, np.maximum(v / STEP_FACTOR, ENERGY_MIN), np.minimum(v * STEP_FACTOR, 1.0))
    x, y = float(nv[0]), float(nv[1])
    capped = x + y > 1.0
    if capped:      # the cap binds: the point of x + y = 1 that the same linear model fits best (relative errors)
        w = 1.0 / np.maximum(target, 1e-12)
        b = (J @ np.array([1.0, -1.0])) * w
        a = (lum + J @ np.array([-st.x, 1.0 - st.y]) - target) * w
        x = float(np.clip(-(a @ b) / (b @ b), ENERGY_MIN, 1.0 - ENERGY_MIN)) if b @ b > 0.0 else x / (x + y)
        y = 1.0 - x
    lum_f, lum_b = target / np.maximum(lum, 1e-12)
    level = np.ones(2)
    if capped or np.any(v + dv < ENERGY_MIN):   # at a bound: what the energies cannot reach, the colours' level
        level = target / np.maximum(lum + J @ (np.array([x, y]) - v), 1e-12)   # carries (as the model predicts)
    scale_r = np.clip(st.scale_r * _ratio(ref[reflect], got[reflect]) / lum_f * level[0], SCALE_MIN, SCALE_MAX)
    scale_t = np.clip(st.scale_t * _ratio(ref["back"], got["back"]) / lum_b * level[1], SCALE_MIN, SCALE_MAX)
    return FitState(x, y, scale_r, scale_t, capped)


def fit_rounds(render_means, ref: dict, st: FitState, iterations: int, progress=print, reflect: str = "front"):
    """(FitState, history): ``iterations`` rounds of ``fit_step``; ``render_means(state, setups)`` gives
    {setup: mean rgb} of bysdf with the state's parameters (as written to the file). Each round measures the
    luminances' slopes in the body energies (``probed_jacobian``): with the dye on both of the transmission
    side's paths the back light does not follow y alone (the specular share 1 - x - y crosses the yarn too,
    and where it crosses more freely than the body's light, less y is a brighter back)."""
    history = []
    for it in range(iterations):
        got = render_means(st, (reflect, "back"))
        err = {n: _ratio(got[n], ref[n]) - 1.0 for n in got}
        history.append({"iteration": it, "reflect_energy": st.x, "transmit_energy": st.y,
                        "body_r_scale": st.scale_r.tolist(), "body_t_scale": st.scale_t.tolist(),
                        **{f"{n}_rel_error": float(LUMA @ got[n] / max(LUMA @ ref[n], 1e-12) - 1.0) for n in got},
                        **{f"{n}_rel_error_rgb": err[n].tolist() for n in got}})
        progress(f"round {it + 1}/{iterations}: body energy reflected {st.x:.4f}, transmitted {st.y:.4f}: "
                 + ", ".join(f"{n} " + " ".join(f"{100 * e:+.1f}" for e in err[n]) + " %" for n in got))
        st = fit_step(st, ref, got, reflect, probed_jacobian(render_means, st, luminances(got, reflect), reflect))
    return st, history


def bysdf_means(by: _Renderer, yarns, lights: dict, masks=None):
    """(rows(state), render_means(state, setups)) of a bysdf ``_Renderer``: the packed BYSDF of every yarn
    with a FitState's parameters as written to the file, and {setup: mean rgb} rendered with them (over
    ``masks[setup]``'s pixels where given, else the whole image)."""
    from ..renderers.bysdf import bysdf_rows, yarn_setup

    _, _, ytypes, kinds = yarn_setup(str(yarns))

    def rows(state):
        return bysdf_rows(by.scene, kinds, ytypes.albedo, by.opts, {"default": state.table()})

    def render_means(state, names):
        params = rows(state)
        out = {}
        for n in names:
            out[n] = _mean(by.image(lights[n], params=params)[0], (masks or {}).get(n))
        return out

    return rows, render_means


def run_fit(scene_path, yarns, fibers, out: Path, width=96, height=72, spp=16, ref_spp=32, iterations=6,
            max_depth=FIT_MAX_DEPTH, threads=None, scene_lights=None, reflect="front", angles=(), azimuths=(),
            progress=print) -> dict:
    from stages.core.shading import bysdf as B
    from stages.evaluate import metrics as mt

    from ..artifacts import Artifact
    from ..scene import load_scene

    scene = load_scene(scene_path)
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    Artifact(fibers, kind="fibers")
    Artifact(yarns, kind="yarns")
    from ..render_setup import check_scene_matches

    check_scene_matches(scene, fibers, "fibers")    # both made from this scene's fabrics and yarn types
    check_scene_matches(scene, yarns, "yarns")
    lights = setup_lights(scene)
    if reflect not in REFLECT_SETUPS:
        raise LoomError(None, "--fit-reflection", f"unknown setup {reflect!r} (known: {', '.join(REFLECT_SETUPS)})")
    if scene_lights is None:
        scene_lights = bool(scene.lights) or reflect == "scene"
    if reflect == "scene" and not scene_lights:
        raise LoomError(None, "--fit-reflection", "fitting to the scene's lights needs them (drop --no-scene-lights)")
    if scene_lights:
        if not scene.lights:
            raise LoomError(scene.path, "lights", "the scene has no lights to check the fit under")
        lights["scene"] = list(scene.lights)
    setups = tuple(lights)
    t0 = time.perf_counter()
    progress("fiberpath reference: " + ", ".join(setups))
    fp = _Renderer(scene, "fiberpath", {"width": width, "height": height, "spp": ref_spp, "seed": scene.seed,
                                        "fibers": str(fibers), "max_depth": max_depth, "threads": threads}, {})
    ref_img = {name: fp.image(lights[name]) for name in setups}
    turned = angle_lights(scene, angles)
    if turned:
        progress("fiberpath, the angle check: " + ", ".join(turned))
    spun = azimuth_lights(scene, azimuths)
    if spun:
        progress("fiberpath, the azimuth check: " + ", ".join(spun))
    ref_turned = {name: _mean(fp.image(ls)[0]) for name, ls in {**turned, **spun}.items()}
    del fp
    ref_s = time.perf_counter() - t0
    p0 = B.pack_bysdf()
    st = FitState((1.0 - p0[B.SPEC_WEIGHT]) * p0[B.REFLECT_WEIGHT],
                  (1.0 - p0[B.SPEC_WEIGHT]) * (1.0 - p0[B.REFLECT_WEIGHT]))
    base = {"width": width, "height": height, "spp": spp, "seed": scene.seed, "max_depth": max_depth,
            "threads": threads}
    by = _Renderer(scene, "bysdf", base, {"yarns": str(yarns)})   # tubes, BVH and tables built once
    # the scene's environment lights the background: its means are over the cloth both methods cover
    # (coverage is geometry's, the same for every parameter)
    masks = {"scene": (ref_img["scene"][1] > 0.5) & (by.image(lights["scene"])[1] > 0.5)} if "scene" in lights else {}
    ref = {n: _mean(img, masks.get(n)) for n, (img, _) in ref_img.items()}
    rows, render_means = bysdf_means(by, yarns, lights, masks)
    t1 = time.perf_counter()
    st, history = fit_rounds(render_means, ref, st, iterations, progress, reflect)
    params = rows(st)
    final = {n: by.image(lights[n], params=params) for n in setups}
    residual = {}
    for n in setups:
        (img_r, _), (img_b, _) = ref_img[n], final[n]
        m_r, m_b = ref[n], _mean(img_b, masks.get(n))
        residual[n] = {**_mean_errors(m_b, m_r),
                       "ssim": mt.ssim(mt.ssim_input(img_b), mt.ssim_input(img_r)), "fitted": n in (reflect, "back")}
    fit_s = time.perf_counter() - t1

    def check(key, values, setups_turned):     # bysdf, fitted, against the reference under each turned light
        return [{key: float(a), "direction": ls[0]["direction"],
                 **_mean_errors(_mean(by.image(ls, params=params)[0]), ref_turned[name])}
                for a, (name, ls) in zip(values, setups_turned.items())]

    angle_check = check("angle_deg", angles, turned)
    azimuth_check = check("azimuth_deg", azimuths, spun)
    write_params(out, st, residual, max_depth)
    report = {"scene": str(scene.path), "yarns": str(yarns), "fibers": str(fibers), "width": width, "height": height,
              "spp": spp, "reference_spp": ref_spp, "max_depth": max_depth, "iterations": iterations,
              "reflection_setup": reflect,
              **st.table(),
              "energy_capped": st.capped, "setups": residual, "angle_check": angle_check,
              "azimuth_check": azimuth_check, "history": history, "reference_s": ref_s, "fit_s": fit_s}
    Path(out).with_suffix(".json").write_text(json.dumps(report, indent=2))
    if angle_check:
        plot_angle_check(angle_check, Path(out).with_suffix(".angles.png"), str(scene.path))
    if azimuth_check:
        plot_angle_check(azimuth_check, Path(out).with_suffix(".azimuths.png"), str(scene.path), "azimuth_deg")
    return report


CHECK_AXES = {"angle_deg": ("light's angle from the view (degrees)", "angle check"),
              "azimuth_deg": ("light's azimuth from the view (degrees)", "azimuth check")}


def plot_angle_check(rows: list, path: Path, title: str, key: str = "angle_deg") -> None:
    """The angle (or azimuth, ``key``) check as a picture: both methods' mean luminance against the light's
    angle from the view (or its azimuth) (left) and bysdf / fiberpath per channel (right, the fitted front at
    0)."""
    from ..report import pyplot, save_figure

    xlabel, name = CHECK_AXES[key]
    plt = pyplot()
    a = np.array([r[key] for r in rows])
    ref = np.array([r["reference_rgb"] for r in rows])
    got = np.array([r["bysdf_rgb"] for r in rows])
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9.0, 3.4))
    ax0.plot(a, ref @ LUMA, "o-", color="k", label="fiberpath")
    ax0.plot(a, got @ LUMA, "s--", color="tab:purple", label="bysdf (fitted)")
    ax0.set_xlabel(xlabel)
    ax0.set_ylabel("image mean luminance")
    ax0.set_ylim(bottom=0.0)
    ax0.legend(frameon=False)
    for c, col in enumerate(("tab:red", "tab:green", "tab:blue")):
        ax1.plot(a, got[:, c] / np.maximum(ref[:, c], 1e-12), "o-", color=col, label="rgb"[c])
    ax1.axhline(1.0, color="0.6", lw=0.8)
    ax1.axhspan(0.95, 1.05, color="0.9", zorder=0)
    ax1.set_xlabel(xlabel)
    ax1.set_ylabel("bysdf / fiberpath")
    ax1.legend(frameon=False, ncol=3)
    fig.suptitle(f"fit-bysdf {name}: {title}", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)


def split(x, y) -> dict:
    """spec_weight and reflect_weight of the body energies x (reflected) and y (transmitted)."""
    return {"spec_weight": max(0.0, 1.0 - x - y), "reflect_weight": x / (x + y)}


def write_params(path, st: FitState, residual=None, max_depth=None):
    lines = ["# BYSDF parameters fitted by loomlight fit-bysdf (render with --set params=THIS.toml)"
             + ("" if max_depth is None else f"; both methods at path depth {max_depth}")]
    for n, r in (residual or {}).items():
        lines.append(f"# {n}: mean error {100 * r['rel_error_luminance']:+.1f} % luminance, rgb "
                     + " ".join(f"{100 * e:+.1f}" for e in r["rel_error_rgb"])
                     + f" % against fiberpath, SSIM {r['ssim']:.3f}" + ("" if r["fitted"] else " (not fitted)"))
    t = st.table()
    def vec(v):
        return "[" + ", ".join(f"{c:.6g}" for c in v) + "]"
    lines += ["[default]", f"spec_weight = {t['spec_weight']:.6g}", f"reflect_weight = {t['reflect_weight']:.6g}",
              f"body_r_scale = {vec(t['body_r_scale'])}", f"body_t_scale = {vec(t['body_t_scale'])}", ""]
    tmp = Path(str(path) + ".tmp")
    tmp.write_text("\n".join(lines))
    tmp.replace(path)
