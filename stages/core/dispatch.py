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
"""
from numba import types
from numba.extending import intrinsic


def is_tuple_class(numba_type, cls) -> bool:
    """True when ``numba_type`` (an overload's argument type) is the namedtuple class ``cls``."""
    return isinstance(numba_type, types.BaseNamedTuple) and numba_type.instance_class is cls



@intrinsic
def runtime_value(typingctx, x):
    """``x`` typed as its non-literal type: a constant passed on through this (``track(..., runtime_value(True))``)
    does not make numba compile the callee once more for that constant (it specialises a compiled callee
    on every literal argument: ``Literal[bool](True)``, ``Literal[int](2)``)."""
    ty = types.unliteral(x)

    def codegen(context, builder, sig, args):
        return context.cast(builder, args[0], sig.args[0], sig.return_type)

    return ty(x), codegen
