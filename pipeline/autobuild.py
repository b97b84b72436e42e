"""One command renders a scene: the artifacts ``loomlight render`` builds when no option names them.

``loomlight render SCENE --method M -o out.exr`` reads the artifacts M's source declares (the renderer
registry, ``pipeline.renderers``). Each one that no option gives (``--fibers``, ``--tables``, ``--set
KEY=PATH.zarr``; those always win) is built here, in this process, by the runner of its command at that
command's defaults, into a cache, and reused from there:

=========  ===========================================================  ==========================================
input      built by (the command's defaults)                           from
=========  ===========================================================  ==========================================
yarns      ``ingest`` (4 frame samples per segment)                    the scene's fabric and yarn types
tables     ``tables`` (seed 0, 32 bins, hybrid hairs)                  yarns
fibers     ``realize`` (seed 0, vertices 0.002 apart)                  yarns; for fiberpath on a tiled scene: tile
tiling     ``tile``                                                    a tiling configuration (below)
svf        ``precompute svf`` (128 x 128 images, 48 components, 48 SGs) the tiling
iirtf      ``precompute iirtf`` (order 4, cells of 1 mean free path,  the tiling; the render scene's yarn
           50,000 paths per cell, uniform light sampling)              materials (``--bcsdf``, ``--set tint``)
btf        ``precompute btf`` (the exemplars the block map uses,      the tiling; the render scene's materials
           32 x 32 texels, 8x8 views and lights, 16 rays)
=========  ===========================================================  ==========================================

The tiling configuration: ``--set tiling=CONFIG.toml`` (or ``--fibers CONFIG.toml``), else the scene's
``render.tiling`` (a path relative to the scene). A method on a tiling without one, a voxel grid (``voxelize``
needs ``--res``) and a mesh are not built: the one-line error says what to pass. Everything that cannot be
built is found before anything is built. The precomputes print their size before they start (at these
defaults the IIRTF is seed 001's full quality: long).

Cache: ``<output's directory>/.loomlight-cache/<artifact>-<key>.zarr`` (``--cache-dir DIR``:
``DIR/<artifact>-<key>.zarr``).
The key (16 hex digits of a sha256) covers what the artifact is made of and nothing else: the step and its
arguments, the key of what it is built from (or the content hash of a given artifact), the code
(``artifacts.code_hash``: loomlight's sources and schemas; ``render_code_version``: also the yarn and BCSDF
presets), and of the scene only what the step reads -- ingest: ``scene.ingest_identity`` and the fabric table
(a fabric file by its bytes); tile: the configuration and its files by their bytes; iirtf and btf: the yarn
types with their BCSDFs (a preset file by its bytes) -- so a render from another camera, light or spp reuses
them. A complete, intact artifact at the key's path is reused; otherwise built there. Artifacts are published
atomically (``ArtifactWriter``); a lock file beside each (``.<name>.lock``) makes a second render that wants
the same artifact wait for the first to publish it, then reuse it. Nothing is ever deleted: remove the
directory to reclaim its space.

One line per artifact: ``built fibers (12.3 s) -> PATH`` or ``reused fibers PATH``.
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .errors import LoomError

CACHE_DIRNAME = ".loomlight-cache"
KEY_DIGITS = 16


@dataclass
class Node:
    """One artifact of the plan: its kind, cache key and path, how it is built, what it is built from."""
    kind: str
    key: str
    path: Path
    build: Callable[[], object]
    needs: tuple = ()
    before: Callable[[], str] | None = None   # a line printed before it is built (the precomputes' size)
    done: bool = field(default=False, compare=False)


def digest(doc) -> str:
    from .artifacts import jsonable

    return hashlib.sha256(json.dumps(jsonable(doc), sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def code_version() -> dict:
    from .artifacts import code_hash
    from .source_graph import render_code_version

    return {"code": code_hash(), "render_code": render_code_version()}


def cache_root(out: Path, cache_dir) -> Path:
    """Where the cache lies: ``--cache-dir``, else ``.loomlight-cache`` beside the output."""
    return Path(cache_dir) if cache_dir else Path(out).parent / CACHE_DIRNAME


def _file_sha(path) -> str:
    from .artifacts import FILE, input_identity

    return input_identity(path, FILE)


# ------------------------------------------------------------------------------------------------ what of the scene
def yarns_identity(scene) -> dict:
    """What ingest makes of the scene: its ``ingest_identity`` (less the scene's name) and the fabric table
    (a fabric file by its bytes, not its path)."""
    from .scene import ingest_identity, without_file_names

    ident = ingest_identity(scene)
    tables = [{k: v for k, v in p.fabric.items() if k != "path"} for p in scene.parts]
    fabric = tables[0] if scene.parts[0].key == "fabric" else tables
    return {"fabric_table": fabric, "fabric": without_file_names(ident["fabric"]), "yarns": ident["yarns"]}


def tiling_files(cfg: dict) -> dict:
    """The files a tiling configuration names that shape the tiling, by their bytes: exemplar curve files or
    drafts, the block map image, the surface mesh (``cfg`` from ``runners.tile.load_config``: paths
    resolved). The scene it names is not among them: the tile stage only records its path."""
    paths = {f"exemplars[{k}].path": ex["path"] for k, ex in enumerate(cfg.get("exemplars", [])) if "path" in ex}
    if isinstance(cfg.get("tiling", {}).get("block_map"), str):
        paths["tiling.block_map"] = cfg["tiling"]["block_map"]
    if "path" in cfg.get("surface", {}):
        paths["surface.path"] = cfg["surface"]["path"]
    return {k: _file_sha(p) if Path(p).is_file() else None for k, p in paths.items()}


def materials_identity(scene, material: dict) -> dict:
    """What the IIRTF and BTF take of the render scene: every yarn group's type with its BCSDF (a preset
    file by its bytes), and the material options."""
    from .scene import YARN_GROUPS

    types = {g: scene.yarn_type(g) for g in YARN_GROUPS}
    files = {}
    for g, t in types.items():
        b = t.get("bcsdf")
        if isinstance(b, str) and b.endswith(".toml") and scene.resolve(b).is_file():
            files[g] = _file_sha(scene.resolve(b))
    b = material.get("bcsdf")
    if isinstance(b, str) and b.endswith(".toml") and Path(b).is_file():
        files["--bcsdf"] = _file_sha(b)
    return {"yarns": types, "bcsdf_files": files, "material": material}


# ------------------------------------------------------------------------------------------------ the plan
class Planner:
    """Builds the nodes of the inputs a render lacks (module doc); errors before anything is built."""

    def __init__(self, scene, m, src, options, root: Path, budget=None, scheduler=None):
        self.scene, self.m, self.src, self.options = scene, m, src, options
        self.root = root
        self.budget, self.scheduler = budget, scheduler
        self.code = code_version()
        self.nodes: dict[str, Node] = {}
        self._config = None

    def node(self, kind: str, ident: dict, build, needs=(), before=None) -> Node:
        key = digest({"step": kind, **ident, **self.code})[:KEY_DIGITS]
        name = f"{kind}-{key}"
        if name not in self.nodes:
            path = self.root / f"{name}.zarr"
            self.nodes[name] = Node(kind, key, path, lambda: build(path), tuple(needs), before)
        return self.nodes[name]

    # -- steps ---------------------------------------------------------------------------------------
    def yarns(self) -> Node:
        from .runners.ingest import run_ingest

        args = {"frame_samples": 4, "radius": None, "scale": None, "merge_duplicates": True}
        scene_path = self.scene.path

        def build(path):
            try:
                return run_ingest(scene_path, path, frame_samples=args["frame_samples"], budget=self.budget)
            except LoomError as e:  # a key of the scene (fabric.generator) named without its file: as ingest says it
                if e.file is None and e.place and not e.place.startswith("-"):
                    raise LoomError(scene_path, e.place, e.message) from None
                raise

        return self.node("yarns", {"args": args, "scene": yarns_identity(self.scene)}, build)

    def tables(self) -> Node:
        from .runners.tables import run_tables

        y = self.yarns()
        args = {"preset": None, "radius": None, "seed": 0, "bins": 32, "hair_mode": "hybrid"}
        return self.node("tables", {"args": args, "yarns": y.key},
                         lambda path: run_tables(y.path, path, budget=self.budget), needs=(y,))

    def fibers(self) -> Node:
        from .runners.realize import DEFAULT_SPACING, run_realize

        y = self.yarns()
        args = {"preset": None, "radius": None, "seed": 0, "spacing": DEFAULT_SPACING}
        return self.node("fibers", {"args": args, "yarns": y.key},
                         lambda path: run_realize(y.path, path, budget=self.budget, scheduler=self.scheduler),
                         needs=(y,))

    def tiling(self, config: Path) -> Node:
        from .runners.tile import load_config, run_tile

        cfg = load_config(config)
        return self.node("tiling", {"config": cfg, "files": tiling_files(cfg)},
                         lambda path: run_tile(config, path, budget=self.budget))

    def _tiling_ref(self, option: str):
        """(key part, path, nodes needed) of the tiling the precompute for ``option`` reads: the one given,
        or the one built."""
        given = self.options.get("fibers")
        if given:
            from .artifacts import Artifact

            return {"tiling": Artifact(given, kind="tiling").meta["content_hash"]}, Path(given), ()
        t = self.tiling(self.config_or_fail(option))
        return {"tiling": t.key}, t.path, (t,)

    def _material(self) -> dict:
        from .runners.precompute import parse_material_options

        tint = (self.options.get("extra") or {}).get("tint")
        return parse_material_options([f"tint={tint}"] if tint else [], self.options.get("bcsdf"))

    def svf(self) -> Node:
        from dataclasses import asdict

        from .runners.precompute import SvfParams, run_svf

        p = SvfParams()
        ref, tpath, needs = self._tiling_ref("svf")
        return self.node("svf", {"args": asdict(p), **ref},
                         lambda path: run_svf(tpath, path, p, budget=self.budget, threads=self.options.get("threads"),
                                              scheduler=self.scheduler),
                         needs=needs, before=lambda: svf_size(tpath, p))

    def iirtf(self) -> Node:
        from dataclasses import asdict

        from .runners.precompute import IirtfParams, run_iirtf

        p = IirtfParams(material=self._material())
        ref, tpath, needs = self._tiling_ref("iirtf")
        scene_path = self.scene.path
        return self.node("iirtf", {"args": asdict(p), **ref, "materials": materials_identity(self.scene, p.material)},
                         lambda path: run_iirtf(tpath, path, p, scene=scene_path, budget=self.budget,
                                                threads=self.options.get("threads"), scheduler=self.scheduler),
                         needs=needs, before=lambda: iirtf_size(tpath, p))

    def btf(self) -> Node:
        from dataclasses import asdict

        from .runners.precompute import parse_material_options
        from .runners.precompute_btf import BtfParams, run_btf

        p = BtfParams(material=parse_material_options([], self.options.get("bcsdf")))
        ref, tpath, needs = self._tiling_ref("btf")
        scene_path = self.scene.path
        return self.node("btf", {"args": asdict(p), "exemplars": "used by the block map", **ref,
                                 "materials": materials_identity(self.scene, p.material)},
                         lambda path: run_btf(tpath, path, p, scene=scene_path, budget=self.budget,
                                              threads=self.options.get("threads"), scheduler=self.scheduler),
                         needs=needs, before=lambda: btf_size(tpath, p))

    # -- the tiling configuration --------------------------------------------------------------------
    def config(self) -> tuple[Path | None, str]:
        """(the tiling configuration, where it was named) or (None, ''): ``--fibers CONFIG.toml``, ``--set
        tiling=CONFIG.toml``, else the scene's ``render.tiling``."""
        if self._config is None:
            self._config = (None, "")
            extra = self.options.get("extra") or {}
            named = self.scene.render.get("tiling")
            for value, where in ((extra.get("tiling"), "--set tiling"), (self.options.get("fibers"), "--fibers")):
                if isinstance(value, str) and value.lower().endswith(".toml"):
                    p = Path(value)
                    if not p.is_file():
                        raise LoomError(p, where, "tiling configuration not found")
                    self._config = (p, where)
                    break
            else:
                if named:
                    p = self.scene.resolve(named)
                    if not p.is_file():
                        raise LoomError(self.scene.path, "render.tiling", f"tiling configuration not found: {p}")
                    self._config = (p, "render.tiling")
        return self._config

    def config_or_fail(self, option: str) -> Path:
        """The tiling configuration, or the one-line refusal: what ``option`` needs and what to pass."""
        from .renderers import CLI_INPUTS

        p, _ = self.config()
        if p is None:
            inp = next(i for i in self.src.inputs if i.option == option)
            how = f"--{option} PATH.zarr" if option in CLI_INPUTS else f"--set {option}=PATH.zarr"
            raise LoomError(self.scene.path, "render.tiling",
                            f"{self.via()} needs {inp.what}, which render builds from a tiling configuration, and "
                            f"the scene names none: pass {how}, or name one (render.tiling = \"CONFIG.toml\" in the "
                            "scene, or --set tiling=CONFIG.toml)")
        return p

    def via(self) -> str:
        return f"{self.m.name} --source {self.src.name}" if len(self.m.sources) > 1 else self.m.name

    # -- what the render lacks -----------------------------------------------------------------------
    def plan(self) -> dict[str, Node]:
        """{option: node} for every input of the source that no option gave (module doc)."""
        from .renderers import CLI_INPUTS

        cfg, _ = self.config()
        fib = self.options.get("fibers")
        if isinstance(fib, str) and fib.lower().endswith(".toml"):
            self.options["fibers"] = None   # a configuration, not an artifact: its tiling is built below
        missing = [inp for inp in self.src.inputs if not self.options.get(inp.option)]
        extra = self.options.get("extra") or {}
        if missing and self.m.name == "btf" and self.src.name == "mesh" and not extra.get("mesh"):
            raise LoomError(None, "--set mesh", "btf --source mesh needs a mesh with texture coordinates, which "
                                                "render does not build: pass --set mesh=MESH.obj (or --source tiling)")
        out = {}
        for inp in missing:
            how = f"--{inp.option} PATH.zarr" if inp.option in CLI_INPUTS else f"--set {inp.option}=PATH.zarr"
            if inp.option == "tables":
                out["tables"] = self.tables()
            elif inp.option == "yarns":
                out["yarns"] = self.yarns()
            elif inp.option == "fibers":
                if "fibers" not in inp.kinds or (cfg is not None and self.m.module == "fiberpath"):
                    out["fibers"] = self.tiling(self.config_or_fail("fibers"))
                else:
                    out["fibers"] = self.fibers()
            elif inp.option in ("svf", "iirtf", "btf"):
                out[inp.option] = getattr(self, inp.option)()
            else:
                raise LoomError(None, f"--{inp.option}" if inp.option in CLI_INPUTS else f"--set {inp.option}",
                                f"{self.via()} needs {inp.what}, which render does not build: pass {how}")
        return out


