"""``--method bysdf``: cloth from yarn curves alone, with implicit plies and fibres (seed 004).

    loomlight render SCENE.toml --method bysdf --set yarns=YARNS.zarr -o out.exr

Reads only the ``yarns`` artifact (``loomlight ingest``): no fibres are realized and no tables artifact
is needed, so it renders the largest inputs. Each yarn is a tube around its spline (within 1 % of its
radius, ``stages.core.yarn.tubes``) whose radius is the farthest reach of its plies plus 2 %; plies follow the
yarn type's procedural model (ply count, ply radius and twist, the ply ellipse; ``pipeline.presets``)
and fibres come from 1D tables around the ply built once per yarn type at setup from the same model
(fibre count, fibre radius, fibre twist; ``stages.procedural.bysdf_tables``; the build time is in the
render's statistics as ``tables_s``). The integrator is ``stages.render.integrators.bysdf``, the shading model
``stages.core.shading.bysdf``.

Settings (``--set KEY=VALUE``):

- ``yarns``: the yarns artifact (required).
- ``mode`` = near (default) | far | multiscale: seed 004 §4.2 (``stages.render.integrators.bysdf`` module doc).
- ``k``: offsets per far / multiscale vertex (default 16; 1 to 256).
- ``params``: a TOML file of BYSDF parameters per yarn group (``[warp]``, ``[weft]``, ``[knit]``,
  ``[other]``, ``[default]`` tables, and ``[<fabric>.<group>]`` ones for a scene of several ``[[fabrics]]``;
  ``loomlight fit-bysdf`` writes one), applied over the scene's.
- ``ply_search`` = march (default) | iteration: how the implicit ply entries are found
  (``stages.core.yarn.implicit_plies``, "Search"): the certified march alone, or the paper's ellipse-plane
  iteration (seed 004 §3.3) followed by the march that certifies it. Both give the same entries (the march
  makes either exact); the march alone is cheaper (on the demo, near: 1.2x faster renders, far: 1.7x,
  multiscale: 1.8x).
- ``ply_tol``, ``ply_iter``: the implicit ply iteration's tolerance (in ply radii, default 1e-3) and
  iteration cap (default 10, at least 3); used with ``ply_search=iteration``.
- ``falloff``: multiscale aggregation weights exp(-falloff |x_k - x_0| / R) (default 40, the reference
  implementation's; smaller values average over more of the footprint).
- ``fibre_threshold``, ``ply_threshold``: the shadowing tables' remap s (1 - thr) + thr (defaults 0.5 and
  0.6, the reference implementation's; 1 turns that shadowing off).

BYSDF parameters of a yarn group: the defaults of ``stages.core.shading.bysdf.pack_bysdf`` (the
reference implementation's example values) with the grey absorbers off (``MATERIAL_DEFAULTS``), then the
scene's ``[yarns.<group>.bysdf]`` table, then the body colours from the yarn's colour by the colour curve,
then ``--set params=``. The scene's ``render.max_depth`` applies; this method's own default is 4, as the
reference implementation's.

Colour
------
A yarn's ``color`` means what it means to every method (``pipeline.dye``): what a dense flat cloth of the
yarn shows under white diffuse light. Here it sets the body colours: per channel a body colour x gives
``body_r`` = the reduced albedo a' whose diffuse reflectance R_d(a') is x (``reduced_albedo``) and ``body_t``
= x, which also filters the specular path through the yarn (``stages.core.shading.bysdf``, the model). The
colour curve A(x) is what the canonical cloth of ``pipeline.dye`` shows, rendered by this method, for body
colour x (``measure_colour_curve``, 20 nodes, three per render, ~2 s in all); a colour c gets x = A^-1(c) per
channel, interpolated as the fibre methods' curves are. The dye is then the yarn's only absorber: the
reference's example absorbers (Beer-Lambert ``sigma_spec`` 5.5 and ``sigma_body`` 0.1 per unit length at its
yarn radius 2, exit transmittance ``kt_exit`` 0.1) would hold a white cotton cloth at 0.15, and the
single-scattering Lommel-Seeliger share of the body reflection (``ls_mix``) at 0.74, so the defaults are
``MATERIAL_DEFAULTS`` (none of them, the diffusion term alone: the white furnace's material). A scene that
sets them keeps them, and its curve is measured with them (colours above its A(1) are rendered at A(1)).
The shadowing tables (``fibre_threshold``, ``ply_threshold``) are part of the curve's key; the curve is
measured in ``near`` mode and serves ``far`` and ``multiscale`` too. Curves of the bundled yarn presets with
the default material are in ``data/bcsdf/albedo_curves.json`` (``make albedo-curves``), others measured on
first use into the user cache. ``fit-bysdf``'s parameters (``--set params=``) apply on top of the colour's
body colours and are not part of the curve.
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from ..errors import LoomError, unknown
from . import RenderResult
from .settings import number_setting

MODES = ("near", "far", "multiscale")
PLY_SEARCHES = ("march", "iteration")   # stages.core.yarn.implicit_plies.SEARCHES
DEFAULT_K = 16
DEFAULT_DEPTH = 4
DEFAULT_FALLOFF = 40.0   # multiscale weights exp(-falloff |x_k - x_0| / R): the reference's exp(-20 |dx|) at radius 2
GROUPS = ("warp", "weft", "knit", "other")
# the grey absorbers off: the yarn's colour is its only absorber (module doc, Colour)
MATERIAL_DEFAULTS = {"sigma_spec": 0.0, "sigma_body": 0.0, "kt_exit": 1.0, "ls_mix": 0.0}
FIBRE_SEED = 0   # realize's and tables' default --seed
# the integrator's tuple of yarn types is padded to a power of two, at least TYPE_SLOTS long (repeating the last
# type, never indexed): numba types a tuple by its length, so scenes of 1 to 4 yarn types share one compiled
# integrator where each count compiled its own (about 18 s of a cold `make test`: two counts)
TYPE_SLOTS = 4


def reduced_albedo(colour, eta=1.5) -> np.ndarray:
    """The reduced albedo a' whose dipole diffuse reflectance R_d(a') (Jensen et al. 2001) is ``colour``,
    per channel, by bisection (R_d rises monotonically from 0 at a' = 0 to 1 at a' = 1): the reference
    implementation maps a body colour to a' through a 17-entry table for the same purpose."""
    from stages.core.shading.bysdf import diffusion_reflectance

    out = []
    for c in np.broadcast_to(np.asarray(colour, float), 3):
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if diffusion_reflectance(mid, eta) < c:
                lo = mid
            else:
                hi = mid
        out.append(0.5 * (lo + hi))
    return np.array(out)


