"""The tree's triangles copied into leaf order, one float32 row per vertex coordinate.

A leaf's triangles are then consecutive in memory, nine rows of them, so the edge-sign screen of
triangle_test.leaf_candidates reads them as vectors (seed 004 §4.7 lays nodes out for the cache the
same way; Embree's leaves hold their triangles' vertices the same way). Row 3 v + k holds coordinate k
of vertex v; column j is the triangle leaf_prims[j]. It costs 36 bytes a reference, kept beside the
(N, 3, 3) triangles, which the full test, normals and statistics read by triangle index.
"""
import numpy as np
from numba import njit, prange


def leaf_triangles(triangles, leaf_prims):
    """(9, R) float32: the vertices of triangles[leaf_prims[j]] in column j."""
    out = np.empty((9, len(leaf_prims)), np.float32)
    if len(leaf_prims):
        _gather(triangles, leaf_prims, out)
    return out


@njit(cache=True, parallel=True)
def _gather(triangles, leaf_prims, out):
    for j in prange(leaf_prims.shape[0]):
        tri = triangles[leaf_prims[j]]
        for row in range(9):
            out[row, j] = tri[row // 3, row % 3]