# ------------------------------------------------------------------------------------------------ sizes
def _tiling_summary(tiling: Path) -> dict:
    from .artifacts import Artifact

    return Artifact(tiling, kind="tiling").summary


def svf_size(tiling: Path, p) -> str:
    s = _tiling_summary(tiling)
    S, K = int(s.get("segments", 0)), int(s.get("exemplars", 0))
    from .memory import fmt_bytes
    from .runners.precompute import svf_estimate

    return (f"precompute svf at its defaults ({p.resolution}x{p.resolution} visibility images, {p.components} PCA "
            f"components, {p.sg_count} SGs): {S:,} segments in {K} exemplar(s), {S * p.resolution ** 2 / 1e6:,.0f} M "
            f"visibility rays, peak memory at most ~{fmt_bytes(svf_estimate(S, S, p, True).total)}")


def iirtf_size(tiling: Path, p) -> str:
    s = _tiling_summary(tiling)
    S, K = int(s.get("segments", 0)), int(s.get("exemplars", 0))
    return (f"precompute iirtf at its defaults (SH order {p.order}, cells of {p.cell_factor:g} mean free path, "
            f"{p.paths:,} paths per cell, {p.light_sampling} light sampling): {S:,} segments in {K} exemplar(s); "
            "the full quality of Khungurn et al. 2017 (its bar shows the time left once the cells are counted); "
            "pass --set iirtf=IIRTF.zarr from a cheaper precompute to skip it "
            "(make demo-full's: --cell-factor 3 --paths 200 --light-sampling mis)")


