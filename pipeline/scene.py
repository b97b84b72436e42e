"""Scene files: TOML, checked against ``schemas/scene.schema.json``.

An unknown or mistyped key is an error naming the key. Every value that names something is checked
when the scene is read (``check_names``), so every command that reads a scene refuses a misspelt
name before any work, naming the file, the dotted key, the known names and the nearest one:
``fabric.source``, ``fabric.generator.kind`` and ``.pattern``, ``yarns.<group>.preset`` (data/yarns/),
``yarns.<group>.bcsdf`` (data/bcsdf/, or a ``.toml`` preset file relative to the scene, checked
against its schema), ``lights[i].type``, ``render.method`` (the renderer registry) and
``render.source`` (a source of that method). Relative paths are resolved against the scene file's
directory. ``load_scene`` returns a :class:`Scene` whose sections are plain dicts with
defaults filled in; ``camera_array`` packs the camera for the render kernels.

``[[meshes]]`` (surfaces besides the cloth): each an OBJ file (checked to exist when the scene is read; its
lines when a renderer reads it, ``pipeline.render_setup.load_scene_meshes``), a material (``lambert`` with an
albedo, or ``dielectric`` with an ``eta`` and a ``roughness``; and an ``emission``: a mesh that emits is an
area light) and a placement (``transform``: translate, a rotation by axis and degrees or a 3 x 3 matrix
checked to be one, a uniform scale), read into ``Scene.meshes`` as dicts with ``name``, ``file`` (absolute),
``type``, ``albedo``, ``eta``, ``roughness``, ``emission`` (rgb) and ``matrix`` (3 x 4: the scaled rotation,
then the translation; ``placement``).

``[[fabrics]]`` (several fabrics in one scene, instead of ``[fabric]`` + ``[yarns]``): each a ``name``, a
``fabric`` table and a ``yarns`` table as a one-fabric scene's, optionally a ``drape`` (laid over a cylinder or
a ball, ``stages.tile.base_surfaces.drape``) and a rigid ``transform``. Both forms are read
into ``Scene.parts``, one ``FabricPart`` per fabric (``[fabric]`` is one part with no placement). A yarn type
is a (fabric, group) pair: type ``t`` is part ``t // 4``'s group ``YARN_GROUPS[t % 4]`` -- the index ingest
writes per yarn (``yarn_type``), the same as the group's index for one fabric -- and its **label** is the
group (``warp``) for one fabric and ``<name>.<group>`` (``rug.warp``) for several: ``Scene.type_labels``,
``Scene.yarn_type(label)``, ``Scene.type_place(label)`` (the key an error names).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import LoomError, check_name
from .renderers import COMMON_DEFAULTS
from .schemas import load_schema, validate
from .toml_file import read_toml

CAMERA_DEFAULTS = {"up": [0.0, 0.0, 1.0], "fov": 40.0, "width": COMMON_DEFAULTS["width"],
                   "height": COMMON_DEFAULTS["height"]}
RENDER_DEFAULTS = {k: COMMON_DEFAULTS[k] for k in ("spp", "seed", "max_depth", "rr_depth", "tile_size")}
YARN_GROUPS = ("warp", "weft", "knit", "other")
RENDER_ONLY_YARN_KEYS = ("bcsdf",)  # yarn-type keys only the renderer reads (not baked into yarns, tables, fibres)
FABRIC_SHAPE_KEYS = ("scale", "crimp", "repeat", "max_threads")  # fabric keys that change a source file's curves


def merged_yarn_type(yarns: dict, group: str) -> dict:
    """The yarn type of ``group`` in a yarns table, ``default`` merged under it."""
    t = dict(yarns.get("default", {}))
    t.update(yarns.get(group, {}))
    return t


@dataclass
class FabricPart:
    """One fabric of a scene (module doc): its source table (paths absolute), yarns table, placement."""
    name: str                   # '' for a [fabric] scene's one fabric
    fabric: dict
    yarns: dict
    matrix: np.ndarray | None   # (3, 4) rigid placement [R | t]; None: where its source puts it
    key: str                    # its key in the scene file: 'fabric' or 'fabrics[i].fabric'
    yarns_key: str              # 'yarns' or 'fabrics[i].yarns'
    drape: dict | None = None   # the surface it is laid on before its placement (schema $defs/placed_fabric)


@dataclass
class Scene:
    path: Path
    raw: dict
    name: str
    seed: int
    fabric: dict                # the first (for a [fabric] scene: the one) fabric's source table
    yarns: dict = field(default_factory=dict)      # the first fabric's yarns table
    camera: dict | None = None
    lights: list = field(default_factory=list)
    render: dict = field(default_factory=dict)
    meshes: list = field(default_factory=list)
    parts: list = field(default_factory=list)      # FabricPart per fabric

    def __post_init__(self):
        if not self.parts:      # a Scene made by hand (tests): its one fabric
            self.parts = [FabricPart("", self.fabric, self.yarns, None, "fabric", "yarns")]

    @property
    def several(self) -> bool:
        """True for a [[fabrics]] scene of more than one fabric (labels name the fabric)."""
        return len(self.parts) > 1

    def type_labels(self) -> list[str]:
        """The label of every yarn type, by type index (module doc)."""
        if not self.several:
            return list(YARN_GROUPS)
        return [f"{p.name}.{g}" for p in self.parts for g in YARN_GROUPS]

    def _part(self, label: str) -> tuple[FabricPart, str]:
        name, _, group = label.rpartition(".")
        if not name:
            return self.parts[0], group
        for p in self.parts:
            if p.name == name:
                return p, group
        raise KeyError(label)

    def yarn_type(self, label: str) -> dict:
        """The yarn type of a label ('warp', 'rug.weft', ...; module doc), falling back to its 'default'."""
        return merged_yarn_type(*self.yarns_of(label))

    def type_place(self, label: str) -> str:
        """The scene key of a label's yarn type: 'yarns.warp', 'fabrics[1].yarns.warp'."""
        part, group = self._part(label)
        return f"{part.yarns_key}.{group}"

    def yarns_of(self, label: str) -> tuple[dict, str]:
        """(the yarns table of the label's fabric, the label's group)."""
        part, group = self._part(label)
        return part.yarns, group

    def resolve(self, rel: str) -> Path:
        p = Path(rel)
        return p if p.is_absolute() else (self.path.parent / p).resolve()


