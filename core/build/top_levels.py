"""The parallel top of the tree: data-parallel splitting of the few large nodes near the root.

Near the root each node's binning (per-thread counters, summed; seed 000 §4) and partition (per-thread
slices placed by a prefix sum) are spread over the cores, until about `TASKS_PER_THREAD` x threads
nodes; each becomes a task whose subtree one thread builds (seed 000 §4.1). Planes: "sah", the binned
SAH at every top node, or "clustering", seed 000 §4.1's approximate object median of the longest axis
from 512 x threads bins (re-binned per node here, so both share one binning kernel).
"""
import heapq

import numpy as np
from numba import njit, prange

from ..trace.array_views import at
from .options import BINNED, EXACT
from .partition import BOTH, LEFT, RIGHT, new_split_scratch, side_of, split_reference
from .sah import beats_leaf
from .subtree import child_room
from .split_binned import best_binned_split, bin_references, skip_stride
from .split_exact import exact_split
from .split_median import median_split

TASKS_PER_THREAD = 4
PARALLEL_MIN_REFS = 16384  # below this a node is not worth splitting in parallel
CHUNKS_PER_THREAD = 4


class TopNode:
    """A node of the top levels: split (axis, pos, left child index) or a task slot."""

    __slots__ = ("axis", "pos", "left", "task")

    def __init__(self):
        self.axis, self.pos, self.left, self.task = -1, 0.0, -1, -1


class Task:
    """A subtree to build: its slot in the top levels, its references, box, depth and room (its share
    of the duplication budget, subtree.py)."""

    def __init__(self, slot, prims, boxes, box, depth, room):
        self.slot, self.prims, self.boxes, self.box, self.depth, self.room = slot, prims, boxes, box, depth, room

    @property
    def size(self):
        return len(self.prims)


def build_top_levels(tris, prims, boxes, root_box, params, strategy, threads):
    """Split the largest open nodes in parallel until there are enough tasks for `threads` threads.
    Returns (top nodes, tasks); tasks are sorted largest first."""
    nodes = [TopNode()]
    if threads == 1 or len(prims) < PARALLEL_MIN_REFS:
        nodes[0].task = 0
        return nodes, [Task(0, prims, boxes, root_box, 0, params.duplication_budget)]
    target = TASKS_PER_THREAD * threads
    nchunks = CHUNKS_PER_THREAD * threads
    open_nodes = [(-len(prims), 0, Task(0, prims, boxes, root_box, 0, params.duplication_budget))]
    tasks = []
    while open_nodes and len(open_nodes) + len(tasks) < target:
        _, _, task = heapq.heappop(open_nodes)
        axis, pos, planar_left = _top_split(task, params, strategy, threads, nchunks)
        if axis < 0:
            tasks.append(task)
            continue
        lp, lb, rp, rb = partition_parallel(tris, task.prims, task.boxes, axis, pos, planar_left,
                                            params.clip, nchunks)
        if len(lp) == len(rp) == len(task.prims):  # separates nothing (subtree.py): the subtree build decides
            tasks.append(task)
            continue
        node = nodes[task.slot]
        node.axis, node.pos, node.left = axis, pos, len(nodes)
        nodes.extend((TopNode(), TopNode()))
        room = child_room(task.room, len(task.prims), len(lp) + len(rp))
        for slot, p, b, is_left in ((node.left, lp, lb, True), (node.left + 1, rp, rb, False)):
            child_box = task.box.copy()
            child_box[axis + 3 if is_left else axis] = pos
            child = Task(slot, p, b, child_box, task.depth + 1, room)
            if len(p) < PARALLEL_MIN_REFS:
                tasks.append(child)
            else:
                heapq.heappush(open_nodes, (-len(p), slot, child))
    tasks.extend(t for _, _, t in open_nodes)
    for i, t in enumerate(tasks):
        nodes[t.slot].task = i
    return nodes, tasks


def _top_split(task, params, strategy, threads, nchunks):
    """(axis, pos, planar_left) for a top node, axis -1 to leave it to its subtree build."""
    n = len(task.prims)
    if task.depth >= params.max_depth or n <= params.leaf_size or task.room < 1.0:
        return -1, 0.0, False
    if params.builder == BINNED:
        nbins = 512 * threads if strategy == "clustering" else params.bins
        stride = skip_stride(n, params)
        min_bins, max_bins = bin_parallel(task.boxes, task.box, nbins, stride, nchunks)
        if strategy == "clustering":
            return _object_median(min_bins, max_bins, task.box)
        cost, axis, pos = best_binned_split(min_bins, max_bins, stride, task.box, params)
        planar_left = False
    elif params.builder == EXACT:
        scratch = np.empty(3 * n, np.float32)
        cost, axis, pos, planar_left = exact_split(task.boxes, 0, n, task.box, params, scratch)
    else:
        cost, axis, pos = median_split(task.boxes, 0, n, task.box, params)
        planar_left = False
    if axis < 0 or not beats_leaf(cost, n, task.box, params):
        return -1, 0.0, False
    # float32, as a split plane is: a compiled split returns it to Python as a float, and a float64 pos
    # would compile partition_parallel a second time (the same value, so the same partition)
    return axis, np.float32(pos), planar_left


