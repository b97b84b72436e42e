"""The renderer registry: every render method declares here, once, what it reads and what it accepts.

A method (``RenderMethod``) names the module that sets it up (``pipeline/renderers/<module>.py``,
defining ``render(scene, options) -> RenderResult``), its geometry sources (``Source``: a name for
``--source`` and the artifacts it reads, ``ArtifactInput``), its method-specific settings
(``Setting``: ``--set KEY=VALUE`` pairs), whether it takes ``--material`` / ``--bcsdf`` and whether it
renders a scene's ``[[meshes]]`` (``meshes``; a method that does not refuses such a scene, naming the key).
Everything else derives from this table: ``loomlight render --help`` (method, source and setting
lists), the ``[render]`` table of the scene schema (``render_schema``), which inputs a render
artifact records as provenance, and the messages for unknown methods, sources and settings.
``COMMON_DEFAULTS`` are the defaults of the settings every method shares (scene key
``render.<name>`` or its command-line option); nothing else in loomlight states them.

``options`` (what ``render`` receives; ``pipeline.runners.render`` fills it): ``width``, ``height``,
``spp``, ``seed``, ``max_depth``, ``rr_depth``, ``tile_size`` (resolved: command line, else the
scene's [render] / [camera] table, else ``COMMON_DEFAULTS``), ``source`` (the command line's value
only, None when not given: a method falls back to the scene's ``render.source``), the artifact paths
``fibers``, ``tables``, ``grid`` (None when not given), ``bcsdf``, ``material``, ``threads`` and the
``--set`` pairs (strings) under ``extra``. A renderer returns linear RGB (H, W, 3) float32, extra
channels (name -> (H, W) float32: ``A``, ``depth``, ``variance``) and ``stats``: at least ``rays``,
``paths`` and ``render_s`` (seconds in the kernels); ``loomlight render`` writes the EXR, the PNG
preview and the ``render`` artifact.

To add a method: its integrator (``stages/render/<method>.py``), its setup module here, one
``RenderMethod`` entry in ``METHODS``, its tests.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..errors import LoomError, did_you_mean, unknown  # noqa: F401 (did_you_mean: for the render runner)
from ..limits import MAX_PATH_DEPTH

if TYPE_CHECKING:  # numpy stays out of `loomlight --help`
    import numpy as np


@dataclass
class RenderResult:
    rgb: np.ndarray
    extra: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


@dataclass(frozen=True)
class ArtifactInput:
    """An artifact a source reads: ``option`` on the command line (``--<option> PATH.zarr``), also
    accepted as ``--set <option>=PATH.zarr``; ``kinds`` the artifact kinds it may be."""
    option: str
    kinds: tuple[str, ...]
    what: str


@dataclass(frozen=True)
class Source:
    name: str
    inputs: tuple[ArtifactInput, ...]
    help: str


@dataclass(frozen=True)
class Setting:
    """A method-specific ``--set KEY=VALUE``."""
    key: str
    help: str
    choices: tuple[str, ...] = ()


@dataclass(frozen=True)
class RenderMethod:
    name: str
    summary: str
    module: str
    sources: tuple[Source, ...]
    default_source: str
    settings: tuple[Setting, ...] = ()
    materials: tuple[str, ...] = ()
    defaults: tuple[tuple[str, int], ...] = ()   # this method's own defaults of COMMON_DEFAULTS settings
    meshes: bool = False                         # renders the scene's [[meshes]] (walls, floor, furniture)
    fabrics: bool = False                        # renders a scene of several [[fabrics]] (yarn types per fabric)

    def default(self, key: str):
        return dict(self.defaults).get(key, COMMON_DEFAULTS[key])

    def source(self, name: str | None) -> Source:
        name = name or self.default_source
        for s in self.sources:
            if s.name == name:
                return s
        raise LoomError(None, "--source", unknown(f"{self.name} source", name, self.source_names))

    @property
    def source_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sources)

    def check_scene(self, scene) -> None:
        """Refuse a scene this method cannot render whole: one with ``[[meshes]]`` when it does not render them,
        one of several ``[[fabrics]]`` when it renders one fabric."""
        if getattr(scene, "meshes", None) and not self.meshes:
            raise LoomError(scene.path, "meshes", f"the {self.name} method does not render a scene's meshes yet "
                            f"(methods that do: {', '.join(mesh_methods())}); remove the [[meshes]] tables or "
                            "render with one of those")
        if getattr(scene, "several", False) and not self.fabrics:
            raise LoomError(scene.path, "fabrics", f"the {self.name} method renders one fabric (its tiling's); "
                            f"a scene of several [[fabrics]] renders with {', '.join(fabric_methods())}")

    def run(self, scene, options) -> RenderResult:
        self.check_scene(scene)
        return importlib.import_module(f"{__name__}.{self.module}").render(scene, options)


# settings every method shares: scene key render.<name> (camera.<name> for the image size), or the option
COMMON_DEFAULTS = {"width": 320, "height": 240, "spp": 16, "seed": 0, "max_depth": 32, "rr_depth": 5, "tile_size": 16,
                   "max_spp": 0, "target_error": 0.05}  # max_spp 0: no adaptive sampling (renderers/film.py)

FIBERS = ArtifactInput("fibers", ("fibers",), "the realized fibres (loomlight realize)")
TILING = ArtifactInput("fibers", ("tiling",), "a tiling artifact (loomlight tile)")
TABLES = ArtifactInput("tables", ("tables",), "the procedural tables (loomlight tables)")
GRID = ArtifactInput("grid", ("grid",), "a voxel grid (loomlight voxelize)")
SVF = ArtifactInput("svf", ("svf",), "the tiling's segment visibility functions (loomlight precompute svf)")
IIRTF = ArtifactInput("iirtf", ("iirtf",), "the tiling's IIRTF transfer matrices (loomlight precompute iirtf)")
BTF = ArtifactInput("btf", ("btf",), "a fitted cloth texture (loomlight precompute btf)")
YARNS = ArtifactInput("yarns", ("yarns",), "the yarn curves (loomlight ingest)")
CLI_INPUTS = ("fibers", "tables", "grid")   # the artifact options ``render`` has; others come by --set

_FIBERPATH_SETTINGS = (
    Setting("tint", "yarn (default): the BCSDF dyed so the yarn shows its colour under white diffuse light (C_TT from "
                          "the yarn's albedo curve, C_R uncoloured; pipeline.dye); none: the presets as tabulated",
            ("yarn", "none")),
    Setting("tiling", "a tiling artifact (same as --fibers TILING.zarr)"),
    Setting("accel", "embree (default): realized fibres traced by Embree 4; bvh: by loomlight's own SAH BVH "
                     "(a tiling always walks its shell)", ("embree", "bvh")),
)
_FIBERPATH_SOURCES = (
    Source("realized", (FIBERS,), "explicit fibres of a fibers artifact, or of a tiling artifact's exemplars "
                                  "under its shell map (both through --fibers)"),
)

METHODS = {m.name: m for m in (
    RenderMethod(
        "volpath", "procedural fibres as an anisotropic micro-flake volume (Luan, Zhao, Bala 2017)", "volpath",
        sources=(Source("procedural", (TABLES,), "lookups on the fly from procedural tables (--tables)"),
                 Source("realized", (FIBERS,), "the realized fibres in a BVH (--fibers)"),
                 Source("grid", (GRID,), "a voxelized medium (--grid)")),
        default_source="procedural",
        settings=(Setting("majorant_cell", "majorant grid cell size in scene units (default: a quarter of the "
                                           "mean yarn extent bound)"),
                  Setting("phase", "bcsdf (default): a collision scatters by the yarn's dyed fibre BCSDF, as "
                                    "fiberpath's fibres do; microflake: the specular micro-flakes of "
                                    "Luan, Zhao, Bala 2017",
                          ("bcsdf", "microflake")),
                  Setting("albedo", "micro-flakes' single-scattering albedo -- bcsdf (default): each yarn's "
                                    "dyed BCSDF's mean albedo; color: the yarn's colour itself",
                          ("bcsdf", "color")),
                  Setting("tables", "the tables artifact (same as --tables)"),
                  Setting("grid", "the grid artifact (same as --grid)")), meshes=True, fabrics=True),
    RenderMethod(
        "fiberpath", "explicit fibres path traced with the fibre BCSDF (Khungurn et al. 2015)", "fiberpath",
        sources=_FIBERPATH_SOURCES, default_source="realized", settings=_FIBERPATH_SETTINGS,
        materials=("bcsdf", "lambert"), meshes=True, fabrics=True),
    RenderMethod(
        "fiberpath_shell", "fiberpath on a tiling artifact (the same as fiberpath --fibers TILING.zarr)",
        "fiberpath", sources=(Source("realized", (TILING,), "a tiling artifact's exemplars under its shell map"),),
        default_source="realized", settings=_FIBERPATH_SETTINGS, materials=("bcsdf", "lambert"), meshes=True),
    RenderMethod(
        "prt", "precomputed light transport on a shell-mapped tiling: SVF single + IIRTF multiple scattering "
               "(Khungurn et al. 2017)", "prt",
        sources=(Source("precomputed", (TILING, SVF, IIRTF), "a tiling (--fibers) with its precomputed SVF and "
                                                              "IIRTF (--set svf=, --set iirtf=)"),),
        default_source="precomputed",
        settings=(Setting("svf", "the svf artifact (loomlight precompute svf)"),
                  Setting("iirtf", "the iirtf artifact (loomlight precompute iirtf)"),
                  Setting("tiling", "a tiling artifact (same as --fibers TILING.zarr)"),
                  Setting("terms", "all (default), single or multi: which scattering terms to render; hits: "
                                   "none (fibre hits left black: times the eye rays' walk alone)",
                          ("all", "single", "multi", "hits")),
                  Setting("sg", "mc (default): SG lights sampled into directions (the paper's CPU version); "
                                "analytic: §5.2.2's Gamma with sum-of-SGs / erf-SSDF visibility", ("mc", "analytic")),
                  Setting("sigma_glo", "std. dev. of the Gaussian filtering multiple scattering's global "
                                       "visibility, flat-fabric units (default: the exemplar thickness)"),
                  Setting("sh_window", "none (default), hann or lanczos: a window on the IIRTF's SH bands "
                                       "against ringing", ("none", "hann", "lanczos")),
                  Setting("ms_incidence", "filtered (default): multiple scattering from the light's incidence at the "
                                          "Gaussian's point of sigma_glo (light gathered around the hit, as on a "
                                          "curved cloth's terminator); local: at the hit (the paper's)",
                          ("local", "filtered")),
                  Setting("tint", "yarn (default) or none, as fiberpath (must match the IIRTF's materials)",
                          ("yarn", "none")))),
    RenderMethod(
        "btf", "a fitted cloth texture (Lafortune lobes x view table, or the compressed acquired table; mip-mapped) "
               "on a triangle mesh (Daubert et al. 2001)",
        "btf",
        sources=(Source("mesh", (BTF,), "an OBJ with texture coordinates (--set mesh=, --set repeat=) and the "
                                        "texture (--set btf=)"),
                 Source("tiling", (TILING, BTF), "a tiling's base surface (--fibers) and the texture fitted from "
                                                 "its repeat (--set btf=)")),
        default_source="mesh",
        settings=(Setting("btf", "the btf artifact (loomlight precompute btf)"),
                  Setting("mesh", "an OBJ mesh with texture coordinates (vt)"),
                  Setting("repeat", "texture repeats across the mesh's uv [0, 1] (default 1; mesh only)"),
                  Setting("tiling", "a tiling artifact (same as --fibers TILING.zarr)"),
                  Setting("mip", "on (default): the mip level of each pixel's footprint, blended between levels; "
                                 "off: level 0 everywhere", ("on", "off")),
                  Setting("shadows", "off (default) or on: shadow rays towards directional lights through the "
                                     "mesh's alpha", ("off", "on")),
                  Setting("relief", "on (default): a relief texture (precompute btf --plane relief) is read where "
                                    "the ray meets its height field; off: where the ray crosses the surface",
                          ("on", "off")),
                  Setting("model", "lafortune (default): seed 002's fitted lobes x view table; tabulated: the "
                                   "acquired table, compressed (precompute btf --model tabulated)",
                          ("lafortune", "tabulated"))),
        # a pixel costs well under a microsecond: 16-pixel tiles spend as long handing tiles to threads as on
        # the pixels (730 x 400: about 10 frames per second on 2 threads, 24 with 64; bench/bench_btf.py)
        defaults=(("tile_size", 64),)),
    RenderMethod(
        "bysdf", "yarn curves only, plies and fibres implicit, four-lobe yarn scattering (A Multi-scale Yarn "
                 "Appearance Model with Fiber Details)", "bysdf",
        sources=(Source("yarns", (YARNS,), "the yarn curves of a yarns artifact (--set yarns=)"),),
        default_source="yarns",
        settings=(Setting("yarns", "the yarns artifact (loomlight ingest)"),
                  Setting("mode", "near (default): the ray's own point; far: the BYSDF integrated over the yarn's "
                                  "width; multiscale: over the pixel's footprint", ("near", "far", "multiscale")),
                  Setting("k", "offsets per far / multiscale shading point (default 16)"),
                  Setting("params", "a TOML of BYSDF parameters per yarn group (loomlight fit-bysdf writes one)"),
                  Setting("ply_tol", "implicit ply iteration tolerance, in ply radii (default 1e-3)"),
                  Setting("ply_iter", "implicit ply iteration cap (default 10)"),
                  Setting("ply_search", "how ply entries are found: march (default: the certified march alone) "
                                        "or iteration (the paper's ellipse-plane iteration, then the march); "
                                        "the same entries", ("march", "iteration")),
                  Setting("falloff", "multiscale aggregation weights exp(-falloff |dx| / R) (default 40)"),
                  Setting("fibre_threshold", "fibre shadowing floor: s (1 - thr) + thr (default 0.5; 1: off)"),
                  Setting("ply_threshold", "ply shadowing floor (default 0.6; 1: off)")),
        defaults=(("max_depth", 4),), meshes=True, fabrics=True),
)}


def input_kinds() -> dict[str, tuple[str, ...]]:
    """option -> every artifact kind a source of some method reads through it, in the order the registry
    declares them (``fibers``: a fibers or a tiling artifact)."""
    kinds: dict[str, tuple[str, ...]] = {}
    for m in METHODS.values():
        for src in m.sources:
            for inp in src.inputs:
                have = kinds.get(inp.option, ())
                kinds[inp.option] = have + tuple(k for k in inp.kinds if k not in have)
    return kinds


def mesh_methods() -> list[str]:
    """The methods that render a scene's ``[[meshes]]``."""
    return [m.name for m in METHODS.values() if m.meshes]


