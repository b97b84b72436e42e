"""loomlight's own import graph, read from the source (never by importing it).

Three users: the house rules (``tests/test_layers.py``: floors, no import circles); the code version of a
method's pictures (``render_code_version``: the files that method's renderer can reach, with the presets and
colour curves), which keys the equal-error comparison's references and renders and the sweeps' renders, so
work on one method does not make another method's converged reference stale and a sweep renders again after
a change to its renderer; and ``code_version``, the same kind of key for a stage's step (``precompute btf``'s
acquisition, which a refit or a new table reuses).

``import_graph(root, tops)``: module -> the project modules its file imports, at its top or inside a
function (a lazy import still ties the two modules together). ``from pkg import name`` counts
``pkg.name`` when that is a module; a script in ``bench/`` or ``scripts/`` imports its neighbours by
their bare names (``import embree_kernels``). ``import_closure``: every module one module can reach,
the packages above each module included (importing ``a.b.c`` runs ``a/__init__`` and ``a/b/__init__``).
"""
from __future__ import annotations

import ast
import functools
import hashlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT_TOPS = ("bench", "scripts")     # folders whose files import their neighbours by bare name


def file_imports(root: Path, path: Path):
    """(module, names) of every import in a file, relative imports made absolute."""
    tree = ast.parse(path.read_text())
    package = list(path.relative_to(root).with_suffix("").parts)[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, []
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            yield mod, [a.name for a in node.names]


def sources(root: Path, top: str) -> list[Path]:
    return sorted(p for p in (root / top).rglob("*.py") if "__pycache__" not in p.parts)


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_files(root: Path, tops) -> dict[str, Path]:
    return {module_name(root, p): p for top in tops for p in sources(root, top)}


def import_graph(root: Path, tops=("pipeline", "stages", "bench", "scripts")) -> dict[str, list[str]]:
    modules = module_files(root, tops)
    graph = {}
    for name, path in modules.items():
        top = name.split(".")[0]
        targets = set()
        for mod, names in file_imports(root, path):
            for m in (mod, f"{top}.{mod}" if top in SCRIPT_TOPS else mod):
                targets.add(m)
                targets.update(f"{m}.{n}" for n in names)
        graph[name] = sorted(t for t in targets if t in modules and t != name)
    return graph


def import_closure(graph: dict[str, list[str]], start: str) -> set[str]:
    """``start`` and every module it reaches, with the packages above each."""
    seen, todo = set(), [start]
    while todo:
        m = todo.pop()
        if m in seen or m not in graph:
            continue
        seen.add(m)
        parts = m.split(".")
        todo.extend(".".join(parts[:i]) for i in range(1, len(parts)))
        todo.extend(graph[m])
    return seen


def code_version(root: Path, starts, data=()) -> str:
    """sha256 (16 hex digits) over the paths and bytes of the ``pipeline``/``stages`` files that the modules
    ``starts`` reach and the .py/.toml/.json files under the folders ``data``: a key that changes when what a
    computation runs changes, and only then (``precompute btf`` keys its acquisition so)."""
    import hashlib

    modules = module_files(root, ("pipeline", "stages"))
    graph = import_graph(root, ("pipeline", "stages"))
    files = sorted({modules[m] for s in starts for m in import_closure(graph, s)})
    for d in data:
        files += sorted(f for f in (root / d).rglob("*") if f.is_file() and f.suffix in (".py", ".toml", ".json"))
    h = hashlib.sha256()
    for f in files:
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


# ------------------------------------------------------------------------------------------------
# what decides a picture: the key of a method's renders
RENDER_CODE = ("stages", "pipeline/renderers", "pipeline/render_setup.py", "pipeline/fibre_cache.py",
               "pipeline/presets.py", "pipeline/bcsdf_presets.py", "pipeline/dye.py", "pipeline/thread_colors.py",
               "pipeline/scene.py", "pipeline/yarns.py", "pipeline/generators.py", "pipeline/io", "data/yarns",
               "data/bcsdf")
NOT_RENDER_CODE = ("stages/evaluate",)   # measures pictures, never makes them
CODE_SUFFIXES = (".py", ".toml", ".json")   # sources, presets, the bundled colour curves


@functools.lru_cache(maxsize=None)
def _source_graph(root: Path) -> tuple[dict, dict]:
    """The modules of ``pipeline`` and ``stages`` and their import graph, read once per process for every
    method a comparison keys."""
    return module_files(root, ("pipeline", "stages")), import_graph(root, ("pipeline", "stages"))


def render_code_files(method: str | None = None, root: Path = ROOT) -> list[Path]:
    """What decides a picture: the kernels (every stage but evaluate), the renderers' setup, the presets
    and the colour curves (``RENDER_CODE``); the evaluation and report code are not part of it. With
    ``method``, only the Python files of ``RENDER_CODE`` that method's renderer
    (``pipeline/renderers/<method>.py``) imports, directly or through others (``source_graph``), and the
    data folders: work on ``bysdf`` leaves ``fiberpath``'s converged references current. A method without
    a module there (a test's stand-in) gets every file."""
    reached = None
    if method is not None and (root / "pipeline" / "renderers" / f"{method}.py").is_file():
        modules, graph = _source_graph(root)
        reached = {modules[m] for m in import_closure(graph, f"pipeline.renderers.{method}")}
    out = []
    for rel in RENDER_CODE:
        p = root / rel
        files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix in CODE_SUFFIXES) if p.is_dir() else [p]
        out += [f for f in files if not any(f.is_relative_to(root / x) for x in NOT_RENDER_CODE)
                and (reached is None or f.suffix != ".py" or f in reached)]
    return out


@functools.lru_cache(maxsize=None)
def render_code_version(method: str | None = None) -> str:
    """sha256 (16 hex digits) of ``render_code_files(method)``, their paths and bytes. Hashed once per
    process and method: every render's stamp and the reference's key ask for it."""
    h = hashlib.sha256()
    for f in render_code_files(method):
        h.update(str(f.relative_to(ROOT)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]
