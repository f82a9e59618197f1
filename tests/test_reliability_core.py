"""Core reliability: the memory limit refuses before allocating, AO at distance 0 and at huge distances, and
scenes at scale 1e-4 and 1e4 render like the same scene at scale 1 (no bpy)."""
import platform
import sys
import tracemalloc

import numpy as np
import pytest

import core
from core import memory
from tests.byte_counts import KIB, TRIANGLE_FLOAT32_BYTES
from tests.core_helpers import assert_same_as_brute
from tests.meshes import icosphere, mesh_triangles, subdivided_cube
from tests.render_scenes import floor, look_at

SIZE = (48, 32)
SMALL_PEAK_BYTES = 100_000  # far below the 7.2 MB input of test_memory_limit_refuses_before_allocating


def box_on_floor(scale=1.0):
    """A 1 x 1 x 1 box (closed, 12 triangles) standing on a 6 x 6 floor, all times `scale`."""
    cube = subdivided_cube(1, half=0.5) + np.array([0.0, 0.0, 0.5])
    return np.concatenate([cube, floor(0.0, half=3.0)]) * scale


def camera(scale=1.0):
    return look_at(np.array([3.0, -4.0, 3.0]) * scale, np.array([0.0, 0.0, 0.3]) * scale)


def render(tris, cam, **settings):
    tree = core.build_kdtree(tris)
    return core.render_preview(tree, cam, *SIZE, **dict(dict(samples=16, ao_distance=1.0), **settings))


# -- memory limit -------------------------------------------------------------------


def test_memory_limit_refuses_before_allocating():
    tris = np.random.default_rng(3).uniform(-1, 1, (200_000, 3, 3)).astype(np.float32)  # 7.2 MB
    limit = memory.build_bytes(len(tris)) - 1
    tracemalloc.start()
    try:
        with pytest.raises(core.MemoryLimitError) as info:
            core.build_kdtree(tris, memory_limit=limit)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < SMALL_PEAK_BYTES  # nothing the size of the input, let alone the build, was allocated
    message = str(info.value)
    assert "kd-tree over 200,000 triangles ('binned' builder)" in message
    assert f"needs about {memory.build_bytes(len(tris)) / memory.MB:,.0f} MB" in message
    assert f"above the memory limit of {limit / memory.MB:,.0f} MB" in message and "raise memory_limit" in message
    assert isinstance(info.value, ValueError)


def test_memory_limit_counts_the_float32_copy_of_float64_input():
    tris64 = box_on_floor()
    n = len(tris64)
    assert memory.build_bytes(n, copies_input=True) - memory.build_bytes(n) == int(memory.MARGIN * TRIANGLE_FLOAT32_BYTES * n)
    with pytest.raises(core.MemoryLimitError):
        core.build_kdtree(tris64, memory_limit=memory.build_bytes(n))  # enough for float32 only
    core.build_kdtree(tris64.astype(np.float32), memory_limit=memory.build_bytes(n))


def test_memory_limit_within_bounds_builds_the_same_tree():
    tris = box_on_floor().astype(np.float32)
    free = core.build_kdtree(tris)
    limited = core.build_kdtree(tris, memory_limit=memory.build_bytes(len(tris), "binned"))
    for a, b in zip(free.arrays, limited.arrays):
        np.testing.assert_array_equal(a, b)


