"""The camera hits' frames: each hit's point, its geometric normal turned to face the camera ray, and
the start of its AO and shadow rays (the point offset off its surface, shading.offset_origin).

A block of hits goes through three loops (docs/choices.md#hit-frames-in-lanes):
1. gather: each hit's ray, triangle and instance matrix into lanes (one scratch row per quantity);
2. the arithmetic, lane by lane, with no branch, call or exception check, which LLVM vectorises
   (whole-register divides and square roots): the per-hit divides and roots were most of the pass;
3. scatter: the lanes into the (M, 3) outputs.
Each lane's operations are the ones a per-hit loop would do, in the same order: the same bits.
The kernels use NumPy's error model: Python's check for a division by zero is a branch out of the loop,
which stops the vectoriser. Every divisor is nonzero for a hit the triangle test reports; a degenerate
triangle's lane (never reported) keeps its point, its normal and start come out NaN.
"""
import numpy as np
from numba import njit, prange

from ..trace.array_views import unowned
from .shading import offset_origin

BLOCK = 64  # hits a parallel task takes, with one scratch

# Rows of a block's scratch. Inputs and outputs share one array made in the block's function, so LLVM
# sees constant row offsets and proves that stores to output rows never touch input rows (separate
# arrays would need more run-time overlap checks than the vectoriser makes).
ORIGIN, DIRECTION, T, VERTEX, OBJECT_NORMAL, MATRIX = 0, 3, 6, 7, 10, 13  # MATRIX: 12 rows, world to object
POINT, NORMAL, START = 25, 28, 31
ROWS = 34


