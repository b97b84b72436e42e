"""The house rules, checked on the source (reference: docs/architecture.md "Floors").

Three floors: ``pipeline/`` -> ``stages/<stage>/`` -> ``stages/core/``. A stage package never imports
another stage package nor ``pipeline``; ``stages/core`` imports no stage package; no module imports
a private name (``_x``) from another module; the import graph has no circle.
"""
import ast
from pathlib import Path

from pipeline import source_graph
from pipeline.source_graph import file_imports, sources
from tests.helpers import ROOT

STAGES = ROOT / "stages"


def _imports(path: Path):
    return file_imports(ROOT, path)


def _sources(top):
    return sources(ROOT, top)


def _floor(module: str):
    """'pipeline', 'core' or the stage package name, for a dotted module."""
    parts = module.split(".")
    if parts[0] == "pipeline":
        return "pipeline"
    if parts[0] == "stages" and len(parts) > 1:
        return parts[1]
    return None


def test_stage_packages_import_only_core():
    bad = []
    for path in _sources("stages"):
        rel = path.relative_to(ROOT)
        own = rel.parts[1] if len(rel.parts) > 2 else None  # stages/<pkg>/...
        for mod, names in _imports(path):
            floor = _floor(mod)
            if floor == "pipeline":
                bad.append(f"{rel}: imports {mod} (stages never import pipeline)")
            elif mod == "stages" and names:
                targets = [n for n in names if (STAGES / n).is_dir()]
                for t in targets:
                    if t not in ("core", own):
                        bad.append(f"{rel}: imports stages.{t}")
            elif floor not in (None, "core", own) and mod.startswith("stages."):
                bad.append(f"{rel}: imports {mod} (another stage package)")
            if own == "core" and mod.startswith("stages.") and floor != "core":
                bad.append(f"{rel}: core imports the stage package {mod}")
    assert not bad, "\n".join(bad)


def test_no_private_names_across_files():
    bad = []
    for top in ("stages", "pipeline", "bench"):
        for path in _sources(top):
            for mod, names in _imports(path):
                if not (mod.startswith("stages") or mod.startswith("pipeline")):
                    continue
                for n in names:
                    if n.startswith("_") and not n.startswith("__"):
                        bad.append(f"{path.relative_to(ROOT)}: from {mod} import {n}")
    assert not bad, "\n".join(bad)


def test_every_package_says_what_it_holds():
    missing = [str(p.relative_to(ROOT)) for p in _sources("stages") + _sources("pipeline")
               if p.name == "__init__.py" and not ast.get_docstring(ast.parse(p.read_text()))]
    assert not missing, f"packages without a docstring: {missing}"


def test_shared_compile_groups_name_real_test_files():
    """``tests/conftest.py`` groups test files by path for xdist; a renamed file would silently leave its
    group and compile the kernel family a second time on the other worker."""
    from collections import Counter

    from tests.conftest import SHARED_COMPILE

    missing = [p for p in SHARED_COMPILE if not (ROOT / p).is_file()]
    assert not missing, f"SHARED_COMPILE names files that do not exist: {missing}"
    assert all(n >= 2 for n in Counter(SHARED_COMPILE.values()).values()), "a group of one file groups nothing"


def import_graph(tops=("pipeline", "stages", "bench", "scripts")) -> dict:
    return source_graph.import_graph(ROOT, tops)


def import_cycles(graph: dict) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def test_import_graph_is_acyclic():
    """No two modules import each other, directly or around a circle, counting imports inside functions:
    a circle means neither module can be understood, tested or moved without the other."""
    graph = import_graph()
    assert len(graph) > 100 and graph["pipeline.runners.render"], "the graph must see the project's imports"
    cycles = import_cycles(graph)
    assert not cycles, "import circles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_cycle_finder_finds_a_circle():
    """The control: a circle of three and a self-contained pair are found, a chain is not."""
    graph = {"a": ["b"], "b": ["c"], "c": ["a"], "d": ["e"], "e": ["d"], "f": ["a"], "g": []}
    assert sorted(import_cycles(graph)) == [["a", "b", "c"], ["d", "e"]]
    assert import_cycles({"a": ["b"], "b": ["c"], "c": []}) == []


MAX_KERNEL_PARAMETERS = 12
KERNEL_DECORATORS = ("njit", "jit", "chunk_kernel")


def long_signatures(files) -> list[str]:
    """'file:line name (N)' of every numba kernel (decorated ``@njit``, ``@jit`` or ``@chunk_kernel``) in
    ``files`` that takes more than MAX_KERNEL_PARAMETERS parameters without saying why: its docstring must
    say "N parameters:" with its own count N, so that the reason is looked at again when the count changes."""
    found = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.FunctionDef):
                continue
            if not any(any(k in ast.unparse(d) for k in KERNEL_DECORATORS) for d in node.decorator_list):
                continue
            n = len(node.args.posonlyargs) + len(node.args.args) + len(node.args.kwonlyargs)
            said = " ".join((ast.get_docstring(node) or "").split())   # line breaks as spaces
            if n > MAX_KERNEL_PARAMETERS and f"{n} parameters:" not in said:
                found.append(f"{path.name}:{node.lineno} {node.name} ({n})")
    return found


def test_long_kernel_signatures_say_why():
    """Issue 56 item 2: values cross calls in named records (``PeriodicPaths``, ``Ray``, ``RenderRequest``, the
    integrators' and media's namedtuples); a kernel over 12 parameters says in its docstring why it is not one."""
    assert long_signatures(_sources("stages")) == []


def test_long_signature_finder_finds_one(tmp_path):
    """The control: 13 parameters without a reason are found, with one (or 12 parameters) they are not."""
    args = ", ".join(f"a{i}" for i in range(13))
    bare = tmp_path / "bare.py"
    bare.write_text(f"@njit(cache=True)\ndef f({args}):\n    \"\"\"Sums.\"\"\"\n    return 0\n")
    said = tmp_path / "said.py"
    said.write_text(f"@chunk_kernel\ndef f({args}):\n    \"\"\"Sums. 13\n    parameters: why.\"\"\"\n    return 0\n")
    twelve = tmp_path / "twelve.py"
    twelve.write_text(f"@njit\ndef f({', '.join(f'a{i}' for i in range(12))}):\n    return 0\n")
    assert long_signatures([bare]) == ["bare.py:2 f (13)"]
    assert long_signatures([said, twelve]) == []
