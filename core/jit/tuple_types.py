"""Faster argument typing for the named tuples of arrays that kernels take.

Numba's dispatcher types plain arrays and plain tuples in C, but a named tuple in Python, array by array
(numba.core.typing.typeof, about 5 µs an array), and a frame's passes take named tuples of 4 to 23
arrays (docs/choices.md#argument-typing-at-each-kernel-call). `typed_by_fields(cls)` registers a typeof
for a named tuple class that gives Numba's own result faster: a field that is exactly an ndarray takes
its type from a cache keyed by everything Numba's array type is made from (dtype, dimensions, C and F
contiguity, the write flag: typeof._typeof_ndarray, numpy_support.map_layout), a miss asking Numba;
any other field is typed by Numba as before.
"""
import numpy as np
from numba.core import types
from numba.extending import typeof_impl

_array_types = {}  # (dtype, ndim, C-contiguous, F-contiguous, writeable) -> Numba's type of such an array
_tuple_types = {}  # (class, its fields' types) -> Numba's named tuple type


def typed_by_fields(cls):
    """Register the faster typeof for the named tuple class `cls`; returns `cls` (a class decorator)."""
    typeof_impl.register(cls)(_typeof_fields)
    return cls


def _typeof_fields(val, c):
    """numba.core.typing.typeof._typeof_tuple's result, with arrays typed through the cache."""
    tys = [_array_type(v, c) if type(v) is np.ndarray else typeof_impl(v, c) for v in val]
    if any(ty is None for ty in tys):
        return None
    key = (type(val), *tys)
    ty = _tuple_types.get(key)
    if ty is None:
        ty = _tuple_types[key] = types.BaseTuple.from_types(tys, type(val))
    return ty


def _array_type(array, c):
    flags = array.flags
    key = (array.dtype, array.ndim, flags.c_contiguous, flags.f_contiguous, flags.writeable)
    ty = _array_types.get(key)
    if ty is None:
        ty = _array_types[key] = typeof_impl(array, c)
    return ty
