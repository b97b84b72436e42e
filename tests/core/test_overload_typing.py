"""Always-inlined overloads typed without a standalone compilation (``stages.core.overload_typing``): the same
machine code, less compiling.

What is compared with what:
- a loomlight kernel whose walk calls an always-inlined overload (``stages.core.geometry.bvh.intersect``: the wide
  walk's ``leaf_test`` for ``PackedLeaves``), compiled on empty numba caches in two processes, one with the patch
  and one without (``LOOMLIGHT_NUMBA_OVERLOAD_TYPING=0``): their LLVM IR equal once the per-process names are
  normalised (as in ``tests/core/test_inline_copy.py``, and the basic blocks, named after numba's process-wide IR
  label counter, numbered in order of appearance), their hits equal to the bit; and the overload's
  implementation compiled as a function of its own only without the patch (its dispatcher's signatures: none with
  it, one without) -- the compilation the patch saves, and nothing else;
- the condition the patch relies on: no loomlight source calls ``numba.literally`` (the one reason numba compiles
  the implementation before typing it);
- installation: patched once numba loads its inliner, whichever of ``stages`` and ``numba`` is imported first;
  ``LOOMLIGHT_NUMBA_OVERLOAD_TYPING=0`` leaves numba alone.
"""
import json
import os
import re
import subprocess
import sys

from tests.helpers import ROOT

PROBE = r'''
import json, re
import numpy as np
import stages  # noqa: F401  (before numba)
from numba.core.registry import cpu_target
from stages.core.geometry.bvh import build_fiber_bvh, intersect
from stages.core.geometry.wide_walk import leaf_test
from stages.core.overload_typing import installed

rng = np.random.default_rng(3)
points = np.cumsum(rng.normal(0.0, 0.2, (60, 3)), axis=0)
bvh, _ = build_fiber_bvh(points, np.array([0, 20, 40, 60]), np.full(60, 0.05))
hits = []
for k in range(40):
    o = points[k] + np.array([0.0, 0.0, 2.0])
    t, s = intersect(bvh, o[0], o[1], o[2], 0.01 * k, 0.0, -1.0, 1e-9, np.inf, -1, -1, 0)
    hits += [float(t).hex(), int(s)]

text = "".join(cres.library.get_llvm_str() for cres in intersect.overloads.values())
text = re.sub(r"@\.bytes\.-?\d+", "@.bytes.H", text)                   # Python's hash of a string constant
text = re.sub(r"B\d+v\d+B", "BvB", re.sub(r"0x[0-9a-f]+", "ADDR", text))  # addresses, unique-id counters
# basic blocks are named after numba's IR labels, drawn from a process-wide counter that the skipped compilation
# no longer advances: numbered in order of appearance
labels = {}
text = re.sub(r"(?<![\w.$])B(\d+)\b", lambda m: "B%d" % labels.setdefault(m.group(1), len(labels)), text)
leaf = cpu_target.typing_context.resolve_value_type(leaf_test)
impls = [disp for template in leaf.templates for disp, _ in template._impl_cache.values() if disp is not None
         and disp.py_func.__module__ == "stages.core.geometry.bvh"]
print(json.dumps({"installed": installed(), "hits": hits, "llvm": text,
                  "standalone": [len(d.signatures) for d in impls]}))
'''


def _probe(tmp_path, enabled):
    (tmp_path / "probe.py").write_text(PROBE)
    env = {**os.environ, "LOOMLIGHT_NUMBA_CACHE_ROOT": str(tmp_path / f"cache-{enabled}"),
           "LOOMLIGHT_NUMBA_OVERLOAD_TYPING": "1" if enabled else "0", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, str(tmp_path / "probe.py")], cwd=ROOT, env=env, capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_same_machine_code_without_the_standalone_compilation(tmp_path):
    on = _probe(tmp_path, True)
    off = _probe(tmp_path, False)
    assert on["installed"] and not off["installed"]
    assert on["hits"] == off["hits"] and any(s >= 0 for s in on["hits"][1::2])
    assert len(on["llvm"]) > 1000 and on["llvm"] == off["llvm"]
    assert on["standalone"] == [0] and off["standalone"] == [1]


def test_no_loomlight_source_calls_literally():
    uses = [f"{p.relative_to(ROOT)}:{i}" for folder in ("stages", "pipeline") for p in (ROOT / folder).rglob("*.py")
            for i, line in enumerate(p.read_text().splitlines(), 1) if re.search(r"\bliterally\s*\(", line)]
    assert uses == [], f"numba.literally in an overload needs numba's standalone compilation: {uses}"


def test_installed_when_numba_loads_whichever_comes_first():
    code = ("import sys; import {first}; import {second}; "
            "from stages.core.overload_typing import installed; print(installed())")
    for first, second in (("stages", "numba"), ("numba", "stages")):
        for flag, expected in (("1", "True"), ("0", "False")):
            env = {**os.environ, "LOOMLIGHT_NUMBA_OVERLOAD_TYPING": flag, "PYTHONPATH": str(ROOT)}
            done = subprocess.run([sys.executable, "-c", code.format(first=first, second=second)], cwd=ROOT,
                                  env=env, capture_output=True, text=True)
            assert done.returncode == 0 and done.stdout.strip() == expected, (first, flag, done.stderr[-2000:])
