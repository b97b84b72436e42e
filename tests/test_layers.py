"""The house rules, checked on the source (reference: docs/architecture.md "Floors").

Three floors: ``pipeline/`` -> ``stages/<stage>/`` -> ``stages/core/``. A stage package never imports
another stage package nor ``pipeline``; ``stages/core`` imports no stage package; no module imports
a private name (``_x``) from another module.
"""
import ast
from pathlib import Path

from tests.helpers import ROOT

STAGES = ROOT / "stages"


def _imports(path: Path):
    """(module, names) of every import in a file, relative imports made absolute."""
    tree = ast.parse(path.read_text())
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    package = parts[:-1] if parts[-1] != "__init__" else parts[:-1]
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


def _sources(top):
    return sorted(p for p in (ROOT / top).rglob("*.py") if "__pycache__" not in p.parts)


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
