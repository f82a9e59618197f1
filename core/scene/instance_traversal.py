"""Tracing a ray through a two-level scene: the top-level tree over instances, then, for each instance
in a top leaf, the mesh's own tree in object space through the one kd-tree traversal (trace_ray).

The top level is walked with the traversal's own steps and stop rules; only the leaf test differs: an
instance test, skipped for an instance that does not stop the ray's kind (ray_visibility.py) or whose
world box the ray misses (issue 50's "instance boxes tested before entering"). The ray
is carried into object space by the world-to-object matrix without normalising the direction, so t is
the same in both spaces and the best hit so far is passed on as tmax (Wald 2004, seed 000 §5).
trace_scene is inlined into its callers (docs/choices.md#inline-the-scene-traversal).
"""
import numpy as np
from numba import njit, prange

from ..trace.array_views import at, rows, unowned
from ..trace.layout import LEAF, NO_HIT, TreeArrays
from ..trace.traversal import (RAYS_PER_TASK, STACK_SIZE, _descend, _pop, block_range, clip_to_box,
                        interleaved_blocks, trace_ray)
from ..trace.triangle_test import LEAF_CHUNK
from .two_level import SceneArrays


@njit(cache=True)
def new_scratch():
    """Per-thread buffers: the top level's stack and inverse direction, the mesh traversal's stack and
    inverse direction, the object-space ray, and the mesh traversal's leaf flags: four allocations cut
    into unowned views, followed by the four owners that keep them alive."""
    nodes = np.empty(2 * STACK_SIZE, np.int32)
    intervals = np.empty((2 * STACK_SIZE, 3))
    vectors = np.empty(12)
    flags = np.empty(LEAF_CHUNK, np.uint8)
    return (rows(nodes, 0, STACK_SIZE), rows(intervals, 0, STACK_SIZE), rows(vectors, 0, 3),
            rows(nodes, STACK_SIZE, 2 * STACK_SIZE), rows(intervals, STACK_SIZE, 2 * STACK_SIZE), rows(vectors, 3, 6),
            rows(vectors, 6, 9), rows(vectors, 9, 12), rows(flags, 0, LEAF_CHUNK), nodes, intervals, vectors, flags)


@njit(cache=True, inline="always")
def unowned_scene(s):
    """The SceneArrays (two_level.TwoLevelScene.arrays) as unowned views, made once per block of rays
    (array_views.py)."""
    return SceneArrays(unowned(s.top_axis), unowned(s.top_split), unowned(s.top_child), unowned(s.top_count),
                       unowned(s.top_items), unowned(s.top_bounds), unowned(s.world_to_object), unowned(s.mesh_of),
                       unowned(s.node_start), unowned(s.ref_start), unowned(s.tri_start), unowned(s.box_start),
                       unowned(s.axis), unowned(s.split), unowned(s.child), unowned(s.count), unowned(s.leaf_prims),
                       unowned(s.triangles), unowned(s.mesh_bounds), unowned(s.leaf_triangles),
                       unowned(s.leaf_boxes), unowned(s.visibility), unowned(s.world_boxes))


@njit(cache=True, inline="always")
def mesh_tree(scene, m):
    """Mesh m's tree as the TreeArrays trace_ray takes: unowned views into the packed arrays
    (array_views.py says why not slices)."""
    node_start, ref_start, tri_start, box_start = scene.node_start, scene.ref_start, scene.tri_start, scene.box_start
    n0, n1 = node_start[m], node_start[m + 1]
    return TreeArrays(rows(scene.axis, n0, n1), rows(scene.split, n0, n1), rows(scene.child, n0, n1),
                      rows(scene.count, n0, n1), rows(scene.leaf_prims, ref_start[m], ref_start[m + 1]),
                      rows(scene.triangles, tri_start[m], tri_start[m + 1]), rows(scene.mesh_bounds, m, m + 1)[0],
                      scene.leaf_triangles, rows(scene.leaf_boxes, box_start[m], box_start[m + 1]), ref_start[m])


