"""The comparison file: which methods render one scene, against which converged reference, at which budgets.

A comparison file (TOML, ``schemas/compare.schema.json``; the shipped ones are ``data/compare/*.toml``)::

    [compare]
    name = "demo-swatch"
    scene = "../scenes/demo.toml"        # relative to the comparison file
    reference = "fiberpath"              # a method below: its converged picture is the reference
    camera = { width = 96, height = 72 } # merged into the scene's [camera]
    render = { max_depth = 32 }          # merged into the scene's [render] for every render
    lights = [{ type = "sg", axis = [0.4, -0.5, 0.77], sharpness = 150.0, power = 3.0 }]   # optional
    levels = [0.3, 0.2, 0.1]             # relative errors for times and speed-ups (default)
    equal_time_spp = 16                  # the equal-time strip: the reference method's time at 16 spp

    [reference]                          # the converged reference, from independent batches
    spp = 64                             # samples per pixel of one batch
    batches = 16                         # rendered first; more follow until both targets hold
    max_batches = 256
    pixel_error = 0.05                   # median relative standard error over cloth pixels
    mean_error = 0.002                   # relative standard error of the cloth's mean

    [[methods]]
    name = "fiberpath"
    method = "fiberpath"                 # loomlight render --method (default: name)
    args = ["--fibers", "out/demo/fibers.zarr"]   # {compare_dir}, {out} expand
    budget = "spp"                       # or "max_spp": adaptive sampling's cap, render.spp fixed
    budgets = [4, 8, 16, 32, 64, 128]    # increasing
    target_speedup = 5.0                 # optional: at equal error, this many times faster than the reference method

``load_comparison(path)`` reads and checks the file: an unknown scene file, render method or budget
kind, budgets that are not positive or not increasing, a reference that is not a method, a name used
twice: one ``LoomError`` line naming the file and the key (exit 2 on the command line).
``derived_scene`` gives the scene a render of the comparison uses.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

from ..errors import LoomError, unknown
from ..schemas import validate
from ..toml_file import read_toml
from .sweep_file import absolute_paths, check_method_names, read_study

BUDGET_KINDS = ("spp", "max_spp")
DEFAULT_LEVELS = (0.3, 0.2, 0.1)
DEFAULT_EQUAL_TIME_SPP = 16


@dataclass(frozen=True)
class ReferenceSettings:
    spp: int                  # per batch
    batches: int              # the first round
    max_batches: int
    pixel_error: float        # target median relative standard error over the cloth
    mean_error: float         # target relative standard error of the cloth's mean


@dataclass(frozen=True)
class CompareMethod:
    name: str
    method: str
    render: dict
    args: list
    budget: str               # "spp" or "max_spp"
    budgets: tuple
    target_speedup: float | None = None   # make compare's target: speed-up over the reference method at equal error


@dataclass(frozen=True)
class Comparison:
    path: Path
    name: str
    description: str
    scene_path: Path
    scene_raw: dict           # the scene with the comparison's lights, camera and render merged in
    reference: str            # the reference method's name
    settings: ReferenceSettings
    methods: tuple
    levels: tuple
    equal_time_spp: int

    def method(self, name: str) -> CompareMethod:
        return next(m for m in self.methods if m.name == name)


def _method(path: Path, i: int, m: dict) -> CompareMethod:
    from ..renderers import known_methods

    where = f"methods[{i}]"
    renderer = m.get("method", m["name"])
    if renderer not in known_methods():
        raise LoomError(path, f"{where}.method", unknown("render method", renderer, known_methods()))
    kind = m.get("budget", "spp")
    if kind not in BUDGET_KINDS:
        raise LoomError(path, f"{where}.budget", unknown("budget", kind, BUDGET_KINDS))
    budgets = list(m["budgets"])
    for j, b in enumerate(budgets):
        if b < 1:
            raise LoomError(path, f"{where}.budgets[{j}]", f"a budget is a positive number of samples, got {b}")
        if j and b <= budgets[j - 1]:
            raise LoomError(path, f"{where}.budgets[{j}]",
                            f"budgets must increase: {b} follows {budgets[j - 1]}")
    return CompareMethod(m["name"], renderer, dict(m.get("render", {})), list(m.get("args", [])), kind, tuple(budgets),
                         m.get("target_speedup"))


def load_comparison(path: str | Path) -> Comparison:
    path, raw, scene_path = read_study(path, "compare", "comparison file")
    cp = raw["compare"]
    methods = tuple(_method(path, i, m) for i, m in enumerate(raw["methods"]))
    check_method_names(path, [m.name for m in methods], cp["reference"], "compare.reference")
    r = raw["reference"]
    settings = ReferenceSettings(int(r["spp"]), int(r.get("batches", 16)), int(r.get("max_batches", 256)),
                                 float(r.get("pixel_error", 0.05)), float(r.get("mean_error", 0.002)))
    if settings.max_batches < settings.batches:
        raise LoomError(path, "reference.max_batches",
                        f"{settings.max_batches} is fewer than the first round's {settings.batches} batches")
    levels = tuple(sorted((float(v) for v in cp.get("levels", DEFAULT_LEVELS)), reverse=True))
    scene_raw = absolute_paths(read_toml(scene_path, what="scene file"), scene_path)
    if "lights" in cp:
        scene_raw["lights"] = copy.deepcopy(cp["lights"])
    scene_raw["camera"] = {**scene_raw.get("camera", {}), **cp.get("camera", {})}
    scene_raw["render"] = {**scene_raw.get("render", {}), **cp.get("render", {})}
    cmp = Comparison(path, cp.get("name", path.stem), cp.get("description", ""), scene_path, scene_raw,
                     cp["reference"], settings, methods, levels, int(cp.get("equal_time_spp", DEFAULT_EQUAL_TIME_SPP)))
    for m in methods:   # every derived scene is a valid scene (lights, camera, render keys)
        validate(derived_scene(cmp, m, m.budgets[0], 0), "scene", path, prefix=f"methods {m.name!r}: ")
    return cmp


def derived_scene(cmp: Comparison, m: CompareMethod, budget: int, seed: int) -> dict:
    """The scene of one render: the comparison's scene, the method's [render] overrides, the budget
    (``render.spp``, or ``render.max_spp`` for adaptive budgets) and the seed."""
    raw = copy.deepcopy(cmp.scene_raw)
    base = {k: v for k, v in raw.get("render", {}).items() if k != "source"}   # the scene's source is its own method's
    render = {**base, **m.render, "method": m.method, "seed": int(seed)}
    render[m.budget] = int(budget)
    raw["render"] = render
    return raw
