"""simd.box_bin_indices (the build's vector min-max binning) against NumPy bin for bin, and the binned
builder's counters against a NumPy histogram of the same references."""
import numpy as np
import pytest
from numba import njit

from core.build.split_binned import bin_references
from core.trace.simd import box_bin_indices


@njit
def _indices(boxes, lo, scale, top):
    out = np.empty((boxes.shape[0], 6), np.int64)
    for i in range(boxes.shape[0]):
        b = box_bin_indices(boxes, i, lo[0], lo[1], lo[2], scale[0], scale[1], scale[2], top)
        for k in range(6):
            out[i, k] = b[k]
    return out


def _numpy_indices(boxes, lo, scale, top):
    """int((bound - lo) * scale) clamped to [0, top]: float32 difference, float64 product, truncation."""
    diff = (boxes - np.concatenate([lo, lo])).astype(np.float32)
    product = diff.astype(np.float64) * np.concatenate([scale, scale])
    return np.clip(np.trunc(product), 0, top).astype(np.int64)


def _awkward_boxes(rng, n, node):
    """Boxes inside, on the edges of and outside `node`, with signed zeros and bin boundaries."""
    lo, hi = node[:3], node[3:]
    boxes = (lo + (hi - lo) * rng.uniform(-0.2, 1.2, (n, 6)).reshape(n, 2, 3)).reshape(n, 6)
    boxes[::5] = np.concatenate([lo, hi])
    boxes[1::7] = 0.0
    boxes[2::7] = -0.0
    edges = lo + (hi - lo) * (np.arange(33) / 32.0)[:, None]
    boxes[3::11, :3] = edges[rng.integers(0, 33, len(boxes[3::11]))]
    return boxes.astype(np.float32)


@pytest.mark.parametrize("n", [1, 7, 1000])
def test_box_bin_indices_match_numpy(n):
    rng = np.random.default_rng(n)
    node = np.array([-1.5, 0.0, -3.0, 2.5, 1.0, 0.0], np.float32)
    boxes = _awkward_boxes(rng, n, node)  # exactly n rows: the last row's loads must stay inside it
    lo = node[:3].copy()
    scale = np.array([32 / (np.float64(node[3 + k]) - node[k]) for k in range(3)])
    got = _indices(boxes, lo, scale, 31)
    assert np.array_equal(got, _numpy_indices(boxes, lo, scale, 31))
    assert got.min() == 0 and (n < 100 or got.max() == 31)


def test_box_bin_indices_flat_axis_bins_everything_at_zero():
    boxes = np.array([[0.0, 1.0, 5.0, 0.0, 2.0, 5.0]], np.float32)
    lo = np.array([0.0, 0.0, 5.0], np.float32)
    got = _indices(boxes, lo, np.array([8.0, 8.0, 0.0]), 31)
    assert got.tolist() == [[0, 8, 0, 0, 16, 0]]


def test_bin_references_counts_match_a_numpy_histogram():
    rng = np.random.default_rng(7)
    node = np.array([0.0, -2.0, 1.0, 4.0, 2.0, 1.5], np.float32)
    boxes = _awkward_boxes(rng, 5000, node)
    min_bins, max_bins = np.zeros((3, 32), np.int64), np.zeros((3, 32), np.int64)
    bin_references(boxes, 100, 4900, 3, node, min_bins, max_bins)
    lo = node[:3].copy()
    scale = np.array([32 / (np.float64(node[3 + k]) - node[k]) for k in range(3)])
    expected = _numpy_indices(boxes[100:4900:3], lo, scale, 31)
    for axis in range(3):
        assert np.array_equal(min_bins[axis], np.bincount(expected[:, axis], minlength=32))
        assert np.array_equal(max_bins[axis], np.bincount(expected[:, axis + 3], minlength=32))
