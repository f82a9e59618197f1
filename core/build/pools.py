"""Memory pools: arrays allocated once with room to spare and grown geometrically when full.

Seed 000 §3.5's chunk lists with a moving end pointer, as growable arrays: a handful of allocations
per build, never one per node.
"""
import numpy as np
from numba import njit

GROWTH = 1.5


@njit(cache=True)
def new_capacity(current, need):
    return max(need, int(current * GROWTH) + 64)


@njit(cache=True, inline="always")
def ensure_refs(prims, boxes, used, need):
    """Reference pool with room for `need` entries, keeping the first `used`."""
    if need <= prims.shape[0]:
        return prims, boxes
    cap = new_capacity(prims.shape[0], need)
    new_prims = np.empty(cap, np.int32)
    new_boxes = np.empty((cap, 6), np.float32)
    new_prims[:used] = prims[:used]
    new_boxes[:used] = boxes[:used]
    return new_prims, new_boxes


@njit(cache=True, inline="always")
def ensure_nodes(axis, split, child, count, used, need):
    """Node arrays with room for `need` nodes, keeping the first `used`."""
    if need <= axis.shape[0]:
        return axis, split, child, count
    cap = new_capacity(axis.shape[0], need)
    new_axis = np.empty(cap, np.int8)
    new_split = np.empty(cap, np.float32)
    new_child = np.empty(cap, np.int32)
    new_count = np.empty(cap, np.int32)
    new_axis[:used] = axis[:used]
    new_split[:used] = split[:used]
    new_child[:used] = child[:used]
    new_count[:used] = count[:used]
    return new_axis, new_split, new_child, new_count


@njit(cache=True)
def ensure_array(values, used, need):
    """A 1-D array of the same dtype (int32 indices, float64 rooms) with room for `need` entries,
    keeping the first `used`; Numba compiles it once per dtype."""
    if need <= values.shape[0]:
        return values
    out = np.empty(new_capacity(values.shape[0], need), values.dtype)
    out[:used] = values[:used]
    return out


@njit(cache=True)
def ensure_floats(values, need):
    """A float32 scratch buffer of at least `need` entries (contents not kept)."""
    if need <= values.shape[0]:
        return values
    return np.empty(new_capacity(values.shape[0], need), np.float32)


@njit(cache=True, inline="always")
def append_leaf(leaf_refs, n_leaf, refs, start, n):
    """refs[start:start + n] appended to a builder's leaf references at n_leaf, the array grown only
    when full (binding an array costs reference counting); returns (leaf_refs, n_leaf + n)."""
    if n_leaf + n > leaf_refs.shape[0]:
        leaf_refs = ensure_array(leaf_refs, n_leaf, n_leaf + n)
    for k in range(n):
        leaf_refs[n_leaf + k] = refs[start + k]
    return leaf_refs, n_leaf + n
