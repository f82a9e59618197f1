"""A kd-tree over boxes alone (a two-level scene's instance boxes): the builder's binned SAH without
triangles, clipping or snapping, lean enough per node for a million boxes.

The same plan as the triangle builder (seed 000 §3-4): the few largest nodes near the root are split
data-parallel (per-chunk bins summed, per-chunk partitions placed by a prefix sum; top_levels.py's
binning and Task), then each remaining node's subtree is built depth first by one thread from one
reference pool. A node's references are item indices with their boxes cut to the node's cell, so a
box straddling a plane is referenced on both sides, its copy on each side cut at the plane; the
duplication budget is spent as in subtree.py (each child's room is the node's divided by the split's
duplication; below 1 a leaf). Nodes of at most SMALL_NODE references try every box face inside the
cell (an exact sweep, counted directly) instead of binning: most nodes of a box tree are that small,
and clearing and sweeping 3 x bins counters cost more than counting a few faces
(docs/choices.md#a-top-level-built-for-boxes).
A box lying in a split plane goes right, as a binned split sends it (partition.py).
"""
import heapq
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit, prange

from ..geometry import extents, half_area
from ..trace.layout import LEAF, NodeArrays
from .merge import merge_tree
from .pools import append_leaf, ensure_nodes, ensure_refs
from .sah import beats_leaf, cost_of_areas, valid_position
from .split_binned import best_binned_split, bin_references, skip_stride
from .subtree import child_room
from .top_levels import CHUNKS_PER_THREAD, PARALLEL_MIN_REFS, TASKS_PER_THREAD, Task, TopNode, bin_parallel

SMALL_NODE = 8
NO_SPLIT = -1


def build_box_tree(boxes, bounds, params, threads):
    """NodeArrays of a kd-tree over `boxes` ((n, 6) float32, each non-empty and inside `bounds`);
    leaf_prims holds box indices. params: BuildParams (binned SAH; clip, snap and exact_below unused)."""
    items = np.arange(len(boxes), dtype=np.int32)
    boxes = np.ascontiguousarray(boxes, np.float32)
    top_nodes, tasks = _split_top(items, boxes, np.asarray(bounds, np.float32), params, threads)

    def build(task):
        return build_box_subtree(task.prims, task.boxes, len(task.prims), task.box, task.depth, task.room, params)

    order = sorted(range(len(tasks)), key=lambda i: -tasks[i].size)
    subtrees = [None] * len(tasks)
    if threads == 1 or len(tasks) == 1:
        for i in order:
            subtrees[i] = build(tasks[i])
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            futures = {i: pool.submit(build, tasks[i]) for i in order}
            for i, future in futures.items():
                subtrees[i] = future.result()
    return NodeArrays(*merge_tree(top_nodes, subtrees))


def _split_top(items, boxes, root_box, params, threads):
    """top_levels.build_top_levels for boxes: the largest open node split with every core until there
    are TASKS_PER_THREAD tasks a thread; returns (top nodes, tasks)."""
    nodes = [TopNode()]
    root = Task(0, items, boxes, root_box, 0, params.duplication_budget)
    if threads == 1 or len(items) < PARALLEL_MIN_REFS:
        nodes[0].task = 0
        return nodes, [root]
    nchunks = CHUNKS_PER_THREAD * threads
    open_nodes, tasks = [(-root.size, 0, root)], []
    while open_nodes and len(open_nodes) + len(tasks) < TASKS_PER_THREAD * threads:
        _, _, task = heapq.heappop(open_nodes)
        axis, pos = _top_split(task, params, nchunks)
        if axis == NO_SPLIT:
            tasks.append(task)
            continue
        lp, lb, rp, rb = partition_boxes_parallel(task.prims, task.boxes, axis, pos, nchunks)
        if len(lp) == len(rp) == task.size:
            tasks.append(task)
            continue
        node = nodes[task.slot]
        node.axis, node.pos, node.left = axis, pos, len(nodes)
        nodes.extend((TopNode(), TopNode()))
        room = child_room(task.room, task.size, len(lp) + len(rp))
        for slot, p, b, is_left in ((node.left, lp, lb, True), (node.left + 1, rp, rb, False)):
            child_box = task.box.copy()
            child_box[axis + 3 if is_left else axis] = pos
            child = Task(slot, p, b, child_box, task.depth + 1, room)
            if child.size < PARALLEL_MIN_REFS:
                tasks.append(child)
            else:
                heapq.heappush(open_nodes, (-child.size, slot, child))
    tasks.extend(t for _, _, t in open_nodes)
    for i, t in enumerate(tasks):
        nodes[t.slot].task = i
    return nodes, tasks


