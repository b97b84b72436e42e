"""Compile-time dispatch on the class of a namedtuple argument.

loomlight's generic kernels -- ``medium_lookup`` (a density source), ``surface_hit`` /
``surface_occluded`` (explicit-fibre geometry), ``radiance`` (an integrator) -- are Python stubs that
each implementation answers through ``numba.extending.overload`` for its own namedtuple class. numba
then compiles one specialisation of a caller per class, and the callers stay cacheable (numba does
not cache a function that takes another compiled function as an argument).

    def medium_lookup(med, x, y, z):                # the stub
        raise TypeError("only callable from numba-compiled code")

    @overload(medium_lookup)
    def _grid(med, x, y, z):
        if is_tuple_class(med, GridMedium):
            return lambda med, x, y, z: grid_lookup(med, x, y, z)

``runtime_value(x)`` keeps constants from multiplying specialisations: it types a constant as a plain
value, so a callee is not compiled once more for it.
"""
from numba import types
from numba.extending import intrinsic


def is_tuple_class(numba_type, cls) -> bool:
    """True when ``numba_type`` (an overload's argument type) is the namedtuple class ``cls``."""
    return isinstance(numba_type, types.BaseNamedTuple) and numba_type.instance_class is cls


@intrinsic
def runtime_value(typingctx, x):
    """``x`` typed as its non-literal type. numba compiles a callee once more for every literal argument
    (``Literal[int](2)``, ``Literal[bool](True)``); a constant passed on through this (volpath's
    ``track(..., runtime_value(dim), ...)``) reaches the callee as a plain value, one specialisation for all."""
    ty = types.unliteral(x)

    def codegen(context, builder, sig, args):
        return context.cast(builder, args[0], sig.args[0], sig.return_type)

    return ty(x), codegen
