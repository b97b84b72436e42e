"""Arrays on the machine stack: a BVH query or a path allocates nothing on the heap.

``stack_array(n, dtype)`` (n a literal integer) is an n-element array in the stack frame of the
function that calls it (an LLVM ``alloca``), with no memory manager, so functions compiled without
numba's reference counting (``_nrt=False``: the fibre BVH queries and fiberpath's path tracer, no
atomic reference-count traffic on the scene's arrays from two threads) can make it, where
``numba.carray`` cannot be called. ``traversal_stack()`` (inline) gives (node stack int64[STACK_SIZE],
entry-distance stack float64[STACK_SIZE]); ``stack_vector3()`` a float64[3] scratch vector.
STACK_SIZE bounds a traversal's pending nodes: a binary SAH tree over 10^8 primitives is well under
128 deep, and a 4-wide query pushes at most 3 nodes per level it descends.
"""
import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

STACK_SIZE = 128


@intrinsic
def stack_array(typingctx, n, dtype):
    """A C-contiguous 1-d array of n elements of ``dtype`` in the calling function's stack frame, with
    no memory manager (n a literal integer)."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    size = n.literal_value
    aryty = types.Array(dtype.dtype, 1, "C")

    def codegen(context, builder, sig, args):
        from numba.np.arrayobj import populate_array

        ptr = cgutils.alloca_once(builder, context.get_data_type(dtype.dtype), size=size)
        ary = context.make_array(aryty)(context, builder)
        itemsize = context.get_abi_sizeof(context.get_data_type(dtype.dtype))
        intp = context.get_value_type(types.intp)
        populate_array(ary, data=ptr, shape=[intp(size)], strides=[intp(itemsize)],
                       itemsize=intp(itemsize), meminfo=None)
        return ary._getvalue()
    return aryty(n, dtype), codegen


@njit(cache=True, inline="always")
def traversal_stack():
    """(node stack, entry-distance stack) of STACK_SIZE each, on the stack of the function that inlines it."""
    return stack_array(STACK_SIZE, np.int64), stack_array(STACK_SIZE, np.float64)


@njit(cache=True, inline="always")
def stack_vector3():
    """A float64[3] scratch vector on the stack of the function that inlines it (uninitialised)."""
    return stack_array(3, np.float64)

