"""numba's inliner with one scope copy per inlined IR (``stages.core.inline_copy``): the same machine code,
faster.

What is compared with what:
- the block copies a session makes against ``copy.deepcopy`` of each block (numba's own copy): the same
  statements, variables and locations (IR equality), every block on one scope copy that is not the original,
  whose variables are the blocks' variables; a copy of those copies (the inliner's discarded second copy) is
  the first copy's blocks;
- machine code: a kernel with nested ``inline="always"`` helpers over several call sites and branches, and a
  loomlight kernel with its inlined helpers (``stages.core.btf.half_rgb``), compiled on empty numba caches in two
  processes, one with the patch and one without (``LOOMLIGHT_NUMBA_INLINE_COPY=0``): their LLVM IR equal once the
  per-process names are normalised (the hashes Python gives string constants, object addresses, numba's
  unique-id counters in mangled names), and their
  results equal to the bit (measured over the 385 kernels that four render tests compile, btf, fiberpath,
  volpath and bysdf: the same; CHANGES.md, 2026-12-06 late night);
- installation: ``import stages`` does not import numba; numba's inliner is patched once numba loads it,
  whichever of the two is imported first; ``LOOMLIGHT_NUMBA_INLINE_COPY=0`` leaves it alone.
"""
import copy
import json
import os
import re
import subprocess
import sys
import textwrap

from tests.helpers import ROOT

KERNELS = '''
import numpy as np
from numba import njit


@njit(inline="always")
def leaf(x, k):
    if k % 3 == 0:
        return x * 1.5 - k
    s = 0.0
    for i in range(k):
        s += x / (i + 1.0)
    return s


@njit(inline="always")
def middle(x, y):
    a = leaf(x, 3) + leaf(y, 4)
    if a > 1.0:
        return a - leaf(x * y, 5)
    return a + leaf(x - y, 6)


@njit
def outer(xs):
    t = 0.0
    for i in range(xs.shape[0]):
        t += middle(xs[i], t) if i % 2 else middle(t, xs[i])
    return t
'''

PROBE = '''
import json, re, sys
import numpy as np
import stages  # noqa: F401  (before numba)
sys.path.insert(0, sys.argv[1])
import probe_kernels
from stages.core.btf import half_cell_geometry, half_rgb
from stages.core.inline_copy import installed

xs = np.linspace(-2.0, 3.0, 37)
rad = np.random.default_rng(0).random((2, 32, 225, 3)).astype(np.float32)
valid = half_cell_geometry(4, 8, 15, 15, True).valid
res = [probe_kernels.outer(xs), *half_rgb(rad, valid, 1, 15, 15, 0.3, 0.2, 0.9, 4, 8, 0.1, -0.2, 0.95)]


def llvm(dispatcher):
    text = "".join(cres.library.get_llvm_str() for cres in dispatcher.overloads.values())
    text = re.sub(r"@\\.bytes\\.-?\\d+", "@.bytes.H", text)      # Python's hash of a string constant
    return re.sub(r"B\\d+v\\d+B", "BvB", re.sub(r"0x[0-9a-f]+", "ADDR", text))   # addresses, unique-id counters


print(json.dumps({"installed": installed(), "results": [float(r).hex() for r in res],
                  "llvm": [llvm(probe_kernels.outer), llvm(half_rgb)]}))
'''


def _probe(tmp_path, enabled):
    (tmp_path / "probe_kernels.py").write_text(textwrap.dedent(KERNELS))
    (tmp_path / "probe.py").write_text(textwrap.dedent(PROBE))
    env = {**os.environ, "LOOMLIGHT_NUMBA_CACHE_ROOT": str(tmp_path / f"cache-{enabled}"),
           "LOOMLIGHT_NUMBA_INLINE_COPY": "1" if enabled else "0", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, str(tmp_path / "probe.py"), str(tmp_path)], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_same_machine_code_and_results_with_and_without(tmp_path):
    on = _probe(tmp_path, True)
    off = _probe(tmp_path, False)
    assert on["installed"] and not off["installed"]
    assert on["results"] == off["results"]
    for a, b in zip(on["llvm"], off["llvm"]):
        assert len(a) > 1000 and a == b


def test_block_copies_share_one_scope_and_equal_numbas_copies():
    from numba.core.compiler import run_frontend

    from stages.core.inline_copy import _Session

    def f(a, n):
        s = 0.0
        for i in range(n):
            if a[i] > 0.5:
                s += a[i]
            else:
                s -= 1.0
        while s > 10.0:
            s *= 0.5
        return s

    fir = run_frontend(f)
    blocks = list(fir.blocks.values())
    assert len(blocks) >= 5 and all(b.scope is blocks[0].scope for b in blocks)
    session = _Session()
    copies = [session.block_copy(b) for b in blocks]
    plain = [copy.deepcopy(b) for b in blocks]
    scope = copies[0].scope
    assert scope is not blocks[0].scope and all(c.scope is scope for c in copies)
    assert len({id(p.scope) for p in plain}) == len(plain)       # numba's own: a scope per block
    for c, p, b in zip(copies, plain, blocks):
        assert c == p and c is not b
        assert [str(s) for s in c.body] == [str(s) for s in b.body]
        for v in (v for stmt in c.body for v in stmt.list_vars()):
            assert v.scope is scope and scope.get(v.name).name == v.name   # variables of the shared scope
    assert all(session.block_copy(c) is c for c in copies)        # the inliner's second copy: the first's blocks
    again = session.block_copy(blocks[0])                          # copied twice: a fresh scope copy
    assert again.scope is not scope and again == plain[0]


def test_installed_when_numba_loads_whichever_comes_first():
    code = ("import sys; import {first}; import {second}; assert 'numba' in sys.modules; "
            "from stages.core.inline_copy import installed; print(installed())")
    for first, second in (("stages", "numba"), ("numba", "stages")):
        for flag, expected in (("1", "True"), ("0", "False")):
            env = {**os.environ, "LOOMLIGHT_NUMBA_INLINE_COPY": flag, "PYTHONPATH": str(ROOT)}
            done = subprocess.run([sys.executable, "-c", code.format(first=first, second=second)], cwd=ROOT,
                                  env=env, capture_output=True, text=True)
            assert done.returncode == 0 and done.stdout.strip() == expected, (first, flag, done.stderr[-2000:])
    done = subprocess.run([sys.executable, "-c", "import sys, stages; print('numba' in sys.modules)"], cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True)
    assert done.stdout.strip() == "False", done.stderr


def test_numba_inliner_still_has_the_shape_patched():
    """The patch replaces what ``inline_closurecall`` calls ``copy`` and wraps ``InlineWorker.inline_ir``: a numba
    release that renames either leaves numba alone (``install`` returns False) -- this says so here first."""
    import inspect

    from numba.core import inline_closurecall

    from stages.core.inline_copy import installed

    assert installed()
    src = inspect.getsource(inline_closurecall.InlineWorker.inline_ir.__wrapped__)
    assert re.search(r"copy\.deepcopy\(the_ir\.blocks\[block_label\]\)", src)
