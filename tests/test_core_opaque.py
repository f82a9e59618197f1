"""core/jit/opaque.py: the value barrier returns its argument unchanged, for every integer type."""
import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from core.jit.opaque import opaque


@njit
def _through(x):
    return opaque(x)


@njit
def _sum_in_branch(n, first):
    """The pattern opaque serves: work inside a loop's rarely taken branch, on a loop-invariant value."""
    total = np.uint64(0)
    for s in range(n):
        for use in range(first, 3):
            if use == 0:
                total += np.uint64(opaque(s)) * np.uint64(0x9E3779B9)
            else:
                total += np.uint64(use)
    return total


@pytest.mark.parametrize("value", [np.int32(-7), np.int64(-(2 ** 63)), np.int64(2 ** 63 - 1), np.uint64(2 ** 64 - 1),
                                   np.uint32(0), np.int8(-128), np.uint16(65535)])
def test_opaque_returns_its_argument(value):
    assert int(_through(value)) == int(value)


def test_opaque_in_a_branch_computes_what_the_plain_code_does():
    expected = [sum((s * 0x9E3779B9) % 2 ** 64 for s in range(50)) % 2 ** 64 * (first == 0) +
                50 * sum(range(max(first, 1), 3)) for first in (0, 1)]
    assert [int(_sum_in_branch(50, first)) % 2 ** 64 for first in (0, 1)] == [e % 2 ** 64 for e in expected]


@njit
def _literal():
    return opaque(7) + opaque(np.uint8(3))


def test_opaque_of_a_literal_is_its_value():
    assert _literal() == 10


def test_opaque_takes_integers_only():
    with pytest.raises(TypingError):
        _through(1.5)
