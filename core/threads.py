"""Running kernels on a chosen number of threads, and putting the old number back afterwards."""
from contextlib import contextmanager

import numba


@contextmanager
def thread_count(threads):
    """Use `threads` Numba threads inside the block (None: all Numba was started with); yields the count."""
    previous = numba.get_num_threads()
    wanted = numba.config.NUMBA_NUM_THREADS if threads is None else min(threads, numba.config.NUMBA_NUM_THREADS)
    numba.set_num_threads(wanted)
    try:
        yield wanted
    finally:
        numba.set_num_threads(previous)
