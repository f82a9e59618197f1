"""Running kernels on a chosen number of threads, and putting the old number back afterwards.

Why OMP_WAIT_POLICY=PASSIVE (unless the user set it): with Numba's OpenMP layer (plain Python; inside
Blender bpy's TBB layer is used instead) idle worker threads spin after every parallel region. The build
runs many short parallel regions near the root, and on a machine where another process holds a core the
spinning threads starve the working ones: the 2-thread build of suzanne-251k took 414-422 ms with one
core busy, 296-304 ms with passive waiting, and 198-219 ms either way on an idle machine (medians of 5).
The variable is read when the OpenMP runtime starts, at the first parallel kernel, so it is set here,
at import, before any kernel runs.
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