def _rgb(v) -> list[float]:
    if isinstance(v, (int, float)):
        return [float(v)] * 3
    return [float(x) for x in v]


def _named(table, key: str, known, path: Path, place: str, what: str) -> str | None:
    """Check ``table[key]`` when it is a string (the schema reports other types); return it when known."""
    if not isinstance(table, dict) or not isinstance(table.get(key), str):
        return None
    check_name(table[key], known, path, place, what)
    return table[key]


def _check_bcsdf(name: str, path: Path, place: str) -> None:
    from .bcsdf_presets import bcsdf_presets, read_bcsdf_preset

    if not name.endswith(".toml"):
        check_name(name, bcsdf_presets(), path, place, "BCSDF preset")
        return
    file = Path(name) if Path(name).is_absolute() else (path.parent / name).resolve()
    if not file.is_file():
        raise LoomError(path, place,
                        f"BCSDF preset file {file} not found (or name one of: {', '.join(bcsdf_presets())})")
    read_bcsdf_preset(str(file))  # its own errors name the preset file and its key


def check_names(raw: dict, path: Path) -> None:
    """Every scene value that names something names something that exists (module doc)."""
    from .generators import KNIT, WOVEN
    from .presets import check_preset_name
    from .renderers import METHODS, all_sources, known_methods

    schema = load_schema("scene")
    fabrics = raw.get("fabrics")
    tables = [(raw.get("fabric"), "fabric", raw.get("yarns"), "yarns")]
    if isinstance(fabrics, list):
        tables += [(f.get("fabric"), f"fabrics[{i}].fabric", f.get("yarns"), f"fabrics[{i}].yarns")
                   for i, f in enumerate(fabrics) if isinstance(f, dict)]
    patterns = {"woven": WOVEN, "knit": KNIT}
    for fab, fkey, yarns, ykey in tables:
        _named(fab, "source", schema["$defs"]["fabric"]["properties"]["source"]["enum"], path, f"{fkey}.source",
               "fabric source")
        gen = fab.get("generator") if isinstance(fab, dict) else None
        kind = _named(gen, "kind", patterns, path, f"{fkey}.generator.kind", "generator kind")
        if kind:
            _named(gen, "pattern", patterns[kind], path, f"{fkey}.generator.pattern", f"{kind} pattern")
        for group, t in (yarns.items() if isinstance(yarns, dict) else ()):
            if isinstance(t, dict) and isinstance(t.get("preset"), str):
                check_preset_name(t["preset"], path, f"{ykey}.{group}.preset")
            if isinstance(t, dict) and isinstance(t.get("bcsdf"), str):
                _check_bcsdf(t["bcsdf"], path, f"{ykey}.{group}.bcsdf")
    lights = raw.get("lights")
    for i, light in enumerate(lights if isinstance(lights, list) else ()):
        _named(light, "type", schema["$defs"]["light"]["properties"]["type"]["enum"], path, f"lights[{i}].type",
               "light type")
    render = raw.get("render")
    m = _named(render, "method", known_methods(), path, "render.method", "render method")
    if m:
        _named(render, "source", METHODS[m].source_names, path, "render.source", f"{m} source")
    else:
        _named(render, "source", all_sources(), path, "render.source", "render source")


