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

from ..trace.array_views import at, keep_alive, rows, unowned
from ..trace.layout import LEAF, NO_HIT, TreeArrays
from ..trace.traversal import (RAYS_PER_TASK, STACK_SIZE, _descend, _pop, block_range, clip_to_box,
                        interleaved_blocks, trace_ray)
from ..trace.triangle_test import LEAF_CHUNK
from .two_level import SceneArrays


@njit(cache=True)
def new_scratch():
    """(views, owners): per-thread buffers, the top level's stack and inverse direction, the mesh
    traversal's stack and inverse direction, the object-space ray, the mesh traversal's leaf flags and
    one spare 3-vector, as unowned views of four allocations, and those four owners, which the caller
    keeps alive (array_views.keep_alive) and passes nowhere else: a tuple holding an owned array counts
    references on it wherever the tuple goes (docs/choices.md#scratch-views-without-their-owners)."""
    nodes = np.empty(2 * STACK_SIZE, np.int32)
    intervals = np.empty((2 * STACK_SIZE, 3))
    vectors = np.empty(15)
    flags = np.empty(LEAF_CHUNK, np.uint8)
    return ((rows(nodes, 0, STACK_SIZE), rows(intervals, 0, STACK_SIZE), rows(vectors, 0, 3),
             rows(nodes, STACK_SIZE, 2 * STACK_SIZE), rows(intervals, STACK_SIZE, 2 * STACK_SIZE),
             rows(vectors, 3, 6), rows(vectors, 6, 9), rows(vectors, 9, 12), rows(flags, 0, LEAF_CHUNK),
             rows(vectors, 12, 15)), (nodes, intervals, vectors, flags))


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
    `scratch` is new_scratch()'s views, reused across rays. A flat tree (one instance in a
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
    scratch, owners = new_scratch()
    views = unowned_scene(scene)
    for r in range(start, stop):
        t, inst, prim, u, v = trace_scene(views, rows(origins, r, r + 1)[0], rows(directions, r, r + 1)[0], tmin[r],
                                          tmax[r], any_hit, ray_mask, scratch)
        out_t[r] = t
        out_inst[r] = inst
        out_prim[r] = prim
        out_u[r] = u
        out_v[r] = v
    keep_alive(owners)