def _object_median(min_bins, max_bins, box):
    """The bin boundary of the longest axis where references left and right balance (seed 000 §4.1)."""
    axis = int(np.argmax(box[3:] - box[:3]))
    nbins = min_bins.shape[1]
    left = np.cumsum(min_bins[axis])[:-1]
    right = max_bins[axis].sum() - np.cumsum(max_bins[axis])[:-1]
    k = int(np.argmin(np.abs(left - right))) + 1
    lo, hi = np.float64(box[axis]), np.float64(box[axis + 3])
    pos = np.float32(lo + k * (hi - lo) / nbins)
    if not box[axis] < pos < box[axis + 3]:
        return -1, 0.0, False
    return axis, pos, False


@njit(cache=True, parallel=True)
def bin_parallel(boxes, node_box, nbins, stride, nchunks):
    """Min-max bins of all references: each chunk bins its slice, then the counters are summed."""
    n = boxes.shape[0]
    local_min = np.zeros((nchunks, 3, nbins), np.int64)
    local_max = np.zeros((nchunks, 3, nbins), np.int64)
    for c in prange(nchunks):
        start = (c * n // nchunks) // stride * stride
        end = ((c + 1) * n // nchunks) // stride * stride if c + 1 < nchunks else n
        bin_references(boxes, start, end, stride, node_box, local_min[c], local_max[c])
    return local_min.sum(axis=0), local_max.sum(axis=0)


@njit(cache=True, parallel=True)
def partition_parallel(tris, prims, boxes, axis, pos, planar_left, clip, nchunks):
    """Left and right reference arrays of a split, computed by `nchunks` slices in parallel."""
    n = prims.shape[0]
    sides = np.empty(n, np.uint8)
    counts = np.zeros((nchunks, 2), np.int64)
    for c in prange(nchunks):
        counts[c, 0], counts[c, 1] = _classify_chunk(tris, prims, boxes, axis, pos, planar_left, clip,
                                                     c * n // nchunks, (c + 1) * n // nchunks, sides)
    offsets = np.zeros((nchunks + 1, 2), np.int64)
    for c in range(nchunks):
        offsets[c + 1] = offsets[c] + counts[c]
    lp = np.empty(offsets[nchunks, 0], np.int32)
    lb = np.empty((offsets[nchunks, 0], 6), np.float32)
    rp = np.empty(offsets[nchunks, 1], np.int32)
    rb = np.empty((offsets[nchunks, 1], 6), np.float32)
    for c in prange(nchunks):
        _write_chunk(tris, prims, boxes, sides, axis, pos, clip, c * n // nchunks, (c + 1) * n // nchunks,
                     (offsets[c, 0], offsets[c, 1]), (lp, lb, rp, rb))
    return lp, lb, rp, rb


@njit(cache=True)
def _classify_chunk(tris, prims, boxes, axis, pos, planar_left, clip, start, end, sides):
    """First pass of partition_parallel: each reference's sides, and how many go left and right.
    Counted in locals: the threads' counters share a cache line, and incrementing them there per
    reference made the pass several times slower (false sharing)."""
    scratch = new_split_scratch()
    box_l, box_r = scratch[3], scratch[4]
    n_left = n_right = 0
    for i in range(start, end):
        side = side_of(boxes, i, axis, pos, planar_left)
        if side == BOTH:
            side = split_reference(tris, prims[i], boxes, i, axis, pos, clip, scratch, box_l, box_r)
        sides[i] = side
        n_left += (side & LEFT) != 0
        n_right += (side & RIGHT) != 0
    return n_left, n_right


@njit(cache=True)
def _write_chunk(tris, prims, boxes, sides, axis, pos, clip, start, end, offsets, out):
    """Second pass of partition_parallel: write one slice's references into out = (left prims, left
    boxes, right prims, right boxes), from offsets = (first left, first right). Straddlers are clipped
    again, as in pass one; a one-sided reference's box is copied straight from its row, not through
    the straddlers' scratch boxes, which the compiler must assume alias the outputs
    (docs/choices.md#one-sided-references-of-the-top-levels-copied-straight)."""
    lp, lb, rp, rb = out
    w_left, w_right = offsets
    scratch = new_split_scratch()
    cut = np.empty((2, 6), np.float32)  # a straddler's boxes on the left and on the right
    box_l, box_r = cut[0], cut[1]  # views made once: views made per straddler would count references
    for i in range(start, end):
        side = sides[at(i)]
        if boxes[at(i), at(axis)] < pos < boxes[at(i), at(axis + 3)]:
            split_reference(tris, prims[i], boxes, i, axis, pos, clip, scratch, box_l, box_r)
            if side & LEFT:
                w_left = _put(lp, lb, w_left, prims[at(i)], cut, 0)
            if side & RIGHT:
                w_right = _put(rp, rb, w_right, prims[at(i)], cut, 1)
        elif side == LEFT:
            w_left = _put(lp, lb, w_left, prims[at(i)], boxes, i)
        else:
            w_right = _put(rp, rb, w_right, prims[at(i)], boxes, i)


@njit(cache=True, inline="always")
def _put(out_prims, out_boxes, w, prim, boxes, row):
    """Reference (prim, boxes[row]) into row w of one side's arrays; the next row. The box is indexed,
    not viewed: a row view would count references on the array's one counter from every thread."""
    out_prims[at(w)] = prim
    for k in range(6):
        out_boxes[at(w), k] = boxes[at(row), k]
    return w + 1
