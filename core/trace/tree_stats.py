"""Statistics of a built tree, recomputed from the flat arrays alone.

SAH cost (seed 001 eq. 6): traversal_cost * sum over inner nodes of A(node)/A(root) + intersection_cost
* sum over leaves of A(leaf)/A(root) * count; an unbuilt lazy subtree counts as a leaf of its references.
"""
import numpy as np
from numba import njit

from ..geometry import half_area
from .layout import LEAF, UNBUILT


@njit(cache=True)
def walk_stats(axis, split, child, count, root_box, traversal_cost, intersection_cost):
    """(sah_cost, leaves, empty_leaves, max_depth, references, inner_area, leaf_area_refs, unbuilt).
    Leaves and references count built leaves only; `unbuilt` counts unbuilt subtrees (lazy trees)."""
    n = axis.shape[0]
    if n == 0:
        return 0.0, 0, 0, 0, 0, 0.0, 0.0, 0
    root_area = half_area(root_box)
    inv_root = 1.0 / root_area if root_area > 0.0 else 0.0
    stack = np.empty(n + 1, np.int64)
    depths = np.empty(n + 1, np.int64)
    boxes = np.empty((n + 1, 6), np.float32)
    stack[0], depths[0] = 0, 0
    boxes[0] = root_box
    sp = 1
    inner_area = 0.0
    leaf_area_refs = 0.0
    leaves = empty = max_depth = refs = unbuilt = 0
    while sp > 0:
        sp -= 1
        node, depth = stack[sp], depths[sp]
        box = boxes[sp].copy()
        area = half_area(box) * inv_root
        max_depth = max(max_depth, depth)
        if axis[node] == UNBUILT:
            unbuilt += 1
            leaf_area_refs += area * count[node]
            continue
        if axis[node] == LEAF:
            leaves += 1
            empty += count[node] == 0
            refs += count[node]
            leaf_area_refs += area * count[node]
            continue
        inner_area += area
        a = axis[node]
        for side in range(2):
            stack[sp], depths[sp] = child[node] + side, depth + 1
            boxes[sp] = box
            boxes[sp, a + 3 if side == 0 else a] = split[node]
            sp += 1
    sah = traversal_cost * inner_area + intersection_cost * leaf_area_refs
    return sah, leaves, empty, max_depth, refs, inner_area, leaf_area_refs, unbuilt


def leaf_size_histogram(axis, count, bins=(0, 1, 2, 4, 8, 16, 32, 64)):
    """How many leaves hold 0, 1, 2-3, 4-7, ... triangles (Mitsuba prints the same table)."""
    sizes = count[axis == LEAF]
    edges = list(bins) + [np.iinfo(np.int32).max]
    return {f"{lo}" if hi == lo + 1 else f"{lo}-{hi - 1}" if hi < edges[-1] else f"{lo}+":
            int(((sizes >= lo) & (sizes < hi)).sum()) for lo, hi in zip(edges[:-1], edges[1:])}