ROTATION_TOL = 1e-6     # a 'matrix' is a rotation when R R^T and det R are within this of I and 1


def placement(tbl: dict | None, path: Path, place: str) -> np.ndarray:
    """The 3 x 4 matrix [s R | t] of a ``transform`` table (schema ``$defs/transform``): x -> t + s R x.
    A zero rotation axis, both 'rotate' and 'matrix', or a 'matrix' that is not a rotation (a reflection,
    shear or scale) are errors at ``place``."""
    tbl = tbl or {}
    R = np.eye(3)
    if "rotate" in tbl and "matrix" in tbl:
        raise LoomError(path, place, "give 'rotate' or 'matrix', not both")
    if "rotate" in tbl:
        axis = np.asarray(tbl["rotate"]["axis"], float)
        n = np.linalg.norm(axis)
        if n == 0:
            raise LoomError(path, f"{place}.rotate.axis", "zero-length rotation axis")
        x, y, z = axis / n
        a = np.radians(float(tbl["rotate"]["degrees"]))
        K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
        R = np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)     # Rodrigues
    if "matrix" in tbl:
        R = np.asarray(tbl["matrix"], float)
        if np.abs(R @ R.T - np.eye(3)).max() > ROTATION_TOL or abs(np.linalg.det(R) - 1.0) > ROTATION_TOL:
            raise LoomError(path, f"{place}.matrix", "not a rotation (rows orthonormal, determinant +1): a reflection, "
                            "shear or scale is refused (a uniform scale is 'scale')")
    M = np.zeros((3, 4))
    M[:, :3] = float(tbl.get("scale", 1.0)) * R
    M[:, 3] = np.asarray(tbl.get("translate", [0.0, 0.0, 0.0]), float)
    return M


def _obj_file(name: str, path: Path, key: str) -> Path:
    """An OBJ file named at ``key`` of the scene ``path``, resolved against the scene's folder; a missing one, or
    a folder, is refused at ``key``."""
    file = Path(name)
    file = file if file.is_absolute() else (path.parent / file).resolve()
    if not file.is_file():
        raise LoomError(path, key, f"OBJ file {file} not found" if not file.exists() else f"{file} is not a file")
    return file


def _meshes(raw: dict, path: Path) -> list[dict]:
    out = []
    for i, m in enumerate(raw.get("meshes", [])):
        file = _obj_file(m["file"], path, f"meshes[{i}].file")
        mat = m.get("material", {})
        kind = mat.get("type", "lambert")
        for key in ("albedo",) if kind == "dielectric" else ("eta", "roughness"):
            if key in mat:
                raise LoomError(path, f"meshes[{i}].material.{key}", f"a {kind} material has no {key}")
        out.append({"name": m.get("name", file.stem), "file": str(file), "type": kind,
                    "albedo": _rgb(mat.get("albedo", 0.5)), "eta": float(mat.get("eta", 1.5)),
                    "roughness": float(mat.get("roughness", 0.1)), "emission": _rgb(mat.get("emission", 0.0)),
                    "matrix": placement(m.get("transform"), path, f"meshes[{i}].transform")})
    return out


def _fabric_table(fab: dict, path: Path, key: str) -> dict:
    """A fabric source table, its path resolved and checked (``key``: where it is in the scene file)."""
    fabric = copy.deepcopy(fab)
    src = fabric["source"]
    if src in ("file", "wif") and "path" not in fabric:
        raise LoomError(path, f"{key}.path", f"source = {src!r} needs a 'path'")
    if src == "generator" and "generator" not in fabric:
        raise LoomError(path, f"{key}.generator", f"source = 'generator' needs a [{key}.generator] table")
    if "path" in fabric:
        if not Path(fabric["path"]).is_absolute():
            fabric["path"] = str((path.parent / fabric["path"]).resolve())
        what = "WIF draft" if src == "wif" else "curve file"
        if Path(fabric["path"]).is_dir():
            raise LoomError(path, f"{key}.path", f"{fabric['path']} is a directory, not a {what}")
        if not Path(fabric["path"]).is_file():
            raise LoomError(path, f"{key}.path", f"{what} {fabric['path']} not found")
    return fabric


