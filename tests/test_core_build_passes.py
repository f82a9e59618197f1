"""The per-node passes of the subtree build against independent references: the snapping passes
(float32) against float64 NumPy, and the clipped boxes' outward rounding against NumPy's nextafter."""
import numpy as np
import pytest
from numba import njit

from core.build.clipping import round_down, round_up
from core.build.split_binned import _nearest_boundaries


def _nearest_reference(boxes, axis, pos, step):
    """_nearest_boundaries in float64 NumPy: the nearest bounds strictly inside (pos - step, pos) and
    (pos, pos + step), else the interval's end, and the counts left of, right of and in each."""
    lo, hi = boxes[:, axis].astype(np.float64), boxes[:, axis + 3].astype(np.float64)
    pos = np.float64(pos)
    values = np.concatenate([lo, hi])
    below = max([pos - step] + list(values[values < pos]))
    above = min([pos + step] + list(values[values > pos]))
    left, right = (lo < pos).sum(), (hi > pos).sum()
    return ((below, left - (lo == below).sum(), right + (hi == pos).sum(), ((lo == below) & (hi == below)).sum()),
            (above, left + (lo == pos).sum(), right - (hi == above).sum(), ((lo == above) & (hi == above)).sum()))


@njit
def _nearest(boxes, axis, pos, step):
    return _nearest_boundaries(boxes, 0, boxes.shape[0], axis, pos, step)


@pytest.mark.parametrize("seed", range(6))
def test_snapping_passes_match_a_float64_reference(seed):
    rng = np.random.default_rng(seed)
    n, axis = 400, seed % 3
    grid = np.float32(0.125) * rng.integers(0, 64, (n, 3)).astype(np.float32)  # shared vertex lines
    widths = np.where(rng.random((n, 3)) < 0.3, 0.0, rng.uniform(0.0, 0.5, (n, 3))).astype(np.float32)
    boxes = np.concatenate([grid, grid + widths], axis=1)
    pos = np.float32(grid[rng.integers(n), axis] if seed % 2 else rng.uniform(1.0, 7.0))
    step = [0.25, 8.0 / 32, 1e-3, 1.0 / 3.0, 2.0, 0.125][seed]  # float64 steps, some exact in float32
    got = _nearest(boxes, axis, pos, step)
    want = _nearest_reference(boxes, axis, pos, step)
    for side_got, side_want in zip(got, want):
        assert side_got[0] == side_want[0]
        assert tuple(int(v) for v in side_got[1:]) == tuple(int(v) for v in side_want[1:])


def _reference_rounding(x):
    """round_down / round_up through NumPy's nextafter."""
    f = x.astype(np.float32)
    down = np.where(f.astype(np.float64) > x, np.nextafter(f, np.float32(-np.inf)), f)
    up = np.where(f.astype(np.float64) < x, np.nextafter(f, np.float32(np.inf)), f)
    return down, up


@njit
def _rounded(x):
    down, up = np.empty(x.shape, np.float32), np.empty(x.shape, np.float32)
    for i in range(x.shape[0]):
        down[i], up[i] = round_down(x[i]), round_up(x[i])
    return down, up


def test_outward_rounding_matches_nextafter_bit_for_bit():
    rng = np.random.default_rng(3)
    tiny = np.float64(np.finfo(np.float32).smallest_subnormal)
    x = np.concatenate([
        rng.normal(size=20000) * 10.0 ** rng.integers(-46, 38, 20000),  # normal and subnormal magnitudes
        rng.normal(size=2000).astype(np.float32).astype(np.float64),  # exactly representable
        tiny * rng.uniform(-4.0, 4.0, 2000),  # around zero, both signs
        [0.0, -0.0, tiny, -tiny, 0.4 * tiny, -0.4 * tiny, 3.0e38, -3.0e38, 1.0, -1.0]])
    got_down, got_up = _rounded(x)
    want_down, want_up = _reference_rounding(x)
    assert np.array_equal(got_down.view(np.int32), want_down.view(np.int32))
    assert np.array_equal(got_up.view(np.int32), want_up.view(np.int32))
    assert (got_down.astype(np.float64) <= x).all() and (got_up.astype(np.float64) >= x).all()