def read_params_file(path) -> dict:
    """{group: {name: value}} of a BYSDF parameter TOML (``--set params=``)."""
    from ..toml_file import read_toml

    d = read_toml(path)
    for g, tab in d.items():
        if g.rpartition(".")[2] not in GROUPS + ("default",) or not isinstance(tab, dict):
            raise LoomError(path, g, f"expected a table per yarn group ({', '.join(GROUPS + ('default',))}, or "
                            "<fabric>.<group> for a scene of [[fabrics]])")
    return d


COLOUR_SCALES = ("body_r_scale", "body_t_scale")   # per-channel factors on the yarn colour (fit-bysdf)


def _colour_scale(v, where, key) -> np.ndarray:
    try:
        c = np.broadcast_to(np.asarray(v, dtype=np.float64), (3,)).copy()
    except (TypeError, ValueError):
        raise LoomError(where, key, f"expected a number or three numbers, got {v!r}") from None
    if not np.all(np.isfinite(c)) or np.any(c < 0.0):
        raise LoomError(where, key, f"expected non-negative finite numbers, got {v!r}")
    return c


class YarnModel(NamedTuple):
    """How the yarn model is rendered (``--set`` settings, module doc): the integrator's mode index, K and
    falloff, and the implicit plies' search (tolerance, iteration cap, thresholds, search name)."""
    mode: int = 0
    K: int = DEFAULT_K
    falloff: float = DEFAULT_FALLOFF
    tol: float = 1e-3
    max_iter: int = 10
    fibre_threshold: float = 0.5
    ply_threshold: float = 0.6
    search: str = "march"


