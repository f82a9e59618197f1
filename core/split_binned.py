"""Min-max binning and the SAH evaluated from the bins (seed 000 §3.3-3.4).

Each reference updates one counter where its box begins and one where it ends, per axis, so binning is a
single pass whose cost does not depend on the number of bins, and the counts left and right of every bin
boundary are exact up to the bin resolution whatever the box sizes. Adaptive skipping (seed 000 §3.3)
bins only every `stride`-th reference and weights the counts by `stride`.
"""
import numpy as np
from numba import njit

from .geometry import half_area
from .sah import split_cost, valid_position


@njit(cache=True)
def bin_references(boxes, start, end, stride, node_box, min_bins, max_bins):
    """Add the references boxes[start:end:stride] to the per-axis min and max bin counters."""
    nbins = min_bins.shape[1]
    scale = np.zeros(3)
    for axis in range(3):
        extent = np.float64(node_box[axis + 3]) - node_box[axis]
        if extent > 0.0:
            scale[axis] = nbins / extent
    for i in range(start, end, stride):
        for axis in range(3):
            lo = node_box[axis]
            a = int((boxes[i, axis] - lo) * scale[axis])
            b = int((boxes[i, axis + 3] - lo) * scale[axis])
            min_bins[axis, min(max(a, 0), nbins - 1)] += 1
            max_bins[axis, min(max(b, 0), nbins - 1)] += 1


@njit(cache=True)
def best_binned_split(min_bins, max_bins, weight, node_box, params):
    """Cheapest split among the bin boundaries: (cost, axis, position); axis -1 if none is valid.

    Planar references are counted where their bins put them; the partition then places them exactly.
    """
    nbins = min_bins.shape[1]
    inv_area = 1.0 / half_area(node_box)
    best_cost, best_axis, best_pos = np.inf, -1, np.float32(0.0)
    for axis in range(3):
        lo = np.float64(node_box[axis])
        step = (np.float64(node_box[axis + 3]) - lo) / nbins
        n_left = 0
        n_right = max_bins[axis].sum()
        for k in range(1, nbins):
            n_left += min_bins[axis, k - 1]
            n_right -= max_bins[axis, k - 1]
            pos = np.float32(lo + k * step)
            if not valid_position(node_box, axis, pos):
                continue
            cost = split_cost(node_box, inv_area, axis, pos, n_left * weight, n_right * weight, params)
            if cost < best_cost:
                best_cost, best_axis, best_pos = cost, axis, pos
    return best_cost, best_axis, best_pos


@njit(cache=True)
def skip_stride(n, params):
    """Bin every l-th reference, l = floor(log10 n), when adaptive skipping is on (seed 000 §3.3)."""
    if not params.skip or n < 100:
        return 1
    return int(np.log10(n))


@njit(cache=True)
def binned_split(boxes, start, end, node_box, params, min_bins, max_bins):
    """Bin the node's references and return the best binned split (cost, axis, position)."""
    min_bins[:] = 0
    max_bins[:] = 0
    stride = skip_stride(end - start, params)
    bin_references(boxes, start, end, stride, node_box, min_bins, max_bins)
    return best_binned_split(min_bins, max_bins, stride, node_box, params)
