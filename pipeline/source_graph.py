"""loomlight's own import graph, read from the source (never by importing it).

Three users: the house rules (``tests/test_layers.py``: floors, no import circles), the equal-error
comparison's code version (``runners.convergence.render_code_version``), which keys a method's pictures
by the files that method's renderer can reach, so work on one method does not make another method's
converged reference stale, and ``code_version``, the same kind of key for a stage's step (``precompute
btf``'s acquisition, which a refit or a new table reuses).

``import_graph(root, tops)``: module -> the project modules its file imports, at its top or inside a
function (a lazy import still ties the two modules together). ``from pkg import name`` counts
``pkg.name`` when that is a module; a script in ``bench/`` or ``scripts/`` imports its neighbours by
their bare names (``import embree_kernels``). ``import_closure``: every module one module can reach,
the packages above each module included (importing ``a.b.c`` runs ``a/__init__`` and ``a/b/__init__``).
"""
from __future__ import annotations

import ast
from pathlib import Path

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
