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
"""
from numba import njit

LEAF = 3
UNBUILT = 4
NO_HIT = -1


@njit(cache=True, inline="always")
def suspended_prim(subtree):
    """The prim a traversal reports when it stops at unbuilt subtree `subtree`."""
    return -2 - subtree


def subtree_of(prim):
    """The unbuilt subtree(s) a suspended ray reported (inverse of suspended_prim; works on arrays)."""
    return -2 - prim
