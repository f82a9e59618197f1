"""Blocks of memory kept from one render to the next for its large per-frame arrays.

A frame's camera rays, hits, hit frames and shadow rays are tens of MB. Allocated afresh, the C library
hands the freed blocks back to the OS at the end of the frame and the next frame faults them in again,
zeroed page by page by the kernel, a cost every frame paid
(docs/choices.md#a-frames-large-arrays-from-kept-blocks). The build keeps its own pools for the same
reason (seed 000 section 3.5; memory.release_before_copy).

`empty(shape, dtype)` hands out a view of a kept block. A block is handed out again only once nothing
refers to it: every array made from a view (a slice, a reshape, Numba's boxed results) holds the block
itself as its base, so the block's reference count says whether any is alive, and an array from here
may be kept or returned to a caller like any other. Where that count does not behave so (checked once,
at import), arrays come from NumPy as before.

What is kept: `new_frame()` (PreviewRender calls it before each frame) lets go of the free blocks the
frame before did not use, so the pool holds about the last frame's arrays, whatever sizes came before;
a free block unused for STALE_AFTER pooled requests goes too; `release()` lets go of every free block
(memory.release_freed_memory, and the add-on under a memory limit, call it).
"""
import math
import operator
import sys
import threading

import numpy as np

MIN_POOLED_BYTES = 1 << 20  # smaller arrays come from NumPy: the C library keeps and reuses them itself
HEADROOM = 1.0625  # a new block's size over the request, so a frame with a few more hits reuses it
LARGEST_OVER_REQUEST = 1.25  # a free block serves requests down to 1 / this of its size
STALE_AFTER = 256  # pooled requests a free block may go unused outside frames (a frame makes about 30)
PAGE = 4096

_lock = threading.RLock()  # reentrant: a garbage collection inside np.empty may free pooled arrays
_blocks = []  # the kept blocks, uint8 arrays
_last_use = []  # the request count at each block's last hand-out
_counts = {"requests": 0, "frame_start": 0, "made": 0}


def _references(blocks, i):
    return sys.getrefcount(blocks[i])


def _counting_works():
    """The baseline count of a block nothing refers to, measured as _free measures it, or None when a
    view of a block does not raise its count (then nothing is pooled)."""
    blocks = [np.empty(16, np.uint8)]
    alone = _references(blocks, 0)
    view = blocks[0][4:8].view(np.int32)
    viewed = _references(blocks, 0)
    del view
    return alone if viewed > alone and _references(blocks, 0) == alone else None


_UNREFERENCED = _counting_works()


def empty(shape, dtype=np.float64):
    """An uninitialised C-contiguous array, as np.empty, on a kept block when it has MIN_POOLED_BYTES or more."""
    dtype = np.dtype(dtype)
    shape = (operator.index(shape),) if isinstance(shape, (int, np.integer)) else tuple(map(operator.index, shape))
    n_bytes = math.prod(shape) * dtype.itemsize  # math.prod: np.prod would make an array of the tuple first
    if n_bytes < MIN_POOLED_BYTES or _UNREFERENCED is None:
        return np.empty(shape, dtype)
    with _lock:
        block = _block_for(n_bytes)
    return block[:n_bytes].view(dtype).reshape(shape)


def zeros(shape, dtype=np.float64):
    """As np.zeros (empty, then filled)."""
    out = empty(shape, dtype)
    out.fill(0)
    return out


def full(shape, value, dtype=np.float64):
    """As np.full with an explicit dtype."""
    out = empty(shape, dtype)
    out.fill(value)
    return out


def take(array, indices):
    """array[indices] for valid integer indices along the first axis, into a pooled array (mode "clip":
    NumPy's default mode writes to a temporary copy of `out` first)."""
    out = empty((len(indices), *array.shape[1:]), array.dtype)
    np.take(array, indices, axis=0, out=out, mode="clip")
    return out


def new_frame():
    """A frame starts: let go of the free blocks not handed out since the last frame started."""
    with _lock:
        start = _counts["frame_start"]
        _drop(lambda i: _last_use[i] <= start)
        _counts["frame_start"] = _counts["requests"]


def release():
    """Let go of every free block (their memory goes back to the C library)."""
    with _lock:
        _drop(lambda i: True)


def stats():
    """{"held": bytes of every kept block, "free": bytes of the free ones, "blocks": how many are kept,
    "made": how many were ever made}."""
    with _lock:
        free = [_free(i) for i in range(len(_blocks))]  # before any name holds a block
        sizes = [b.nbytes for b in _blocks]
        return {"held": sum(sizes), "free": sum(s for s, is_free in zip(sizes, free) if is_free),
                "blocks": len(sizes), "made": _counts["made"]}


def _free(i):
    """Whether block i is free: nothing but the list refers to it (no name may hold it while asking)."""
    return _references(_blocks, i) == _UNREFERENCED


def _block_for(n_bytes):
    """The smallest free block of n_bytes up to LARGEST_OVER_REQUEST times that, else a new one; stale
    free blocks are let go first."""
    _counts["requests"] += 1
    now = _counts["requests"]
    _drop(lambda i: now - _last_use[i] > STALE_AFTER)
    best, best_size = -1, 0
    for i in range(len(_blocks)):
        size = _blocks[i].nbytes
        if n_bytes <= size <= n_bytes * LARGEST_OVER_REQUEST and (best < 0 or size < best_size) and _free(i):
            best, best_size = i, size
    if best < 0:
        _blocks.append(np.empty(-(-int(n_bytes * HEADROOM) // PAGE) * PAGE, np.uint8))
        _last_use.append(now)
        _counts["made"] += 1
        best = len(_blocks) - 1
    _last_use[best] = now
    return _blocks[best]


def _drop(should_drop):
    """Let go of the free blocks i for which should_drop(i)."""
    keep = [i for i in range(len(_blocks)) if not (_free(i) and should_drop(i))]
    _blocks[:] = [_blocks[i] for i in keep]
    _last_use[:] = [_last_use[i] for i in keep]
