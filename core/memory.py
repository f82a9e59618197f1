"""Peak memory of a build and of a render, estimated from sizes alone, before anything is allocated.

A scene too big for the machine fails with a message naming the estimate, the limit and what to change,
instead of being killed half-way. The figures are peak RSS growth per triangle and per pixel
(`benchmarks/bench_memory.py --calibrate`, docs/reliability.md) times MARGIN.
"""
import ctypes
import os

import numpy as np

from . import buffer_pool

MB = 1 << 20
MARGIN = 1.25  # peaks vary by scene (references per triangle); the limit is a promise

# Peak RSS growth of build_kdtree per input triangle, not counting the triangle array, for the worst
# calibration scene (dense coplanar cards; docs/choices.md#build-memory-per-triangle).
BUILD_BYTES_PER_TRIANGLE = {"binned": 620.0, "exact": 600.0, "median": 620.0}
TRIANGLE_BYTES = 36  # (3, 3) float32: the array the tree keeps
# Peak RSS growth of PreviewRender plus image(), per pixel, every pixel hit (the worst case: 230 B, the
# hard-shadow pass's camera and shadow packets), plus each pixel's 24 B ray start, up to 64 B of ray-memo
# bits (render_kernels.MEMO_BITS), three int64 counts and with an error target a float64 variance per check
# (convergence.py; 64 B: eight checks, up to 1,024 samples from min_samples 8), and for lights without
# extent the hard-shadow pass's answer and weight (9 B a light; 36 B: four lights). Calibrated by
# bench_memory.py --calibrate (docs/choices.md#render-memory-per-pixel-with-the-packet-passes).
RENDER_BYTES_PER_PIXEL = 230.0 + 24.0 + 64.0 + 3 * 8.0 + 64.0 + 36.0
# The last frame's pixel state kept for pixel reuse (PreviewRender.pixel_state): index, depth, point,
# normal, ray start, sums, counts (float64 / int64), up to 64 bytes of visibility bits and the checks'
# variances (64 B, as above) per hit pixel.
PIXEL_STATE_BYTES_PER_PIXEL = 136 + 64 + 64


class MemoryLimitError(ValueError):
    """A request whose estimated peak memory is above the caller's limit; nothing was allocated."""


def build_bytes(n_triangles, builder="binned", *, copies_input=False):
    """Estimated peak bytes of building a tree over `n_triangles` (plus the float32 copy of the input when
    it is not already a C-contiguous float32 array)."""
    per_triangle = BUILD_BYTES_PER_TRIANGLE[builder] + (TRIANGLE_BYTES if copies_input else 0)
    return int(MARGIN * per_triangle * n_triangles)


def render_bytes(width, height, keeps_previous=False):
    """Estimated peak bytes of a PreviewRender of width x height pixels and its image (plus the last
    frame's pixel state while it is continued from it)."""
    per_pixel = RENDER_BYTES_PER_PIXEL + (PIXEL_STATE_BYTES_PER_PIXEL if keeps_previous else 0)
    return int(MARGIN * per_pixel * width * height)


def check_limit(estimate, limit, what, advice):
    """Raise MemoryLimitError when `estimate` bytes exceed `limit` (None: no limit)."""
    if limit is not None and estimate > limit:
        raise MemoryLimitError(f"{what} needs about {_size(estimate)}, above the memory limit of "
                               f"{_size(limit)}: {advice}")


# The limit also holds while building: options that force splits past what the SAH pays for duplicate
# references at every level, exponentially. So each subtree checks the bytes its pools hold after every
# split against its share of the limit (subtree.py), halved because the merged tree copies the subtrees'
# arrays, with a floor for tiny builds whose fixed-size scratch is not what the limit is about.
MIN_SUBTREE_BUDGET = 1 << 20


def subtree_bytes_per_reference(memory_limit, n_references):
    """Bytes a subtree's pools may hold per reference it starts with (0.0: no limit)."""
    if memory_limit is None or n_references == 0:
        return 0.0
    return memory_limit / (2.0 * n_references)


def _size(n_bytes):
    return f"{n_bytes / MB:,.0f} MB" if n_bytes >= MB else f"{n_bytes:,.0f} bytes"


def check_build_memory(triangles, options):
    """build_kdtree's check, from the input's shape and dtype only (before it is even converted)."""
    if options.memory_limit is None:
        return
    arr = np.asarray(triangles)
    n = int(arr.shape[0]) if arr.ndim >= 1 else 0
    copies = arr.dtype != np.float32 or not arr.flags.c_contiguous
    check_limit(build_bytes(n, options.builder, copies_input=copies), options.memory_limit,
                f"building a kd-tree over {n:,} triangles ({options.builder!r} builder)",
                "pass fewer triangles or raise memory_limit (None = no limit)")


def physical_memory():
    """This machine's physical memory in bytes, or None where the OS does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None


def check_render_memory(width, height):
    """A render whose estimated buffers exceed the machine's physical memory is refused up front:
    numpy would fail part-way (MemoryError) or the machine would swap."""
    check_limit(render_bytes(width, height), physical_memory(), f"a {width}x{height} render",
                "lower the resolution")


def _malloc_trim():
    """glibc's malloc_trim, or None where the C library has none (macOS, Windows, musl)."""
    try:
        return ctypes.CDLL(None).malloc_trim
    except (AttributeError, OSError, TypeError):
        return None


_MALLOC_TRIM = _malloc_trim()


# A build whose leaf copy is smaller keeps its freed memory for the next build instead of handing it back
# to the OS before the copy: released, every build faults its pools in afresh, zeroed page by page
# (docs/choices.md#freed-build-memory-kept-below-64-mb-of-leaf-copy).
RELEASE_MIN_BYTES = 64 * MB


def release_before_copy(copy_bytes, memory_limit):
    """Hand the build's freed memory back to the OS before the tree's leaf copy of `copy_bytes` is made,
    where the peak matters: under a memory limit, or for a copy of at least RELEASE_MIN_BYTES. Otherwise
    the copy adds at most RELEASE_MIN_BYTES to the peak, and the next build reuses the kept memory."""
    if memory_limit is not None or copy_bytes >= RELEASE_MIN_BYTES:
        release_freed_memory()


def release_freed_memory():
    """Give the memory a build has freed back to the OS, where the C library can (glibc's
    malloc_trim). The subtree builds' pools are freed into their worker threads' malloc arenas, which
    keep it, and the tree's leaf copy, allocated afterwards, would add its whole size to the peak. The
    renderer's kept blocks (buffer_pool.py) go first."""
    buffer_pool.release()
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)
