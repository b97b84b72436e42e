"""Faster ``inline="always"``: numba's inliner copies each inlined function's IR with one scope copy, not one a block.

What it fixes. loomlight's kernels inline their helpers (``@njit(inline="always")`` and
``@overload(..., inline="always")``: the tile loop, the integrators, the BTF texel reads), and numba copies the
callee's IR at every call site it inlines (``numba.core.inline_closurecall.InlineWorker.inline_ir``, numba
0.60-0.68): block by block, each block with a ``copy.deepcopy`` of its own. A block's variables point to the
function's scope, which holds every variable of the function, so each block's copy copies the whole scope again:
the cost is (blocks x variables) per call site, twice (the worker keeps a second, unmutated copy), and an inlined
function that itself inlines others has many of both. Profiled on the btf render's first compilation, the copies
took 30 % of it (numba/numba#8989, NVIDIA/numba-cuda#689 describe the same costs).

What it changes. Inside ``InlineWorker.inline_ir`` only: (1) a block is deep-copied with the copy of its scope made
once for all the blocks of that IR that share the scope (the block's copy starts from that scope copy's memo, so
its variables are the scope copy's variables). The IR the inliner receives is then shaped as numba's own front end
shapes a function (one scope object shared by its blocks) instead of one equal scope per block; numba reads a
function's scope once for all its blocks (``_get_all_scopes`` merges equal scopes), so the inlined code, its types
and the machine code are the same. (2) The second copy, of the first one, which ``inline_ir`` returns as the
callee's unmutated original and which every numba caller discards (``_, _, _, new_blocks = ...``), shares the
first copy's blocks instead. Nothing else in numba is touched: ``inline_closurecall``'s ``copy`` becomes a proxy
that hands everything but those block copies to the ``copy`` module, and no other module sees it.

Measured (2 cores, numba 0.68.1): the btf render's first compilation (``tests/render/test_btf_render.py``'s
first test on an empty cache) 59.4 -> 46.7 s wall (52 s with (1) alone); the LLVM IR of the 385 kernels that four
render tests compile (btf, fiberpath, volpath, bysdf) the same with and without, but for per-process names;
``make test`` from a clean clone in CHANGES.md.

``install(module)`` patches ``numba.core.inline_closurecall`` (called by ``stages/__init__.py`` when numba imports
it, before any kernel compiles); ``LOOMLIGHT_NUMBA_INLINE_COPY=0`` leaves numba as it is (to compare, or should a
numba release change the inliner: ``install`` also checks the shape it patches and leaves numba alone otherwise).
"""
from __future__ import annotations

import copy
import functools
import os
import threading

DISABLE_ENV = "LOOMLIGHT_NUMBA_INLINE_COPY"

_state = threading.local()       # the copy session of the inline_ir call running on this thread (None: none)


class _Session:
    """The scope copies of one ``inline_ir`` call: id(scope) -> (scope, memo of its deep copy); ``made``: the ids of
    the scope copies themselves (alive in their memos while the session lives)."""
    __slots__ = ("scopes", "copied", "made")

    def __init__(self):
        self.scopes: dict[int, tuple] = {}
        self.copied: set[int] = set()
        self.made: set[int] = set()

    def block_copy(self, block):
        scope = block.scope
        if id(scope) in self.made:
            # a block of this session's own copy: the inliner's second copy, the "unmutated original" it returns
            # and every numba caller discards (``_, _, _, new_blocks = ...inline_ir(...)``): not copied again
            return block
        entry = self.scopes.get(id(scope))
        if entry is None or entry[0] is not scope or id(block) in self.copied:
            memo: dict = {}
            self.made.add(id(copy.deepcopy(scope, memo)))   # the scope, its variable map and variables, once
            memo.pop(id(memo), None)                        # deepcopy's keep-alive list is per memo
            entry = (scope, memo)
            self.scopes[id(scope)] = entry
            self.copied = set()        # a block copied twice: a new copy of everything from here on
        self.copied.add(id(block))
        return copy.deepcopy(block, dict(entry[1]))


class _CopyModule:
    """What ``inline_closurecall`` sees as ``copy``: ``deepcopy`` of an IR block inside ``inline_ir`` goes through
    the running session, everything else to the ``copy`` module."""

    def __init__(self, block_type):
        self._block_type = block_type

    def __getattr__(self, name):
        return getattr(copy, name)

    def deepcopy(self, x, memo=None):
        session = getattr(_state, "session", None)
        if session is None or memo is not None or type(x) is not self._block_type:
            return copy.deepcopy(x, memo)
        return session.block_copy(x)


def _in_session(inline_ir):
    @functools.wraps(inline_ir)
    def wrapper(*args, **kwargs):
        outer = getattr(_state, "session", None)
        _state.session = _Session()
        try:
            return inline_ir(*args, **kwargs)
        finally:
            _state.session = outer
    wrapper.loomlight_inline_copy = True
    return wrapper


def install(module) -> bool:
    """Patch ``module`` (``numba.core.inline_closurecall``); True when patched (now or before)."""
    if os.environ.get(DISABLE_ENV, "1").strip() == "0":
        return False
    from numba.core import ir

    worker = getattr(module, "InlineWorker", None)
    inline_ir = getattr(worker, "inline_ir", None)
    if inline_ir is None:
        return False
    if getattr(inline_ir, "loomlight_inline_copy", False):
        return True
    if module.__dict__.get("copy") is not copy:      # not the inliner this was written for
        return False
    worker.inline_ir = _in_session(inline_ir)
    module.copy = _CopyModule(ir.Block)
    return True


def installed() -> bool:
    """Whether numba's inliner copies through this module (imports numba)."""
    from numba.core import inline_closurecall

    return bool(getattr(inline_closurecall.InlineWorker.inline_ir, "loomlight_inline_copy", False))