def yarn_model(extra: dict) -> YarnModel:
    """The ``YarnModel`` of the ``--set`` settings (module doc), each checked."""
    mode = extra.get("mode", "near")
    if mode not in MODES:
        raise LoomError(None, "--set mode", unknown("bysdf mode", mode, MODES))
    search = extra.get("ply_search", "march")
    if search not in PLY_SEARCHES:
        raise LoomError(None, "--set ply_search", unknown("ply search", search, PLY_SEARCHES))
    return YarnModel(MODES.index(mode), int(number_setting(extra, "k", DEFAULT_K, int, 1, 256)),
                     number_setting(extra, "falloff", DEFAULT_FALLOFF, float, 0.0, 1e6),
                     number_setting(extra, "ply_tol", 1e-3, float, 1e-9, 0.5),
                     int(number_setting(extra, "ply_iter", 10, int, 3, 100)),
                     number_setting(extra, "fibre_threshold", 0.5, float, 0.0, 1.0),
                     number_setting(extra, "ply_threshold", 0.6, float, 0.0, 1.0), search)


def bysdf_rows(scene, types, albedo, options, fitted=None) -> np.ndarray:
    """(Y, BYSDF_SIZE) packed BYSDF of every yarn: its yarn type's declared material (``MATERIAL_DEFAULTS``
    and the scene's ``[yarns.<group>.bysdf]``; ``types``: per yarn its type, ``pipeline.scene``), its body colour
    from the yarn's colour by the colour curve (``colour_curve``: the convention of ``pipeline.dye``), then
    ``--set params=`` (or ``fitted``, the same {group: {name: value}} as that file; with [[fabrics]] a table
    '<fabric>.<group>' applies to that fabric's group after the group's own). ``body_r_scale`` /
    ``body_t_scale`` (three factors, or one) multiply the body colour per channel (clipped to 1): the
    per-channel freedom ``fit-bysdf`` fits. A ``body_r`` / ``body_t`` given explicitly replaces the
    colour-derived one."""
    from stages.core.shading.bysdf import pack_bysdf

    from ..dye import Dyer

    extra = options.get("extra") or {}
    if fitted is None:
        fitted = read_params_file(extra["params"]) if extra.get("params") else {}
    where = extra.get("params") or scene.path
    model = yarn_model(extra)
    dyer = Dyer(scene)
    brighter: dict = {}
    rows = []
    cache = {}
    labels = scene.type_labels()
    for y in range(len(types)):
        g = labels[min(int(types[y]), len(labels) - 1)]
        key = (g, tuple(np.round(albedo[y], 12)))
        if key not in cache:
            place = f"{scene.type_place(g)}.bysdf"
            declared = {**MATERIAL_DEFAULTS, **(scene.yarn_type(g).get("bysdf") or {})}
            kw = dict(declared)
            for tab_name in dict.fromkeys(("default", g.rpartition(".")[2], g)):   # the group's, then the label's
                kw.update(fitted.get(tab_name, {}))
            scale = {k: _colour_scale(kw.pop(k), where, f"{place}.{k}") if k in kw else np.ones(3)
                     for k in COLOUR_SCALES}
            material = {k: v for k, v in declared.items() if k not in COLOUR_SCALES}
            body = np.asarray(albedo[y], float)
            if not ("body_r" in material and "body_t" in material):
                try:
                    curve = colour_curve(material, dyer.geometry(g), model, g)
                except (TypeError, ValueError) as e:
                    raise LoomError(scene.path, place, str(e)) from None
                bright = too_bright(curve, body)
                body, reach = curve.invert(body)
                if not np.all(reach):
                    dyer.unreachable.setdefault(("bysdf", g), float(curve.albedo[0]))
                if np.any(bright):
                    brighter.setdefault(g, float(curve.albedo[-1]))
            colour_r = np.clip(body * scale["body_r_scale"], 0.0, 1.0)
            colour_t = np.clip(body * scale["body_t_scale"], 0.0, 1.0)
            kw = {"body_r": tuple(reduced_albedo(colour_r)), "body_t": tuple(colour_t), **kw}
            try:
                cache[key] = pack_bysdf(**kw)
            except (TypeError, ValueError) as e:
                raise LoomError(where, place, str(e)) from None
        rows.append(cache[key])
    dyer.report()
    from ..progress import warn

    for g, top in sorted(brighter.items()):
        warn(f"{scene.type_place(g)}: a colour above {top:.3f} in some channel is brighter than the bysdf material "
             f"of {scene.type_place(g)}.bysdf lets a yarn be; rendered at that ceiling")
    return np.ascontiguousarray(np.stack(rows))


