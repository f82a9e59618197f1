"""Sequential construction of one subtree, iteratively and depth first, from pooled memory.

Each thread builds one subtree after the parallel top levels (seed 000 §4). Nodes come off an explicit
stack, left child first; a node's references live in one pool (partition.py keeps the left child on
top), so the pool's live part is the pending right siblings plus the current node: no per-node allocation.
A lazy build (params.defer_size > 0, seed 003 §3) marks nodes of at most defer_size references UNBUILT
and copies their references out; a node's split depends only on its references (in order), box, depth
and room, so building it later gives exactly the eager subtree. A node's room is its share of
params.duplication_budget: each split divides it by its duplication (n_left + n_right) / n, and room
below 1 makes a leaf, so leaves hold at most twice the budget's references. A split that leaves every
reference in both children separates nothing: the node becomes a leaf instead.
The per-node functions it calls (split search, partition, pool checks) are inlined into it: a call of a
compiled function counts every array argument's references atomically (docs/choices.md#inlined-per-node-calls),
and so does each binding of an inlined function's array argument, so they get unowned views, whose
counts are no-ops (docs/choices.md#unowned-views-in-the-subtree-kernel).
"""
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from ..trace.array_views import keep_alive, unowned
from ..trace.layout import LEAF, UNBUILT
from .leaf_triangles import BYTES_PER_REFERENCE as LEAF_COPY_BYTES
from ..memory import MIN_SUBTREE_BUDGET, MemoryLimitError
from .options import EXACT
from .partition import new_split_scratch, partition_in_place
from .pools import append_leaf, ensure_array, ensure_floats, ensure_nodes, ensure_refs
from .split_binned import new_sweep_scratch
from .split_choice import NO_SPLIT, choose_split


