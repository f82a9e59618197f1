"""Running kernels on a chosen number of threads, and putting the old number back afterwards.

OMP_WAIT_POLICY=PASSIVE unless set: idle OpenMP workers otherwise spin after each of the build's many
short parallel regions (docs/choices.md#passive-openmp-waiting). Read at the first parallel kernel, so
it is set here, at import.
"""
import os
from contextlib import contextmanager

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
import numpy as np  # noqa: E402


@contextmanager
def thread_count(threads):
    """Use `threads` Numba threads inside the block (None: all Numba was started with); yields the count."""
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, (int, np.integer))
                                or threads < 1):
        raise ValueError(f"threads must be None or an integer >= 1, got {threads!r}")
    previous = numba.get_num_threads()
    wanted = numba.config.NUMBA_NUM_THREADS if threads is None else min(threads, numba.config.NUMBA_NUM_THREADS)
    numba.set_num_threads(wanted)
    try:
        yield wanted
    finally:
        numba.set_num_threads(previous)
