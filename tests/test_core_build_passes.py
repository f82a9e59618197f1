"""The per-node passes of the build against independent references: the snapping passes (float32)
against float64 NumPy, the clipped boxes' outward rounding against NumPy's nextafter, the partitions of
the subtree kernel and of the parallel top levels against NumPy, and the subtree kernel's unowned views
kept valid."""
import numpy as np
import pytest
from numba import njit

from core.build.clipping import round_down, round_up
from core.build.partition import new_split_scratch, partition_in_place
from core.build.split_binned import _nearest_boundaries
from core.build.top_levels import partition_parallel
from core.geometry import triangle_boxes
from core.trace.array_views import keep_alive, unowned


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


@njit
def _partition(tris, prims, boxes, start, end, axis, pos, planar_left):
    return partition_in_place(tris, prims, boxes, start, end, axis, pos, planar_left, False, new_split_scratch())


@pytest.mark.parametrize("seed", range(4))
def test_partition_matches_a_numpy_reference(seed):
    """Right references compacted in order at start, left ones in order from the node's end (where the
    partition writes them, not moved down), straddlers (unclipped) on both sides and planar ones on the
    chosen side, each with its own index and box, the rows before start untouched: the vector row copies
    and unsigned indices against NumPy."""
    rng = np.random.default_rng(seed)
    n, start, axis = 500, 37, seed % 3
    lo = rng.integers(0, 20, (n, 3)).astype(np.float32)
    boxes = np.concatenate([lo, lo + rng.integers(0, 3, (n, 3))], axis=1).astype(np.float32)
    pos, planar_left = np.float32(10.0), seed % 2 == 0
    pool_prims = np.full(start + 2 * n + 1, -1, np.int32)
    pool_boxes = np.full((start + 2 * n + 1, 6), -1.0, np.float32)
    prims = rng.permutation(n).astype(np.int32)
    pool_prims[start:start + n], pool_boxes[start:start + n] = prims, boxes
    before = pool_boxes[:start].copy()
    n_right, n_left = _partition(np.zeros((n, 3, 3), np.float32), pool_prims, pool_boxes, start, start + n,
                                 axis, pos, planar_left)
    a, b = boxes[:, axis], boxes[:, axis + 3]
    planar = (a == b) & (a == pos)
    goes_left = np.where(planar, planar_left, a < pos)
    goes_right = np.where(planar, not planar_left, b > pos)
    right, left = np.flatnonzero(goes_right), np.flatnonzero(goes_left)
    assert (n_right, n_left) == (len(right), len(left))
    cut = boxes.copy()
    sides = ((start, right, axis, np.maximum), (start + n, left, axis + 3, np.minimum))
    for first, chosen, column, bound in sides:
        expected = cut[chosen]
        expected[:, column] = bound(expected[:, column], pos)  # a straddler's part of its box
        np.testing.assert_array_equal(pool_prims[first:first + len(chosen)], prims[chosen])
        np.testing.assert_array_equal(pool_boxes[first:first + len(chosen)], expected)
    np.testing.assert_array_equal(pool_boxes[:start], before)


@njit
def _view_after_more_allocations(keep_owner):
    owner = np.full(4096, 1.0)
    second = np.empty(1, np.float64)
    view = unowned(owner)
    scratch = np.full(4096, 7.0)  # would reuse the owner's memory were the owner freed at its last use
    value = view[100] + scratch[0] * 0.0
    if keep_owner:
        keep_alive((owner, second))
    return value


def test_keep_alive_keeps_the_owner_of_an_unowned_view():
    """The subtree kernel's unowned views stay valid while their owners are named after its loop
    (array_views.keep_alive): Numba frees an array after its last use otherwise."""
    assert _view_after_more_allocations(True) == 1.0


def test_the_top_levels_partition_compiles_once_for_every_builder():
    """The parallel top levels' split plane reaches partition_parallel as float32 whichever split chose
    it (a compiled split returns its float32 plane to Python as a float), so the partition compiles one
    version (docs/choices.md#one-compiled-version-of-each-kernel)."""
    import numba

    import core
    from core.build import top_levels

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("the parallel top levels need two threads")
    rng = np.random.default_rng(31)
    tris = (rng.uniform(-1.0, 1.0, (40000, 1, 3)) + rng.normal(0.0, 0.02, (40000, 3, 3))).astype(np.float32)
    for options in ({"top": "sah"}, {"top": "clustering"}, {"builder": "exact"}, {"builder": "median"}):
        core.build_kdtree(tris, threads=2, **options)
    signatures = top_levels.partition_parallel.signatures
    assert len(signatures) == 1 and str(signatures[0][4]) == "float32", signatures