def fabric_methods() -> list[str]:
    """The methods that render a scene of several ``[[fabrics]]``."""
    return [m.name for m in METHODS.values() if m.fabrics]


def known_methods() -> list[str]:
    return sorted(METHODS)


def method(name: str) -> RenderMethod:
    """The registered method ``name``; unknown names raise a LoomError listing the known ones."""
    if name not in METHODS:
        raise LoomError(None, "--method", unknown("render method", name, known_methods()))
    return METHODS[name]


def all_sources() -> list[str]:
    return sorted({s.name for m in METHODS.values() for s in m.sources})


def method_help() -> str:
    return "Render method: " + "; ".join(f"{m.name}, {m.summary}" for m in METHODS.values()) + \
        ". Default: the scene's render.method."


def _input_option(inp: ArtifactInput) -> str:
    return f"--{inp.option}" if inp.option in CLI_INPUTS else f"--set {inp.option}="


def source_help() -> str:
    parts = []
    for m in METHODS.values():
        srcs = [f"{s.name}{' (default)' if s.name == m.default_source and len(m.sources) > 1 else ''} "
                f"from {' + '.join(_input_option(i) for i in s.inputs)}" for s in m.sources]
        parts.append(f"{m.name}: {', '.join(srcs)}")
    return "Where the method takes its geometry from -- " + "; ".join(parts) + \
        ". Default: the scene's render.source, else the method's default."


