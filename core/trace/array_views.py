"""Sub-array views that cost no reference counting, for views made once per ray in parallel kernels.

A Numba slice (`a[i:j]`) holds a reference to its parent's memory: creating and dropping it is an
atomic increment and decrement of one shared counter. Made for every instance a ray visits, from two
threads at once, those atomics made rendering a flat tree wrapped as a one-instance scene 1.4x slower
(the counter's cache line bounces between cores). `rows` builds the same C-contiguous view from the
data pointer instead, with no owner: valid only while the caller holds the parent array, which every
caller here does (the scene's arrays outlive the kernel call). `unowned` views a whole array so:
a kernel converts the arrays it hands to per-ray inlined code once per block of rays, because even
reading an array out of a tuple or passing it to an inlined function can cost the same atomic pair.
"""
import numpy as np
from numba import carray, njit, types
from numba.extending import intrinsic


@intrinsic
def _element_pointer(typingctx, array_type, index_type):
    """Pointer to element `index` of a C-contiguous array's flat data."""
    if not isinstance(array_type, types.Array) or array_type.layout != "C" or not isinstance(index_type, types.Integer):
        return None  # a typing error: a view of a non-C-contiguous array would read the wrong memory
    sig = types.CPointer(array_type.dtype)(array_type, index_type)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        index = context.cast(builder, args[1], signature.args[1], types.intp)
        return builder.gep(ary.data, [index])

    return sig, codegen


@njit(cache=True, inline="always")
def rows(array, start, stop):
    """array[start:stop] (along the first axis of a C-contiguous array) as an unowned view."""
    inner = array.size // max(array.shape[0], 1)
    return carray(_element_pointer(array, start * inner), (stop - start,) + array.shape[1:])


@njit(cache=True, inline="always")
def unowned(array):
    """The whole of a C-contiguous array as an unowned view (see rows)."""
    return rows(array, 0, array.shape[0])


@njit(cache=True, inline="always")
def at(i):
    """Index i (never negative where used) as Numba reads it without wraparound. A signed index gets
    'if i < 0: i += length' at each access; in the traversal's node step that lands on the chain of
    dependent loads (node -> axis -> the ray's component -> the split test -> the next node). With it
    there, seed 000's camera and shadow rays took 0.94x as long and its render 0.905x
    (benchmarks/bench_against_revision.py, 21 pairs, identical results; docs/choices.md)."""
    return np.uint64(i)
