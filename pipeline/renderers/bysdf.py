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
  ``[other]``, ``[default]`` tables; ``loomlight fit-bysdf`` writes one), applied over the scene's.
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
reference implementation's example values) with the body colours set from the yarn's colour (the
reflection side's ``body_r`` is the reduced albedo a' whose diffuse reflectance R_d(a') is the colour,
``reduced_albedo``; the transmission side's ``body_t`` the colour itself) and the attenuations per yarn
radius (``SCALE_DEFAULTS``), then the scene's ``[yarns.<group>.bysdf]`` table, then ``--set params=``. The
scene's ``render.max_depth`` applies; this method's own default is 4, as the reference implementation's.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import LoomError, unknown
from . import RenderResult

MODES = ("near", "far", "multiscale")
PLY_SEARCHES = ("march", "iteration")   # stages.core.yarn.implicit_plies.SEARCHES
DEFAULT_K = 16
DEFAULT_DEPTH = 4
DEFAULT_FALLOFF = 40.0   # multiscale weights exp(-falloff |x_k - x_0| / R): the reference's exp(-20 |dx|) at radius 2
GROUPS = ("warp", "weft", "knit", "other")
# attenuation per yarn radius: the reference implementation's 5.5 and 0.1 per unit length at its yarn radius 2
SCALE_DEFAULTS = {"sigma_spec": 11.0, "sigma_body": 0.2}
FIBRE_SEED = 0   # realize's and tables' default --seed


def _number(extra, key, default, kind=float, lo=None, hi=None):
    v = extra.get(key)
    if v is None:
        return default
    try:
        x = kind(v)
    except ValueError:
        raise LoomError(None, f"--set {key}",
                        f"expected {'an integer' if kind is int else 'a number'}, got {v!r}") from None
    if not math.isfinite(x) or (lo is not None and x < lo) or (hi is not None and x > hi):
        raise LoomError(None, f"--set {key}", f"{x:g} is outside [{lo:g}, {hi:g}]")
    return x


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
        if g not in GROUPS + ("default",) or not isinstance(tab, dict):
            raise LoomError(path, g, f"expected a table per yarn group ({', '.join(GROUPS + ('default',))})")
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


def bysdf_rows(scene, groups, albedo, options, fitted=None) -> np.ndarray:
    """(Y, BYSDF_SIZE) packed BYSDF of every yarn: defaults, body colours from the yarn's colour, the
    scene's ``[yarns.<group>.bysdf]``, then ``--set params=`` (or ``fitted``, the same {group: {name:
    value}} as that file). ``body_r_scale`` / ``body_t_scale`` (three factors, or one) multiply the yarn's
    colour per channel before it becomes the body colours (clipped to 1; the reflection side's through
    ``reduced_albedo``): the per-channel freedom ``fit-bysdf`` fits. A ``body_r`` / ``body_t`` given
    explicitly replaces the colour-derived one."""
    from stages.core.shading.bysdf import pack_bysdf

    extra = options.get("extra") or {}
    if fitted is None:
        fitted = read_params_file(extra["params"]) if extra.get("params") else {}
    where = extra.get("params") or scene.path
    rows = []
    cache = {}
    for y in range(len(groups)):
        g = GROUPS[int(groups[y])]
        key = (g, tuple(np.round(albedo[y], 12)))
        if key not in cache:
            place = f"yarns.{g}.bysdf"
            kw = dict(scene.yarn_type(g).get("bysdf") or {})
            for tab_name in ("default", g):
                kw.update(fitted.get(tab_name, {}))
            scale = {k: _colour_scale(kw.pop(k), where, f"{place}.{k}") if k in kw else np.ones(3)
                     for k in COLOUR_SCALES}
            colour_r = np.clip(np.asarray(albedo[y], float) * scale["body_r_scale"], 0.0, 1.0)
            colour_t = np.clip(np.asarray(albedo[y], float) * scale["body_t_scale"], 0.0, 1.0)
            kw = {"body_r": tuple(reduced_albedo(colour_r)), "body_t": tuple(colour_t), **SCALE_DEFAULTS, **kw}
            try:
                cache[key] = pack_bysdf(**kw)
            except (TypeError, ValueError) as e:
                raise LoomError(where, place, str(e)) from None
        rows.append(cache[key])
    return np.ascontiguousarray(np.stack(rows))


def yarn_setup(yarns_path):
    """(artifact, Curves, YarnTypes, yarn groups (Y,)) of a yarns artifact."""
    from ..artifacts import Artifact
    from ..runners.yarn_types import yarn_types_of
    from ..yarns import load_curves

    art = Artifact(yarns_path, kind="yarns")
    cv = load_curves(art)
    types = yarn_types_of(art, None, None)
    Y = len(cv.offsets) - 1
    groups = np.clip(np.asarray(art["group"], np.int64), 0, 3) if "group" in art else np.full(Y, 3)
    return art, cv, types, groups


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


def film_setup(scene, options: dict):
    """The ``FilmSetup`` of a bysdf render (``pipeline.renderers.film``)."""
    from stages.core.geometry.bvh import build_fiber_bvh
    from stages.core.yarn.tubes import tube_pieces
    from stages.procedural.tables import yarn_key
    from stages.render.camera import CAM_TAN_HALF_FOV
    from stages.render.film import VARIANCE_CHANNELS
    from stages.render.integrators.bysdf import MODES as KMODES, BysdfIntegrator

    from ..render_setup import ground_array, pack_lights, ray_eps
    from ..scene import camera_array
    from .film import FilmSetup

    extra = options.get("extra") or {}
    path = options.get("yarns") or extra.get("yarns")
    if not path:
        raise LoomError(None, "--set yarns",
                        "bysdf needs the yarn curves: pass --set yarns=PATH.zarr (loomlight ingest)")
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    mode = extra.get("mode", "near")
    if mode not in MODES:
        raise LoomError(None, "--set mode", unknown("bysdf mode", mode, MODES))
    K = int(_number(extra, "k", DEFAULT_K, int, 1, 256))
    tol = _number(extra, "ply_tol", 1e-3, float, 1e-9, 0.5)
    max_iter = int(_number(extra, "ply_iter", 10, int, 3, 100))
    search = extra.get("ply_search", "march")
    if search not in PLY_SEARCHES:
        raise LoomError(None, "--set ply_search", unknown("ply search", search, PLY_SEARCHES))
    fibre_thr = _number(extra, "fibre_threshold", 0.5, float, 0.0, 1.0)
    ply_thr = _number(extra, "ply_threshold", 0.6, float, 0.0, 1.0)
    falloff = _number(extra, "falloff", DEFAULT_FALLOFF, float, 0.0, 1e6)
    lights = pack_lights(scene.lights, scene.path)
    if len(lights.lights) == 0:
        raise LoomError(scene.path, "lights", "the scene has no lights (the image would be black)")
    t0 = time.perf_counter()
    _, cv, ytypes, groups = yarn_setup(path)
    from stages.core.yarn.implicit_plies import PLY_MAX

    for t, d in enumerate(ytypes.dicts):   # the ply search keeps its per-ply scratch on the machine stack
        if int(d["ply_num"]) > PLY_MAX:
            raise LoomError(path, f"yarn type {t} ({d.get('name', '?')}).ply_num",
                            f"{int(d['ply_num'])} plies; bysdf's implicit plies handle at most {PLY_MAX}")
    types, tables_s = build_types(ytypes.tparams, tol, max_iter, fibre_thr, ply_thr, search)
    radius = np.array([types[t].radius for t in ytypes.yarn_type])
    pieces = tube_pieces(cv, radius)
    bvh, _ = build_fiber_bvh(pieces.points, pieces.offsets, pieces.radius)
    # pieces skipped around the one a ray leaves: a window wider than 4 envelope radii of yarn
    seg_len = np.linalg.norm(np.diff(pieces.points, axis=0), axis=1)
    seg_len = seg_len[seg_len > 0]
    window = (int(min(1 << 20, math.ceil(4.0 * radius.max() / max(float(seg_len.min()), 1e-30)) + 1))
              if len(seg_len) else 1)
    params = bysdf_rows(scene, groups, ytypes.albedo, options)
    ground, has_ground = ground_array(scene.render)
    W, H = options["width"], options["height"]
    cam = camera_array(scene.camera, W, H)
    pixel_angle = 2.0 * float(cam[CAM_TAN_HALF_FOV]) / W
    keys = np.array([yarn_key(FIBRE_SEED, y) for y in range(len(groups))], np.int64)
    max_depth = int(options["max_depth"])
    integ = BysdfIntegrator(bvh, cv, pieces, types, np.ascontiguousarray(ytypes.yarn_type, np.int32), keys, params,
                            lights.table(), ground, has_ground, np.ascontiguousarray(ground[1:4]),
                            KMODES.index(mode), K, falloff, pixel_angle, max_depth, int(options["rr_depth"]), window,
                            ray_eps(pieces.points.min(axis=0), pieces.points.max(axis=0)), 64)
    geometry_bytes = int(sum(a.nbytes for a in (pieces.points, pieces.offsets, pieces.piece_seg, pieces.piece_t0,
                                                 pieces.piece_t1, pieces.piece_curve, pieces.radius))
                         + sum(a.nbytes for a in bvh if isinstance(a, np.ndarray))
                         + sum(a.nbytes for a in cv if isinstance(a, np.ndarray)))
    stats = {"setup_s": time.perf_counter() - t0, "tables_s": tables_s, "yarns": len(groups),
             "yarn_types": len(types), "tube_pieces": len(bvh.seg_a), "geometry_bytes": geometry_bytes,
             "mode": mode, "k": K, "ply_search": search, "max_depth": max_depth,
             "envelope_radius": [t.radius for t in types]}
    return FilmSetup(f"bysdf ({mode})", integ, cam, VARIANCE_CHANNELS, stats)


def render(scene, options: dict) -> RenderResult:
    from .film import render_with_film

    s, run = render_with_film(__name__, scene, options)
    return RenderResult(run.rgb, run.extra, {**run.stats(), **s.stats})
