"""The sweep file: render methods and light/view configurations over one base scene.

A sweep file (TOML, ``schemas/sweep.schema.json``) names a base scene, render methods and
configurations; seed 001 §6.3 is the model (Fig. 13: RMSE of the mean image intensity of every
configuration against path tracing; Table 2: time per image and speed-up over path tracing)::

    [sweep]
    name = "demo-sg"
    scene = "../scenes/demo.toml"   # relative to the sweep file
    reference = "fiberpath"         # a method name below
    render = { spp = 16 }           # merged into every scene's [render]
    camera = { width = 96, height = 72 }   # merged into every scene's [camera]

    [[methods]]
    name = "fiberpath"              # label: output file renders/<config>/<name>.exr
    method = "fiberpath"            # the renderer (loomlight render --method); default: name
    render = { spp = 64 }           # merged into the scene's [render] for this method only
    args = []                       # extra arguments for loomlight render ({sweep_dir}, {out} expand)

    [grid]                          # the product of these becomes configurations
    axes = [[0, 0, 1], [0.5, 0, 0.866]]   # SG axes (towards the light), normalised
    sharpness = [10, 100, 1000]     # SG sharpness lambda
    power = 1.0                     # SG power (total radiant intensity)
    directional = true              # also a directional light along -axis (the lambda -> inf limit)
    irradiance = 1.0
    views = [{ name = "top", origin = [0, 0, 3], target = [0, 0, 0], up = [0, 1, 0] }]

    [[configurations]]              # explicit configurations, after the grid's
    name = "grazing"
    lights = [{ type = "directional", direction = [-1, 0, -0.2], irradiance = 1.0 }]
    camera = { origin = [0, -3, 1] }

A configuration replaces the scene's lights (when it gives ``lights``) and merges ``camera`` and
``render`` into the scene's tables. Grid configurations are named ``<view>_a<i>_l<lambda>``
(``<view>_a<i>_dir`` for directional lights; no view prefix without views).

``load_sweep(path)`` reads and checks the file (names used twice, an unknown reference, no
configurations: one ``LoomError`` line naming the key) into a :class:`Sweep`; ``derived_scene``
is the base scene with the sweep's, a configuration's and a method's overrides.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import LoomError
from ..scene import load_scene
from ..schemas import validate
from ..toml_file import read_toml


@dataclass
class Method:
    name: str
    method: str
    render: dict
    args: list[str]


@dataclass
class Configuration:
    name: str
    lights: list | None
    camera: dict
    render: dict
    label: str


@dataclass
class Sweep:
    path: Path
    name: str
    scene_path: Path
    scene_raw: dict
    reference: str
    render: dict
    camera: dict
    methods: list[Method]
    configurations: list[Configuration]


def _unit(v) -> list[float]:
    a = np.asarray(v, float)
    return (a / np.linalg.norm(a)).tolist()


def _grid_configurations(path: Path, grid: dict) -> list[Configuration]:
    axes = grid.get("axes", [])
    for i, a in enumerate(axes):
        if np.linalg.norm(np.asarray(a, float)) == 0:
            raise LoomError(path, f"grid.axes[{i}]", "zero-length vector")
    views = grid.get("views") or [None]
    power = grid.get("power", 1.0)
    out = []
    for view in views:
        prefix = f"{view['name']}_" if view else ""
        cam = {k: v for k, v in view.items() if k != "name"} if view else {}
        for i, axis in enumerate(axes):
            ax = _unit(axis)
            for lam in grid.get("sharpness", []):
                out.append(Configuration(f"{prefix}a{i}_l{lam:g}",
                                         [{"type": "sg", "axis": ax, "sharpness": float(lam), "power": power}],
                                         cam, {}, f"SG axis {np.round(ax, 3).tolist()}, lambda {lam:g}"
                                         + (f", view {view['name']}" if view else "")))
            if grid.get("directional", False):
                d = (-np.asarray(ax)).tolist()
                out.append(Configuration(f"{prefix}a{i}_dir", [{"type": "directional", "direction": d,
                                                                "irradiance": grid.get("irradiance", 1.0)}],
                                         cam, {}, f"directional towards {np.round(ax, 3).tolist()}"
                                         + (f", view {view['name']}" if view else "")))
    return out


def absolute_paths(raw: dict, scene_path: Path) -> dict:
    """Scene file paths made absolute, so the derived scene can live in another folder."""
    raw = copy.deepcopy(raw)
    base = scene_path.parent
    fab = raw.get("fabric", {})
    if "path" in fab and not Path(fab["path"]).is_absolute():
        fab["path"] = str((base / fab["path"]).resolve())
    for light in raw.get("lights", []):
        if light.get("type") == "envmap" and "path" in light and not Path(light["path"]).is_absolute():
            light["path"] = str((base / light["path"]).resolve())
    return raw


def read_study(path: str | Path, kind: str, what: str) -> tuple[Path, dict, Path]:
    """(path, the file's TOML, its base scene's path) of a sweep or comparison file (``kind``: its schema and its
    top table): read (``what`` names it in errors), validated, and the scene its ``<kind>.scene`` names
    (relative to it) checked and read."""
    path = Path(path)
    raw = read_toml(path, what=what)
    validate(raw, kind, path)
    scene_path = Path(raw[kind]["scene"])
    if not scene_path.is_absolute():
        scene_path = (path.parent / scene_path).resolve()
    if not scene_path.is_file():
        raise LoomError(path, f"{kind}.scene", f"scene file {scene_path} not found")
    load_scene(scene_path)  # the base scene's names checked now, not at each derived render
    return path, raw, scene_path


def check_method_names(path: Path, names: list[str], reference: str, place: str) -> None:
    """Each ``methods[].name`` once, and the reference (named at ``place``) one of them."""
    for j, n in enumerate(names):
        if names.index(n) != j:
            raise LoomError(path, f"methods[{j}].name", f"method name {n!r} is used twice")
    if reference not in names:
        raise LoomError(path, place, f"{reference!r} is not one of the methods ({', '.join(names)})")


def load_sweep(path: str | Path) -> Sweep:
    path, raw, scene_path = read_study(path, "sweep", "sweep file")
    sw = raw["sweep"]
    scene_raw = read_toml(scene_path, what="scene file")
    methods = [Method(m["name"], m.get("method", m["name"]), dict(m.get("render", {})), list(m.get("args", [])))
               for m in raw["methods"]]
    check_method_names(path, [m.name for m in methods], sw["reference"], "sweep.reference")
    configs = _grid_configurations(path, raw["grid"]) if "grid" in raw else []
    for c in raw.get("configurations", []):
        configs.append(Configuration(c["name"], c.get("lights"), dict(c.get("camera", {})), dict(c.get("render", {})),
                                     c.get("description", c["name"])))
    if not configs:
        raise LoomError(path, "configurations", "the sweep has no configurations (give [grid] or [[configurations]])")
    cnames = [c.name for c in configs]
    for i, n in enumerate(cnames):
        if cnames.index(n) != i:
            raise LoomError(path, "configurations", f"configuration name {n!r} occurs twice")
    return Sweep(path, sw.get("name", path.stem), scene_path, absolute_paths(scene_raw, scene_path), sw["reference"],
                 dict(sw.get("render", {})), dict(sw.get("camera", {})), methods, configs)


def derived_scene(sweep: Sweep, config: Configuration, method: Method) -> dict:
    """The base scene with the sweep's, the configuration's and the method's overrides."""
    raw = copy.deepcopy(sweep.scene_raw)
    if config.lights is not None:
        raw["lights"] = copy.deepcopy(config.lights)
    cam = {**raw.get("camera", {}), **sweep.camera, **config.camera}
    if cam:
        raw["camera"] = cam
    render = {**raw.get("render", {}), **sweep.render, **config.render, **method.render}
    render["method"] = method.method
    raw["render"] = render
    return raw