def too_bright(curve, colour) -> np.ndarray:
    """Per channel: is ``colour`` above the curve's A(1), what the material shows with a white dye?"""
    return np.asarray(colour, np.float64) > float(np.max(curve.albedo))


# ------------------------------------------------------------------------------------------------
# the colour curve: a yarn's colour (pipeline.dye's convention) -> the BYSDF's body colour
CURVE_VERSION = 1
CURVE_PIXELS = 32             # the canonical cloth's picture, CURVE_PIXELS^2 pixels over its middle square
CURVE_SPP = 32                # samples per pixel: 32,768 paths per node (standard error ~0.2 %)
CURVE_DEPTH = 100_000         # every bounce (roulette ends the paths)
CURVE_RR_DEPTH = 8
CURVE_CAMERA_HEIGHT = 1000.0  # yarn radii above the cloth: camera rays within 0.1 degrees of straight down
CURVE_SKY = [{"type": "constant", "radiance": 1.0}]


def node_material(material: dict, x) -> dict:
    """The BYSDF keywords of body colour ``x`` (a number or three): the reflection side's ``body_r`` the
    reduced albedo whose diffuse reflectance is x (``reduced_albedo``), the transmission side's ``body_t`` x,
    each unless ``material`` gives it."""
    x = np.broadcast_to(np.asarray(x, np.float64), (3,))
    return {"body_r": tuple(reduced_albedo(x)), "body_t": tuple(x), **material}


def colour_curve_key(material: dict, geometry: dict, model: YarnModel) -> str:
    import hashlib
    import json

    from stages.core.shading.bysdf import N_PARAMS, pack_bysdf

    from .. import dye

    row = pack_bysdf(**node_material(material, 0.0))[:N_PARAMS]
    doc = {"method": "bysdf", "version": CURVE_VERSION, "pixels": CURVE_PIXELS, "spp": CURVE_SPP,
           "nodes": dye.CURVE_NODES, "row": dye._round(row.tolist()), "geometry": dye.unit_geometry(geometry),
           "thresholds": dye._round([model.fibre_threshold, model.ply_threshold])}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:20]


def colour_curve(material: dict, geometry: dict, model: YarnModel, group: str = ""):
    """The ``pipeline.dye.AlbedoCurve`` of the BYSDF ``material`` (keywords of ``pack_bysdf`` without body
    colours) on yarn ``geometry`` (a resolved preset): A(x), what the canonical cloth (``pipeline.dye``)
    rendered by this method shows under a white sky for body colour x (``node_material``), kept as the
    fibre methods' curves are (``pipeline.dye.stored_curve``)."""
    from .. import dye

    key = colour_curve_key(material, geometry, model)
    return dye.stored_curve(key, lambda: measure_colour_curve(material, geometry, model),
                            {"method": "bysdf", "yarn": geometry.get("name", ""), "group": group})


