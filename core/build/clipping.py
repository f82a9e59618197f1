"""Exact-enough clipping of a triangle to a box, for "perfect splits".

A straddler's box in each child is the box of its part inside that child (Havran's split clipping;
seed 002), so fewer references go further down and empty space is cut off sooner. Robustness: clipped
in float64, the box rounded *outward* to float32 and cut to the clip box, so it always contains the true
part and a ray hitting the triangle finds it in a leaf it visits.
"""
import numpy as np
from numba import njit

MAX_POLY = 9  # a triangle clipped by 6 planes has at most 3 + 6 vertices


@njit(cache=True)
def new_clip_scratch():
    """Two polygon buffers reused by every clip call of one thread (no allocation per call)."""
    return np.empty((MAX_POLY + 1, 3), np.float64), np.empty((MAX_POLY + 1, 3), np.float64)


@njit(cache=True)
def clip_triangle(tri, box, scratch_a, scratch_b, out):
    """Write the box of (triangle ∩ box) into `out`; return False if the intersection is empty."""
    poly, other = scratch_a, scratch_b
    for i in range(3):
        for k in range(3):
            poly[i, k] = tri[i, k]
    n = 3
    for axis in range(3):
        for side in range(2):  # the box's low plane, then its high one
            plane, sign = box[axis + 3 * side], 1.0 - 2.0 * side
            if _inside_plane(tri, axis, plane, sign):
                continue  # the whole triangle is on the kept side: the clip would copy the polygon
            n = _clip_plane(poly, n, axis, plane, sign, other)
            poly, other = other, poly
            if n == 0:
                return False
    _polygon_box(poly, n, box, out)
    return True


@njit(cache=True, inline="always")
def split_triangle_inside(tris, prim, axis, pos, poly_left, poly_right, out_left, out_right):
    """The clip_triangle results for both sides of the plane `pos` on `axis` when triangle tris[prim] lies in
    `box` (triangle_in_box): then the split plane is the only one that cuts, and one pass over the
    edges builds both polygons as _clip_plane does, vertex for vertex in the same order (a crossing
    edge's point is the same computed from either side, negation being exact), so the boxes are
    bit-identical to clipping each side. out_left / out_right hold the two clip regions on entry.
    Returns (left part not empty, right part not empty). The triangle is indexed, not taken as a view:
    a view costs reference counting per straddler (docs/choices.md#no-views-per-straddler)."""
    n_left = n_right = 0
    for i in range(3):
        j = i + 1 if i < 2 else 0
        di = np.float64(tris[prim, i, axis]) - pos
        dj = np.float64(tris[prim, j, axis]) - pos
        if di <= 0.0:
            n_left = _put_vertex(poly_left, n_left, tris, prim, i)
        if di >= 0.0:
            n_right = _put_vertex(poly_right, n_right, tris, prim, i)
        if (di < 0.0 and dj > 0.0) or (di > 0.0 and dj < 0.0):
            f = di / (di - dj)
            for k in range(3):
                vi = np.float64(tris[prim, i, k])
                poly_left[n_left, k] = poly_right[n_right, k] = vi + f * (np.float64(tris[prim, j, k]) - vi)
            poly_left[n_left, axis] = poly_right[n_right, axis] = pos
            n_left += 1
            n_right += 1
    if n_left:
        _polygon_box(poly_left, n_left, out_left, out_left)
    if n_right:
        _polygon_box(poly_right, n_right, out_right, out_right)
    return n_left > 0, n_right > 0


@njit(cache=True, inline="always")
def _put_vertex(poly, n, tris, prim, i):
    for k in range(3):
        poly[n, k] = tris[prim, i, k]
    return n + 1


@njit(cache=True, inline="always")
def triangle_in_box(tris, prim, boxes, row):
    """Does every vertex of tris[prim] lie in the closed box boxes[row] (no plane of it would cut the
    triangle)?"""
    for i in range(3):
        for k in range(3):
            if not boxes[row, k] <= tris[prim, i, k] <= boxes[row, k + 3]:
                return False
    return True


@njit(cache=True, inline="always")
def _inside_plane(tri, axis, plane, sign):
    """Does the whole triangle lie on the kept side of the plane (as _clip_plane measures it)?
    A straddler is usually small against its node, so most of the six planes cut nothing. Skipping
    them leaves the polygon as the copy would, and the tree bit-identical (checked on suzanne-251k)."""
    for i in range(3):
        if sign * (np.float64(tri[i, axis]) - plane) < 0.0:
            return False
    return True


@njit(cache=True, inline="always")
def _clip_plane(poly, n, axis, plane, sign, out):
    """Sutherland-Hodgman step: keep the part of `poly` with sign * (x[axis] - plane) >= 0."""
    m = 0
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        di = sign * (poly[i, axis] - plane)
        dj = sign * (poly[j, axis] - plane)
        if di >= 0.0:
            for k in range(3):
                out[m, k] = poly[i, k]
            m += 1
        if (di < 0.0 and dj > 0.0) or (di > 0.0 and dj < 0.0):
            f = di / (di - dj)
            for k in range(3):
                out[m, k] = poly[i, k] + f * (poly[j, k] - poly[i, k])
            out[m, axis] = plane  # the new vertex lies exactly on the plane
            m += 1
    return m


@njit(cache=True, inline="always")
def _polygon_box(poly, n, clip_box, out):
    """Box of the polygon, rounded outward to float32 and intersected with `clip_box`."""
    for k in range(3):
        lo = poly[0, k]
        hi = poly[0, k]
        for i in range(1, n):
            lo = min(lo, poly[i, k])
            hi = max(hi, poly[i, k])
        out[k] = max(round_down(lo), clip_box[k])
        out[k + 3] = min(round_up(hi), clip_box[k + 3])


@njit(cache=True, inline="always")
def round_down(x):
    """The largest float32 <= x."""
    f = np.float32(x)
    if np.float64(f) > x:
        f = next_float32(f, False)
    return f


@njit(cache=True, inline="always")
def round_up(x):
    """The smallest float32 >= x."""
    f = np.float32(x)
    if np.float64(f) < x:
        f = next_float32(f, True)
    return f


@njit(cache=True, inline="always")
def next_float32(f, up):
    """np.nextafter(f, +inf if up else -inf) for a finite float32 f, by stepping its bit pattern:
    Numba's nextafter is a library call that nothing can inline, and every clipped box rounds six
    bounds (docs/choices.md#rounding-without-nextafter)."""
    bits = f.view(np.int32)
    if bits == 0 or bits == np.int32(-2147483648):  # +0 or -0: the smallest subnormal of that direction
        return np.int32(1 if up else -2147483647).view(np.float32)
    away_from_zero = (bits > 0) == up
    return np.int32(bits + 1 if away_from_zero else bits - 1).view(np.float32)