def btf_size(tiling: Path, p) -> str:
    from .artifacts import Artifact
    from .runners.precompute_btf import used_exemplars

    art = Artifact(tiling, kind="tiling")
    E = len(used_exemplars(art))
    r, (vt, vp), (lt, lp) = p.resolution, p.views, p.lights
    n = E * r * r * vt * vp * lt * lp * p.spp
    return (f"precompute btf at its defaults ({E} exemplar(s) of {int(art.summary.get('exemplars', 0))}: those its "
            f"block map uses, {r}x{r} texels, "
            f"{vt}x{vp} views x {lt}x{lp} lights, {p.spp} rays): {n / 1e6:,.0f} M radiance samples")


# ------------------------------------------------------------------------------------------------ building
def intact(path: Path, kind: str) -> bool:
    """A complete artifact of ``kind`` at ``path`` whose metadata and content hash check out."""
    from .artifacts import Artifact

    if not (path / "zarr.json").is_file():
        return False
    try:
        Artifact(path, kind=kind)
    except LoomError:
        return False
    return True


def ensure(node: Node, say: Callable[[str], None]) -> None:
    """Reuse ``node``'s artifact or build it (and, first, what it needs), one line each."""
    import fcntl

    from . import compilation
    from .progress import status

    if node.done:
        return
    if intact(node.path, node.kind):
        say(f"reused {node.kind} {node.path}")
        node.done = True
        return
    node.path.parent.mkdir(parents=True, exist_ok=True)
    with open(node.path.parent / f".{node.path.name}.lock", "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            with status(f"waiting for another loomlight building {node.kind} {node.path}"):
                fcntl.flock(lock, fcntl.LOCK_EX)
        if intact(node.path, node.kind):   # built by the render that held the lock
            say(f"reused {node.kind} {node.path}")
            node.done = True
            return
        for dep in node.needs:
            ensure(dep, say)
        if node.before is not None:
            say(node.before())
        t0 = time.perf_counter()
        with status(f"building {node.kind} -> {node.path}"), compilation.group(node.kind):
            node.build()
        say(f"built {node.kind} ({time.perf_counter() - t0:.1f} s) \u2192 {node.path}")
    node.done = True


def build_missing(scene, m, src, options: dict, out: Path, cache_dir=None, budget=None, scheduler=None,
                  say: Callable[[str], None] = print) -> dict[str, Path]:
    """Fill ``options`` with the cached or built artifacts of every input of ``src`` no option gave;
    returns {option: path} of those."""
    from .outputs import DIRECTORY, check_output

    root = cache_root(out, cache_dir)
    planner = Planner(scene, m, src, options, root, budget, scheduler)
    plan = planner.plan()
    if not plan:
        return {}
    check_output(root, "--cache-dir" if cache_dir else "-o", DIRECTORY)
    from . import compilation

    compilation.watch()
    extra = options.setdefault("extra", {})
    for option, node in plan.items():
        ensure(node, say)
        options[option] = str(node.path)
        if option in extra or option not in ("fibers", "tables", "grid"):
            extra[option] = str(node.path)
        if option == "fibers" and "tiling" in extra:
            extra["tiling"] = str(node.path)
    return {o: n.path for o, n in plan.items()}