DRAPE_KEYS = {"cylinder": ("radius",), "sphere": ("radius", "folds", "fold_amplitude"),
              "obj": ("file", "uv_size", "scale")}


def _drape(spec: dict, path: Path, key: str) -> dict:
    """A fabric's ``drape`` table with its defaults (schema $defs/placed_fabric); a key its surface does not
    read is refused, an OBJ's file resolved against the scene and checked."""
    surface = spec["surface"]
    for k in spec:
        if k != "surface" and k not in DRAPE_KEYS[surface]:
            raise LoomError(path, f"{key}.{k}", f"a drape on surface {surface!r} has no {k} (it reads "
                            f"{', '.join(DRAPE_KEYS[surface])})")
    if surface == "sphere":
        return {"folds": 6, "fold_amplitude": 0.15, **spec}
    if surface != "obj":
        return dict(spec)
    return {"scale": 1.0, **spec, "file": str(_obj_file(spec["file"], path, f"{key}.file"))}


def _fabric_parts(raw: dict, path: Path) -> list[FabricPart]:
    """The scene's fabrics (module doc): its [fabric] + [yarns], or its [[fabrics]] (names unique, placements
    rigid)."""
    if "fabric" in raw and "fabrics" in raw:
        raise LoomError(path, "fabrics", "a scene has one [fabric] or several [[fabrics]], not both")
    if "fabrics" not in raw:
        if "fabric" not in raw:
            raise LoomError(path, "fabric", "missing: a scene needs a [fabric] table (or [[fabrics]])")
        return [FabricPart("", _fabric_table(raw["fabric"], path, "fabric"), copy.deepcopy(raw.get("yarns", {})),
                           None, "fabric", "yarns")]
    if "yarns" in raw:
        raise LoomError(path, "yarns", "with [[fabrics]], each fabric has its own yarn types (fabrics[i].yarns)")
    parts, seen = [], set()
    for i, f in enumerate(raw["fabrics"]):
        if f["name"] in seen:
            raise LoomError(path, f"fabrics[{i}].name", f"a second fabric named {f['name']!r} (names are unique)")
        seen.add(f["name"])
        tf = f.get("transform")
        if tf and tf.get("scale", 1.0) != 1.0:
            raise LoomError(path, f"fabrics[{i}].transform.scale", "a fabric's placement is rigid: scale its source "
                            "(fabric.scale, or the generator's spacing and yarn radius) instead")
        drape = _drape(f["drape"], path, f"fabrics[{i}].drape") if "drape" in f else None
        parts.append(FabricPart(f["name"], _fabric_table(f["fabric"], path, f"fabrics[{i}].fabric"),
                                copy.deepcopy(f.get("yarns", {})),
                                placement(tf, path, f"fabrics[{i}].transform") if tf else None,
                                f"fabrics[{i}].fabric", f"fabrics[{i}].yarns", drape))
    return parts


def load_scene(path: str | Path) -> Scene:
    path = Path(path)
    raw = read_toml(path, what="scene file")
    check_names(raw, path)
    validate(raw, "scene", path)
    parts = _fabric_parts(raw, path)
    scene_tbl = raw.get("scene", {})
    camera = None
    if "camera" in raw:
        camera = {**CAMERA_DEFAULTS, **raw["camera"]}
        o, t, u = (np.asarray(camera[k], float) for k in ("origin", "target", "up"))
        if np.linalg.norm(t - o) == 0:
            raise LoomError(path, "camera.target", "camera target equals its origin")
        if np.linalg.norm(np.cross(t - o, u)) < 1e-9 * np.linalg.norm(t - o) * max(np.linalg.norm(u), 1e-30):
            raise LoomError(path, "camera.up", "camera up vector is parallel to the viewing direction (or zero)")
    lights = []
    for i, light in enumerate(raw.get("lights", [])):
        light = dict(light)
        for k in ("irradiance", "radiance", "power"):
            if k in light:
                light[k] = _rgb(light[k])
        for k in ("direction", "axis"):
            if k in light:
                v = np.asarray(light[k], float)
                n = np.linalg.norm(v)
                if n == 0:
                    raise LoomError(path, f"lights[{i}].{k}", "zero-length vector")
                light[k] = (v / n).tolist()
        if light["type"] == "envmap":
            lp = Path(light["path"])
            light["path"] = str(lp if lp.is_absolute() else (path.parent / lp).resolve())
            light.setdefault("scale", 1.0)
            if not Path(light["path"]).exists():
                raise LoomError(path, f"lights[{i}].path", f"environment map {light['path']} not found")
        lights.append(light)
    render = {**RENDER_DEFAULTS, **raw.get("render", {})}
    if "ground" in render:
        render["ground"] = {"height": 0.0, "albedo": [0.5, 0.5, 0.5], **render["ground"]}
        render["ground"]["albedo"] = _rgb(render["ground"]["albedo"])
    return Scene(path=path, raw=raw, name=scene_tbl.get("name", path.stem), seed=int(scene_tbl.get("seed", 0)),
                 fabric=parts[0].fabric, yarns=parts[0].yarns, camera=camera, lights=lights, render=render,
                 meshes=_meshes(raw, path), parts=parts)


