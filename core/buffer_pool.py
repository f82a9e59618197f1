"""Blocks of memory kept from one render to the next for its large per-frame arrays.

A frame's camera rays, hits, hit frames and shadow rays are tens of MB. Allocated afresh, the C library
hands the freed blocks back to the OS at the end of the frame and the next frame faults them in again,
zeroed page by page by the kernel: about a tenth of a preview's render time
(docs/choices.md#a-frames-large-arrays-from-kept-blocks). The build keeps its own pools for the same reason
(seed 000 section 3.5; memory.release_before_copy).

`empty(shape, dtype)` hands out a view of a kept block. A block is handed out again only once nothing
refers to it: every array made from a view (a slice, a reshape, Numba's boxed results) holds the block
itself as its base, so the block's reference count says whether any is alive, and an array from here
may be kept or returned to a caller like any other. A free block not handed out during the last
STALE_AFTER pooled requests is let go, so the pool holds about one frame's arrays; `release()` lets go of
every free block (memory.release_freed_memory calls it).
"""
import sys
import threading

import numpy as np

MIN_POOLED_BYTES = 1 << 20  # smaller arrays come from NumPy: the C library keeps and reuses them itself
HEADROOM = 1.0625  # a new block's size over the request, so a frame with a few more hits reuses it
LARGEST_OVER_REQUEST = 1.25  # a free block serves requests down to 1 / this of its size
STALE_AFTER = 64  # pooled requests a free block may go unused before it is let go (a frame makes ~30)
PAGE = 4096

_lock = threading.Lock()
_blocks = []  # the kept blocks, uint8 arrays
_last_use = []  # the request count at each block's last hand-out
_requests = [0]


def _references(blocks, i):
    return sys.getrefcount(blocks[i])


# A block no array refers to, counted the way _free counts: the list's reference and the call's own.
_UNREFERENCED = _references([np.empty(1, np.uint8)], 0)


def empty(shape, dtype=np.float64):
    """An uninitialised C-contiguous array, as np.empty, on a kept block when it has MIN_POOLED_BYTES or more."""
    dtype = np.dtype(dtype)
    shape = (shape,) if np.ndim(shape) == 0 else tuple(shape)
    n_bytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if n_bytes < MIN_POOLED_BYTES:
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
    """array[indices] for integer indices along the first axis, into a pooled array."""
    out = empty((len(indices), *array.shape[1:]), array.dtype)
    np.take(array, indices, axis=0, out=out)
    return out


def release():
    """Let go of every free block (their memory goes back to the C library)."""
    with _lock:
        _drop(lambda i: True)


def held_bytes():
    """(bytes of every kept block, bytes of the free ones)."""
    with _lock:
        free = [_free(i) for i in range(len(_blocks))]  # before any name holds a block
        sizes = [b.nbytes for b in _blocks]
    return sum(sizes), sum(size for size, is_free in zip(sizes, free) if is_free)


def _free(i):
    """Whether block i is free: nothing but the list refers to it (no name may hold it while asking)."""
    return _references(_blocks, i) == _UNREFERENCED


def _block_for(n_bytes):
    """The smallest free block of n_bytes up to LARGEST_OVER_REQUEST times that, else a new one; stale
    free blocks are let go first."""
    _requests[0] += 1
    now = _requests[0]
    _drop(lambda i: now - _last_use[i] > STALE_AFTER)
    best, best_size = -1, 0
    for i in range(len(_blocks)):
        size = _blocks[i].nbytes
        if n_bytes <= size <= n_bytes * LARGEST_OVER_REQUEST and (best < 0 or size < best_size) and _free(i):
            best, best_size = i, size
    if best < 0:
        _blocks.append(np.empty(-(-int(n_bytes * HEADROOM) // PAGE) * PAGE, np.uint8))
        _last_use.append(now)
        best = len(_blocks) - 1
    _last_use[best] = now
    return _blocks[best]


def _drop(should_drop):
    """Let go of the free blocks i for which should_drop(i)."""
    keep = [i for i in range(len(_blocks)) if not (_free(i) and should_drop(i))]
    _blocks[:] = [_blocks[i] for i in keep]
    _last_use[:] = [_last_use[i] for i in keep]
