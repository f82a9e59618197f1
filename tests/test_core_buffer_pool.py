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
    assert buffer_pool.stats()["free"] == 0


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
    assert buffer_pool.stats()["free"] >= BIG * 4 * 8
    for _ in range(buffer_pool.STALE_AFTER + 1):
        buffer_pool.empty(BIG // 2)  # other sizes: the big block is never asked for
    assert buffer_pool.stats()["held"] < BIG * 4 * 8 + 3 * BIG * 8
    buffer_pool.release()
    kept = buffer_pool.stats()
    assert kept["free"] == 0 and kept["held"] >= held.nbytes  # the held array's block stays, with its values
    assert np.all(held == 5.0)


def test_a_new_frame_lets_go_of_blocks_the_last_frame_did_not_use():
    """Frames of changing sizes (a viewport resized): after each frame starts, the free blocks are those
    of the frame before it, not of every size seen."""
    frames = [BIG, 2 * BIG, 4 * BIG, BIG, BIG]
    for k, size in enumerate(frames):
        buffer_pool.new_frame()
        arrays = [buffer_pool.empty(size) for _ in range(3)]
        in_use = buffer_pool.stats()
        if k > 0:
            assert in_use["free"] <= 3 * frames[k - 1] * 8 * buffer_pool.HEADROOM + 3 * buffer_pool.PAGE
        del arrays
    assert buffer_pool.stats()["held"] <= 3 * BIG * 8 * buffer_pool.HEADROOM + 3 * buffer_pool.PAGE


def test_reference_counts_are_checked_once_and_pooling_stops_without_them(monkeypatch):
    assert buffer_pool._counting_works() == buffer_pool._UNREFERENCED is not None  # this Python counts views
    monkeypatch.setattr(buffer_pool, "_UNREFERENCED", None)
    a = buffer_pool.empty((BIG, 3))
    assert a.flags.owndata and buffer_pool.stats()["blocks"] == 0


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
    assert buffer_pool.stats()["held"] > 10 * buffer_pool.MIN_POOLED_BYTES
    state = render.pixel_state()
    kept = [np.array(a, copy=True) for a in state if isinstance(a, np.ndarray)]
    del render
    second = core.render_preview(tree, camera, 512, 512, samples=2, mode="shadow", lights=lights)
    made = buffer_pool.stats()["made"]
    np.testing.assert_array_equal(first, second)
    for before, now in zip(kept, [a for a in state if isinstance(a, np.ndarray)]):
        np.testing.assert_array_equal(before, now)
    del state
    third = core.render_preview(tree, camera, 512, 512, samples=2, mode="shadow", lights=lights)
    np.testing.assert_array_equal(first, third)
    assert buffer_pool.stats()["made"] == made  # no block added


@pytest.mark.parametrize("limit_mb, kept", [(4096, False), (0, True)])  # 0: no limit
def test_the_addon_lets_go_of_kept_blocks_before_a_frame_under_a_memory_limit(limit_mb, kept):
    """Under a memory limit the frame's estimate must be all it adds: the add-on's frame check lets go of
    earlier frames' free blocks first; without a limit they stay for the frame to reuse."""
    from types import SimpleNamespace

    from kd_addon import memory_limit
    from kd_addon.config import make_config

    buffer_pool.empty((BIG, 3))  # freed at once: a free block
    assert buffer_pool.stats()["free"] > 0
    memory_limit.check_frame(100, 64, 48, make_config(SimpleNamespace(memory_limit_mb=limit_mb)))
    assert (buffer_pool.stats()["free"] > 0) == kept
