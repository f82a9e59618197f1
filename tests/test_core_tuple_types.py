"""The named tuples' faster argument typing (core/jit/tuple_types.py) against Numba's own typeof of a
tuple, field by field: arrays of every layout, dtype, dimension and write flag, scalars and None."""
from typing import NamedTuple

import numpy as np
import pytest
from numba.core.errors import NumbaValueError
from numba.core.typing.typeof import Purpose, _typeof_tuple, _TypeofContext, typeof

from core.jit.tuple_types import typed_by_fields
from core.render.render_kernels import PixelFrames, SampleBatch
from core.scene.two_level import SceneArrays
from core.trace.packet_traversal import PacketRays


@typed_by_fields
class Fields(NamedTuple):
    a: object
    b: object
    c: object


class Subclassed(np.ndarray):
    pass


def _arrays():
    """Arrays whose Numba types all differ: layouts C, F and A, dtypes, dimensions, read-only, a subclass."""
    c = np.zeros((4, 3))
    read_only = np.zeros(5, np.int32)
    read_only.setflags(write=False)
    return [c, np.asfortranarray(c), c[:, ::2], c[::2], np.zeros(5, np.float32), np.zeros((2, 2, 2), np.uint8),
            read_only, np.zeros(5, np.int32), np.zeros(0), np.zeros((5, 1)), np.zeros(4).view(Subclassed)]


def _numbas_own(value):
    return _typeof_tuple(value, _TypeofContext(Purpose.argument))


@pytest.mark.parametrize("k", range(len(_arrays())))
def test_every_array_field_is_typed_as_numba_types_it(k):
    arrays = _arrays()
    for other in (arrays[0], arrays[-1], arrays[k]):
        value = Fields(arrays[k], other, arrays[(k + 1) % len(arrays)])
        assert typeof(value, Purpose.argument) == _numbas_own(value)


def test_an_array_numba_cannot_type_fails_as_in_numba():
    value = Fields(np.zeros(3, ">f8"), np.zeros(3), None)  # big-endian: no Numba type
    with pytest.raises(NumbaValueError, match="Unsupported array dtype"):
        _numbas_own(value)
    with pytest.raises(NumbaValueError, match="Unsupported array dtype"):
        typeof(value, Purpose.argument)


def test_scalars_none_and_nested_tuples_are_typed_as_numba_types_them():
    for value in (Fields(1, 2.5, None), Fields(True, (np.zeros(2), 3), np.int32(4)), Fields(2 ** 63, -1, 1j)):
        assert typeof(value, Purpose.argument) == _numbas_own(value)


def test_the_cache_tells_apart_what_numba_tells_apart():
    """Typed first as one array, then as one that differs only in its write flag, contiguity or dtype:
    each gets its own type, as from Numba."""
    a = np.zeros((3, 4))
    first = typeof(Fields(a, a, a), Purpose.argument)
    frozen = a.copy()
    frozen.setflags(write=False)
    for changed in (frozen, a[:, :2], a.T, a.astype(np.float32)):
        value = Fields(changed, a, a)
        assert typeof(value, Purpose.argument) == _numbas_own(value) != first


def test_the_kernels_named_tuples_are_registered():
    """The named tuples a frame passes to kernels take the faster typeof, with Numba's result."""
    n = 6
    frames = PixelFrames(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.arange(n))
    batch = SampleBatch(0, 4, 1, 1.0, 0.2, 0, 7, np.zeros((4, 2), np.uint8))
    rays = PacketRays(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n), np.full(n, np.inf), np.arange(8))
    for value in (frames, batch, rays):
        assert typeof(value, Purpose.argument) == _numbas_own(value)
    from numba.extending import typeof_impl
    assert all(typeof_impl.dispatch(cls) is typeof_impl.dispatch(Fields)
               for cls in (SceneArrays, PixelFrames, SampleBatch, PacketRays))
