"""Min-max binning and the SAH evaluated from the bins (seed 000 §3.3-3.4).

Each reference increments one counter where its box begins and one where it ends, per axis: one pass
whatever the bin count, with exact counts left and right of every bin boundary. Adaptive skipping
(seed 000 §3.3) bins every `stride`-th reference of large nodes and weights counts by `stride`; a
sampled zero is not trusted as an empty side (no empty bonus), or the builder cuts "empty" slivers.
"""
import numpy as np
from numba import njit

from ..trace.simd import box_bin_indices
from ..geometry import cut_half_area, extents, half_area, longest_axis
from .sah import cost_of_areas, improves_on_leaf, split_cost, valid_position


@njit(cache=True, inline="always")
def bin_references(boxes, start, end, stride, node_box, min_bins, max_bins):
    """Add the references boxes[start:end:stride] to the per-axis min and max bin counters."""
    top = min_bins.shape[1] - 1
    lo0, lo1, lo2 = node_box[0], node_box[1], node_box[2]
    s0 = _bin_scale(node_box, 0, top + 1)
    s1 = _bin_scale(node_box, 1, top + 1)
    s2 = _bin_scale(node_box, 2, top + 1)
    for i in range(start, end, stride):
        b0, b1, b2, b3, b4, b5 = box_bin_indices(boxes, i, lo0, lo1, lo2, s0, s1, s2, top)  # _bin's, in lanes
        # Unsigned indices (they are clamped to [0, top]): no negative-index wraparound code per increment.
        min_bins[0, np.uint64(b0)] += 1
        min_bins[1, np.uint64(b1)] += 1
        min_bins[2, np.uint64(b2)] += 1
        max_bins[0, np.uint64(b3)] += 1
        max_bins[1, np.uint64(b4)] += 1
        max_bins[2, np.uint64(b5)] += 1


@njit(cache=True)
def bin_longest_axis(boxes, start, end, stride, node_box, min_bins, max_bins):
    """bin_references on the node's longest axis only (BuildOptions.split_axes "longest"); the other
    axes' counters stay zero, which best_binned_split takes as "not binned"."""
    axis = longest_axis(node_box)
    top = min_bins.shape[1] - 1
    lo = node_box[axis]
    scale = _bin_scale(node_box, axis, top + 1)
    for i in range(start, end, stride):
        min_bins[axis, _bin(boxes[i, axis], lo, scale, top)] += 1
        max_bins[axis, _bin(boxes[i, axis + 3], lo, scale, top)] += 1


@njit(cache=True, inline="always")
def _bin_scale(node_box, axis, nbins):
    extent = np.float64(node_box[axis + 3]) - node_box[axis]
    return nbins / extent if extent > 0.0 else 0.0


@njit(cache=True, inline="always")
def _bin(x, lo, scale, top):
    b = int((x - lo) * scale)
    return min(max(b, 0), top)


@njit(cache=True)
def new_sweep_scratch(nbins):
    """Per-thread buffers for best_binned_split_into: every boundary's cost, the running counts."""
    return np.empty((3, nbins), np.float64), np.empty((2, nbins), np.float64)


@njit(cache=True)
def best_binned_split(min_bins, max_bins, weight, node_box, params):
    """best_binned_split_into with buffers of its own (the top levels' few nodes)."""
    return best_binned_split_into(min_bins, max_bins, weight, node_box, params,
                                  new_sweep_scratch(min_bins.shape[1]))


@njit(cache=True, inline="always")
def best_binned_split_into(min_bins, max_bins, weight, node_box, params, sweep_scratch):
    """Cheapest split among the bin boundaries: (cost, axis, position); axis -1 if none is valid. Every
    boundary's cost is computed first (_boundary_costs, a loop LLVM vectorizes), then the first cheapest
    is taken axis by axis, boundary by boundary: the plane a scan comparing with `<` would take.
    sweep_scratch: new_sweep_scratch's buffers, so a subtree's nodes allocate nothing."""
    nbins = min_bins.shape[1]
    costs, counts = sweep_scratch
    for axis in range(3):
        _boundary_costs(min_bins, max_bins, weight, node_box, axis, params, counts, costs)
    best_cost, best_axis, best_k = np.inf, -1, 0
    for axis in range(3):
        for k in range(1, nbins):
            if costs[axis, k] < best_cost:
                best_cost, best_axis, best_k = costs[axis, k], axis, k
    if best_axis < 0:
        return best_cost, best_axis, np.float32(0.0)
    return best_cost, best_axis, _boundary(node_box, best_axis, best_k, nbins)


