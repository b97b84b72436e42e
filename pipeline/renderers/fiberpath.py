"""``--method fiberpath``: explicit fibres (capsule chains) path traced with the Khungurn 2015 BCSDF.

Fibres come from ``--fibers PATH.zarr``: a ``fibers`` artifact (realized fibres, traced by Embree 4 --
``--set accel=embree``, the default, ``stages.core.geometry.embree`` -- or by loomlight's own SAH BVH,
``--set accel=bvh``; the two agree within noise, ``bench/bench_mitsuba.py``) or a
``tiling`` artifact (``loomlight tile``: exemplar fibres under a shell map, rays walking the shell's
tetrahedra; ``--method fiberpath_shell`` and ``--set tiling=PATH`` are the same). ``--source
realized`` is accepted and means the same; it is the only fibre source this method has, so the
scene's ``render.source``, which selects volpath's density source, is ignored. The estimator is one
(``stages.render.integrators.fiberpath``) for both geometries. Materials: ``--material bcsdf``
(default) gives every fibre the BCSDF preset of its yarn type -- scene key ``yarns.<group>.bcsdf``
(falling back to ``yarns.default.bcsdf``; a scene of several ``[[fabrics]]``: its own fabric's, a yarn type
being a (fabric, group) pair, ``pipeline.scene``), else ``--bcsdf NAME``; ``--material lambert`` gives every
fibre a Lambertian surface with its yarn's albedo (for comparisons with other renderers).
Each yarn's colour (the scene's ``yarns.<group>.color``, else a WIF draft's thread colour, else the
preset's albedo, as realized into the fibers artifact) is what the yarn shows under white diffuse light
(``--set tint=yarn``, the default): its BCSDF is dyed to that colour by the yarn's albedo curve
(``pipeline.dye``: C_TT per channel, C_R uncoloured); ``--set tint=none`` renders the presets as
tabulated and ignores the colour. A preset given as a ``.toml`` path in the scene
is resolved against the scene file.
On a tiling, each yarn's albedo is the scene's ``yarns.<group>.color``, else its WIF exemplar's draft
colour, else the yarn preset's (``tiling_fibers``; docs/wif-colours.md).
Lights, camera, the optional ground plane and the scene's meshes (``[[meshes]]``: OBJ files with a
Lambertian material, placed by a transform; ``pipeline.render_setup.load_scene_meshes``) come from the
scene; with meshes, the rays' offset is set by the fibres' and the meshes' bounds together.
"""
from __future__ import annotations

import time

import numpy as np

from ..bcsdf_presets import load_bcsdf_preset
from ..dye import Dyer
from ..errors import LoomError, unknown
from ..render_setup import (
    GROUP_NAMES,
    OTHER,
    SELF_WINDOW,
    Fibers,
    ground_array,
    has_light,
    load_fibers,
    load_scene_meshes,
    pack_lights,
    ray_eps,
)
from ..scene import camera_array
from . import RenderResult


def bcsdf_names(scene, options) -> dict:
    """Yarn type index -> BCSDF preset name: the scene's ``yarns.<group>.bcsdf`` (of each fabric, for
    ``[[fabrics]]``; a ``.toml`` path is resolved against the scene file), else ``--bcsdf``."""
    names = {}
    for t, label in enumerate(scene.type_labels()):
        name = scene.yarn_type(label).get("bcsdf")
        if name and name.endswith(".toml"):
            name = str(scene.resolve(name))
        name = name or options.get("bcsdf")
        if name:
            names[t] = name
    return names


def yarn_types(yarn_type, n_yarns, names, n_types) -> np.ndarray:
    """The yarn type of every yarn (``pipeline.scene``: the group's index for one fabric -- 0 warp, 1 weft,
    2 knit, 3 other); unknown types (no yarns artifact among the inputs) count as 'other' (of the first
    fabric), which takes the one preset the scene names when it names one."""
    if yarn_type is not None:
        t = np.clip(np.asarray(yarn_type, np.int64), 0, n_types - 1)
        if len(t) < n_yarns:
            t = np.concatenate([t, np.full(n_yarns - len(t), OTHER)])
        return t
    named = sorted(set(names.values()))
    if OTHER not in names and len(named) == 1:
        names[OTHER] = named[0]
    return np.full(n_yarns, OTHER)


def yarn_bcsdfs(scene, yarn_type, n_yarns, used_yarns, options, required=True) -> list:
    """The packed (undyed) BCSDF of every yarn, None where its yarn type names none and not ``required``;
    a used yarn whose type names none is an error when ``required``."""
    names = bcsdf_names(scene, options)
    labels = scene.type_labels()
    types = yarn_types(yarn_type, n_yarns, names, len(labels))
    loaded = {}
    out = [None] * n_yarns
    for t in sorted(set(int(t) for t in types[used_yarns])):
        if t not in names and required:
            known = ", ".join(f"{labels[k]}={v}" for k, v in sorted(names.items())) or "none"
            raise LoomError(scene.path, f"{scene.type_place(labels[t])}.bcsdf",
                            f"no BCSDF preset for the fibres of yarn group {labels[t]!r} (scene names: {known}); "
                            "set it (or yarns.default.bcsdf) in the scene or pass --bcsdf NAME")
    for y in range(n_yarns):
        name = names.get(int(types[y]))
        if name:
            if name not in loaded:
                loaded[name] = load_bcsdf_preset(name)
            out[y] = loaded[name]
    return out


