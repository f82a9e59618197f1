"""traversal.interleaved_blocks / block_range: how a prange's iterations deal blocks of rays to threads.

Every item must run exactly once whatever the thread count, and each thread's contiguous range of
iterations (Numba's static schedule) must hold an equal share of every band of the image, as one run of
consecutive blocks per band (docs/choices.md#one-run-a-band-per-thread)."""
import numba
import numpy as np
import pytest

from core.trace.traversal import BANDS, block_range, dealt_blocks, interleaved_blocks

CASES = [(0, 8), (1, 8), (7, 8), (64, 8), (1000, 64), (307_200, 64), (38_400, 8), (BANDS * 8 * 5 + 3, 8)]


def blocks_of_iterations(first, last, per_band, run, n, block_size):
    """The block index each iteration in first..last-1 runs (None for an empty one)."""
    out = []
    for i in range(first, last):
        start, stop = block_range(i, per_band, run, n, block_size)
        out.append(start // block_size if stop > start else None)
    return out


@pytest.mark.parametrize("threads", [1, 2, 3, 4])
@pytest.mark.parametrize("n, block_size", CASES)
def test_every_item_runs_once(n, block_size, threads):
    iterations, per_band, run = dealt_blocks(-(-n // block_size), threads)
    counts = np.zeros(n, np.int64)
    for i in range(iterations):
        start, stop = block_range(i, per_band, run, n, block_size)
        assert 0 <= start <= stop <= n and stop - start <= block_size
        counts[start:stop] += 1
    assert (counts == 1).all()


@pytest.mark.parametrize("threads", [1, 2, 3, 4])
def test_each_thread_takes_one_run_of_every_band(threads):
    n, block_size = 100_000, 64
    n_blocks = -(-n // block_size)
    iterations, per_band, run = dealt_blocks(n_blocks, threads)
    assert iterations % threads == 0
    share = iterations // threads
    for k in range(threads):  # the static schedule: thread k runs iterations k share .. (k + 1) share - 1
        blocks = blocks_of_iterations(k * share, (k + 1) * share, per_band, run, n, block_size)
        for band in range(BANDS):
            mine = [b for b in blocks if b is not None and b // per_band == band]
            want = [b for b in range(band * per_band + k * run, band * per_band + (k + 1) * run) if b < n_blocks]
            assert mine == want  # consecutive blocks, an equal share of the band
        # ...and the thread's share of the work differs from the others' by less than one run a band
        assert abs(sum(b is not None for b in blocks) - n_blocks / threads) <= BANDS * run


def test_one_thread_runs_blocks_in_image_order():
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        iterations, per_band, run = interleaved_blocks(100_000, 64)
    finally:
        numba.set_num_threads(before)
    assert run == per_band  # each band is one run
    blocks = [b for b in blocks_of_iterations(0, iterations, per_band, run, 100_000, 64) if b is not None]
    assert blocks == list(range(len(blocks))) and len(blocks) == -(-100_000 // 64)
