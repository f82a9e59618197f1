"""Joining the top levels and the concurrently built subtrees into one flat tree (seed 000 §4.1).

Each task's subtree root replaces its task slot and the rest is appended, child indices and leaf
offsets shifted; a lazy tree splices its on-demand subtrees into their UNBUILT slots the same way.
"""
import numpy as np

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
        shifted = np.where(s_axis == LEAF, s_child + prim_base,
                           np.where(s_axis == UNBUILT, s_child + deferred_base, s_child + (base - 1)))
        shifted = shifted.astype(np.int32)
        axis[slot], split[slot], child[slot], count[slot] = s_axis[0], s_split[0], shifted[0], s_count[0]
        m = len(s_axis) - 1
        axis[base:base + m], split[base:base + m] = s_axis[1:], s_split[1:]
        child[base:base + m], count[base:base + m] = shifted[1:], s_count[1:]
        leaf_prims[prim_base:prim_base + len(s_prims)] = s_prims
        base += m
        prim_base += len(s_prims)
        deferred_base += len(s_deferred_node)
    return axis, split, child, count, leaf_prims


def _grown(a, n):
    out = np.empty(n, a.dtype)
    out[:len(a)] = a
    return out
