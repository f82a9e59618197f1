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

The single-ray traversal reads the same nodes packed into one 8-byte record a node (pack_nodes; pbrt-v3's
KdAccelNode, Pharr, Jakob and Humphreys §4.4.1), `nodes` (2 N,) uint32, node i's words at 2 i and 2 i + 1
(flat, so the address is a shift of the index; a 2-D array multiplies by its row stride every step):
    word 0     inner: the split position's float32 bits (read through the float32 view `node_split`);
               leaf: its first leaf column (child above); unbuilt: its subtree index
    word 1     bits 31-30: 0-2 the split axis, 3 a leaf or unbuilt node; bits 29-0: inner: the left
               child's index; leaf: its triangle count; unbuilt: UNBUILT_COUNT
One cache line touched a step instead of three arrays' (docs/choices.md#eight-byte-records-with-the-float32-step).
The builder, merge, statistics and the packet kernel keep the four arrays.

A ray that reaches an unbuilt node stops there and reports prim = suspended_prim(subtree) (<= -2)
instead of a hit; -1 stays "no hit".

The kernels take a tree's arrays as one named tuple (TreeArrays) and read them by name; Numba compiles
a named tuple to the same code as a plain one.
"""
from typing import NamedTuple

import numpy as np
from numba import njit, prange

LEAF = 3
UNBUILT = 4
NO_HIT = -1
KIND_SHIFT = 30
LOW_MASK = (1 << KIND_SHIFT) - 1  # word 1's child index or count
UNBUILT_COUNT = LOW_MASK  # word 1's count of an unbuilt node; a leaf holds fewer triangles


class NodeArrays(NamedTuple):
    """A tree's nodes as the builder makes them (the arrays above): per node `axis` (int8), `split` (float32),
    `child` (int32) and `count` (int32), and `leaf_prims` (int32 triangle indices in leaf order)."""

    axis: np.ndarray
    split: np.ndarray
    child: np.ndarray
    count: np.ndarray
    leaf_prims: np.ndarray


class TreeArrays(NamedTuple):
    """What the traversal kernels read of one tree (traversal.trace_ray), by name: the node arrays, the
    same nodes as records `nodes` (2 N,) uint32 and their float32 view `node_split` (pack_nodes), the
    triangles (N, 3, 3) float32, the root box `bounds` (6,) float32, the leaf-ordered triangles (9, R)
    float32 and `base`, where this tree's columns start in them (0 for a stand-alone tree; a mesh's first
    column in a two-level scene's packed arrays)."""

    axis: np.ndarray
    split: np.ndarray
    child: np.ndarray
    count: np.ndarray
    nodes: np.ndarray
    node_split: np.ndarray
    leaf_prims: np.ndarray
    triangles: np.ndarray
    bounds: np.ndarray
    leaf_triangles: np.ndarray
    base: int


@njit(cache=True, inline="always")
def suspended_prim(subtree):
    """The prim a traversal reports when it stops at unbuilt subtree `subtree`."""
    return -2 - subtree


def subtree_of(prim):
    """The unbuilt subtree(s) a suspended ray reported (inverse of suspended_prim; works on arrays)."""
    return -2 - prim


def pack_nodes(axis, split, child, count, n_prims):
    """The (2 N,) uint32 node records (module docstring) of the node arrays; `n_prims`, the length of
    leaf_prims, bounds the leaf offsets. Raises ValueError when an index or count does not fit its field."""
    n = len(axis)
    if n > LOW_MASK + 1 or n_prims >= 1 << 32:
        raise ValueError(f"a kd-tree of {n:,} nodes and {n_prims:,} leaf references exceeds the node records' "
                         f"limits ({LOW_MASK + 1:,} nodes, {2 ** 32 - 1:,} references)")
    # a leaf holds at most n_prims triangles: only then is a scan over all nodes needed
    leaves = axis == LEAF if n_prims >= UNBUILT_COUNT else np.zeros(0, bool)
    if leaves.any() and count[leaves].max() >= UNBUILT_COUNT:
        raise ValueError(f"a kd-tree leaf holds {int(count[leaves].max()):,} triangles, more than the node "
                         f"records hold ({UNBUILT_COUNT - 1:,})")
    out = np.empty(2 * n, np.uint32)
    if n:
        _pack(axis, split, child, count, out)
    return out


@njit(cache=True, parallel=True)
def _pack(axis, split, child, count, out):
    bits = split.view(np.uint32)
    for i in prange(axis.shape[0]):
        a = axis[i]
        if a < LEAF:
            out[2 * i] = bits[i]
            out[2 * i + 1] = (np.uint32(a) << KIND_SHIFT) | np.uint32(child[i])
        else:
            out[2 * i] = np.uint32(child[i])
            low = count[i] if a == LEAF else UNBUILT_COUNT
            out[2 * i + 1] = (np.uint32(LEAF) << KIND_SHIFT) | np.uint32(low)


def split_view(nodes):
    """The float32 view of the records (word 0 of an inner node is its split)."""
    return nodes.view(np.float32)