def dyed_bcsdfs(scene, options, colours, yarn_type, params) -> list:
    """Per yarn its BCSDF ``params[y]`` dyed to show colour ``colours[y]`` (``pipeline.dye``) on its type's
    yarn geometry; None where ``params[y]`` is None. Warns once per type whose colour is out of reach."""
    names = bcsdf_names(scene, options)
    labels = scene.type_labels()
    types = yarn_types(yarn_type, len(params), names, len(labels))
    dyer = Dyer(scene)
    rows = [None if p is None else dyer.row(p, colours[y], labels[types[y]], names.get(int(types[y]), ""))
            for y, p in enumerate(params)]
    dyer.report()
    return rows


def fiber_materials(scene, fibers, options):
    """(mat_of_fiber (F,) int32, materials (NM, MAT_SIZE)) for the chosen material model.

    ``bcsdf`` with ``tint=yarn`` (the default): one material per yarn, its group's BCSDF dyed to show the
    yarn's colour (``pipeline.dye``: C_TT from the yarn's albedo curve, C_R uncoloured); ``tint=none``: the
    presets as tabulated, one material per preset. ``lambert``: the yarn's colour as the fibres' albedo."""
    from stages.core.shading.material import pack_material_bcsdf, pack_material_lambert

    material = options.get("material") or "bcsdf"
    if material == "lambert":
        mats = np.stack([pack_material_lambert(a) for a in fibers.yarn_albedo])
        return fibers.fiber_yarn.astype(np.int32), mats
    if material != "bcsdf":
        raise LoomError(None, "--material", unknown("fibre material", material, ("bcsdf", "lambert")))
    tint = (options.get("extra") or {}).get("tint", "yarn")
    if tint not in ("yarn", "none"):
        raise LoomError(None, "--set tint", unknown("tint", tint, ("yarn", "none")))
    Y = len(fibers.yarn_albedo)
    params = yarn_bcsdfs(scene, fibers.yarn_type, Y, np.unique(fibers.fiber_yarn), options)
    if tint == "yarn":
        rows = dyed_bcsdfs(scene, options, fibers.yarn_albedo, fibers.yarn_type, params)
        mats = [pack_material_bcsdf(q) if q is not None else pack_material_lambert(fibers.yarn_albedo[y])
                for y, q in enumerate(rows)]
        return fibers.fiber_yarn.astype(np.int32), np.stack(mats)
    index, rows, lut = {}, [], np.zeros(Y, np.int32)
    for y, p in enumerate(params):
        if p is None:
            continue
        key = p.tobytes()
        if key not in index:
            index[key] = len(rows)
            rows.append(pack_material_bcsdf(p))
        lut[y] = index[key]
    return lut[fibers.fiber_yarn], np.stack(rows)


def tiling_fibers(scene, art) -> Fibers:
    """``Fibers``-like view of a tiling's exemplar fibres (per fibre: a global yarn index, its group and albedo).

    A yarn's albedo: the scene's ``yarns.<group>.color``, else its WIF exemplar's draft colour
    (``ex_yarn_color`` where ``ex_yarn_color_source`` is draft), else the yarn preset's albedo -- the
    precedence ingest applies (``pipeline.runners.ingest.curve_colors``)."""
    from ..thread_colors import FROM_DRAFT

    sizes = art.summary["exemplar_sizes"]
    ex_fibers = art["ex_fibers"]
    fy = art["ex_fiber_yarn"].astype(np.int64)
    yarn_off = np.cumsum([0] + [e + p for e, p in sizes])
    for k in range(len(sizes)):
        fy[ex_fibers[k]:ex_fibers[k + 1]] += yarn_off[k]
    group = art["ex_yarn_group"].astype(np.int64)
    # absent in tilings made before it: no draft colours
    draft = (np.asarray(art["ex_yarn_color_source"]) == FROM_DRAFT) if "ex_yarn_color_source" in art \
        else np.zeros(len(group), bool)
    albedo = np.empty((len(group), 3))
    for g in range(len(GROUP_NAMES)):  # every group present (was warp and weft only: other rows stayed unset)
        if not np.any(group == g):
            continue
        yt = scene.yarn_type(GROUP_NAMES[g])
        col = yt.get("color")
        if col is not None:   # the scene's colour wins over the draft's
            albedo[group == g] = np.broadcast_to(np.asarray(col, float), 3)
            continue
        from ..presets import load_preset

        col = load_preset(yt.get("preset") or (art.params["config"].get("yarn", {}).get("preset", "cotton1")))["albedo"]
        albedo[group == g] = np.broadcast_to(np.asarray(col, float), 3)
        here = (group == g) & draft
        albedo[here] = np.asarray(art["ex_yarn_color"], float)[here]
    return Fibers(art.path, art["ex_points"], art["ex_radius"], art["ex_offsets"], fy.astype(np.int32),
                  albedo, group)