def measure_colour_curve(material: dict, geometry: dict, model: YarnModel, spp: int = CURVE_SPP):
    """A(x) at ``pipeline.dye.curve_nodes()`` by ``cloth_albedo``, three nodes per render (one per channel; the
    channels do not mix)."""
    from .. import dye

    xs = dye.curve_nodes()
    padded = np.concatenate([xs, np.full(-len(xs) % 3, xs[-1])]).reshape(-1, 3)
    return dye.AlbedoCurve(xs, cloth_albedo(material, geometry, model, padded, spp).reshape(-1)[:len(xs)])


def cloth_albedo(material: dict, geometry: dict, model: YarnModel, body, spp: int = CURVE_SPP,
                 seed: int | None = None) -> np.ndarray:
    """(k, 3): for each of the k body colours ``body`` (k, 3), what the canonical cloth of the yarn
    (``pipeline.dye.flat_cloth_curves``) shows under a uniform sky of radiance 1, every bounce: this method's
    near mode renders it from ``CURVE_CAMERA_HEIGHT`` above onto its middle ``CLOTH_SPACING`` square,
    ``CURVE_PIXELS``^2 pixels at ``spp`` (seeds ``seed`` + j, default ``pipeline.dye.CURVE_SEED``), and takes
    the mean over the samples whose camera ray met a yarn (a pixel's alpha is that share of its samples and
    the others see the sky's 1), as the fibre methods' walk counts the rays that meet a fibre."""
    from stages.core.shading.bysdf import pack_bysdf
    from stages.render.camera import CAM_TAN_HALF_FOV
    from stages.render.film import VARIANCE_CHANNELS

    from .. import dye
    from ..render_setup import ground_array, pack_lights
    from ..scene import camera_array
    from .film import Sampling, render_film

    cv, tparams = dye.flat_cloth_curves(dye.unit_geometry(geometry))
    Y = len(cv.offsets) - 1
    top = 2.0                     # the upper layer's top (yarns of radius 1 at z = 1)
    half = math.degrees(math.atan(0.5 * dye.CLOTH_SPACING / (CURVE_CAMERA_HEIGHT - top)))
    n = CURVE_PIXELS
    cam = camera_array({"origin": [0.0, 0.0, CURVE_CAMERA_HEIGHT], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                        "fov": 2.0 * half}, n, n)
    lights = pack_lights(CURVE_SKY).table()
    ground, has_ground = ground_array({})
    seed = dye.CURVE_SEED if seed is None else int(seed)
    out = []
    body = np.asarray(body, np.float64).reshape(-1, 3)
    rows = [pack_bysdf(**node_material(material, x3)) for x3 in body]
    # the geometry (tables, tube pieces, BVH) once; each body colour only swaps the rows
    integ = make_integrator(cv, tparams, np.zeros(Y, np.int32), np.repeat(rows[0][None, :], Y, axis=0), lights,
                            ground, has_ground, 2.0 * float(cam[CAM_TAN_HALF_FOV]) / n, CURVE_DEPTH, CURVE_RR_DEPTH,
                            model._replace(mode=0)).integ
    for k, row in enumerate(rows):
        run = render_film("bysdf canonical cloth", integ._replace(params=np.repeat(row[None, :], Y, axis=0)), cam,
                          n, n, Sampling(int(spp)), seed + k, 16, VARIANCE_CHANNELS)
        alpha = run.extra["A"].astype(np.float64)
        hits = float(alpha.sum())
        if hits <= 0.0:
            raise ValueError("the canonical cloth's camera rays met no yarn")
        out.append((run.rgb.astype(np.float64).sum(axis=(0, 1)) - float((1.0 - alpha).sum())) / hits)
    return np.array(out)


def yarn_setup(yarns_path):
    """(artifact, Curves, YarnTypes, yarn type per yarn (Y,); ``pipeline.scene``) of a yarns artifact."""
    from ..artifacts import Artifact
    from ..render_setup import OTHER
    from ..runners.yarn_types import yarn_types_of
    from ..yarns import load_curves

    art = Artifact(yarns_path, kind="yarns")
    cv = load_curves(art)
    types = yarn_types_of(art, None, None)
    Y = len(cv.offsets) - 1
    kinds = np.asarray(art["yarn_type"], np.int64) if "yarn_type" in art else np.full(Y, OTHER)
    return art, cv, types, kinds


