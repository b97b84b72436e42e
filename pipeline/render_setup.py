"""Shared render plumbing: scene lights -> packed light arrays, fibres artifacts (BCSDF presets:
``pipeline.bcsdf_presets``).

- ``pack_lights(scene)`` -> ``LightSet(lights, env, marginal, conditional)`` in the layout of
  ``stages.render.lights`` (at most one envmap; its EXR is read here).
- ``load_fibers(path)`` -> ``Fibers`` arrays of a ``fibers`` artifact, refusing empty or broken ones.
- ``recorded_input(art, name, kind)`` -> the input an artifact records (its yarns), refused naming the
  artifact and ``inputs.<name>`` when the recorded path is gone or unreadable.
- ``ground_array(scene)`` -> (float64[4] height + albedo, enabled).
- ``load_scene_meshes(scene)`` -> (``stages.render.meshes.SceneMeshes`` of the scene's ``[[meshes]]``, their
  bounds (lo, hi) or None, stats): each OBJ read (``pipeline.io.obj_mesh``, without uv) and placed by its
  transform; meshes with an ``emission`` are the scene's area lights.
- ``has_light(scene)``: the scene has a light (a ``[[lights]]`` entry or an emitting mesh), else the
  renderers refuse it (the image would be black).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import LoomError

GROUP_NAMES = ("warp", "weft", "knit", "other")
OTHER = GROUP_NAMES.index("other")   # the yarn type of yarns of unknown type (the first fabric's 'other')

# Rays leaving a BCSDF vertex skip the whole fibre they leave (a window of segments wider than any
# fibre): the curve BCSDF already integrates over the fibre's cross-section, and a ray that travels
# inside a straight fibre at a grazing angle would otherwise 'enter' a joint sphere further along it.
# The cost: a fibre never shadows its own distant turns (other fibres still do).
SELF_WINDOW = 1 << 40


def ray_eps(lo, hi):
    """Ray offset: 1e-7 of the scene's size (its diagonal plus its largest coordinate)."""
    lo, hi = np.asarray(lo), np.asarray(hi)
    return 1e-7 * max(float(np.linalg.norm(hi - lo) + np.abs(np.concatenate([lo, hi])).max()), 1e-12)


@dataclass
class LightSet:
    lights: np.ndarray        # (NL, LIGHT_SIZE) float64
    env: np.ndarray           # (H, W, 3) float32 (1 x 1 black when the scene has no envmap)
    marginal: np.ndarray      # (H + 1,)
    conditional: np.ndarray   # (H, W + 1)

    def arrays(self):
        return self.lights, self.env, self.marginal, self.conditional

    def table(self):
        """The ``LightTable`` integrators take (``stages.render.lights``)."""
        from stages.render.lights import LightTable

        return LightTable(self.lights, self.env, self.marginal, self.conditional)


def pack_lights(lights: list[dict], scene_path: str | Path | None = None) -> LightSet:
    """Pack ``Scene.lights`` (rgb expanded, directions normalised, envmap paths resolved)."""
    from stages.render.lights import LIGHT_SIZE, envmap_tables, pack_light

    rows = []
    env_img = None
    for i, light in enumerate(lights):
        kind = light["type"]
        place = f"lights[{i}]"
        if kind == "directional":
            rows.append(pack_light("directional", light["irradiance"], light["direction"]))
        elif kind == "constant":
            rows.append(pack_light("constant", light["radiance"]))
        elif kind == "sg":
            if not light["sharpness"] > 0:
                raise LoomError(scene_path, f"{place}.sharpness", f"must be > 0, got {light['sharpness']}")
            rows.append(pack_light("sg", light["power"], light["axis"], float(light["sharpness"])))
        elif kind == "envmap":
            if env_img is not None:
                raise LoomError(scene_path, place, "only one envmap light per scene is supported")
            from .images import read_exr

            img, _ = read_exr(light["path"])
            if img.ndim != 3 or img.shape[0] < 1 or img.shape[1] < 1:
                raise LoomError(light["path"], None, "environment map has no pixels")
            if not np.all(np.isfinite(img)) or np.any(img < 0):
                raise LoomError(light["path"], None, "environment map has negative or non-finite pixels")
            env_img = img
            s = float(light.get("scale", 1.0))
            rows.append(pack_light("envmap", [s, s, s]))
        else:
            raise LoomError(scene_path, f"{place}.type", f"unknown light type {kind!r}")
        if not np.all(np.isfinite(rows[-1])) or np.any(rows[-1][1:4] < 0):
            raise LoomError(scene_path, place, "light values and directions must be finite, colours non-negative")
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, LIGHT_SIZE)
    env, marg, cond = envmap_tables(env_img)
    return LightSet(arr, env, marg, cond)


