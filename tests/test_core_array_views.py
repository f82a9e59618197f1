"""core/trace/array_views.py: unowned row views equal NumPy's slices, for every dimension count."""
import numpy as np
import pytest
from numba import njit

from core.trace.array_views import rows, unowned


@njit
def _rows_copy(array, start, stop):
    return rows(array, start, stop).copy()


@njit
def _write_row(array, i, value):
    rows(array, i, i + 1)[0][...] = value


@pytest.mark.parametrize("shape", [(7,), (7, 3), (5, 2, 4), (6, 0), (1, 3), (4, 1, 1)])
def test_rows_equal_slices(shape):
    array = np.arange(int(np.prod(shape)), dtype=np.float64).reshape(shape)
    for start in range(shape[0] + 1):
        for stop in range(start, shape[0] + 1):
            view = _rows_copy(array, start, stop)
            assert view.shape == array[start:stop].shape and np.array_equal(view, array[start:stop])


@pytest.mark.parametrize("index", [np.int32, np.uint32, np.uint64, np.int64])
def test_rows_take_any_integer_index_type(index):
    """Kernels pass int32 instance and triangle indices and uint64 ones (array_views.at)."""
    array = np.arange(60.0).reshape(5, 3, 4)
    assert np.array_equal(_rows_copy(array, index(2), index(4)), array[2:4])


@pytest.mark.parametrize("dtype", [np.int32, np.float32, np.uint8])
def test_a_row_view_writes_into_its_parent(dtype):
    array = np.zeros((6, 5), dtype)
    _write_row(array, 4, 3)
    expected = np.zeros((6, 5), dtype)
    expected[4] = 3
    assert np.array_equal(array, expected)


def test_unowned_is_the_whole_array():
    array = np.arange(24.0).reshape(2, 3, 4)
    assert np.array_equal(njit(lambda a: unowned(a).copy())(array), array)