@njit(cache=True, inline="always")
def _to_object(w2o, o, d, o_obj, d_obj):
    for k in range(3):
        o_obj[k] = w2o[k, 0] * o[0] + w2o[k, 1] * o[1] + w2o[k, 2] * o[2] + w2o[k, 3]
        d_obj[k] = w2o[k, 0] * d[0] + w2o[k, 1] * d[1] + w2o[k, 2] * d[2]


@njit(cache=True, inline="always")
def trace_instance(scene, inst, o, d, tmin, tmax, any_hit, scratch):
    """(t, prim, u, v) of the ray against one instance, in (tmin, tmax); prim -1 on a miss."""
    stack_node, stack_t, inv, o_obj, d_obj, flags = scratch[3:9]
    _to_object(rows(scene.world_to_object, inst, inst + 1)[0], o, d, o_obj, d_obj)
    if d_obj[0] == 0.0 and d_obj[1] == 0.0 and d_obj[2] == 0.0:
        return np.inf, -1, 0.0, 0.0  # underflow of an extreme scale: nothing to trace
    return trace_ray(mesh_tree(scene, scene.mesh_of[inst]), o_obj, d_obj, tmin, tmax, any_hit, stack_node, stack_t,
                     inv, flags)


@njit(cache=True, inline="always")
def _misses_box(world_boxes, inst, o, d, inv, tmin, tmax):
    """Whether the ray misses the instance's world box within (tmin, tmax): most instances of a top leaf
    do (their boxes only overlap the leaf's cell), and this float64 clip of a box rounded outward, widened
    as every clip is (traversal.clip_to_box), spares them the transform into object space."""
    t0, t1 = clip_to_box(rows(world_boxes, inst, inst + 1)[0], o, d, inv, tmin, tmax)
    return t0 > t1


@njit(cache=True, inline="always")
def trace_scene(scene, o, d, tmin, tmax, any_hit, ray_mask, scratch):
    """(t, instance, prim, u, v) of the closest hit in (tmin, tmax), or of any hit if `any_hit`, among
    the instances whose visibility shares a bit with `ray_mask` (the ray's kind, ray_visibility.py);
    instance and prim are -1 on a miss. A ray that reaches an unbuilt subtree of a lazy mesh tree stops
    there: prim is then trace_ray's suspended value (< NO_HIT) and instance the one it stopped in.
    `scratch` comes from new_scratch() and is reused across rays. A flat tree (one instance in a
    one-leaf top) goes through the same leaf loop, without the top's clip."""
    axis, split, child, count = scene.top_axis, scene.top_split, scene.top_child, scene.top_count
    items, root_box, visibility = scene.top_items, scene.top_bounds, scene.visibility
    if items.shape[0] == 0:
        return np.inf, -1, -1, 0.0, 0.0
    stack_node, stack_t, inv = scratch[0], scratch[1], scratch[2]
    t0, t1 = tmin, tmax
    flat = items.shape[0] == 1 and axis[0] == LEAF
    if not flat:
        for k in range(3):
            inv[k] = 1.0 / d[k] if d[k] != 0.0 else 0.0
        t0, t1 = clip_to_box(root_box, o, d, inv, tmin, tmax)
        if t0 > t1:
            return np.inf, -1, -1, 0.0, 0.0
    best_t, best_inst, best_prim, best_u, best_v = tmax, -1, -1, 0.0, 0.0
    node, sp, t_exit = 0, 0, t1
    while True:
        a = axis[at(node)]
        if a != LEAF:
            node, t1, t_exit, sp = _descend(node, a, split[at(node)], child[at(node)], o[at(a)], d[at(a)], inv[at(a)],
                                            t0, t1, t_exit, (stack_node, stack_t), sp)
            continue
        first = child[at(node)]
        for j in range(first, first + count[at(node)]):
            if visibility[items[j]] & ray_mask == 0:
                continue
            if not flat and _misses_box(scene.world_boxes, items[j], o, d, inv, tmin, best_t):
                continue
            t, prim, u, v = trace_instance(scene, items[j], o, d, tmin, best_t, any_hit, scratch)
            if prim < NO_HIT:  # a lazy mesh tree's unbuilt subtree: the caller builds it and retraces
                return np.inf, items[j], prim, 0.0, 0.0
            if prim >= 0 and t < best_t:
                best_t, best_inst, best_prim, best_u, best_v = t, items[j], prim, u, v
                if any_hit:
                    return best_t, best_inst, best_prim, best_u, best_v
        if best_prim >= 0 and best_t <= t_exit:  # the traversal's stop rules (traversal.py)
            break
        node, t0, t1, t_exit, sp = _pop(stack_node, stack_t, sp, best_t, best_prim >= 0)
        if node < 0:
            break
    if best_prim < 0:
        return np.inf, -1, -1, 0.0, 0.0
    return best_t, best_inst, best_prim, best_u, best_v