def one_fabric(scene: Scene, file, key: str) -> Scene:
    """``scene``, refused (at ``file``'s ``key``) when it has several fabrics: a tiling's exemplars and the
    precomputes made from it take one fabric's yarn types."""
    if scene.several:
        raise LoomError(file, key, f"{scene.path.name} has several [[fabrics]]; a tiling and its precomputes take "
                        "the yarn types of a scene of one fabric")
    return scene


def ingest_identity(scene: Scene) -> dict:
    """What of a scene its ``yarns`` artifact (and the tables and fibres made from that) is made of:
    ``fabric`` -- ``fabric_identity`` of its source (of a [[fabrics]] scene: ``{"fabrics": [...]}``, each
    fabric's name, source and placement) -- and ``yarns`` -- every yarn type by its label
    (``yarns.default`` merged in) without the keys only the renderer reads (``bcsdf``). Recorded by
    ingest in the artifact's summary, carried by tables and realize, compared by render
    (``pipeline.render_setup.check_scene_matches``)."""
    if scene.parts[0].key == "fabric":
        fabric = fabric_identity(scene.fabric)
    else:       # [[fabrics]]: each by its name, source and placement
        fabric = {"fabrics": [{"name": p.name, **fabric_identity(p.fabric), "drape": drape_identity(p.drape),
                               "placement": None if p.matrix is None else p.matrix.tolist()} for p in scene.parts]}
    yarns = {}
    for label in scene.type_labels():
        t = {k: v for k, v in scene.yarn_type(label).items() if k not in RENDER_ONLY_YARN_KEYS}
        if t:
            yarns[label] = t
    return {"scene": scene.path.name, "fabric": fabric, "yarns": yarns}


def without_file_names(ident: dict) -> dict:
    """An ``ingest_identity``'s fabric less its files' names (a renamed copy is the same file: its sha256)."""
    if "fabrics" in ident:
        return {"fabrics": [without_file_names(x) for x in ident["fabrics"]]}
    out = {k: v for k, v in ident.items() if k != "file"}
    if isinstance(out.get("drape"), dict):
        out["drape"] = {k: v for k, v in out["drape"].items() if k != "file"}
    return out


def fabric_identity(fab: dict) -> dict:
    """What of a fabric source table shapes its curves: the generator table, or the file by its sha256 (its
    name kept for messages) and the keys that reshape it."""
    from .artifacts import sha256_file

    fabric = {"source": fab["source"]}
    if fab["source"] == "generator":
        fabric["generator"] = copy.deepcopy(fab["generator"])
    else:
        p = Path(fab["path"])
        fabric.update(file=p.name, sha256=sha256_file(p) if p.is_file() else None)
        fabric.update({k: fab[k] for k in FABRIC_SHAPE_KEYS if k in fab})
    return fabric


def drape_identity(drape: dict | None) -> dict | None:
    """A ``drape`` table as its fabric's identity holds it: an OBJ by its name and sha256 (as a fabric file)."""
    if drape is None or "file" not in drape:
        return drape
    from .artifacts import sha256_file

    p = Path(drape["file"])
    return {**drape, "file": p.name, "sha256": sha256_file(p)}


def file_identity(path: str | Path, scale: float | None = None) -> dict:
    """``ingest_identity`` of a curve file or WIF draft ingested without a scene: the file, no yarn types."""
    from .artifacts import sha256_file

    p = Path(path)
    fabric = {"source": "wif" if p.suffix.lower() == ".wif" else "file", "file": p.name, "sha256": sha256_file(p)}
    if scale:
        fabric["scale"] = scale
    return {"scene": None, "fabric": fabric, "yarns": {}}


def camera_array(camera: dict, width: int | None = None, height: int | None = None) -> np.ndarray:
    """Pack a camera dict for ``stages.render.camera`` (see its layout)."""
    from stages.render.camera import pack_camera

    return pack_camera(np.asarray(camera["origin"], float), np.asarray(camera["target"], float),
                       np.asarray(camera["up"], float), float(camera["fov"]),
                       int(width or camera["width"]), int(height or camera["height"]))
