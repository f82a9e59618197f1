"""Spatial median split: the cheap baseline builder.

The plane halves the node's longest axis. The SAH is still evaluated for the chosen plane so that the
same termination rule (cost ratio, leaf size, depth) decides when to stop.
"""
import numpy as np
from numba import njit

from ..geometry import half_area, longest_axis
from .sah import split_cost, valid_position


@njit(cache=True)
def median_split(boxes, start, end, node_box, params):
    """(cost, axis, position) of the spatial median of the longest axis; axis -1 if it is flat."""
    axis = longest_axis(node_box)
    pos = np.float32(0.5 * (np.float64(node_box[axis]) + node_box[axis + 3]))
    if not valid_position(node_box, axis, pos):
        return np.inf, -1, pos
    n_left = 0
    n_right = 0
    for i in range(start, end):
        lo = boxes[i, axis]
        hi = boxes[i, axis + 3]
        n_left += lo < pos
        n_right += hi > pos or (lo == hi and lo == pos)
    cost = split_cost(node_box, 1.0 / half_area(node_box), axis, pos, n_left, n_right, params)
    return cost, axis, pos
