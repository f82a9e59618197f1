"""The flat tree layout shared by builder, merge, statistics and traversal.

Node i is four parallel arrays (structure of arrays, seed 004 §4.7):
    axis[i]   int8     0, 1, 2 for an inner node split on x, y, z; LEAF for a leaf; UNBUILT for a subtree
                       a lazy build deferred (seed 003 §3: built when a ray first reaches it)
    split[i]  float32  the split position (inner nodes)
    child[i]  int32    inner: index of the left child, the right child is child[i] + 1;
                       leaf: offset of its first triangle index in `leaf_prims`, and of its first
                       column in the leaf-ordered triangle copy (leaf_triangles.py);
                       unbuilt: index of its deferred subtree (lazy.py)
    count[i]  int32    leaf: number of triangles (0 for an empty leaf); unbuilt: its references; inner: 0
Children are allocated in pairs, so one index names both (13 bytes a node in all).

A ray that reaches an unbuilt node stops there and reports prim = suspended_prim(subtree) (<= -2)
instead of a hit; -1 stays "no hit".

The kernels take a tree's arrays as one named tuple (TreeArrays) and read them by name; Numba compiles
a named tuple to the same code as a plain one.
"""
from typing import NamedTuple

import numpy as np
from numba import njit

LEAF = 3
UNBUILT = 4
NO_HIT = -1


class NodeArrays(NamedTuple):
    """A tree's nodes as the builder makes them (the arrays above): per node `axis` (int8), `split` (float32),
    `child` (int32) and `count` (int32), and `leaf_prims` (int32 triangle indices in leaf order)."""

    axis: np.ndarray
    split: np.ndarray
    child: np.ndarray
    count: np.ndarray
    leaf_prims: np.ndarray


class TreeArrays(NamedTuple):
    """What the traversal kernels read of one tree (traversal.trace_ray), by name: the node arrays,
    the triangles (N, 3, 3) float32, the root box `bounds` (6,) float32, the leaf-ordered triangles
    (9, R) float32, the boxes of their column groups `leaf_boxes` (ceil(R / LEAF_GROUP), 6) float32
    (leaf_triangles.py) and `base`, where this tree's columns start in them (0 for a stand-alone tree;
    a mesh's first column in a two-level scene's packed arrays)."""

    axis: np.ndarray
    split: np.ndarray
    child: np.ndarray
    count: np.ndarray
    leaf_prims: np.ndarray
    triangles: np.ndarray
    bounds: np.ndarray
    leaf_triangles: np.ndarray
    leaf_boxes: np.ndarray
    base: int


@njit(cache=True, inline="always")
def suspended_prim(subtree):
    """The prim a traversal reports when it stops at unbuilt subtree `subtree`."""
    return -2 - subtree


def subtree_of(prim):
    """The unbuilt subtree(s) a suspended ray reported (inverse of suspended_prim; works on arrays)."""
    return -2 - prim