@njit(cache=True, inline="always")
def _boundary(node_box, axis, k, nbins):
    """Bin boundary k on `axis` as the float32 plane a split stores."""
    return _plane(np.float64(node_box[axis]), np.float64(node_box[axis + 3]), k, nbins)


@njit(cache=True, inline="always")
def _plane(lo, hi, k, nbins):
    """_boundary from the node's bounds on the axis, lo and hi (float64)."""
    return np.float32(lo + k * ((hi - lo) / nbins))


@njit(cache=True, inline="always")
def _boundary_costs(min_bins, max_bins, weight, node_box, axis, params, counts, costs):
    """costs[axis, k]: the SAH cost of bin boundary k (1 <= k < nbins) on `axis`; inf at k = 0, where
    the plane is not strictly inside the node, and on an axis not binned (every binned reference ends in
    a bin). The running counts go to `counts` first so the cost loop has no loop-carried value. Rows are
    indexed, not sliced, and the function is inlined: a call or a row view costs reference counting."""
    nbins = min_bins.shape[1]
    n_right = 0
    for k in range(nbins):
        costs[axis, k] = np.inf
        n_right += max_bins[axis, k]
    if n_right == 0:
        return
    n_left = 0
    for k in range(1, nbins):
        n_left += min_bins[axis, k - 1]
        n_right -= max_bins[axis, k - 1]
        counts[0, k] = _estimate(n_left, weight)
        counts[1, k] = _estimate(n_right, weight)
    inv_area = 1.0 / half_area(node_box)
    e = extents(node_box)
    lo32, hi32 = node_box[axis], node_box[axis + 3]  # read once: a load per boundary keeps the loop scalar
    lo, hi = np.float64(lo32), np.float64(hi32)
    for k in range(1, nbins):
        pos = _plane(lo, hi, k, nbins)
        cost = cost_of_areas(cut_half_area(e, axis, np.float64(pos) - lo),
                             cut_half_area(e, axis, hi - np.float64(pos)), inv_area,
                             counts[0, k], counts[1, k], params)
        costs[axis, k] = cost if lo32 < pos < hi32 else np.inf  # valid_position


@njit(cache=True, inline="always")
def _estimate(count, weight):
    if weight == 1:
        return count
    return max(count * weight, 1)


SKIP_MIN_REFS = 4096


@njit(cache=True)
def skip_stride(n, params):
    """Bin every l-th reference, l = floor(log10 n), when skipping is on and the node is large (seed 000 §3.3)."""
    if not params.skip or n < SKIP_MIN_REFS:
        return 1
    return int(np.log10(n))


@njit(cache=True, inline="always")
def binned_split(boxes, start, end, node_box, params, bins):
    """Bin the node's references and return the best binned split (cost, axis, position, planar_left),
    refined to the nearest box boundaries when every reference was binned (`snap_to_boundaries`).
    With params.longest_axis_only, the longest axis first, and all three only when it offers no plane
    better than a leaf (a cylinder along the cell's length gives the longest axis nothing to split)."""
    min_bins, max_bins, sweep_scratch = bins
    stride = skip_stride(end - start, params)
    cost, axis, pos = np.inf, -1, np.float32(0.0)
    if params.longest_axis_only:
        _clear(min_bins, max_bins)
        bin_longest_axis(boxes, start, end, stride, node_box, min_bins, max_bins)
        cost, axis, pos = best_binned_split_into(min_bins, max_bins, stride, node_box, params, sweep_scratch)
    if axis < 0 or not improves_on_leaf(cost, end - start, params):
        _clear(min_bins, max_bins)
        bin_references(boxes, start, end, stride, node_box, min_bins, max_bins)
        cost, axis, pos = best_binned_split_into(min_bins, max_bins, stride, node_box, params, sweep_scratch)
    if axis < 0 or stride != 1 or not params.snap:
        return cost, axis, pos, False
    return snap_to_boundaries(boxes, start, end, node_box, params, cost, axis, pos)


@njit(cache=True, inline="always")
def _clear(min_bins, max_bins):
    min_bins[:] = 0
    max_bins[:] = 0