def choices_metavar(names) -> str:
    """An option's metavar in ``--help`` listing the values it takes: ``<volpath|fiberpath|...>``."""
    return "<" + " | ".join(names) + ">"


def method_metavar() -> str:
    return choices_metavar(METHODS)


def source_metavar() -> str:
    return choices_metavar(dict.fromkeys(s.name for m in METHODS.values() for s in m.sources))


def material_metavar() -> str:
    return choices_metavar(dict.fromkeys(x for m in METHODS.values() for x in m.materials))


def settings_help() -> str:
    parts = []
    for m in METHODS.values():
        if m.settings and m.module == m.name:
            parts.append(f"{m.name}: " + ", ".join(s.key + (f"={'|'.join(s.choices)}" if s.choices else "")
                                                    for s in m.settings))
    return "Method-specific setting KEY=VALUE (repeatable) -- " + "; ".join(parts) + "."


def material_help() -> str:
    parts = [f"{m.name}: {' or '.join(m.materials)} (default {m.materials[0]})" for m in METHODS.values()
             if m.materials and m.module == m.name]
    return "Fibre material -- " + "; ".join(parts) + "."


def render_schema() -> dict:
    """The JSON Schema of a scene's [render] table (``schemas/scene.schema.json`` takes it from here)."""
    positive = {"type": "integer", "minimum": 1}
    depth = {"type": "integer", "minimum": 1, "maximum": MAX_PATH_DEPTH}
    return {
        "type": "object",
        "additionalProperties": False,
        "description": "render settings; defaults: " + ", ".join(f"{k} {v}" for k, v in COMMON_DEFAULTS.items()
                                                                 if k not in ("width", "height")),
        "properties": {
            "method": {"type": "string", "description": "a registered method: " + ", ".join(known_methods())
                       + " (checked against the registry when the scene is read)"},
            "spp": positive,
            "seed": {"type": "integer", "minimum": 0},
            "max_depth": depth,
            "rr_depth": depth,
            "source": {"enum": all_sources()},
            "tile_size": {"type": "integer", "minimum": 4},
            "scheduler": {"type": "string", "pattern": "^(local|processes|tcp://.+:[0-9]+)$",
                          "description": "where the render's tile tasks run: local, processes (a Dask LocalCluster) "
                                         "or tcp://HOST:PORT (a Dask scheduler); --scheduler overrides it"},
            "max_spp": {"type": "integer", "minimum": 0,
                        "description": "adaptive sampling: a second pass gives each pixel up to max_spp more samples, "
                                       "as many as its neighbours' relative error after spp samples asks for "
                                       "to reach target_error (0: off)"},
            "target_error": {"type": "number", "exclusiveMinimum": 0, "maximum": 1,
                             "description": "adaptive sampling: relative standard error of a pixel's mean aimed at"},
            "tiling": {"type": "string", "minLength": 1,
                       "description": "a tiling configuration (.toml, relative to the scene) for methods on a tiling "
                                      "(prt, btf, fiberpath_shell; fiberpath then renders the tiling too): render "
                                      "builds the tiling and its precomputes from it when no option gives them "
                                      "(--set tiling=CONFIG.toml does the same)"},
            "cache": {"type": "number", "minimum": 0,
                      "description": "volpath --source procedural: the render-time fibre cache budget in MiB "
                                     "(0: every lookup procedural; default 2048); --cache overrides it"},
            "ground": {
                "type": "object",
                "additionalProperties": False,
                "properties": {"height": {"type": "number"}, "albedo": {"$ref": "#/$defs/rgb"}},
            },
        },
    }
