"""Boxes of triangles and the few box measures the builder needs.

A box is 6 float32 numbers: (xmin, ymin, zmin, xmax, ymax, zmax). Boxes stay float32 so that split
positions, which are taken from box faces or bin boundaries rounded to float32, compare exactly.
"""
import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def triangle_boxes(tris):
    """Boxes of all triangles, and which triangles have non-zero area.
    Zero-area triangles (all three cross-product components exactly zero) can never be hit (the
    watertight test rejects them), so the builder leaves them out of the tree altogether."""
    n = tris.shape[0]
    boxes = np.empty((n, 6), np.float32)
    keep = np.empty(n, np.bool_)
    for i in prange(n):
        for k in range(3):
            lo = min(tris[i, 0, k], tris[i, 1, k], tris[i, 2, k])
            hi = max(tris[i, 0, k], tris[i, 1, k], tris[i, 2, k])
            boxes[i, k] = lo
            boxes[i, k + 3] = hi
        keep[i] = has_area(tris[i])
    return boxes, keep


@njit(cache=True)
def has_area(tri):
    """True unless the triangle's edge cross product is exactly zero (computed in float64)."""
    ax = np.float64(tri[1, 0]) - tri[0, 0]
    ay = np.float64(tri[1, 1]) - tri[0, 1]
    az = np.float64(tri[1, 2]) - tri[0, 2]
    bx = np.float64(tri[2, 0]) - tri[0, 0]
    by = np.float64(tri[2, 1]) - tri[0, 1]
    bz = np.float64(tri[2, 2]) - tri[0, 2]
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    return cx != 0.0 or cy != 0.0 or cz != 0.0


@njit(cache=True)
def union_of_boxes(boxes):
    """The box around all `boxes` (an (n, 6) array); an inverted box when n == 0."""
    out = np.empty(6, np.float32)
    for k in range(3):
        out[k] = np.inf
        out[k + 3] = -np.inf
    for i in range(boxes.shape[0]):
        for k in range(3):
            out[k] = min(out[k], boxes[i, k])
            out[k + 3] = max(out[k + 3], boxes[i, k + 3])
    return out


@njit(cache=True, inline="always")
def extents(box):
    """The box's three extents in float64."""
    return np.float64(box[3]) - box[0], np.float64(box[4]) - box[1], np.float64(box[5]) - box[2]


@njit(cache=True, inline="always")
def longest_axis(box):
    """The axis of the box's largest extent (in the box's own precision), the first of equal ones."""
    axis = 0
    for k in range(1, 3):
        if box[k + 3] - box[k] > box[axis + 3] - box[axis]:
            axis = k
    return axis


@njit(cache=True, inline="always")
def half_area(box):
    """Half the surface area of a box: the SAH only ever uses ratios of it."""
    ex, ey, ez = extents(box)
    return ex * ey + ey * ez + ez * ex


@njit(cache=True, inline="always")
def half_area_cut(box, axis, lo, hi):
    """Half area of `box` with its extent along `axis` replaced by [lo, hi]."""
    return cut_half_area(extents(box), axis, np.float64(hi) - lo)


@njit(cache=True, inline="always")
def cut_half_area(e, axis, extent):
    """Half area of a box of extents `e` with the one along `axis` replaced by `extent`; a loop over
    many cuts of one box computes `e` once (the same products in the same order as half_area)."""
    e0, e1, e2 = e
    if axis == 0:
        e0 = extent
    elif axis == 1:
        e1 = extent
    else:
        e2 = extent
    return e0 * e1 + e1 * e2 + e2 * e0
