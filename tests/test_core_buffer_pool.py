"""Kept blocks for a frame's large arrays (core/buffer_pool.py): a block is handed out again only once
nothing refers to it, arrays from it behave as NumPy's, and a render's second frame of the same size
takes every large array from the first frame's blocks, with the same image."""
import threading

import numpy as np
import pytest
from numba import njit

import core
from core import buffer_pool
from tests.meshes import subdivided_cube
from tests.render_scenes import look_at

BIG = buffer_pool.MIN_POOLED_BYTES // 4 + 1000  # elements: 4-byte ones and larger pass the pooled size


@pytest.fixture(autouse=True)
def empty_pool():
    buffer_pool.release()
    yield
    buffer_pool.release()


def address(a):
    return a.__array_interface__["data"][0]


def test_a_freed_arrays_block_is_handed_out_again():
    a = buffer_pool.empty((BIG, 3))
    where = address(a)
    del a
    b = buffer_pool.empty((BIG - 10, 3), np.float64)  # a little smaller: the same block
    assert address(b) == where
    assert buffer_pool.held_bytes()[1] == 0


@njit
def _middle(a):
    return a[1:-1]


@pytest.mark.parametrize("derive", [
    lambda a: a[3:7],
    lambda a: a.reshape(-1),
    lambda a: a.T,
    lambda a: a.view(np.int64),
    lambda a: _middle(a),  # a view Numba made and boxed
    lambda a: np.asarray(a),
])
def test_a_block_is_not_handed_out_while_any_array_made_from_it_lives(derive):
    a = buffer_pool.empty((BIG, 3))
    a.fill(7.0)
    kept = derive(a)
    where = address(a)
    del a
    b = buffer_pool.empty((BIG, 3))
    b.fill(-1.0)
    assert address(b) != where
    assert np.all(np.asarray(kept).view(np.float64) == 7.0)
    del kept, b
    assert address(buffer_pool.empty((BIG, 3))) == where  # free again: the first of two equal blocks


def test_arrays_match_numpys():
    rng = np.random.default_rng(1)
    src = rng.standard_normal((BIG, 3))
    idx = rng.integers(0, BIG, BIG // 2)
    for made, expected in [(buffer_pool.zeros((BIG, 3)), np.zeros((BIG, 3))),
                           (buffer_pool.zeros(BIG, np.int64), np.zeros(BIG, np.int64)),
                           (buffer_pool.full(BIG, np.nan), np.full(BIG, np.nan)),
                           (buffer_pool.full(BIG, -1, np.int32), np.full(BIG, -1, np.int32)),
                           (buffer_pool.full(BIG, 3.5, np.float32), np.full(BIG, 3.5, np.float32)),
                           (buffer_pool.take(src, idx), src[idx]),
                           (buffer_pool.empty(7), np.empty(7))]:
        assert made.dtype == expected.dtype and made.shape == expected.shape and made.flags.c_contiguous
        if made.size > 7:
            np.testing.assert_array_equal(made, expected)
            assert made.flags.writeable and not made.flags.owndata  # from a kept block
    assert buffer_pool.empty(7).flags.owndata  # a small array is NumPy's own


def test_a_block_goes_stale_and_release_keeps_held_arrays():
    held = buffer_pool.full(BIG, 5.0)
    gone = buffer_pool.empty(BIG * 4)
    del gone
    assert buffer_pool.held_bytes()[1] >= BIG * 4 * 8
    for _ in range(buffer_pool.STALE_AFTER + 1):
        buffer_pool.empty(BIG // 2)  # other sizes: the big block is never asked for
    total, free = buffer_pool.held_bytes()
    assert total < BIG * 4 * 8 + 3 * BIG * 8
    buffer_pool.release()
    total, free = buffer_pool.held_bytes()
    assert free == 0 and total >= held.nbytes  # the held array's block stays, with its values
    assert np.all(held == 5.0)


def test_threads_never_share_a_live_block():
    errors = []

    def work(k):
        for round_ in range(30):
            a = buffer_pool.full(BIG + 37 * round_, float(k))
            b = buffer_pool.take(a, np.arange(0, len(a), 2))
            if not (np.all(a == k) and np.all(b == k)):
                errors.append((k, round_))

    threads = [threading.Thread(target=work, args=(k,)) for k in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors


def test_a_second_frame_takes_the_first_frames_blocks_with_the_same_image():
    """The renderer's large arrays come from kept blocks (arrays of a 512 x 512 frame's rays and hits pass
    MIN_POOLED_BYTES); a second frame, rendered while the first one's pixel state is kept (as the add-on
    keeps it), leaves that state as it was, and a third reuses blocks instead of adding new ones."""
    tree = core.build_kdtree(subdivided_cube(24))
    camera = look_at((2.5, -3.0, 2.0), (0.0, 0.0, 0.0), fov=0.9)
    lights = [core.Light.point((2.0, -3.0, 4.0))]
    render = core.PreviewRender(tree, camera, 512, 512, samples=2, mode="shadow", lights=lights)
    render.step(2)
    first = render.image()
    held_after_first = buffer_pool.held_bytes()[0]
    assert held_after_first > 10 * buffer_pool.MIN_POOLED_BYTES
    state = render.pixel_state()
    kept = [np.array(a, copy=True) for a in state if isinstance(a, np.ndarray)]
    del render
    second = core.render_preview(tree, camera, 512, 512, samples=2, mode="shadow", lights=lights)
    held_after_second = buffer_pool.held_bytes()[0]
    np.testing.assert_array_equal(first, second)
    for before, now in zip(kept, [a for a in state if isinstance(a, np.ndarray)]):
        np.testing.assert_array_equal(before, now)
    del state
    third = core.render_preview(tree, camera, 512, 512, samples=2, mode="shadow", lights=lights)
    np.testing.assert_array_equal(first, third)
    assert buffer_pool.held_bytes()[0] <= held_after_second  # no block added