@njit(cache=True, parallel=True, error_model="numpy")
def surface_frames(scene, origins, directions, t, inst, prim, hit_index, points, normals, starts):
    """The frames of the hits hit_index lists (rows of the ray and hit arrays) into rows of points,
    normals and starts (M, 3), in the order of hit_index."""
    n = hit_index.shape[0]
    for b in prange((n + BLOCK - 1) // BLOCK):
        first = np.int64(b) * BLOCK  # int64: Numba types a prange index differently in two places
        _frames_block(scene, (origins, directions, t, inst, prim), hit_index, (points, normals, starts), first,
                      min(n, first + BLOCK))


@njit(cache=True, error_model="numpy")
def _frames_block(scene, hits, hit_index, frames, start, stop):
    """surface_frames for hits start..stop-1 (at most BLOCK): gather, arithmetic in lanes, scatter."""
    lanes = np.empty((ROWS, BLOCK))
    count = stop - start
    _gather(scene, hits, hit_index, start, count, lanes)
    for k in range(count):  # no array passed to a helper here: its reference counts would stop the vectoriser
        o = (lanes[ORIGIN, k], lanes[ORIGIN + 1, k], lanes[ORIGIN + 2, k])
        d = (lanes[DIRECTION, k], lanes[DIRECTION + 1, k], lanes[DIRECTION + 2, k])
        v0 = (lanes[VERTEX, k], lanes[VERTEX + 1, k], lanes[VERTEX + 2, k])
        n = (lanes[OBJECT_NORMAL, k], lanes[OBJECT_NORMAL + 1, k], lanes[OBJECT_NORMAL + 2, k])
        a = ((lanes[MATRIX, k], lanes[MATRIX + 1, k], lanes[MATRIX + 2, k], lanes[MATRIX + 3, k]),
             (lanes[MATRIX + 4, k], lanes[MATRIX + 5, k], lanes[MATRIX + 6, k], lanes[MATRIX + 7, k]),
             (lanes[MATRIX + 8, k], lanes[MATRIX + 9, k], lanes[MATRIX + 10, k], lanes[MATRIX + 11, k]))
        frame = _frame_of(o, d, lanes[T, k], a, v0, n)
        for row in range(9):
            lanes[POINT + row, k] = frame[row]
    points, normals, starts = unowned(frames[0]), unowned(frames[1]), unowned(frames[2])
    for k in range(count):
        for c in range(3):
            points[start + k, c] = lanes[POINT + c, k]
            normals[start + k, c] = lanes[NORMAL + c, k]
            starts[start + k, c] = lanes[START + c, k]


@njit(cache=True, inline="always", error_model="numpy")
def _gather(scene, hits, hit_index, start, count, lanes):
    """Each hit's ray, its triangle's first vertex and object-space normal, its instance's matrix."""
    origins, directions, t, inst, prim = hits
    origins, directions = unowned(origins), unowned(directions)
    triangles, matrices = unowned(scene.triangles), unowned(scene.world_to_object)
    tri_start, mesh_of = unowned(scene.tri_start), unowned(scene.mesh_of)
    for k in range(count):
        r = hit_index[start + k]
        i = inst[r]
        j = tri_start[mesh_of[i]] + prim[r]
        for c in range(3):
            lanes[ORIGIN + c, k] = origins[r, c]
            lanes[DIRECTION + c, k] = directions[r, c]
            lanes[VERTEX + c, k] = triangles[j, 0, c]
        lanes[T, k] = t[r]
        n = _object_normal(triangles, j)
        for c in range(3):
            lanes[OBJECT_NORMAL + c, k] = n[c]
        for row in range(3):
            for c in range(4):
                lanes[MATRIX + 4 * row + c, k] = matrices[i, row, c]


@njit(cache=True, inline="always")
def _object_normal(triangles, j):
    """The unnormalised object-space normal e1 x e2 of float32 triangle j, in float64."""
    tri = triangles[j]
    e1x, e1y, e1z = (np.float64(tri[1, 0]) - tri[0, 0], np.float64(tri[1, 1]) - tri[0, 1],
                     np.float64(tri[1, 2]) - tri[0, 2])
    e2x, e2y, e2z = (np.float64(tri[2, 0]) - tri[0, 0], np.float64(tri[2, 1]) - tri[0, 1],
                     np.float64(tri[2, 2]) - tri[0, 2])
    return e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x


@njit(cache=True, inline="always", error_model="numpy")
def _frame_of(o, d, t, a, v0, n_object):
    """A hit's point, normal and ray start (9 values) from its ray (o, d, t), its instance's world-to-object
    rows `a` (3 x 4 tuples), its triangle's first vertex and object-space normal; no branch, so the loop
    around it vectorises."""
    p, moved = _onto_triangle_plane(a, v0, n_object, (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]))
    w = _world_normal_unnormalised(a, n_object)
    length = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    n = (w[0] / length, w[1] / length, w[2] / length)
    if n[0] * d[0] + n[1] * d[1] + n[2] * d[2] > 0.0:  # turned to face the ray; a select, not a branch
        n = (-n[0], -n[1], -n[2])
    start = offset_origin(p, n, _error_scale(a, v0, n_object, length, p, n, moved))
    return p[0], p[1], p[2], n[0], n[1], n[2], start[0], start[1], start[2]


@njit(cache=True, inline="always")
def _object_point(a, p):
    """World point p in object space (a: the instance's world-to-object rows, 3 x 4 tuples)."""
    return (a[0][0] * p[0] + a[0][1] * p[1] + a[0][2] * p[2] + a[0][3],
            a[1][0] * p[0] + a[1][1] * p[1] + a[1][2] * p[2] + a[1][3],
            a[2][0] * p[0] + a[2][1] * p[1] + a[2][2] * p[2] + a[2][3])


@njit(cache=True, inline="always")
def _world_normal_unnormalised(a, n):
    """The object-space normal times the inverse transpose of the object-to-world matrix, i.e. the
    transposed world-to-object matrix. A mirroring matrix flips its side; the caller turns it anyway."""
    return (a[0][0] * n[0] + a[1][0] * n[1] + a[2][0] * n[2], a[0][1] * n[0] + a[1][1] * n[1] + a[2][1] * n[2],
            a[0][2] * n[0] + a[1][2] * n[1] + a[2][2] * n[2])