@njit(cache=True, parallel=True)
def trace_scene_rays(scene, origins, directions, tmin, tmax, any_hit, ray_mask, out_t, out_inst, out_prim, out_u,
                     out_v):
    """Trace all rays (of kind ray_mask) in parallel, in blocks of RAYS_PER_TASK that share one scratch."""
    n = origins.shape[0]
    iterations, per_band, run = interleaved_blocks(n, RAYS_PER_TASK)  # balances image regions (traversal.py)
    for i in prange(iterations):
        start, stop = block_range(i, per_band, run, n, RAYS_PER_TASK)
        _trace_block(scene, origins, directions, tmin, tmax, any_hit, ray_mask, start, stop,
                     (out_t, out_inst, out_prim, out_u, out_v))


@njit(cache=True)
def _trace_block(scene, origins, directions, tmin, tmax, any_hit, ray_mask, start, stop, out):
    """Rays start..stop-1 with one scratch and the scene as unowned views; out: the five output arrays
    of trace_scene_rays, in its order."""
    out_t, out_inst, out_prim, out_u, out_v = out
    scratch = new_scratch()
    views = unowned_scene(scene)
    for r in range(start, stop):
        t, inst, prim, u, v = trace_scene(views, rows(origins, r, r + 1)[0], rows(directions, r, r + 1)[0], tmin[r],
                                          tmax[r], any_hit, ray_mask, scratch)
        out_t[r] = t
        out_inst[r] = inst
        out_prim[r] = prim
        out_u[r] = u
        out_v[r] = v


@njit(cache=True, inline="always")
def _object_normal(tri):
    """The unnormalised object-space normal e1 x e2 of a float32 triangle, in float64."""
    e1x, e1y, e1z = (np.float64(tri[1, 0]) - tri[0, 0], np.float64(tri[1, 1]) - tri[0, 1],
                     np.float64(tri[1, 2]) - tri[0, 2])
    e2x, e2y, e2z = (np.float64(tri[2, 0]) - tri[0, 0], np.float64(tri[2, 1]) - tri[0, 1],
                     np.float64(tri[2, 2]) - tri[0, 2])
    return e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x


@njit(cache=True, inline="always")
def hit_surface(scene, inst, prim):
    """What the hit frame needs of instance inst's triangle prim, fetched and computed once per hit:
    (triangle (3, 3), world-to-object rows (3, 4), inverse_parts of them, object-space normal e1 x e2)."""
    j = scene.tri_start[scene.mesh_of[inst]] + prim
    tri = rows(scene.triangles, j, j + 1)[0]
    a = rows(scene.world_to_object, inst, inst + 1)[0]
    return tri, a, inverse_parts(a), _object_normal(tri)


@njit(cache=True, inline="always")
def world_normal(surface, out):
    """Unit geometric normal of a hit_surface in world space: the object-space normal times
    the inverse transpose of the object-to-world matrix, i.e. the transposed world-to-object matrix.
    A mirroring matrix flips its side; callers turn it to face the ray anyway."""
    _, w2o, _, (nx, ny, nz) = surface
    for k in range(3):
        out[k] = w2o[0, k] * nx + w2o[1, k] * ny + w2o[2, k] * nz
    norm = np.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
    for k in range(3):
        out[k] /= norm


@njit(cache=True, inline="always")
def _object_point(a, p):
    """World point p in object space (a: the instance's 3x4 world-to-object rows)."""
    return (a[0, 0] * p[0] + a[0, 1] * p[1] + a[0, 2] * p[2] + a[0, 3],
            a[1, 0] * p[0] + a[1, 1] * p[1] + a[1, 2] * p[2] + a[1, 3],
            a[2, 0] * p[0] + a[2, 1] * p[1] + a[2, 2] * p[2] + a[2, 3])


