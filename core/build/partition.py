"""Distributing a node's references to its children.

Exact in float32 (no epsilon): a reference goes left when its box ends at or before the plane, right
when it begins at or after it, both when it straddles. One lying in the plane goes to the side the split
chose (seed 004 §4.1's problem): a ray hitting it crosses the plane there, so either side finds it.
Straddlers are clipped to each child (clipping.py); a side where the clipped triangle is empty lacks it.
"""
import numpy as np
from numba import njit

from ..trace.array_views import at
from .clipping import clip_triangle, new_clip_scratch, split_triangle_inside, triangle_in_box

LEFT, RIGHT, BOTH = 1, 2, 3


@njit(cache=True)
def new_split_scratch():
    """Per-thread buffers for split_reference (two polygons, one clip region) and for the two child
    boxes of a straddler, so partitioning allocates nothing per node."""
    poly_a, poly_b = new_clip_scratch()
    return poly_a, poly_b, np.empty(6, np.float32), np.empty(6, np.float32), np.empty(6, np.float32)


@njit(cache=True, inline="always")
def side_of(boxes, i, axis, pos, planar_left):
    """LEFT, RIGHT or BOTH for reference i's box and a split plane."""
    lo = boxes[i, axis]
    hi = boxes[i, axis + 3]
    if lo == hi and lo == pos:
        return LEFT if planar_left else RIGHT
    if hi <= pos:
        return LEFT
    if lo >= pos:
        return RIGHT
    return BOTH


@njit(cache=True, inline="always")
def split_reference(tris, prim, boxes, row, axis, pos, clip, scratch, out_left, out_right):
    """Boxes of the parts on each side of the plane of straddling reference boxes[row] (triangle
    tris[prim]); returns the sides that are not empty. Indexed, never viewed: a view or a row assignment
    costs reference counting per straddler (docs/choices.md#no-views-per-straddler)."""
    _cut_parts(boxes, row, axis, pos, out_left, out_right)
    if not clip:
        return BOTH
    poly_a, poly_b, region, _, _ = scratch
    if triangle_in_box(tris, prim, boxes, row):  # the usual straddler, never cut before: one pass for both sides
        in_left, in_right = split_triangle_inside(tris, prim, axis, pos, poly_a, poly_b, out_left, out_right)
    else:
        tri = tris[prim]
        for k in range(6):
            region[k] = out_left[k]
        in_left = clip_triangle(tri, region, poly_a, poly_b, out_left)
        for k in range(6):
            region[k] = boxes[row, k]
        region[axis] = pos
        in_right = clip_triangle(tri, region, poly_a, poly_b, out_right)
    if not (in_left or in_right):
        # Only rounding can empty both sides of a straddler; keep it on both, unclipped.
        _cut_parts(boxes, row, axis, pos, out_left, out_right)
        return BOTH
    return (LEFT if in_left else 0) | (RIGHT if in_right else 0)


@njit(cache=True, inline="always")
def _cut_parts(boxes, row, axis, pos, out_left, out_right):
    """out_left / out_right = box boxes[row] cut at the plane: its parts left and right of it."""
    b0, b1, b2, b3, b4, b5 = boxes[row, 0], boxes[row, 1], boxes[row, 2], boxes[row, 3], boxes[row, 4], boxes[row, 5]
    out_left[0], out_left[1], out_left[2], out_left[3], out_left[4], out_left[5] = b0, b1, b2, b3, b4, b5
    out_right[0], out_right[1], out_right[2], out_right[3], out_right[4], out_right[5] = b0, b1, b2, b3, b4, b5
    out_left[axis + 3] = pos
    out_right[axis] = pos


@njit(cache=True, inline="always")
def partition_in_place(tris, prims, boxes, start, end, axis, pos, planar_left, clip, scratch):
    """Split references [start, end) into right ones at [start, start+nr) and left ones at [end, end+nl).
    Right ones are compacted in place (each makes at most one, so writes never pass reads); left ones
    stay where they are written, past the node's own range: moving them down next to the right ones
    would copy them a second time (docs/choices.md#left-children-left-in-place). The caller leaves room
    for 2 * (end - start) from `start`. Returns (n_right, n_left). The left child is on top of the pool,
    so built first it grows freely (seed 000 §3.5)."""
    box_l, box_r = scratch[3], scratch[4]
    w_right = start
    w_left = end
    for j in range(start, end):
        i = at(j)  # unsigned: no negative-index fix-up at each access (array_views.at)
        side = side_of(boxes, i, axis, pos, planar_left)
        if side == LEFT:
            _copy_ref(prims, boxes, i, at(w_left))
            w_left += 1
            continue
        if side == RIGHT:
            _copy_ref(prims, boxes, i, at(w_right))
            w_right += 1
            continue
        prim = prims[i]
        side = split_reference(tris, prim, boxes, i, axis, pos, clip, scratch, box_l, box_r)
        if side & LEFT:
            _put_ref(prims, boxes, at(w_left), prim, box_l)
            w_left += 1
        if side & RIGHT:
            _put_ref(prims, boxes, at(w_right), prim, box_r)
            w_right += 1
    return w_right - start, w_left - end


@njit(cache=True, inline="always")
def _put_ref(prims, boxes, dst, prim, box):
    """Reference `prim` with `box` at dst, the box read whole first (see _copy_ref)."""
    b0, b1, b2, b3, b4, b5 = box[0], box[1], box[2], box[3], box[4], box[5]
    prims[dst] = prim
    boxes[dst, 0], boxes[dst, 1], boxes[dst, 2], boxes[dst, 3], boxes[dst, 4], boxes[dst, 5] = b0, b1, b2, b3, b4, b5


@njit(cache=True, inline="always")
def _copy_ref(prims, boxes, src, dst):
    """Reference src to dst, the box read whole before it is written: rows of one array may overlap
    for all the compiler knows, so interleaved element copies stay scalar, while this becomes vector
    loads and stores."""
    b0, b1, b2, b3, b4, b5 = boxes[src, 0], boxes[src, 1], boxes[src, 2], boxes[src, 3], boxes[src, 4], boxes[src, 5]
    prims[dst] = prims[src]
    boxes[dst, 0], boxes[dst, 1], boxes[dst, 2], boxes[dst, 3], boxes[dst, 4], boxes[dst, 5] = b0, b1, b2, b3, b4, b5