@njit(cache=True, inline="always", error_model="numpy")
def _world_vector(a, ux, uy, uz):
    """The world vector x with a x = u (a's 3x3 part), by Cramer's rule: the scene keeps only
    world-to-object matrices."""
    c0x, c0y, c0z = a[1][1] * a[2][2] - a[1][2] * a[2][1], a[1][2] * a[2][0] - a[1][0] * a[2][2], \
        a[1][0] * a[2][1] - a[1][1] * a[2][0]
    c1x, c1y, c1z = a[0][2] * a[2][1] - a[0][1] * a[2][2], a[0][0] * a[2][2] - a[0][2] * a[2][0], \
        a[0][1] * a[2][0] - a[0][0] * a[2][1]
    c2x, c2y, c2z = a[0][1] * a[1][2] - a[0][2] * a[1][1], a[0][2] * a[1][0] - a[0][0] * a[1][2], \
        a[0][0] * a[1][1] - a[0][1] * a[1][0]
    det = a[0][0] * c0x + a[0][1] * c0y + a[0][2] * c0z
    return ((c0x * ux + c1x * uy + c2x * uz) / det, (c0y * ux + c1y * uy + c2y * uz) / det,
            (c0z * ux + c1z * uy + c2z * uz) / det)


@njit(cache=True, inline="always", error_model="numpy")
def _onto_triangle_plane(a, v0, n, p):
    """Hit point p moved along its triangle's normal onto the triangle's plane, and how far (the move's
    |x| + |y| + |z|, for _error_scale).

    p = o + t d inherits t's error, and t is a ratio of terms of the size of the triangle's reach R
    that cancel down to its width w across the ray: an error of about eps R^2 / w, which can exceed the
    ray offset on long thin triangles (AO rays starting under the face). The distance to the plane,
    (q - v0) . n, errs by only eps sum |n_k| |q_k - v0_k|, as a point rebuilt from barycentrics (pbrt-v3
    §3.9), which _error_scale's object-space term carries. Done in object space, where the triangle is.
    A degenerate triangle (n = 0) is never hit; its lane keeps p (the quotients are discarded)."""
    qx, qy, qz = _object_point(a, p)
    nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2]
    above = ((qx - v0[0]) * n[0] + (qy - v0[1]) * n[1] + (qz - v0[2]) * n[2]) / nn
    x, y, z = _world_vector(a, above * n[0], above * n[1], above * n[2])
    if nn == 0.0:
        return p, 0.0
    return (p[0] - x, p[1] - y, p[2] - z), abs(x) + abs(y) + abs(z)


@njit(cache=True, inline="always")
def _row_magnitude(a, k, p):
    """The magnitude of the terms of object coordinate k of world point p (what its rounding scales with)."""
    return abs(a[k][0] * p[0]) + abs(a[k][1] * p[1]) + abs(a[k][2] * p[2]) + abs(a[k][3])


@njit(cache=True, inline="always", error_model="numpy")
def _error_scale(a, v0, n_object, length, p, n, moved):
    """A magnitude whose float64 rounding bounds how far hit point p, moved onto its triangle's plane by
    `moved` (_onto_triangle_plane), may lie off it along unit normal n (`length`: |a^T n_object|): the
    largest of
    - sum |n_k| |p_k|: p's world coordinates round to their own ulps, seen along the normal;
    - the same for the object-space point q = a p + a_t and the operands q - v0, as a world distance
      (|a^T n_o| / |n_o| times shorter, so a shear stretching along the normal makes it longer);
    - the move: p, q = a p + a_t and q - v0 rounded at the size they had before it (bounded so for
      rotations with per-axis scales; a near-singular shear can exceed it).
    Not max |p_k| (a floor far along x would lift ray starts through a roof just above it), nor the
    camera ray's |o| and t |d|, whose error moves p along the ray, which the projection takes out, nor
    the triangle's reach: the triangle test drops a t within its rounding bound of the start, and an
    offset scaled by the reach lifted rays a unit off a ground of half-size 1e12
    (docs/choices.md#the-hit-distance-on-huge-triangles)."""
    world = abs(n[0] * p[0]) + abs(n[1] * p[1]) + abs(n[2] * p[2])
    qx, qy, qz = _object_point(a, p)
    along = (abs(n_object[0]) * (_row_magnitude(a, 0, p) + abs(qx - v0[0]))
             + abs(n_object[1]) * (_row_magnitude(a, 1, p) + abs(qy - v0[1]))
             + abs(n_object[2]) * (_row_magnitude(a, 2, p) + abs(qz - v0[2])))
    objectspace = along / length if length > 0.0 else 0.0
    return max(world, objectspace, moved)