def test_memory_limit_holds_while_splitting_past_the_sah():
    """Forced splits (cost_ratio 100, leaf_size 1, a deep max_depth) duplicate the references that
    meet at a sphere's vertices: 320 triangles make 3.3M nodes and 165 MB if splits that separate
    nothing are taken, 26,861 nodes, 34 references a triangle, ~0.8 MB of tree as they make leaves
    (subtree.py; docs/choices.md#a-split-that-separates-nothing-makes-a-leaf). Without the duplication budget the subtree's pools are
    checked after every split, so under a limit below that the build stops with the settings named;
    with the default budget (at most 32 references a triangle) or the default cost ratio it builds."""
    tris = mesh_triangles(*icosphere(2))
    limit = 512 * KIB
    forced = dict(leaf_size=1, cost_ratio=100.0, max_depth=40, memory_limit=limit)
    with pytest.raises(core.MemoryLimitError, match=r"outgrew memory_limit \(0.5 MB\) while splitting: .*cost_ratio "
                                                    r"100, leaf_size 1, max_depth 40, duplication_budget off "
                                                    r"\(None\)\) do; .*set a duplication_budget"):
        core.build_kdtree(tris, duplication_budget=None, **forced)
    assert core.build_kdtree(tris, **forced).stats()["references_per_triangle"] <= 32
    tree = core.build_kdtree(tris, leaf_size=1, max_depth=40, memory_limit=limit, duplication_budget=None)
    assert tree.stats()["nodes"] < 10_000


def test_forced_splits_of_coincident_triangles_stop_where_nothing_is_separated():
    """3,000 triangles, 20 distinct, with cost_ratio 2 and no duplication budget: no plane separates
    copies of a triangle, and taking the forced split anyway gains ~1.4x references a level (382 a
    triangle at depth 28; max_depth 60 runs out of memory). A split that leaves every reference in
    both children makes a leaf (docs/choices.md#a-split-that-separates-nothing-makes-a-leaf); the tree
    still answers exactly."""
    rng = np.random.default_rng(0)
    centres = rng.random((20, 1, 3))
    distinct = (centres + (rng.random((20, 3, 3)) - 0.5) * 0.3).astype(np.float32)
    tris = distinct[rng.integers(0, 20, 3000)]
    tree = core.build_kdtree(tris, cost_ratio=2.0, duplication_budget=None, max_depth=60)
    assert tree.stats()["references_per_triangle"] < 3
    o = rng.uniform(-0.5, 1.5, (500, 3))
    d = rng.normal(size=(500, 3))
    assert_same_as_brute(tree, tris, o, d)


def test_the_parallel_top_levels_do_not_copy_coincident_triangles():
    """top="clustering" (seed 000's object median, which asks no cost) would split 40,000 copies of
    one triangle into 23 nodes holding 280,000 references; with it, as with "sah", they stay 40,000."""
    tris = np.repeat(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32), 40_000, axis=0)
    for top in ("sah", "clustering"):
        assert core.build_kdtree(tris, threads=2, top=top).stats()["references"] == 40_000


@pytest.mark.parametrize("bad", [-1, 1.5, "1GB", True])
def test_bad_memory_limit_is_named(bad):
    with pytest.raises(ValueError, match="memory_limit"):
        core.build_kdtree(box_on_floor(), memory_limit=bad)


def test_estimates_grow_with_triangles_and_pixels():
    assert memory.build_bytes(2_000_000) == 2 * memory.build_bytes(1_000_000) > 0
    assert memory.render_bytes(1920, 1080) == 4 * memory.render_bytes(960, 540) > 0
    for builder in core.build.options.BUILDERS:
        assert memory.build_bytes(10, builder) > 0


# -- ao_distance ----------------------------------------------------------------------


def test_ao_distance_zero_is_exactly_unoccluded():
    img = render(box_on_floor(), camera(), ao_distance=0.0)
    hit = img[..., 3] == 1.0
    assert hit.sum() > 200 and (img[..., :3][hit] == 1.0).all() and (img[..., :3][~hit] == 0.0).all()


@pytest.mark.parametrize("far", [1e6, 1e30])
def test_ao_distance_far_beyond_the_scene_equals_the_scene_size(far):
    """No occluder lies further than the scene's diagonal (~9), so any longer distance gives the same image."""
    tris = box_on_floor()
    near = render(tris, camera(), ao_distance=20.0)
    huge = render(tris, camera(), ao_distance=far)
    assert np.isfinite(huge).all()
    np.testing.assert_array_equal(near, huge)
    assert near[..., 0][near[..., 3] == 1.0].min() < 0.8  # the box does occlude the floor


