"""Sub-array views that cost no reference counting, for views made once per ray in parallel kernels.

A Numba slice (`a[i:j]`) references its parent: an atomic increment and decrement of one shared counter
whose cache line bounces between threads when made per ray (docs/choices.md#unowned-array-views).
`rows` builds the same C-contiguous view from the data pointer with no owner: valid only while the
caller holds the parent, as every caller here does. `unowned` views a whole array so; kernels convert
the arrays they hand to per-ray inlined code once per block of rays.
"""
import numpy as np
from numba import carray, njit, types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def _row_pointer(typingctx, array_type, row_type):
    """Pointer to the first element of row `row` of a C-contiguous array: the row times the product of
    the other extents, multiplied out at code generation (no loop for Numba to compile at each inlined
    call, and no integer division at run time: docs/choices.md#row-views-without-a-division)."""
    if not isinstance(array_type, types.Array) or array_type.layout != "C" or not isinstance(row_type, types.Integer):
        return None  # a typing error: a view of a non-C-contiguous array would read the wrong memory
    sig = types.CPointer(array_type.dtype)(array_type, row_type)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        index = context.cast(builder, args[1], signature.args[1], types.intp)
        for extent in cgutils.unpack_tuple(builder, ary.shape, signature.args[0].ndim)[1:]:
            index = builder.mul(index, extent)
        return builder.gep(ary.data, [index])

    return sig, codegen


@njit(cache=True, inline="always")
def rows(array, start, stop):
    """array[start:stop] (along the first axis of a C-contiguous array) as an unowned view."""
    return carray(_row_pointer(array, start), (stop - start,) + array.shape[1:])


@njit(cache=True, inline="always")
def unowned(array):
    """The whole of a C-contiguous array as an unowned view (see rows)."""
    return rows(array, 0, array.shape[0])


@njit(cache=True, inline="always")
def at(i):
    """Index i (never negative where used) as Numba reads it without wraparound. A signed index gets
    'if i < 0: i += length' at each access, which in the node step lands on the chain of dependent
    loads (node -> axis -> ray component -> split test -> next node)
    (docs/choices.md#unsigned-indices-in-the-traversal)."""
    return np.uint64(i)


@njit(cache=True, inline="always")
def keep_alive(owners):
    """Nothing, but a use of `owners` (an array or a tuple of them): Numba frees an array after its last
    use in a function, and an unowned view does not keep its owner alive, so a kernel that works through
    views of arrays it allocated names their owners once more after its loop."""
