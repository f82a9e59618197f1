"""Peak memory of a build and of a render, estimated from sizes alone, before anything is allocated.

Why: a scene too big for the machine should fail with a message naming the estimate, the limit and what
to change, not get the process killed by the out-of-memory killer half-way through a build. The figures
are the peak resident-memory growth measured per triangle and per pixel in fresh processes
(`benchmarks/bench_memory.py --calibrate`, numbers in docs/reliability.md), times a safety margin:
the build's working set (references, boxes, clipped boxes, pools, nodes) grows linearly with the
triangle count, and the renderer's buffers (camera rays, hit points, normals, sums) with the pixel count.
"""
import ctypes
import os

import numpy as np

MB = 1 << 20
MARGIN = 1.25  # measured peaks vary by scene (references per triangle); the limit is a promise

# Peak RSS growth of build_kdtree per input triangle, not counting the triangle array itself, worst scene
# measured (bench_memory.py --calibrate). It follows the references per triangle: 108-192 B on soup-1m,
# suzanne-1m and a wavy 1M height field (1.6-4.3 references a triangle), but a *flat* subdivided plane
# makes the binned and median builders clip it into 13-14 references a triangle: 612 B (binned) and
# 487 B (median) per triangle. The exact sweep splits such a plane on its grid lines (1.0 reference).
# The limit is a promise, so the estimate covers the flat plane: typical scenes need 3-6x less. The
# exact sweep's 190 B (soup-1m) was exceeded by a denser soup (100k triangles 0.05 wide in a 2-unit
# cube, 4.5 references a triangle: 324 B of peak, 405 B with the 1.25 of the table in docs/reliability.md),
# which the in-build check below found: 420 B. All of these were measured at the SAH's former
# intersection_cost of 1.5. At today's 0.3 trees are shallower but keep a 36-byte copy of every leaf
# reference (leaf_triangles.py), made after release_freed_memory: 91-124 B (binned), 105-177 (median),
# 96-128 (exact) on the scenes above (the flat plane now 1.04 references a triangle), and 289 / 307 /
# 278 B on the dense soup (6.1-6.8 references a triangle). Where the C library cannot release memory
# the copy adds to the peak: 318 / 365 / 338 B on the dense soup, 338 B being 423 with the 1.25 of the
# table in docs/reliability.md: hence 430 for the exact sweep. Densely overlapping triangles in one plane (cards
# on a floor) split on until the duplication budget stops them (options.py): ~18 references a triangle,
# 710 / 774 / 750 B peak (binned / median / exact, bench_memory.py --calibrate --scenes flat-cards-200k),
# so median and exact now cover 774 / 1.25 and 750 / 1.25.
BUILD_BYTES_PER_TRIANGLE = {"binned": 620.0, "exact": 600.0, "median": 620.0}
TRIANGLE_BYTES = 36  # (3, 3) float32: the array the tree keeps
# Peak RSS growth of PreviewRender plus image(), per pixel, every pixel hit (the worst case): measured
# 198 B at 960x540 and 171 B at 1920x1080, before the 24 B of each pixel's ray start were added.
# Plus, computed rather than measured, the ray memo of pixel reuse: up to 64 bytes of visibility bits
# (render_kernels.MEMO_BITS), and three int64 counts per pixel: the bits known from last frame, the rays
# reused from it and the rays of lights without extent repeated from sample 0.
RENDER_BYTES_PER_PIXEL = 200.0 + 24.0 + 64.0 + 3 * 8.0
# The last frame's pixel state kept for pixel reuse (render.PreviewRender.pixel_state): pixel index,
# depth, point, normal, ray start, sums, squared sums, sample and ray counts (float64 / int64) and up to
# 64 bytes of visibility bits per hit pixel.
PIXEL_STATE_BYTES_PER_PIXEL = 136 + 64


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


# The promise also holds while building: options that force splits past what the SAH pays for (a huge
# cost_ratio with leaf_size 1 and a deep max_depth) duplicate references that can never be separated
# at every level, exponentially (outside QA: 320 triangles, 3.3M nodes and 165 MB under a 32 MiB
# limit). So each subtree checks the bytes its pools hold after every split against its share of the
# limit (subtree.py), halved because the merged tree is a copy of the subtrees' arrays, with a floor
# for tiny builds whose fixed-size scratch is not what the limit is about.
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


def release_freed_memory():
    """Give the memory a build has freed back to the OS, where the C library can (glibc's
    malloc_trim). The subtree builds' pools are freed into their worker threads' malloc arenas, which
    keep it: the tree's leaf copy, allocated afterwards, then added its whole size to the process's
    peak (bench_core.py's peak build memory, suzanne-251k: 187 B a triangle against 111 without the
    copy)."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)