# -- scale ------------------------------------------------------------------------------


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_scaled_scene_renders_like_scale_one(scale):
    """Everything (geometry, camera, ao_distance) times `scale`: the same image up to sampling-free noise."""
    reference = render(box_on_floor(), camera())
    scaled = render(box_on_floor(scale), camera(scale), ao_distance=scale)
    np.testing.assert_array_equal(reference[..., 3], scaled[..., 3])
    rmse = np.sqrt(np.mean((reference[..., 0] - scaled[..., 0]) ** 2))
    assert rmse < 0.01, rmse


# -- found by the long property run ------------------------------------------------------


def test_ray_in_a_split_plane_finds_the_closer_hit_in_the_in_plane_sibling():
    """HYPOTHESIS_PROFILE=long found this (exact builder, leaf_size 1), shrunk to six triangles: the ray
    lies in the split plane y = 0, so both children cover the same interval; the search stopped after a
    farther hit in one child (t 0.4) when it popped a node starting after it, although the in-plane
    sibling, still lower on the stack, held the closer hit on its edge (t 0.375)."""
    tris = np.array([[[-0.5, -1, 0], [2, 0, 1.5], [0, 0, -1.5]], [[0, 0, -0.5], [-1, 2, 2], [0, -1.5, -1.5]],
                     [[0, 0, -1.5], [0, 1, 0], [-1, -2, 0]], [[2, 0, 0], [0, 0, 2], [-0.5, 0, 0]],
                     [[0, -0.5, 0], [0, -1, 2], [-1, 1, 0]], [[-1.5, 0, 0], [0, 0, 0.5], [0, 0.5, 0]]], np.float32)
    origins, directions = np.zeros((1, 3)), np.array([[-1.0, 0.0, 1.0]])
    for options in ({"builder": "exact", "leaf_size": 1}, {"builder": "exact", "leaf_size": 1, "clip": False}, {}):
        hits = core.intersect(core.build_kdtree(tris, **options), origins, directions)
        assert (hits.t[0], hits.prim[0]) == (np.float32(0.375), 5), options


@pytest.mark.parametrize("options, release_min, released", [
    ({"memory_limit": 1 << 30}, memory.RELEASE_MIN_BYTES, True),  # a limit: the peak matters
    ({}, 0, True),  # a leaf copy of at least RELEASE_MIN_BYTES
    ({}, memory.RELEASE_MIN_BYTES, False),  # a small copy: the freed memory is kept for the next build
])
def test_build_releases_freed_memory_before_a_large_leaf_copy(monkeypatch, options, release_min, released):
    """The subtree pools are freed before the tree's leaf copy is made, and handed back to the OS in
    between (memory.release_freed_memory) under a memory limit or when the copy is large: otherwise the
    copy adds its whole size to the process's peak (bench_core.py: 188 against 127 B a triangle on
    suzanne-251k). Below RELEASE_MIN_BYTES without a limit the memory is kept: released, the next build
    faults it in again page by page."""
    import core.build.builder as build
    calls = []
    real_copy = build.leaf_triangles
    monkeypatch.setattr(memory, "release_freed_memory", lambda: calls.append("release"))
    monkeypatch.setattr(memory, "RELEASE_MIN_BYTES", release_min)
    monkeypatch.setattr(build, "leaf_triangles", lambda *a: calls.append("copy") or real_copy(*a))
    tree = core.build_kdtree(mesh_triangles(*icosphere(2)), **options)
    assert calls == (["release", "copy"] if released else ["copy"])
    assert tree.leaf_triangles.shape == (9, len(tree.leaf_prims))
    if sys.platform.startswith("linux") and "glibc" in platform.libc_ver()[0]:
        assert memory._MALLOC_TRIM is not None  # the release is real where glibc provides it