# ------------------------------------------------------------------------------------------------
@dataclass
class Fibers:
    path: Path
    points: np.ndarray         # (M, 3) float64
    point_radius: np.ndarray   # (M,) float64
    fiber_offsets: np.ndarray  # (F + 1,) int64
    fiber_yarn: np.ndarray     # (F,) int32
    yarn_albedo: np.ndarray    # (Y, 3) float64
    yarn_type: np.ndarray | None  # (Y,) yarn type per yarn (pipeline.scene: fabric * 4 + group) when known

    @property
    def n_fibers(self) -> int:
        return len(self.fiber_offsets) - 1


def fibers_from_arrays(points, point_radius, fiber_offsets, fiber_yarn=None, yarn_albedo=None,
                       yarn_type=None, path: str | Path = "<arrays>") -> Fibers:
    """Check fibre arrays (as in a ``fibers`` artifact) and return them as ``Fibers``."""
    path = Path(path)
    points = np.asarray(points, np.float64).reshape(-1, 3)
    point_radius = np.asarray(point_radius, np.float64).reshape(-1)
    off = np.asarray(fiber_offsets, np.int64).reshape(-1)
    F = len(off) - 1
    if F < 1 or len(points) == 0:
        raise LoomError(path, "fiber_offsets", "the fibers artifact is empty (no fibres)")
    if off[0] != 0 or off[-1] != len(points) or np.any(np.diff(off) < 0):
        raise LoomError(path, "fiber_offsets", f"offsets must rise from 0 to the point count {len(points)}")
    if np.all(np.diff(off) < 2):
        raise LoomError(path, "fiber_offsets", "the fibers artifact has no fibre with two points (no segments)")
    if len(point_radius) != len(points):
        raise LoomError(path, "point_radius", f"length {len(point_radius)} differs from the point count {len(points)}")
    if not np.all(np.isfinite(points)):
        i = int(np.argwhere(~np.isfinite(points))[0, 0])
        raise LoomError(path, f"points[{i}]", "non-finite coordinate")
    bad = ~(np.isfinite(point_radius) & (point_radius > 0))
    if np.any(bad):
        i = int(np.argmax(bad))
        raise LoomError(path, f"point_radius[{i}]", f"fibre radius must be > 0, got {point_radius[i]}")
    fiber_yarn = np.zeros(F, np.int32) if fiber_yarn is None else np.asarray(fiber_yarn, np.int32)
    if yarn_albedo is None:
        yarn_albedo = np.full((int(fiber_yarn.max()) + 1, 3), 0.5)
    yarn_albedo = np.asarray(yarn_albedo, np.float64).reshape(-1, 3)
    if len(fiber_yarn) != F or fiber_yarn.min() < 0 or fiber_yarn.max() >= len(yarn_albedo):
        raise LoomError(path, "fiber_yarn", "yarn indices must be in [0, number of yarns)")
    if np.any(yarn_albedo < 0) or np.any(yarn_albedo > 1):
        raise LoomError(path, "yarn_albedo", "albedo outside [0, 1]")
    return Fibers(path, points, point_radius, off, fiber_yarn, yarn_albedo, yarn_type)


# The command that builds each kind of artifact from its recorded inputs (what to run again).
REBUILT_BY = {"fibers": "loomlight realize", "tables": "loomlight tables", "grid": "loomlight voxelize"}


def recorded_input(art, name: str, kind: str | None = None):
    """The artifact ``art`` records as its input ``name`` (``inputs.<name>`` of its metadata), opened as
    an ``Artifact`` of ``kind``; None when it records no such input.

    The recorded path is the one its stage was given, which the user of ``art`` never typed: a path
    that is gone (moved or deleted) or no longer reads as that input is refused naming ``art`` and the
    key, e.g. ``F.zarr: inputs.yarns: recorded input /old/y.zarr is gone (moved or deleted); re-run
    loomlight realize on the yarns artifact where it is now``."""
    from .artifacts import Artifact

    rec = (art.meta.get("inputs") or {}).get(name)
    if not isinstance(rec, dict) or not rec.get("path"):
        return None
    p = Path(str(rec["path"]))
    stage = art.meta.get("stage", "its stage")
    where = "" if p.is_absolute() else f" (a relative path, from the directory {stage} ran in)"
    again = REBUILT_BY.get(art.kind, f"its stage ({art.meta.get('stage')})")
    if not p.exists():
        raise LoomError(art.path, f"inputs.{name}", f"recorded input {p}{where} is gone (moved or deleted); re-run "
                        f"{again} on the {name} artifact where it is now")
    try:
        return Artifact(p, kind=kind)
    except LoomError as e:
        raise LoomError(art.path, f"inputs.{name}", f"recorded input {p}{where} cannot be read: "
                        f"{': '.join(x for x in (e.place, e.message) if x)}; re-run {again} on a good {name} "
                        "artifact") from None


