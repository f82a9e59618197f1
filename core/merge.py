"""Joining the top levels and the concurrently built subtrees into one flat tree (seed 000 §4.1).

Top nodes keep their indices; each task's subtree root replaces its task slot and the rest of the
subtree is appended, with child indices and leaf offsets shifted.
"""
import numpy as np

from .layout import LEAF


def merge_tree(top_nodes, subtrees):
    """One set of flat arrays (axis, split, child, count, leaf_prims) from the top and the subtrees."""
    n_top = len(top_nodes)
    n_nodes = n_top + sum(len(s[0]) - 1 for s in subtrees)
    n_prims = sum(len(s[4]) for s in subtrees)
    axis = np.empty(n_nodes, np.int8)
    split = np.empty(n_nodes, np.float32)
    child = np.empty(n_nodes, np.int32)
    count = np.zeros(n_nodes, np.int32)
    leaf_prims = np.empty(n_prims, np.int32)
    for i, node in enumerate(top_nodes):
        if node.task < 0:
            axis[i], split[i], child[i] = node.axis, node.pos, node.left
    base, prim_base = n_top, 0
    for node_index, node in enumerate(top_nodes):
        if node.task < 0:
            continue
        s_axis, s_split, s_child, s_count, s_prims = subtrees[node.task]
        shifted = np.where(s_axis == LEAF, s_child + prim_base, s_child + (base - 1)).astype(np.int32)
        axis[node_index], split[node_index], child[node_index] = s_axis[0], s_split[0], shifted[0]
        count[node_index] = s_count[0]
        m = len(s_axis) - 1
        axis[base:base + m], split[base:base + m] = s_axis[1:], s_split[1:]
        child[base:base + m], count[base:base + m] = shifted[1:], s_count[1:]
        leaf_prims[prim_base:prim_base + len(s_prims)] = s_prims
        base += m
        prim_base += len(s_prims)
    return axis, split, child, count, leaf_prims
