"""The JIT plumbing around Numba: kernels cached on disk and keyed by the digest of all of core's
sources (kernel_cache.py, sources_digest.py), a faster copy in Numba's inliner (inline_copy.py) and
one translation of each inlined callee per compile (inline_memo.py), a
helper process that compiles the rendering kernels during a first build (parallel_compile.py), thread
counts set and restored around kernels (threads.py), a clock that leaves compiles out of timings
(compile_clock.py), and a value the optimiser cannot move work ahead of (opaque.py). Nothing here traces a ray.
"""
