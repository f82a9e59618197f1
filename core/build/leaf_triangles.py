"""The tree's triangles copied into leaf order, one float32 row per vertex coordinate, and the boxes of
groups of its columns.

A leaf's triangles are consecutive, nine rows of them, so triangle_test.leaf_candidates reads them as
vectors (as Embree's leaves hold their vertices). Row 3 v + k holds coordinate k of vertex v; column j
is triangle leaf_prims[j]. 36 bytes a reference, beside the (N, 3, 3) triangles read by index.

leaf_boxes: the box of LEAF_GROUP consecutive columns (group g: a tree's columns g G .. g G + G - 1,
across leaf boundaries) wherever they meet a large leaf, which a packet tests before that leaf's triangles
(packet_leaf.py), so a group no lane can hit costs one box test
(docs/choices.md#boxes-over-groups-of-a-large-leafs-triangles).
"""
import numpy as np
from numba import njit, prange

from ..trace.layout import LEAF


LEAF_GROUP = 4  # columns a box of leaf_boxes covers
# leaves of more triangles get group boxes, and packets test them a group at a time (packet_leaf.py);
# below, the box tests cost more than they save (docs/choices.md#boxes-over-groups-of-a-large-leafs-triangles)
GROUPED_LEAF = 32
BYTES_PER_REFERENCE = 36 + 24 // LEAF_GROUP  # nine float32 a column, and its share of a group's box


def leaf_triangles(triangles, leaf_prims, previous=None):
    """(9, R) float32: the vertices of triangles[leaf_prims[j]] in column j. `previous`: (how many
    leading columns are unchanged (kept_columns), old copy); those columns are copied instead of
    gathered again."""
    out = np.empty((9, len(leaf_prims)), np.float32)
    start = 0
    if previous is not None:
        start = previous[0]
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


def leaf_boxes(leaf_tris, nodes, bounds, previous=None):
    """(ceil(R / LEAF_GROUP), 6) float32 for the (9, R) leaf-ordered copy of a tree with node arrays
    `nodes` (NodeArrays) and box `bounds`: each group of columns that shares a column with a leaf of more
    than GROUPED_LEAF triangles gets the box (min x, y, z, max x, y, z) of all its columns' vertices; any
    other group, which no packet reads, the tree's box. `previous`: (old boxes, how many leading columns
    of the copy are unchanged since: a lazy tree's splice appends), whose whole groups are kept."""
    out = np.empty((-(-leaf_tris.shape[1] // LEAF_GROUP), 6), np.float32)
    start = 0
    if previous is not None:
        start = min(previous[1] // LEAF_GROUP, len(previous[0]), len(out))
        out[:start] = previous[0][:start]
    boxed = _groups_of_large_leaves(nodes.axis, nodes.child, nodes.count, len(out))
    _group_boxes(leaf_tris, boxed, np.asarray(bounds, np.float32), start, out)
    return out


@njit(cache=True)
def _groups_of_large_leaves(axis, child, count, n_groups):
    """(n_groups,) uint8: 1 for each group holding a column of a leaf of more than GROUPED_LEAF triangles."""
    boxed = np.zeros(n_groups, np.uint8)
    for i in range(axis.shape[0]):
        if axis[i] == LEAF and count[i] > GROUPED_LEAF:
            for g in range(child[i] // LEAF_GROUP, (child[i] + count[i] - 1) // LEAF_GROUP + 1):
                boxed[g] = 1
    return boxed


@njit(cache=True, parallel=True)
def _group_boxes(leaf_tris, boxed, bounds, start, out):
    n = leaf_tris.shape[1]
    for g in prange(start, out.shape[0]):
        if boxed[g] == 0:
            out[g, :] = bounds
            continue
        for k in range(3):
            lo, hi = leaf_tris[k, g * LEAF_GROUP], leaf_tris[k, g * LEAF_GROUP]
            for j in range(g * LEAF_GROUP, min(n, g * LEAF_GROUP + LEAF_GROUP)):
                for v in range(3):
                    lo, hi = min(lo, leaf_tris[3 * v + k, j]), max(hi, leaf_tris[3 * v + k, j])
            out[g, k], out[g, 3 + k] = lo, hi