ACCELS = ("embree", "bvh")


def _realized_scene(path, accel: str):
    """(surface scene, Fibers, eps, label, stats, keep) of a fibers artifact: its fibres in Embree 4
    (``accel="embree"``: ``EmbreeFibers``; ``keep`` holds the Embree scene, alive while rendering) or in
    loomlight's own SAH BVH (``"bvh"``: ``FiberBVH``)."""
    import numba

    fibers = load_fibers(path)
    t0 = time.perf_counter()
    if accel == "embree":
        from stages.core.geometry.embree import EmbreeScene, EmbreeUnavailable

        try:
            es = EmbreeScene(fibers.points, fibers.fiber_offsets, fibers.point_radius, numba.get_num_threads())
        except EmbreeUnavailable as e:
            raise LoomError(None, "--set accel", f"{e}; or render with --set accel=bvh") from None
        geometry, keep, nodes = es.fibers, (es,), {}
    else:
        from stages.core.geometry.bvh import build_fiber_bvh

        geometry, _ = build_fiber_bvh(fibers.points, fibers.fiber_offsets, fibers.point_radius)
        keep, nodes = (), {"bvh_nodes": int(len(geometry.node_left))}
    stats = {"accel_build_s": time.perf_counter() - t0, "accel": accel, "segments": int(len(geometry.seg_a)),
             "fibers": fibers.n_fibers, **nodes}
    eps = ray_eps(fibers.points.min(axis=0), fibers.points.max(axis=0))
    return geometry, fibers, eps, "fiberpath", stats, keep


def _tiling_scene(scene, path):
    """(ShellScene, Fibers, eps, label, stats) of a tiling artifact."""
    from ..runners.tile import load_tiling

    t0 = time.perf_counter()
    sc, art = load_tiling(path)
    build_s = time.perf_counter() - t0
    fibers = tiling_fibers(scene, art)
    stats = {"scene_build_s": build_s, "tetrahedra": int(art.summary["tetrahedra"]),
             "exemplars": int(art.summary["exemplars"]), "blocks": int(art.summary["blocks"]),
             "segments": int(len(sc.seg_a)), "fibers": fibers.n_fibers}
    return sc, fibers, ray_eps(*art.summary["bounds"]), "fiberpath (shell)", stats


def film_setup(scene, options: dict):
    """The ``FilmSetup`` of a fiberpath render (``pipeline.renderers.film``): integrator, camera, label."""
    from stages.core.shading.material import pack_material_lambert
    from stages.render.film import VARIANCE_CHANNELS
    from stages.render.integrators.fiberpath import FiberpathIntegrator

    from ..artifacts import read_meta
    from .film import FilmSetup

    path = options.get("fibers") or (options.get("extra") or {}).get("tiling")
    source = options.get("source")
    if source not in (None, "realized"):
        raise LoomError(None, "--source",
                        f"fiberpath renders realized fibres only (got {source!r}); pass --fibers PATH.zarr")
    if not path:
        raise LoomError(None, "--fibers", "fiberpath needs the realized fibres: pass --fibers PATH.zarr")
    if scene.camera is None:
        raise LoomError(scene.path, "camera", "the scene has no [camera] table")
    lights = pack_lights(scene.lights, scene.path)
    if not has_light(scene):
        raise LoomError(scene.path, "lights", "the scene has no lights and no mesh emits (the image would be black)")
    accel = (options.get("extra") or {}).get("accel", "embree")
    if accel not in ACCELS:
        raise LoomError(None, "--set accel", unknown("accel", accel, ACCELS))
    keep = ()
    if read_meta(path).get("kind") == "tiling":  # shell-mapped exemplars (stage tile)
        geometry, fibers, eps, label, stats = _tiling_scene(scene, path)
    else:
        geometry, fibers, eps, label, stats, keep = _realized_scene(path, accel)
    mat_of_fiber, mats = fiber_materials(scene, fibers, options)
    ground, has_ground = ground_array(scene.render)
    meshes, mesh_bounds, mesh_stats = load_scene_meshes(scene)
    if mesh_bounds is not None:   # the offset of the whole scene's size (ray_eps: its diagonal and largest coordinate)
        eps = max(eps, ray_eps(*mesh_bounds))
    max_depth, rr_depth = int(options["max_depth"]), int(options["rr_depth"])
    cam = camera_array(scene.camera, options["width"], options["height"])
    integ = FiberpathIntegrator(geometry, mat_of_fiber, mats, pack_material_lambert(ground[1:4]), lights.table(),
                                ground, has_ground, meshes, max_depth, rr_depth, SELF_WINDOW, eps)
    stats = {**stats, **mesh_stats, "max_depth": max_depth, "rr_depth": rr_depth, "materials": int(len(mats))}
    return FilmSetup(label, integ, cam, VARIANCE_CHANNELS, stats, keep)


def render(scene, options: dict) -> RenderResult:
    from .film import render_with_film

    s, run = render_with_film(__name__, scene, options)
    return RenderResult(run.rgb, run.extra, {**run.stats(), **s.stats})
