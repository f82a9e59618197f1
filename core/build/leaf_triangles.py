"""The tree's triangles copied into leaf order, one float32 row per vertex coordinate.

A leaf's triangles are consecutive, nine rows of them, so triangle_test.leaf_candidates reads them as
vectors (as Embree's leaves hold their vertices). Row 3 v + k holds coordinate k of vertex v; column j
is triangle leaf_prims[j]. 36 bytes a reference, beside the (N, 3, 3) triangles read by index.
"""
import numpy as np
from numba import njit, prange


BYTES_PER_REFERENCE = 36  # nine float32 a column


def leaf_triangles(triangles, leaf_prims, previous=None):
    """(9, R) float32: the vertices of triangles[leaf_prims[j]] in column j. `previous`: (old
    leaf_prims, old copy); where the new leaf_prims starts with the old ones (a lazy tree's splice
    appends), those columns are copied instead of gathered again."""
    out = np.empty((9, len(leaf_prims)), np.float32)
    start = 0
    if previous is not None:
        old_prims, old_copy = previous
        n_old = len(old_prims)
        if n_old <= len(leaf_prims) and np.array_equal(leaf_prims[:n_old], old_prims):
            out[:, :n_old] = old_copy
            start = n_old
    if start < len(leaf_prims):
        _gather(triangles, leaf_prims, start, out)
    return out


@njit(cache=True, parallel=True)
def _gather(triangles, leaf_prims, start, out):
    for j in prange(start, leaf_prims.shape[0]):
        tri = triangles[leaf_prims[j]]
        for row in range(9):
            out[row, j] = tri[row // 3, row % 3]