def build_types(tparams, tol, max_iter, fibre_threshold=0.5, ply_threshold=0.6, search="march"):
    """Tuple of ``YarnType`` (one per type) with its implicit tables, and the build seconds."""
    from stages.core.yarn.implicit_plies import SEARCHES, ply_reach_radius
    from stages.core.yarn.shading_points import YarnType
    from stages.procedural.bysdf_tables import build_implicit_tables
    from stages.procedural.tables import type_key

    t0 = time.perf_counter()
    out = []
    for t, tp in enumerate(tparams):
        tp = np.ascontiguousarray(tp, np.float64)
        # the fibre sample of realize's (and the tables') default --seed 0: the fibres fiberpath is compared on
        tables = build_implicit_tables(tp, type_key(FIBRE_SEED, t), fibre_threshold=fibre_threshold,
                                       ply_threshold=ply_threshold)
        # the tube: the farthest ply point from the axis, plus 2 % (the tube polyline's 1 % and margin)
        out.append(YarnType(tp, tables, 1.02 * float(ply_reach_radius(tp)), float(tol), int(max_iter),
                            SEARCHES.index(search)))
    return tuple(out), time.perf_counter() - t0


def padded_types(types: tuple) -> tuple:
    """``types`` with its last entry repeated up to the next power of two, at least ``TYPE_SLOTS`` (see there)."""
    if not types:
        return tuple(types)
    slots = max(TYPE_SLOTS, 1 << (len(types) - 1).bit_length())
    return tuple(types) + (types[-1],) * (slots - len(types))


class BuiltIntegrator(NamedTuple):
    integ: object           # stages.render.integrators.bysdf.BysdfIntegrator
    pieces: object          # TubePieces
    bvh: object             # FiberBVH of the tube pieces
    types: tuple            # YarnType per yarn type
    tables_s: float


def make_integrator(cv, tparams, yarn_type, params, lights, ground, has_ground, pixel_angle, max_depth, rr_depth,
                    model: YarnModel, meshes=None, mesh_bounds=None) -> BuiltIntegrator:
    """The ``BysdfIntegrator`` of yarns ``cv`` (``Curves``) of packed types ``tparams`` (T, P), ``yarn_type``
    (Y,), BYSDF rows ``params`` (Y, BYSDF_SIZE), a ``LightTable``, a ground (``render_setup.ground_array``) and
    the scene's meshes with their bounds (``render_setup.load_scene_meshes``; None: none). The rays' offset is
    set by the tubes' bounds, and the meshes' with them."""
    from stages.core.geometry.bvh import build_fiber_bvh
    from stages.core.yarn.tubes import tube_pieces
    from stages.procedural.tables import yarn_key
    from stages.render.integrators.bysdf import BysdfIntegrator
    from stages.render.meshes import no_meshes

    from ..render_setup import ray_eps

    types, tables_s = build_types(tparams, model.tol, model.max_iter, model.fibre_threshold, model.ply_threshold,
                                  model.search)
    yarn_type = np.ascontiguousarray(yarn_type, np.int32)
    radius = np.array([types[t].radius for t in yarn_type])
    pieces = tube_pieces(cv, radius)
    bvh, _ = build_fiber_bvh(pieces.points, pieces.offsets, pieces.radius)
    # pieces skipped around the one a ray leaves: a window wider than 4 envelope radii of yarn
    seg_len = np.linalg.norm(np.diff(pieces.points, axis=0), axis=1)
    seg_len = seg_len[seg_len > 0]
    window = (int(min(1 << 20, math.ceil(4.0 * radius.max() / max(float(seg_len.min()), 1e-30)) + 1))
              if len(seg_len) else 1)
    keys = np.array([yarn_key(FIBRE_SEED, y) for y in range(len(yarn_type))], np.int64)
    eps = ray_eps(pieces.points.min(axis=0), pieces.points.max(axis=0))
    if mesh_bounds is not None:
        eps = max(eps, ray_eps(*mesh_bounds))
    integ = BysdfIntegrator(bvh, cv, pieces, padded_types(types), yarn_type, keys,
                            np.ascontiguousarray(params, np.float64), lights, ground, has_ground,
                            np.ascontiguousarray(ground[1:4]), no_meshes() if meshes is None else meshes, model.mode,
                            model.K, model.falloff, pixel_angle, max_depth, rr_depth, window, eps, 64)
    return BuiltIntegrator(integ, pieces, bvh, types, tables_s)