def _top_split(task, params, nchunks):
    """(axis, pos) of a top node's binned SAH split, NO_SPLIT to leave it to its subtree build."""
    n = task.size
    if task.depth >= params.max_depth or n <= params.leaf_size or task.room < 1.0:
        return NO_SPLIT, 0.0
    stride = skip_stride(n, params)
    min_bins, max_bins = bin_parallel(task.boxes, task.box, params.bins, stride, nchunks)
    cost, axis, pos = best_binned_split(min_bins, max_bins, stride, task.box, params)
    if axis < 0 or not beats_leaf(cost, n, task.box, params):
        return NO_SPLIT, 0.0
    return axis, pos


@njit(cache=True, parallel=True)
def partition_boxes_parallel(items, boxes, axis, pos, nchunks):
    """(left items, left boxes, right items, right boxes) of a split, by `nchunks` slices in parallel:
    count each slice's sides, then write each slice from its prefix-summed offsets (order kept)."""
    n = items.shape[0]
    counts = np.zeros((nchunks, 2), np.int64)
    for c in prange(nchunks):
        n_left = n_right = 0
        for i in range(c * n // nchunks, (c + 1) * n // nchunks):
            lo, hi = boxes[i, axis], boxes[i, axis + 3]
            n_left += lo < pos
            n_right += (hi > pos) | ((lo == pos) & (hi == pos))
        counts[c, 0], counts[c, 1] = n_left, n_right
    offsets = np.zeros((nchunks + 1, 2), np.int64)
    for c in range(nchunks):
        offsets[c + 1] = offsets[c] + counts[c]
    out = (np.empty(offsets[nchunks, 0], np.int32), np.empty((offsets[nchunks, 0], 6), np.float32),
           np.empty(offsets[nchunks, 1], np.int32), np.empty((offsets[nchunks, 1], 6), np.float32))
    for c in prange(nchunks):
        w_left, w_right = offsets[c, 0], offsets[c, 1]
        for i in range(c * n // nchunks, (c + 1) * n // nchunks):
            w_left, w_right = _write_sides(items, boxes, i, axis, pos, out, w_left, w_right)
    return out


@njit(cache=True, inline="always")
def _write_sides(items, boxes, i, axis, pos, out, w_left, w_right):
    """Write reference i to the left and/or right arrays of out = (lp, lb, rp, rb), cut at the plane."""
    lp, lb, rp, rb = out
    lo, hi = boxes[i, axis], boxes[i, axis + 3]
    if lo < pos:
        lp[w_left] = items[i]
        for k in range(6):
            lb[w_left, k] = boxes[i, k]
        lb[w_left, axis + 3] = min(hi, pos)
        w_left += 1
    if hi > pos or (lo == pos and hi == pos):
        rp[w_right] = items[i]
        for k in range(6):
            rb[w_right, k] = boxes[i, k]
        rb[w_right, axis] = max(lo, pos)
        w_right += 1
    return w_left, w_right


@njit(cache=True, nogil=True)
def build_box_subtree(items, boxes, n_refs, root_box, root_depth, root_room, params):
    """The subtree over the first n_refs references (items, boxes) in root_box, depth first from one pool
    (_partition: right child compacted in place, left child on top of the pool, built first).
    Returns (axis, split, child, count, leaf items, no deferred nodes): merge.merge_tree's subtree tuple."""
    stack_size = params.max_depth - root_depth + 2
    stack_range = np.empty((stack_size, 3), np.int64)  # node, first reference, end
    stack_depth = np.empty(stack_size, np.int32)
    stack_room = np.empty(stack_size, np.float64)
    stack_box = np.empty((stack_size, 6), np.float32)
    box = np.empty(6, np.float32)
    faces = np.empty((2, SMALL_NODE), np.float32)
    bins = (np.zeros((3, params.bins), np.int64), np.zeros((3, params.bins), np.int64))
    items, boxes = ensure_refs(items, boxes, n_refs, 3 * n_refs + 64)
    axis, split, child, count = ensure_nodes(np.empty(0, np.int8), np.empty(0, np.float32), np.empty(0, np.int32),
                                             np.empty(0, np.int32), 0, max(16, n_refs))
    leaf_items = np.empty(max(16, 2 * n_refs), np.int32)
    n_nodes, n_leaf = 1, np.int64(0)  # int64 from the start: a literal 0 costs a second compile of the callees
    stack_range[0, 0], stack_range[0, 1], stack_range[0, 2] = 0, 0, n_refs
    stack_depth[0], stack_room[0], stack_box[0] = root_depth, root_room, root_box
    sp = 1
    while sp > 0:
        sp -= 1
        node, start, end = stack_range[sp, 0], stack_range[sp, 1], stack_range[sp, 2]
        depth, room = stack_depth[sp], stack_room[sp]
        for k in range(6):
            box[k] = stack_box[sp, k]
        n = end - start
        split_axis, pos = NO_SPLIT, np.float32(0.0)
        if room >= 1.0 and n > params.leaf_size and depth < params.max_depth:
            split_axis, pos = _node_split(boxes, start, end, box, params, bins, faces)
        n_right = n_left = 0
        if split_axis != NO_SPLIT:
            if end + n > items.shape[0]:  # pools.py's growth, called only when needed (a call counts references)
                items, boxes = ensure_refs(items, boxes, end, end + n)
            n_right, n_left = _partition(items, boxes, start, end, split_axis, pos)
            if n_left == n and n_right == n:  # separates nothing: the right copy at start..end is the leaf
                split_axis = NO_SPLIT
        if split_axis == NO_SPLIT:
            axis[node], split[node], child[node], count[node] = LEAF, 0.0, n_leaf, n
            leaf_items, n_leaf = append_leaf(leaf_items, n_leaf, items, start, n)
            continue
        if n_nodes + 2 > axis.shape[0]:
            axis, split, child, count = ensure_nodes(axis, split, child, count, n_nodes, n_nodes + 2)
        left = n_nodes
        n_nodes += 2
        axis[node], split[node], child[node], count[node] = split_axis, pos, left, 0
        room = child_room(room, n, n_left + n_right)
        # right child first on the stack, so the left one (on top of the pool) is built first
        _push(stack_range, stack_depth, stack_room, stack_box, sp, (left + 1, start, start + n_right), depth + 1,
              room, box)
        stack_box[sp, split_axis] = pos
        sp += 1
        _push(stack_range, stack_depth, stack_room, stack_box, sp, (left, end, end + n_left),
              depth + 1, room, box)
        stack_box[sp, split_axis + 3] = pos
        sp += 1
    return (axis[:n_nodes].copy(), split[:n_nodes].copy(), child[:n_nodes].copy(), count[:n_nodes].copy(),
            leaf_items[:n_leaf].copy(), np.empty(0, np.int32))


@njit(cache=True, inline="always")
def _push(stack_range, stack_depth, stack_room, stack_box, sp, node_range, depth, room, box):
    stack_range[sp, 0], stack_range[sp, 1], stack_range[sp, 2] = node_range
    stack_depth[sp], stack_room[sp] = depth, room
    for k in range(6):
        stack_box[sp, k] = box[k]


@njit(cache=True, inline="always")
def _node_split(boxes, start, end, box, params, bins, faces):
    """(axis, pos) of a subtree node's split (exact among box faces when small, else binned), or NO_SPLIT
    when no split beats the leaf (sah.beats_leaf)."""
    n = end - start
    if n <= SMALL_NODE:
        cost, axis, pos = _face_split(boxes, start, end, box, params, faces)
    else:
        min_bins, max_bins = bins
        for a in range(3):
            for k in range(min_bins.shape[1]):
                min_bins[a, k] = max_bins[a, k] = 0
        stride = skip_stride(n, params)
        bin_references(boxes, start, end, stride, box, min_bins, max_bins)
        cost, axis, pos = _bin_sweep(min_bins, max_bins, stride, box, params)
    if axis < 0 or not beats_leaf(cost, n, box, params):
        return NO_SPLIT, np.float32(0.0)
    return axis, pos


@njit(cache=True, inline="always")
def _cut_areas(box, axis):
    """(lo, extent, a, b) of the cell along `axis`: a cut at lo + x leaves a child of half area a x + b
    (geometry.cut_half_area with the other two extents folded into a and b)."""
    e0, e1, e2 = extents(box)
    if axis == 0:
        return np.float64(box[0]), e0, e1 + e2, e1 * e2
    if axis == 1:
        return np.float64(box[1]), e1, e0 + e2, e0 * e2
    return np.float64(box[2]), e2, e0 + e1, e0 * e1


@njit(cache=True, inline="always")
def _bin_sweep(min_bins, max_bins, weight, box, params):
    """split_binned.best_binned_split_into's choice (the first cheapest bin boundary, axis by axis; counts
    weighted by the sampling stride), with each boundary's areas from _cut_areas' constants: the sweep
    is the cost of most nodes of a box tree, and the shared one's per-boundary division and axis
    branches cost more than the binning."""
    nbins = min_bins.shape[1]
    inv_area = 1.0 / half_area(box)
    best_cost, best_axis, best_pos = np.inf, -1, np.float32(0.0)
    for a in range(3):
        lo, extent, ca, cb = _cut_areas(box, a)
        n_right = 0
        for k in range(nbins):
            n_right += max_bins[a, k]
        if n_right == 0 or not extent > 0.0:  # an axis not binned, or a cell without extent on it
            continue
        step = extent / nbins
        n_left = 0
        for k in range(1, nbins):
            n_left += min_bins[a, k - 1]
            n_right -= max_bins[a, k - 1]
            x = k * step
            cost = cost_of_areas(ca * x + cb, ca * (extent - x) + cb, inv_area, _weighted(n_left, weight),
                                 _weighted(n_right, weight), params)
            if cost < best_cost:
                pos = np.float32(lo + k * step)
                if valid_position(box, a, pos):
                    best_cost, best_axis, best_pos = cost, a, pos
    return best_cost, best_axis, best_pos


@njit(cache=True, inline="always")
def _weighted(count, weight):
    """A sampled count scaled by its stride; a sampled zero is not trusted (split_binned's module docstring)."""
    return count if weight == 1 else max(count * weight, 1)


@njit(cache=True, inline="always")
def _face_split(boxes, start, end, box, params, faces):
    """(cost, axis, pos) of the cheapest plane through a box face strictly inside the cell, each counted
    as the partition sends references (left: begins below it; right: ends above it or lies in it);
    the first cheapest in axis, reference, min-then-max order; axis -1 when no face is inside.
    faces: a (2, SMALL_NODE) float32 buffer the axis' faces are gathered into, so the counting loops
    run over contiguous values without branches."""
    n = end - start
    inv_area = 1.0 / half_area(box)
    best_cost, best_axis, best_pos = np.inf, -1, np.float32(0.0)
    for a in range(3):
        flat = 0
        for i in range(n):
            faces[0, i], faces[1, i] = boxes[start + i, a], boxes[start + i, a + 3]
            flat += faces[0, i] == faces[1, i]
        lo, extent, ca, cb = _cut_areas(box, a)
        for j in range(2 * n):
            c = faces[j & 1, j >> 1]
            if not valid_position(box, a, c):
                continue
            n_left = n_right = 0
            for i in range(n):
                n_left += faces[0, i] < c
                n_right += faces[1, i] > c
            if flat:
                for i in range(n):
                    n_right += (faces[0, i] == c) & (faces[1, i] == c)
            x = np.float64(c) - lo
            cost = cost_of_areas(ca * x + cb, ca * (extent - x) + cb, inv_area, n_left, n_right, params)
            if cost < best_cost:
                best_cost, best_axis, best_pos = cost, a, c
    return best_cost, best_axis, best_pos


@njit(cache=True, inline="always")
def _partition(items, boxes, start, end, axis, pos):
    """Right references compacted in place at [start, start + n_right) (each makes at most one, so writes
    never pass reads), left ones written from `end` on, where they stay: the left child is built next, on
    top of the pool, and the right one's children overwrite its range only once its subtree is done.
    Straddlers are cut at the plane. The caller leaves room for end - start more from `end`.
    Returns (n_right, n_left)."""
    w_right, w_left = start, end
    out = (items, boxes, items, boxes)  # reference i is read before either write: the left one lands past end
    for i in range(start, end):
        w_left, w_right = _write_sides(items, boxes, i, axis, pos, out, w_left, w_right)
    return w_right - start, w_left - end
