"""Traversal stacks on the machine stack: a BVH query per ray allocates nothing on the heap.

``traversal_stack()`` (inline) gives (node stack int64[STACK_SIZE], entry-distance stack
float64[STACK_SIZE]) in the stack frame of the function that inlines it (an LLVM ``alloca``); the
triangle mesh queries use it. ``stack_array(n, dtype)`` (n a literal) is the same as one intrinsic: an
array with no memory manager, which functions compiled without numba's reference counting
(``_nrt=False``: the fibre BVH queries, so no atomic reference-count traffic on the scene's arrays
from two threads) can make; ``numba.carray`` cannot be called there. STACK_SIZE bounds a traversal's pending nodes: a binary
SAH tree over 10^8 primitives is well under 128 deep, and a 4-wide query pushes at most 3 nodes per
level it descends.
"""
import numba
import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

STACK_SIZE = 128


@intrinsic
def stack_buffer(typingctx, n, dtype):
    """A pointer to n elements of ``dtype`` on the calling function's stack (n a literal integer)."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    size = n.literal_value

    def codegen(context, builder, sig, args):
        return cgutils.alloca_once(builder, context.get_data_type(dtype.dtype), size=size)
    return types.CPointer(dtype.dtype)(n, dtype), codegen


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
    return (numba.carray(stack_buffer(STACK_SIZE, np.int64), STACK_SIZE),
            numba.carray(stack_buffer(STACK_SIZE, np.float64), STACK_SIZE))



@njit(cache=True, inline="always")
def stack_vector3():
    """A float64[3] scratch vector on the stack of the function that inlines it (uninitialised)."""
    return stack_array(3, np.float64)