def film_setup(scene, options: dict):
    """The ``FilmSetup`` of a bysdf render (``pipeline.renderers.film``)."""
    from stages.render.camera import CAM_TAN_HALF_FOV
    from stages.render.film import VARIANCE_CHANNELS

    from ..render_setup import ground_array, has_light, load_scene_meshes, pack_lights
    from ..scene import camera_array
    from .film import FilmSetup

    extra = options.get("extra") or {}
    path = options.get("yarns") or extra.get("yarns")
    if not path:
        raise LoomError(None, "--set yarns",
                        "bysdf needs the yarn curves: pass --set yarns=PATH.zarr (loomlight ingest)")
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    model = yarn_model(extra)
    mode = MODES[model.mode]
    lights = pack_lights(scene.lights, scene.path)
    if not has_light(scene):
        raise LoomError(scene.path, "lights", "the scene has no lights and no mesh emits (the image would be black)")
    t0 = time.perf_counter()
    _, cv, ytypes, kinds = yarn_setup(path)
    from stages.core.yarn.implicit_plies import PLY_MAX

    for t, d in enumerate(ytypes.dicts):   # the ply search keeps its per-ply scratch on the machine stack
        if int(d["ply_num"]) > PLY_MAX:
            raise LoomError(path, f"yarn type {t} ({d.get('name', '?')}).ply_num",
                            f"{int(d['ply_num'])} plies; bysdf's implicit plies handle at most {PLY_MAX}")
    params = bysdf_rows(scene, kinds, ytypes.albedo, options)
    ground, has_ground = ground_array(scene.render)
    W, H = options["width"], options["height"]
    cam = camera_array(scene.camera, W, H)
    max_depth = int(options["max_depth"])
    meshes, mesh_bounds, mesh_stats = load_scene_meshes(scene)
    built = make_integrator(cv, ytypes.tparams, ytypes.yarn_type, params, lights.table(), ground, has_ground,
                            2.0 * float(cam[CAM_TAN_HALF_FOV]) / W, max_depth, int(options["rr_depth"]), model,
                            meshes, mesh_bounds)
    integ, pieces, bvh, types = built.integ, built.pieces, built.bvh, built.types
    geometry_bytes = int(sum(a.nbytes for a in (pieces.points, pieces.offsets, pieces.piece_seg, pieces.piece_t0,
                                                 pieces.piece_t1, pieces.piece_curve, pieces.radius))
                         + sum(a.nbytes for a in bvh if isinstance(a, np.ndarray))
                         + sum(a.nbytes for a in cv if isinstance(a, np.ndarray)))
    stats = {"setup_s": time.perf_counter() - t0, "tables_s": built.tables_s, "yarns": len(kinds),
             "yarn_types": len(types), "tube_pieces": len(bvh.seg_a), "geometry_bytes": geometry_bytes,
             "mode": mode, "k": model.K, "ply_search": model.search, "max_depth": max_depth,
             "envelope_radius": [t.radius for t in types], **mesh_stats}
    return FilmSetup(f"bysdf ({mode})", integ, cam, VARIANCE_CHANNELS, stats)


def render(scene, options: dict) -> RenderResult:
    from .film import render_with_film

    s, run = render_with_film(__name__, scene, options)
    return RenderResult(run.rgb, run.extra, {**run.stats(), **s.stats})