def _partition_case(shrink):
    """A soup of straddling, one-sided and planar triangles (every 50th lying in the plane y = 0.125), their
    references numbered out of row order, as a child task's are; with `shrink`, boxes cut down on x and z
    as an earlier clip leaves them, so that a clipped straddler can lie on one side of the plane only."""
    rng = np.random.default_rng(47)
    n = 6000
    tris = (rng.uniform(-1.0, 1.0, (n, 1, 3)) + rng.normal(0.0, 0.1, (n, 3, 3))).astype(np.float32)
    axis, pos = 1, np.float32(0.125)
    tris[::50, :, axis] = pos
    prims = rng.permutation(n).astype(np.int32)
    boxes = triangle_boxes(tris)[0][prims]
    if shrink:
        for k in (0, 2):
            lo, hi = boxes[:, k].copy(), boxes[:, k + 3].copy()
            boxes[:, k] = lo + (hi - lo) * np.float32(0.45)
            boxes[:, k + 3] = hi - (hi - lo) * np.float32(0.45)
    return tris, prims, np.ascontiguousarray(boxes), axis, pos


@pytest.mark.parametrize("clip, shrink", [(False, False), (True, False), (True, True)])
def test_the_top_levels_partition_keeps_one_sided_boxes_and_cuts_straddlers(clip, shrink):
    """partition_parallel (the parallel top levels' split) against NumPy, in chunks of every size: each
    side lists its references in row order; one-sided references keep their prim and box row exactly,
    triangles lying in the plane go to the side asked for, and a straddler's part on each side lies in its
    box cut at the plane (exactly that box without clipping). Clipped, a straddler whose box is its
    triangle's reaches both sides; with boxes cut down, some reach one side only, and none is lost."""
    tris, prims, boxes, axis, pos = _partition_case(shrink)
    lo, hi = boxes[:, axis], boxes[:, axis + 3]
    straddle, planar = (lo < pos) & (pos < hi), (lo == pos) & (hi == pos)
    assert straddle.sum() > 300 and planar.sum() > 100
    one_side_only = 0
    for planar_left in (True, False):
        left_only = (hi <= pos) & ~planar | planar & planar_left
        right_only = (lo >= pos) & ~planar | planar & (not planar_left)
        results = [partition_parallel(tris, prims, boxes, axis, pos, planar_left, clip, chunks) for chunks in (1, 3, 8)]
        for other in results[1:]:
            for a, b in zip(results[0], other):
                np.testing.assert_array_equal(a, b)
        lp, lb, rp, rb = results[0]
        sides = []
        for side_prims, side_boxes, one_sided, cut in ((lp, lb, left_only, axis + 3), (rp, rb, right_only, axis)):
            rows = _rows_of(prims, side_prims)  # each listed prim's row of the input, in increasing order
            assert np.all(np.diff(rows) > 0)
            listed = np.isin(prims, side_prims)
            assert np.all(listed[one_sided]) and not np.any(listed[~(one_sided | straddle)])
            np.testing.assert_array_equal(side_boxes[one_sided[rows]], boxes[rows[one_sided[rows]]])
            cut_boxes = boxes[rows[straddle[rows]]].copy()
            cut_boxes[:, cut] = pos
            parts = side_boxes[straddle[rows]]
            if clip:
                assert np.all(parts[:, :3] >= cut_boxes[:, :3]) and np.all(parts[:, 3:] <= cut_boxes[:, 3:])
            else:
                np.testing.assert_array_equal(parts, cut_boxes)
            sides.append(listed & straddle)
        assert np.all(sides[0] | sides[1] | ~straddle)  # no straddler lost
        one_side_only += int((sides[0] ^ sides[1]).sum())
        if not shrink:  # a straddling triangle's own box: the triangle crosses the plane
            assert np.all(sides[0][straddle] & sides[1][straddle])
    assert (one_side_only > 20) == shrink


def _rows_of(prims, listed):
    """The input rows of the listed prims (prims holds each once)."""
    row_of = np.empty(len(prims), np.int64)
    row_of[prims] = np.arange(len(prims))
    return row_of[listed]
