"""The tree's triangles copied into leaf order, one float32 row per vertex coordinate, and the boxes of
groups of its columns.

A leaf's triangles are consecutive, nine rows of them, so triangle_test.leaf_candidates reads them as
vectors (as Embree's leaves hold their vertices). Row 3 v + k holds coordinate k of vertex v; column j
is triangle leaf_prims[j]. 36 bytes a reference, beside the (N, 3, 3) triangles read by index.

leaf_boxes: the box of every LEAF_GROUP consecutive columns (group g: columns g G .. g G + G - 1, across
leaf boundaries), which a packet tests before a large leaf's triangles (packet_leaf.py), so a group no
lane can hit costs one box test (docs/choices.md#boxes-over-groups-of-a-large-leafs-triangles).
"""
import numpy as np
from numba import njit, prange


LEAF_GROUP = 4  # columns a box of leaf_boxes covers
BYTES_PER_REFERENCE = 36 + 24 // LEAF_GROUP  # nine float32 a column, and its share of a group's box


def leaf_triangles(triangles, leaf_prims, previous=None):
    """(9, R) float32: the vertices of triangles[leaf_prims[j]] in column j. `previous`: (old
    leaf_prims, old copy); where the new leaf_prims starts with the old ones (a lazy tree's splice
    appends), those columns are copied instead of gathered again."""
    out = np.empty((9, len(leaf_prims)), np.float32)
    start = 0
    if previous is not None:
        start = kept_columns(previous[0], leaf_prims)
        out[:, :start] = previous[1][:, :start]
    if start < len(leaf_prims):
        _gather(triangles, leaf_prims, start, out)
    return out


def kept_columns(old_prims, leaf_prims):
    """How many leading columns of the copy stay as they were: all the old ones where the new leaf_prims
    start with the old (a lazy tree's splice appends), else none."""
    n_old = len(old_prims)
    return n_old if n_old <= len(leaf_prims) and np.array_equal(leaf_prims[:n_old], old_prims) else 0


@njit(cache=True, parallel=True)
def _gather(triangles, leaf_prims, start, out):
    for j in prange(start, leaf_prims.shape[0]):
        tri = triangles[leaf_prims[j]]
        for row in range(9):
            out[row, j] = tri[row // 3, row % 3]


def leaf_boxes(leaf_tris, previous=None):
    """(ceil(R / LEAF_GROUP), 6) float32: each group's box (min x, y, z, max x, y, z) of its columns'
    vertices in the (9, R) leaf-ordered copy; the last group covers the columns left. `previous`: (old
    boxes, how many leading columns of the copy are unchanged since), whose whole groups are kept."""
    out = np.empty((-(-leaf_tris.shape[1] // LEAF_GROUP), 6), np.float32)
    start = 0
    if previous is not None:
        start = min(previous[1] // LEAF_GROUP, len(previous[0]), len(out))
        out[:start] = previous[0][:start]
    _group_boxes(leaf_tris, start, out)
    return out


@njit(cache=True, parallel=True)
def _group_boxes(leaf_tris, start, out):
    n = leaf_tris.shape[1]
    for g in prange(start, out.shape[0]):
        for k in range(3):
            lo, hi = leaf_tris[k, g * LEAF_GROUP], leaf_tris[k, g * LEAF_GROUP]
            for j in range(g * LEAF_GROUP, min(n, g * LEAF_GROUP + LEAF_GROUP)):
                for v in range(3):
                    lo, hi = min(lo, leaf_tris[3 * v + k, j]), max(hi, leaf_tris[3 * v + k, j])
            out[g, k], out[g, 3 + k] = lo, hi