@njit(cache=True, nogil=True)
def build_subtree(tris, prims, boxes, n_refs, root_box, root_depth, root_room, params):
    """Build the subtree over the first `n_refs` references of (prims, boxes) inside `root_box`, its
    root at depth `root_depth` with room `root_room`. Returns the node arrays (axis, split, child, count;
    layout.py) with local indices (node 0 the root), the leaf triangle indices, and the deferred subtrees
    (d_node, d_start, d_depth, d_box, d_prims, d_boxes, d_room): subtree k is local node d_node[k] (child k)
    with references d_prims/d_boxes[d_start[k]:d_start[k+1]]."""
    stack_size = params.max_depth - root_depth + 2
    stack_node = np.empty(stack_size, np.int32)
    stack_range = np.empty((stack_size, 2), np.int64)
    stack_depth = np.empty(stack_size, np.int32)
    stack_room = np.empty(stack_size, np.float64)
    stack_box = np.empty((stack_size, 6), np.float32)
    box = np.empty(6, np.float32)
    bins = (np.zeros((3, params.bins), np.int64), np.zeros((3, params.bins), np.int64),
            new_sweep_scratch(params.bins))
    scratch = np.empty(3 * min(n_refs, max(params.exact_below, 16)) + 16, np.float32)
    split_scratch = new_split_scratch()

    # Left children start at their parent's end (partition.py), so a chain of them reaches past 2 n:
    # room for 3 n up front, or the pool is grown and copied once early in every subtree.
    prims, boxes = ensure_refs(prims, boxes, n_refs, 3 * n_refs + 64)
    # What the inlined per-node code takes, as unowned views (module docstring); their owners stay
    # bound to the end (keep_alive).
    prims_v, boxes_v, tris_v, box_v = unowned(prims), unowned(boxes), unowned(tris), unowned(box)
    bins_v, split_v = _unowned_scratch(bins, split_scratch)
    axis, split, child, count = ensure_nodes(np.empty(0, np.int8), np.empty(0, np.float32),
                                             np.empty(0, np.int32), np.empty(0, np.int32), 0,
                                             max(16, n_refs // 2))
    leaf_prims = np.empty(max(16, n_refs + n_refs // 2), np.int32)
    # int64 from the start: a literal 0 makes Numba compile the callees once more for Literal[int](0).
    n_nodes, n_leaf_prims = 1, np.int64(0)
    deferred = (np.empty(0, np.int32), np.zeros(1, np.int32), np.empty(0, np.int32),
                np.empty((0, 6), np.float32), np.empty(0, np.int32), np.empty((0, 6), np.float32),
                np.empty(0, np.float64))
    n_deferred = np.int64(0)

    stack_node[0], stack_range[0, 0], stack_range[0, 1], stack_depth[0] = 0, 0, n_refs, root_depth
    stack_box[0], stack_room[0] = root_box, root_room
    sp = 1
    while sp > 0:
        sp -= 1
        node, start, end, depth = stack_node[sp], stack_range[sp, 0], stack_range[sp, 1], stack_depth[sp]
        room = stack_room[sp]
        for k in range(6):  # element by element: a row view costs reference counting
            box[k] = stack_box[sp, k]
        n = end - start
        if room >= 1.0 and params.leaf_size < n <= params.defer_size:
            deferred = _defer(deferred, n_deferred, node, prims, boxes, start, end, box, depth, room)
            axis[node], split[node], child[node], count[node] = UNBUILT, 0.0, n_deferred, n
            n_deferred += 1
            continue
        # The pools are re-bound only when they grow: binding an array costs reference counting.
        if start + 2 * n + 1 > prims.shape[0]:
            prims, boxes = ensure_refs(prims, boxes, end, start + 2 * n + 1)
            prims_v, boxes_v = unowned(prims), unowned(boxes)
        if params.builder == EXACT or n <= params.exact_below:
            scratch = ensure_floats(scratch, 3 * n)
        split_axis, pos, planar_left = NO_SPLIT, np.float32(0.0), False
        if room >= 1.0:  # else no room left for more references (module docstring)
            split_axis, pos, planar_left = choose_split(boxes_v, start, end, box_v, depth, params, bins_v, scratch)
        n_right = n_left = 0
        if split_axis != NO_SPLIT:
            n_right, n_left = partition_in_place(tris_v, prims_v, boxes_v, start, end, split_axis, pos,
                                                 planar_left, params.clip, split_v)
            if n_left == n and n_right == n:  # separates nothing (module docstring): the right child's
                split_axis = NO_SPLIT  # copy, at start..end like the node's own references, is the leaf
        if split_axis == NO_SPLIT:
            axis[node], split[node], child[node], count[node] = LEAF, 0.0, n_leaf_prims, n
            leaf_prims, n_leaf_prims = append_leaf(leaf_prims, n_leaf_prims, prims_v, start, n)
            continue
        if n_nodes + 2 > axis.shape[0]:
            axis, split, child, count = ensure_nodes(axis, split, child, count, n_nodes, n_nodes + 2)
        if params.bytes_per_reference > 0.0:
            _check_budget(prims, leaf_prims, axis, deferred, params.bytes_per_reference * n_refs)
        left = n_nodes
        n_nodes += 2
        axis[node], split[node], child[node], count[node] = split_axis, pos, left, 0
        stack_room[sp] = stack_room[sp + 1] = child_room(room, n, n_left + n_right)
        # Right child first on the stack so the left one (on top of the pool) is built first.
        _cut_box(stack_box, sp, box, split_axis, pos, False)
        sp = _push(stack_node, stack_range, stack_depth, sp, left + 1, start, start + n_right, depth + 1)
        _cut_box(stack_box, sp, box, split_axis, pos, True)
        sp = _push(stack_node, stack_range, stack_depth, sp, left, end, end + n_left, depth + 1)
    keep_alive((bins, split_scratch))
    d_node, d_start, d_depth, d_box, d_prims, d_boxes, d_room = deferred
    n_deferred_refs = d_start[n_deferred]
    # Views, not copies: merge.py and lazy.py copy every part into the tree's own arrays.
    return (axis[:n_nodes], split[:n_nodes], child[:n_nodes], count[:n_nodes], leaf_prims[:n_leaf_prims],
            d_node[:n_deferred], d_start[:n_deferred + 1], d_depth[:n_deferred], d_box[:n_deferred],
            d_prims[:n_deferred_refs], d_boxes[:n_deferred_refs], d_room[:n_deferred])


@njit(cache=True, inline="always")
def _unowned_scratch(bins, split_scratch):
    """The thread's bin counters, sweep buffers and split scratch as unowned views (array_views.py)."""
    costs, counts = bins[2]
    poly_a, poly_b, region, box_l, box_r = split_scratch
    return ((unowned(bins[0]), unowned(bins[1]), (unowned(costs), unowned(counts))),
            (unowned(poly_a), unowned(poly_b), unowned(region), unowned(box_l), unowned(box_r)))


@njit(cache=True, inline="always")
def child_room(room, n, n_children):
    """Each child's room after a split of n references into n_children (module docstring)."""
    return room * n / max(n_children, 1)


@njit(cache=True, inline="always")
def _check_budget(prims, leaf_prims, axis, deferred, budget):
    """Raise MemoryLimitError when the pools hold more bytes than the subtree's share of memory_limit
    (memory.py says why a build can outgrow its estimate). A leaf reference counts its index and the
    copy of its triangle the finished tree keeps (leaf_triangles.py)."""
    held = (28 * prims.shape[0] + (4 + LEAF_COPY_BYTES) * leaf_prims.shape[0] + 13 * axis.shape[0]
            + 28 * deferred[4].shape[0])
    if held > max(budget, MIN_SUBTREE_BUDGET):
        raise MemoryLimitError("the kd-tree outgrew memory_limit while splitting: its triangles need more "
                               "references than the limit allows (dense overlapping triangles, or settings "
                               "that force splits); raise memory_limit")


@njit(cache=True)
def _defer(deferred, k, node, prims, boxes, start, end, box, depth, room):
    """Record node `node` as deferred subtree k: copy its references (the pool range is reused)."""
    d_node, d_start, d_depth, d_box, d_prims, d_boxes, d_room = deferred
    d_node, d_box = ensure_refs(d_node, d_box, k, k + 1)
    d_start = ensure_array(d_start, k + 1, k + 2)
    d_depth = ensure_array(d_depth, k, k + 1)
    d_room = ensure_array(d_room, k, k + 1)
    used = d_start[k]
    n = end - start
    d_prims, d_boxes = ensure_refs(d_prims, d_boxes, used, used + n)
    d_prims[used:used + n] = prims[start:end]
    d_boxes[used:used + n] = boxes[start:end]
    d_node[k], d_depth[k], d_room[k] = node, depth, room
    d_box[k] = box
    d_start[k + 1] = used + n
    return d_node, d_start, d_depth, d_box, d_prims, d_boxes, d_room


@njit(cache=True, inline="always")
def _push(stack_node, stack_range, stack_depth, sp, node, start, end, depth):
    """Push a child (its box already in slot sp, _cut_box); returns the new stack size. The stack's
    arrays are passed one by one: a tuple of them built per node costs reference counting."""
    stack_node[sp] = node
    stack_range[sp, 0] = start
    stack_range[sp, 1] = end
    stack_depth[sp] = depth
    return sp + 1


@njit(cache=True, inline="always")
def _cut_box(stack_box, slot, box, axis, pos, is_left):
    """stack_box[slot] = `box` cut at `pos` on `axis`: its part left of the plane, or right of it."""
    for k in range(6):
        stack_box[slot, k] = box[k]
    if is_left:
        stack_box[slot, axis + 3] = pos
    else:
        stack_box[slot, axis] = pos


def build_subtrees(tris, tasks, params, threads):
    """Build every task's subtree (top_levels.Task), largest first, on `threads` threads (the kernel
    releases the GIL). Returns build_subtree's tuples in task order."""
    def build(task):
        return build_subtree(tris, task.prims, task.boxes, len(task.prims), task.box, task.depth, task.room,
                             params)

    if threads == 1 or len(tasks) == 1:
        return [build(task) for task in tasks]
    order = sorted(range(len(tasks)), key=lambda i: -tasks[i].size)
    results = [None] * len(tasks)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        futures = {i: pool.submit(build, tasks[i]) for i in order}
        for i, future in futures.items():
            results[i] = future.result()
    return results
