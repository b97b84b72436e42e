"""Cheaper ``@overload(..., inline="always")``: numba types an always-inlined overload without compiling it alone.

What it fixes. When a kernel's type inference meets a call of an ``@overload``-ed function, numba's overload
template (``numba.core.typing.templates._OverloadFunctionTemplate``, numba 0.56-0.68) wraps the implementation
the overload returns in a dispatcher and *compiles it as a function of its own* (``_build_impl``: "make sure that
the implementation can be fully compiled"; then ``generic`` asks the dispatcher's ``get_call_template``, which
would compile it there too, to let a ``numba.literally`` in it raise first, numba/numba#5887): type inference,
lowering, LLVM optimisation and machine code. For an ``inline="always"`` overload that machine code is never
called: ``generic`` runs type inference on the implementation once more, records the overload as ``always
inlined``, and the caller inlines that typed IR. In loomlight, ``btf.radiance`` (the Daubert et al. 2001 texel
model and the scene's lights, inlined into the tile loop; 3.5 s of a cold compile) and the BVH / shell leaf tests
are such overloads.

What it changes. The template's jit decorator (``_get_jit_decorator``, called by ``_build_impl`` only) makes the
dispatcher of one of loomlight's own always-inlined implementations (defined under ``stages`` or ``pipeline``)
unable to compile, so neither step compiles it, and ``generic`` types it as before (the second typing, from the
function's source). numba's own overloads and overloads that are not always inlined are left as they are. No
loomlight overload calls ``numba.literally`` (``tests/core/test_overload_typing.py`` checks it), so what is skipped
has no effect but its cost: the caller's machine code is the same (the test compares a kernel's LLVM IR with and
without; basic blocks are named after a process-wide label counter the skipped compilation no longer advances).

Measured (2 cores, numba 0.68.1): CHANGES.md. ``install()`` patches the template class (called by
``stages/__init__.py`` when numba imports its inliner, before any kernel compiles);
``LOOMLIGHT_NUMBA_OVERLOAD_TYPING=0`` leaves numba as it is (to compare, or should a numba release change the
template: ``install`` also checks the shape it patches and leaves numba alone otherwise).
"""
from __future__ import annotations

import functools
import os

DISABLE_ENV = "LOOMLIGHT_NUMBA_OVERLOAD_TYPING"
OWN_PACKAGES = ("stages", "pipeline")     # whose always-inlined overloads are typed without a compilation


def _own(py_func) -> bool:
    module = getattr(py_func, "__module__", None) or ""
    return module.split(".", 1)[0] in OWN_PACKAGES


def _jitter_without_standalone_compile(get_jit_decorator):
    @functools.wraps(get_jit_decorator)
    def wrapper(self):
        jitter = get_jit_decorator(self)
        if not self._inline.is_always_inline:
            return jitter

        def typing_only_jitter(**options):
            decorate = jitter(**options)

            def dispatcher_of(pyfunc):
                disp = decorate(pyfunc)
                if _own(pyfunc):
                    # typed by the template, inlined by the caller, never called (``disable_compile`` itself
                    # asserts that a signature was compiled before)
                    disp._can_compile = False
                return disp
            return dispatcher_of
        return typing_only_jitter
    wrapper.loomlight_overload_typing = True
    return wrapper


def install() -> bool:
    """Patch numba's overload template class; True when patched (now or before)."""
    if os.environ.get(DISABLE_ENV, "1").strip() == "0":
        return False
    import inspect

    from numba.core.dispatcher import Dispatcher
    from numba.core.typing import templates

    template = getattr(templates, "_OverloadFunctionTemplate", None)
    get_jit_decorator = getattr(template, "_get_jit_decorator", None)
    if get_jit_decorator is None:
        return False
    if getattr(get_jit_decorator, "loomlight_overload_typing", False):
        return True
    # the shape this was written for: the template makes the implementation's dispatcher with the jit decorator
    # it gets here, then types through the dispatcher's call template, which compiles where ``_can_compile`` says
    try:
        build, generic = inspect.getsource(template._build_impl), inspect.getsource(template.generic)
        call_template = inspect.getsource(Dispatcher.get_call_template)
    except (OSError, TypeError):
        return False
    if ("self._get_jit_decorator()" not in build or "get_call_template" not in generic
            or "if self._can_compile:" not in call_template):
        return False
    template._get_jit_decorator = _jitter_without_standalone_compile(get_jit_decorator)
    return True


def installed() -> bool:
    """Whether numba's overload template types loomlight's always-inlined overloads through this module (imports
    numba and its inliner, which installs it: ``stages/__init__.py``)."""
    from numba.core import inline_closurecall  # noqa: F401
    from numba.core.typing import templates

    return bool(getattr(templates._OverloadFunctionTemplate._get_jit_decorator, "loomlight_overload_typing", False))