def input_yarn_types(art) -> np.ndarray | None:
    """The yarn type of every yarn (``pipeline.scene``: fabric * 4 + group, the group's index -- 0 warp,
    1 weft, 2 knit, 3 other -- for one fabric) from the yarns artifact an artifact was built from (its
    ``inputs.yarns``: refused, naming ``art``, when that is gone or unreadable, ``recorded_input``); None
    when it records none (arrays written by other means)."""
    from .artifacts import Artifact

    yarns = recorded_input(art, "yarns", "yarns")
    if yarns is None:
        for inp in art.meta.get("inputs", {}).values():
            try:
                src = Artifact(inp["path"])
            except LoomError:
                continue
            if src.kind == "yarns":
                yarns = src
                break
    for name in ("yarn_type", "group"):
        if yarns is not None and name in yarns:
            return np.asarray(yarns[name], np.int64)
    return None


def load_fibers(path: str | Path) -> Fibers:
    """Arrays of a ``fibers`` artifact (stage realize); the yarn groups come from its yarns input."""
    from .artifacts import Artifact

    path = Path(path)
    art = Artifact(path, kind="fibers")
    types = input_yarn_types(art)
    albedo = art["yarn_albedo"] if "yarn_albedo" in art else None
    yarn = art["fiber_yarn"] if "fiber_yarn" in art else None
    return fibers_from_arrays(art["points"], art["point_radius"], art["fiber_offsets"], yarn, albedo, types, path)


def ground_array(render: dict) -> tuple[np.ndarray, bool]:
    g = render.get("ground")
    out = np.zeros(4)
    if not g:
        return out, False
    out[0] = float(g.get("height", 0.0))
    out[1:4] = g.get("albedo", [0.5, 0.5, 0.5])
    return out, True


def has_light(scene) -> bool:
    """A light in ``[[lights]]`` or a mesh that emits (module doc)."""
    return bool(scene.lights) or any(max(m["emission"]) > 0.0 for m in scene.meshes)


# a scene's meshes' peak while they are read and built (measured on grids and triangle soups of 0.18 M and
# 0.98 M triangles: about 650 bytes per OBJ vertex -- the reader's lists -- and 300 per triangle -- faces, the
# triangle BVH and its rows); ~10 % above what was measured
MESH_VERTEX_BYTES = 700
MESH_TRIANGLE_BYTES = 330


def obj_counts(path) -> tuple[int, int]:
    """(vertices, triangles) of an OBJ file by a scan of its lines (a polygon of n corners is n - 2
    triangles, as the reader fans it), before it is read."""
    vertices = triangles = 0
    with open(path, "rb") as f:
        for line in f:
            if line.startswith(b"v ") or line.startswith(b"v\t"):
                vertices += 1
            elif line.startswith(b"f ") or line.startswith(b"f\t"):
                triangles += max(len(line.split()) - 3, 0)
    return vertices, triangles


def meshes_estimate(scene) -> tuple[float, str]:
    """(peak bytes, what) of reading and building the scene's meshes (``load_scene_meshes``)."""
    V = T = 0
    for m in scene.meshes:
        v, tri = obj_counts(m["file"])
        V, T = V + v, T + tri
    return float(MESH_VERTEX_BYTES * V + MESH_TRIANGLE_BYTES * T), f"{V:,} vertices, {T:,} triangles"


