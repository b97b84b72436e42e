"""``stages.core.dispatch.runtime_value``: a constant passed through it reaches the callee as its value, typed
as the non-literal type, so the callee compiles once for every constant (what volpath's calls of
``track`` rely on)."""
from numba import njit, types

from stages.core.dispatch import runtime_value


@njit
def _callee(flag, n):
    return n + 1 if flag else n - 1


@njit
def _through_runtime_value():
    return _callee(runtime_value(True), runtime_value(2)) * 10 + _callee(runtime_value(False), runtime_value(5))


@njit
def _literal_callee(flag, n):
    return n + 1 if flag else n - 1


@njit
def _with_literals():
    return _literal_callee(True, 2) * 10 + _literal_callee(False, 5)


def test_runtime_value_passes_the_value_with_one_specialisation():
    assert _through_runtime_value() == 34
    assert _callee.signatures == [(types.boolean, types.int64)]
    # the contrast: literal constants make numba compile the callee once per constant
    assert _with_literals() == 34
    assert len(_literal_callee.signatures) == 2
    assert all(isinstance(a, types.Literal) for sig in _literal_callee.signatures for a in sig)
