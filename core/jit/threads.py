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
from llvmlite import ir  # noqa: E402
from numba.core import cgutils, types  # noqa: E402
from numba.extending import intrinsic  # noqa: E402


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


@intrinsic
def kernel_threads(typingctx):
    """The Numba thread count a kernel runs with, read inside compiled code (the kernel's prange splits
    by it). Calls the threading layer's `get_num_threads` symbol as Numba's own parallel loops do:
    numba.get_num_threads() in a kernel reads it through a ctypes pointer, which Numba cannot cache."""
    from numba.np.ufunc.parallel import _launch_threads
    _launch_threads()  # registers the symbol with LLVM

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)  # the type Numba's parfor lowering declares it with, in the same module
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(i64, []), "get_num_threads")
        return builder.sext(builder.trunc(builder.call(fn, []), ir.IntType(32)), i64)  # the C function's int

    return types.int64(), codegen
