"""Which split a node gets, if any: the builder's finder plus the termination rules (seed 003 §3.5)."""
import numpy as np
from numba import njit

from .options import EXACT, MEDIAN
from .sah import beats_leaf
from .split_binned import binned_split
from .split_exact import exact_split
from .split_median import median_split

NO_SPLIT = -1


@njit(cache=True, inline="always")
def choose_split(boxes, start, end, node_box, depth, params, bins, scratch):
    """(axis, position, planar_left) of the node's split; axis is NO_SPLIT when it becomes a leaf.
    "binned" switches to the exact sweep at `exact_below` references (seed 000 §3.4). bins: the
    thread's (min_bins, max_bins, sweep scratch) for binned_split."""
    n = end - start
    if n <= params.leaf_size or depth >= params.max_depth:
        return NO_SPLIT, np.float32(0.0), False
    planar_left = False
    if params.builder == MEDIAN:
        cost, axis, pos = median_split(boxes, start, end, node_box, params)
    elif params.builder == EXACT or n <= params.exact_below:
        cost, axis, pos, planar_left = exact_split(boxes, start, end, node_box, params, scratch)
    else:
        cost, axis, pos, planar_left = binned_split(boxes, start, end, node_box, params, bins)
    if axis < 0 or not beats_leaf(cost, n, node_box, params):
        return NO_SPLIT, np.float32(0.0), False
    return axis, pos, planar_left
