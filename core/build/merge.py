"""Joining the top levels and the concurrently built subtrees into one flat tree (seed 000 §4.1).

Each task's subtree root replaces its task slot and the rest is appended, child indices and leaf
offsets shifted; a lazy tree splices its on-demand subtrees into their UNBUILT slots the same way.
"""
import numpy as np
from numba import njit

from ..trace.layout import LEAF, UNBUILT


def merge_tree(top_nodes, subtrees):
    """One set of flat arrays (axis, split, child, count, leaf_prims) from the top and the subtrees.
    Deferred subtrees (lazy builds) are numbered globally in task order."""
    n_top = len(top_nodes)
    axis = np.empty(n_top, np.int8)
    split = np.zeros(n_top, np.float32)
    child = np.zeros(n_top, np.int32)
    count = np.zeros(n_top, np.int32)
    slots = [0] * len(subtrees)
    for i, node in enumerate(top_nodes):
        if node.task < 0:
            axis[i], split[i], child[i] = node.axis, node.pos, node.left
        else:
            slots[node.task] = i
    return splice_subtrees((axis, split, child, count, np.empty(0, np.int32)), slots, subtrees)


def splice_subtrees(arrays, slots, subtrees, first_deferred=0):
    """New flat arrays: node slots[k] becomes the root of subtrees[k] (build_subtree's tuple), the rest
    of each subtree is appended and its leaf triangles appended to leaf_prims. Deferred subtrees inside
    the new subtrees are numbered from `first_deferred` on."""
    axis, split, child, count, leaf_prims = arrays
    n_old, p_old = len(axis), len(leaf_prims)
    n_nodes = n_old + sum(len(s[0]) - 1 for s in subtrees)
    axis, split, child, count = (_grown(a, n_nodes) for a in (axis, split, child, count))
    leaf_prims = _grown(leaf_prims, p_old + sum(len(s[4]) for s in subtrees))
    base, prim_base, deferred_base = n_old, p_old, first_deferred
    for slot, (s_axis, s_split, s_child, s_count, s_prims, s_deferred_node) in zip(
            slots, (s[:6] for s in subtrees)):
        _place_subtree((axis, split, child, count), int(slot), base, (s_axis, s_split, s_child, s_count),
                       (int(prim_base), int(deferred_base)))
        leaf_prims[prim_base:prim_base + len(s_prims)] = s_prims
        base += len(s_axis) - 1
        prim_base += len(s_prims)
        deferred_base += len(s_deferred_node)
    return axis, split, child, count, leaf_prims


@njit(cache=True)
def _place_subtree(nodes, slot, base, subtree, offsets):
    """Subtree node 0 into node `slot`, its nodes 1.. into base.. of `nodes` (axis, split, child, count),
    child indices shifted: a leaf's by the first leaf reference and an unbuilt node's by the first
    deferred index (offsets), an inner node's to the new place of its children. One compiled pass instead
    of NumPy's where / astype / slice copies, which run serially in every build
    (docs/choices.md#serial-steps-of-the-build-compiled)."""
    axis, split, child, count = nodes
    s_axis, s_split, s_child, s_count = subtree
    prim_base, deferred_base = offsets
    for j in range(s_axis.shape[0]):
        a = s_axis[j]
        shift = prim_base if a == LEAF else (deferred_base if a == UNBUILT else base - 1)
        dst = slot if j == 0 else base + j - 1
        axis[dst], split[dst], count[dst] = a, s_split[j], s_count[j]
        child[dst] = s_child[j] + shift


def _grown(a, n):
    out = np.empty(n, a.dtype)
    out[:len(a)] = a
    return out
