"""Exact SAH by sweeping sorted events (seed 004 §3.1; Wald and Havran 2006).

Per axis, a reference is a start and an end event where its box has extent, or one planar event where
it has none. The sweep visits each distinct position once, counting references that end, lie and start
there; planar references at a candidate plane go to the cheaper side (seed 004 §4.1 widens planar
boxes instead; this rule is exact and needs no epsilon).
"""
import numpy as np
from numba import njit

from ..geometry import half_area
from .sah import split_cost, valid_position


@njit(cache=True)
def exact_split(boxes, start, end, node_box, params, scratch):
    """Cheapest split of the node: (cost, axis, position, planar_left); axis -1 if none is valid.
    `scratch` is a float32 buffer of at least 3 * (end - start) values."""
    n = end - start
    inv_area = 1.0 / half_area(node_box)
    best_cost, best_axis, best_pos, best_planar_left = np.inf, -1, np.float32(0.0), False
    for axis in range(3):
        if not node_box[axis] < node_box[axis + 3]:
            continue
        starts, ends, planars, n_spans, n_planar = _axis_events(boxes, start, end, axis, scratch)
        cost, pos, planar_left = _sweep(starts, ends, planars, n_spans, n_planar, n, node_box, inv_area,
                                        axis, params)
        if cost < best_cost:
            best_cost, best_axis, best_pos, best_planar_left = cost, axis, pos, planar_left
    return best_cost, best_axis, best_pos, best_planar_left


@njit(cache=True)
def _axis_events(boxes, start, end, axis, scratch):
    """Sorted start, end and planar positions of the references along one axis."""
    n = end - start
    starts = scratch[0:n]
    ends = scratch[n:2 * n]
    planars = scratch[2 * n:3 * n]
    n_spans = 0
    n_planar = 0
    for i in range(start, end):
        lo = boxes[i, axis]
        hi = boxes[i, axis + 3]
        if lo == hi:
            planars[n_planar] = lo
            n_planar += 1
        else:
            starts[n_spans] = lo
            ends[n_spans] = hi
            n_spans += 1
    _sort(starts, n_spans)
    _sort(ends, n_spans)
    _sort(planars, n_planar)
    return starts, ends, planars, n_spans, n_planar


INSERTION_SORT_MAX = 48


@njit(cache=True, inline="always")
def _sort(values, n):
    """Sort values[:n] in place; insertion sort for the short lists of small nodes (less overhead)."""
    if n > INSERTION_SORT_MAX:
        values[:n].sort()
        return
    for i in range(1, n):
        v = values[i]
        j = i - 1
        while j >= 0 and values[j] > v:
            values[j + 1] = values[j]
            j -= 1
        values[j + 1] = v


@njit(cache=True)
def _sweep(starts, ends, planars, n_spans, n_planar, n, node_box, inv_area, axis, params):
    """Walk the three sorted event lists together and keep the cheapest valid plane."""
    best_cost, best_pos, best_planar_left = np.inf, np.float32(0.0), False
    i_start = i_end = i_planar = 0
    n_left, n_right = 0, n
    while i_start < n_spans or i_end < n_spans or i_planar < n_planar:
        pos = _next_position(starts, ends, planars, i_start, i_end, i_planar, n_spans, n_planar)
        ending, i_end = _count_at(ends, i_end, n_spans, pos)
        lying, i_planar = _count_at(planars, i_planar, n_planar, pos)
        beginning, i_start = _count_at(starts, i_start, n_spans, pos)
        n_right -= ending + lying
        if valid_position(node_box, axis, pos):
            cost_l = split_cost(node_box, inv_area, axis, pos, n_left + lying, n_right, params)
            cost_r = split_cost(node_box, inv_area, axis, pos, n_left, n_right + lying, params)
            if cost_l < best_cost:
                best_cost, best_pos, best_planar_left = cost_l, pos, True
            if cost_r < best_cost:
                best_cost, best_pos, best_planar_left = cost_r, pos, False
        n_left += beginning + lying
    return best_cost, best_pos, best_planar_left


@njit(cache=True, inline="always")
def _next_position(starts, ends, planars, i_start, i_end, i_planar, n_spans, n_planar):
    pos = np.float32(np.inf)
    if i_start < n_spans:
        pos = min(pos, starts[i_start])
    if i_end < n_spans:
        pos = min(pos, ends[i_end])
    if i_planar < n_planar:
        pos = min(pos, planars[i_planar])
    return pos


@njit(cache=True, inline="always")
def _count_at(values, i, n, pos):
    """How many of the sorted values from index i equal pos, and the index after them."""
    j = i
    while j < n and values[j] == pos:
        j += 1
    return j - i, j
