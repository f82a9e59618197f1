"""The kernels most tests need, compiled beside pytest: `python -m tests.warm_kernels` (scripts/test.sh
starts it in the background). A cold suite compiles for most of its run on one core, so the other core
compiles the sampling kernel's packed version (the longest single compile) and the first frames'
kernels into the same cache meanwhile (numba_cache.py), and the tests that reach them later load them.
The suite does not depend on it: a kernel not yet saved is compiled by the test that needs it, as
without it, and Numba saves each cache file under a temporary name, so stopping it breaks nothing.
"""
from tests.numba_cache import use_test_cache


def main() -> None:
    use_test_cache()
    from core.jit import first_frame

    first_frame.compile_packed_samples()
    first_frame.compile_first_frames()


if __name__ == "__main__":
    main()