@njit(cache=True, inline="always")
def snap_to_boundaries(boxes, start, end, node_box, params, cost, axis, pos):
    """Try the box boundaries nearest the binned plane on each side (within one bin) and keep the
    cheapest of the three, counted exactly. Bin boundaries fall between the vertex lines of grids and
    height fields, so the binned plane cuts a row of triangles a vertex-line plane would not
    (docs/choices.md#snapping-to-box-boundaries-snap-on); refining a sampled SAH near its minimum follows Hunt,
    Mark and Stoll 2006. Planar references on a candidate go to the cheaper side, as in the exact sweep."""
    step = (np.float64(node_box[axis + 3]) - node_box[axis]) / params.bins
    near = _nearest_boundaries(boxes, start, end, axis, pos, step)
    best = (cost, axis, pos, False)
    inv_area = 1.0 / half_area(node_box)
    for c, n_left, n_right, n_planar in near:
        c = np.float32(c)
        if not (valid_position(node_box, axis, c) and pos - step < c < pos + step):
            continue
        for planar_left in (True, False):
            c_cost = split_cost(node_box, inv_area, axis, c, n_left + n_planar * planar_left,
                                n_right + n_planar * (not planar_left), params)
            if c_cost < best[0]:
                best = (c_cost, axis, c, planar_left)
    return best


@njit(cache=True, inline="always")
def _nearest_boundaries(boxes, start, end, axis, pos, step):
    """The box boundaries nearest to pos strictly below and above it within one bin, each with the
    references left of it, right of it and lying in it: ((below, left, right, planar), (above, ...)).
    Two branch-free passes in float32 (the boxes' precision, so nothing is widened per reference): the
    nearest boundary each side, then the counts at pos and at those two. Without a boundary in the bin,
    the bin's edge (rejected by the caller); a float64 edge no float32 equals gets zero counts, as the
    float64 comparisons gave (docs/choices.md#snapping-passes-in-float32)."""
    below, above = _nearest_values(boxes, start, end, axis, pos, step)
    below32, above32 = np.float32(below), np.float32(above)
    left_of_pos = right_of_pos = begin_at_pos = end_at_pos = 0
    begin_below = end_below = planar_below = begin_above = end_above = planar_above = 0
    for i in range(start, end):
        lo, hi = boxes[i, axis], boxes[i, axis + 3]
        left_of_pos += lo < pos
        right_of_pos += hi > pos
        begin_at_pos += lo == pos
        end_at_pos += hi == pos
        begin_below += lo == below32
        end_below += hi == below32
        planar_below += (lo == below32) & (hi == below32)
        begin_above += lo == above32
        end_above += hi == above32
        planar_above += (lo == above32) & (hi == above32)
    at_below = np.float64(below32) == below  # else no float32 lies on it
    at_above = np.float64(above32) == above
    begin_below, end_below, planar_below = begin_below * at_below, end_below * at_below, planar_below * at_below
    begin_above, end_above, planar_above = begin_above * at_above, end_above * at_above, planar_above * at_above
    return ((below, left_of_pos - begin_below, right_of_pos + end_at_pos, planar_below),
            (above, left_of_pos + begin_at_pos, right_of_pos - end_above, planar_above))


@njit(cache=True, inline="always")
def _nearest_values(boxes, start, end, axis, pos, step):
    """The largest box boundary in (pos - step, pos) and the smallest in (pos, pos + step); the
    interval's far end where it holds none. The running extremes stay float32, one per bound and side
    (four independent chains: one chain waits for each max before the next), and meet the float64
    interval ends once, after the loop: the same maxima and minima as taking them in float64."""
    lo_below, hi_below = np.float32(-np.inf), np.float32(-np.inf)
    lo_above, hi_above = np.float32(np.inf), np.float32(np.inf)
    for i in range(start, end):
        lo, hi = boxes[i, axis], boxes[i, axis + 3]
        lo_below = max(lo_below, lo) if lo < pos else lo_below
        hi_below = max(hi_below, hi) if hi < pos else hi_below
        lo_above = min(lo_above, lo) if lo > pos else lo_above
        hi_above = min(hi_above, hi) if hi > pos else hi_above
    below = max(pos - step, np.float64(max(lo_below, hi_below)))
    above = min(pos + step, np.float64(min(lo_above, hi_above)))
    return below, above