def load_scene_meshes(scene):
    """(SceneMeshes, bounds, stats) of the scene's meshes (module doc); bounds None without meshes."""
    import time

    from stages.core.shading.material import pack_material_dielectric, pack_material_lambert
    from stages.render.meshes import no_meshes, scene_meshes

    from .io.obj_mesh import read_obj_mesh

    if not scene.meshes:
        return no_meshes(), None, {}
    t0 = time.perf_counter()
    Vs, Fs, rows, mat_of_tri, n = [], [], [], [], 0
    for i, m in enumerate(scene.meshes):
        obj = read_obj_mesh(m["file"], scene.path, uv_for=None, place=f"meshes[{i}].file",
                            faces_for="a scene's mesh needs triangles or polygons (f lines)")
        M = m["matrix"]
        Vs.append(obj.V @ M[:, :3].T + M[:, 3])
        Fs.append(obj.F + n)
        n += len(obj.V)
        rows.append(pack_material_dielectric(m["eta"], m["roughness"]) if m.get("type") == "dielectric"
                    else pack_material_lambert(m["albedo"]))
        mat_of_tri.append(np.full(len(obj.F), i, np.int32))
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    sm = scene_meshes(V, F, np.concatenate(mat_of_tri), np.stack(rows), [m["emission"] for m in scene.meshes])
    stats = {"meshes": len(scene.meshes), "mesh_triangles": int(len(F)), "mesh_build_s": time.perf_counter() - t0,
             "area_light_triangles": int(len(sm.emitters))}
    return sm, (V.min(axis=0), V.max(axis=0)), stats


# ------------------------------------------------------------------------------------------------
def _describe_fabric(f: dict) -> str:
    if "fabrics" in f:
        return "; ".join(f"{x.get('name')}: {_describe_fabric(x)}" for x in f["fabrics"])
    if f.get("source") == "generator":
        g = f.get("generator") or {}
        return "generator " + ", ".join(f"{k} = {g[k]}" for k in sorted(g))
    extra = ", ".join(f"{k} = {f[k]}" for k in sorted(f) if k not in ("source", "file", "sha256"))
    return f"{f.get('source')} {f.get('file')} (sha256 {str(f.get('sha256'))[:12]})" + (f", {extra}" if extra else "")


def check_scene_matches(scene, path, option: str) -> None:
    """Refuse a scene whose fabric or yarn types are not those the ``fibers``, ``tables`` or ``yarns`` artifact at
    ``path`` was made of (``--fibers``/``--tables`` of another scene, file or preset), naming both.

    The rule: ingest records ``pipeline.scene.ingest_identity`` of its scene (or of its bare curve
    file: that file, no yarn types) in the yarns artifact's summary, tables and realize carry it into
    theirs; the render scene's identity must equal it -- the same fabric source (a file by its
    sha256 and the keys that reshape it, or the same generator table) and, for every yarn group
    the fabric has, the same yarn type (preset, radius, colour, fibre radius, density, roughness,
    packing fraction; ``bcsdf`` is the renderer's own and may differ). A ``--preset`` or
    ``--radius`` the artifact was made with must equal the preset or radius the scene states for
    those groups (a scene that states none leaves it open). An artifact that records no identity
    (made from arrays by hand, a tiling, whose exemplars come from its tile config) is not compared."""
    from .artifacts import Artifact, jsonable
    from .scene import ingest_identity, without_file_names

    art = Artifact(path)
    rec = art.summary.get("ingest_identity")
    if not isinstance(rec, dict) or art.kind not in ("fibers", "tables", "yarns"):
        return
    mine = jsonable(ingest_identity(scene))
    made = f"{Path(path).name} (--{option}, made from {rec.get('scene') or rec['fabric'].get('file')})"
    rerun = {"fibers": " and realize", "tables": " and tables"}.get(art.kind, "")
    fix = "render the scene it was made from, or re-run ingest" + rerun + " on this scene"
    def place(label):
        try:
            return scene.type_place(label)
        except KeyError:    # a label of another scene's fabric
            return f"yarns.{label}"

    if without_file_names(mine["fabric"]) != without_file_names(rec["fabric"]):
        key = scene.parts[0].key.partition("[")[0]    # 'fabric' or 'fabrics'
        raise LoomError(scene.path, key, f"the scene's fabric ({_describe_fabric(mine['fabric'])}) is not the one "
                        f"{made} is made of ({_describe_fabric(rec['fabric'])}); {fix}")
    groups = rec.get("groups") or list(GROUP_NAMES)
    for g in groups:
        a, b = mine["yarns"].get(g, {}), (rec.get("yarns") or {}).get(g, {})
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                raise LoomError(scene.path, f"{place(g)}.{key}", f"the scene's {g} yarns have {key} = "
                                f"{a.get(key, '(unset)')}, but {made} has {key} = {b.get(key, '(unset)')}; {fix}")
    for key in ("preset", "radius"):
        override = art.params.get(key)
        if override is None:
            continue
        for g in groups:
            stated = mine["yarns"].get(g, {}).get(key)
            if stated is not None and stated != override:
                raise LoomError(scene.path, f"{place(g)}.{key}", f"the scene's {g} yarns have {key} = {stated}, but "
                                f"{made} was made with --{key} {override}; {fix}")