@njit(cache=True, inline="always")
def inverse_parts(a):
    """The cofactors (by column of the inverse) and determinant of a's 3x3 part, for _world_vector."""
    c0x, c0y, c0z = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1], a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2], \
        a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    c1x, c1y, c1z = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2], a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0], \
        a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c2x, c2y, c2z = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1], a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2], \
        a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    det = a[0, 0] * c0x + a[0, 1] * c0y + a[0, 2] * c0z
    return c0x, c0y, c0z, c1x, c1y, c1z, c2x, c2y, c2z, det


@njit(cache=True, inline="always")
def _world_vector(parts, ux, uy, uz):
    """The world vector x with a x = u (a's 3x3 part, given as inverse_parts(a)), by Cramer's rule:
    the scene keeps only world-to-object matrices."""
    c0x, c0y, c0z, c1x, c1y, c1z, c2x, c2y, c2z, det = parts
    return ((c0x * ux + c1x * uy + c2x * uz) / det, (c0y * ux + c1y * uy + c2y * uz) / det,
            (c0z * ux + c1z * uy + c2z * uz) / det)


@njit(cache=True, inline="always")
def _row_magnitude(a, k, p):
    """The magnitude of the terms of object coordinate k of world point p (what its rounding scales with)."""
    return abs(a[k, 0] * p[0]) + abs(a[k, 1] * p[1]) + abs(a[k, 2] * p[2]) + abs(a[k, 3])


@njit(cache=True, inline="always")
def surface_error_scale(surface, p, n, moved):
    """A magnitude whose float64 rounding bounds how far hit point p, moved onto its triangle's plane by
    `moved` (onto_triangle_plane), may lie off it along unit normal n: the largest of
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
    tri, a, _, (nx, ny, nz) = surface
    world = abs(n[0] * p[0]) + abs(n[1] * p[1]) + abs(n[2] * p[2])
    qx, qy, qz = _object_point(a, p)
    along = (abs(nx) * (_row_magnitude(a, 0, p) + abs(qx - tri[0, 0]))
             + abs(ny) * (_row_magnitude(a, 1, p) + abs(qy - tri[0, 1]))
             + abs(nz) * (_row_magnitude(a, 2, p) + abs(qz - tri[0, 2])))
    wx, wy, wz = (a[0, 0] * nx + a[1, 0] * ny + a[2, 0] * nz, a[0, 1] * nx + a[1, 1] * ny + a[2, 1] * nz,
                  a[0, 2] * nx + a[1, 2] * ny + a[2, 2] * nz)
    length = np.sqrt(wx * wx + wy * wy + wz * wz)
    objectspace = along / length if length > 0.0 else 0.0
    return max(world, objectspace, moved)


@njit(cache=True, inline="always")
def onto_triangle_plane(surface, p):
    """Move hit point p (in place) along its triangle's normal onto the triangle's plane; returns how far
    (the move's |x| + |y| + |z|, for surface_error_scale).

    p = o + t d inherits t's error, and t is a ratio of terms of the size of the triangle's reach R
    that cancel down to its width w across the ray: an error of about eps R^2 / w, which can exceed the
    ray offset on long thin triangles (AO rays starting under the face). The distance to the plane,
    (q - v0) . n, errs by only eps sum |n_k| |q_k - v0_k|, as a point rebuilt from barycentrics (pbrt-v3
    §3.9), which surface_error_scale's object-space term carries. Done in object space, where the
    triangle is."""
    tri, a, parts, (nx, ny, nz) = surface
    qx, qy, qz = _object_point(a, p)
    nn = nx * nx + ny * ny + nz * nz
    if nn == 0.0:  # a degenerate triangle is never hit; nothing to project onto
        return 0.0
    above = ((qx - tri[0, 0]) * nx + (qy - tri[0, 1]) * ny + (qz - tri[0, 2]) * nz) / nn
    x, y, z = _world_vector(parts, above * nx, above * ny, above * nz)
    p[0] -= x
    p[1] -= y
    p[2] -= z
    return abs(x) + abs(y) + abs(z)
