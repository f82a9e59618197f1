"""Boxes over groups of leaf columns (leaf_triangles.leaf_boxes) and the packets' test of them
(packet_boxes.lanes_meeting_box), which lets a packet skip a large leaf's triangles group by group.

The box test must keep every lane whose ray meets the box within its range (checked against exact
rational arithmetic on rays aimed at faces, edges and corners, at extreme scales), and packets through
leaves large enough to be grouped must give core.intersect's and core.occluded's answers exactly.
"""
from fractions import Fraction

import numpy as np
import pytest
from numba import njit

import core
from core.build.leaf_triangles import GROUPED_LEAF, LEAF_GROUP, leaf_boxes
from core.trace import simd as S
from core.trace.packet_boxes import ROWS32, lanes_meeting_box
from core.trace.layout import LEAF
from core.trace.traversal import trace_rays
from core.trace.triangle_test import ray_shear
from core.trace.packet_setup import _fill_rows32
from tests.meshes import random_soup, subdivided_cube
from tests.test_core_occlusion_packets import ao_rays, assert_same_as_single_rays
from tests.test_core_packet_traversal import assert_same_as_intersect, grid_rays

L = S.LANES


def numpy_group_boxes(tree):
    """leaf_boxes by NumPy: the box of each LEAF_GROUP columns of the tree's leaf-ordered copy where they
    meet a leaf of more than GROUPED_LEAF triangles, the tree's box elsewhere."""
    copy = tree.leaf_triangles
    out = np.tile(tree.bounds, (-(-copy.shape[1] // LEAF_GROUP), 1)).astype(np.float32)
    for leaf in np.flatnonzero((tree.axis == LEAF) & (tree.count > GROUPED_LEAF)):
        first, count = tree.child[leaf], tree.count[leaf]
        for g in range(first // LEAF_GROUP, (first + count - 1) // LEAF_GROUP + 1):
            verts = copy[:, g * LEAF_GROUP:(g + 1) * LEAF_GROUP].reshape(3, 3, -1)  # vertex, axis, column
            out[g] = np.concatenate([verts.min(axis=(0, 2)), verts.max(axis=(0, 2))])
    return out


@pytest.mark.parametrize("depth", [2, 5, 20])
def test_leaf_boxes_hold_the_groups_of_large_leaves(depth):
    """Groups meeting a large leaf hold their columns' box (a group across a leaf boundary holds the
    neighbour's columns too); the rest hold the tree's box."""
    rng = np.random.default_rng(depth)
    tris = (random_soup(rng, 900) * 10.0 ** rng.integers(-3, 4, (900, 1, 1))).astype(np.float32)
    tree = core.build_kdtree(tris, max_depth=depth)
    np.testing.assert_array_equal(tree.leaf_boxes, numpy_group_boxes(tree))
    if depth < 10:
        assert (tree.count > GROUPED_LEAF).any()


def test_leaf_boxes_keep_whole_unchanged_groups_and_redo_the_rest():
    """After a lazy splice (new columns appended) whole groups of old columns are copied, and a group
    the new columns reach is computed again: stale boxes given as `previous` show which."""
    tree = core.build_kdtree(random_soup(np.random.default_rng(1), 900), max_depth=3)
    n = tree.leaf_triangles.shape[1]
    stale = np.full((len(tree.leaf_boxes), 6), 7.0, np.float32)
    kept = 2 * LEAF_GROUP + 1  # columns unchanged: the first two groups are whole
    got = leaf_boxes(tree.leaf_triangles, tree.node_arrays, tree.bounds, (stale, kept))
    np.testing.assert_array_equal(got[:2], stale[:2])
    np.testing.assert_array_equal(got[2:], numpy_group_boxes(tree)[2:])
    assert n > 3 * LEAF_GROUP


def test_lazy_tree_boxes_follow_its_growth():
    """A lazy tree's boxes after rays built part of it equal a fresh computation over its grown arrays."""
    rng = np.random.default_rng(2)
    tree = core.build_kdtree(random_soup(rng, 3000), lazy=True, lazy_subtree_size=16, rays=5000)  # large leaves
    before = tree.node_count
    core.intersect(tree, np.zeros((1000, 3)), rng.normal(size=(1000, 3)))
    assert tree.node_count > before and (tree.count > GROUPED_LEAF).any()
    np.testing.assert_array_equal(tree.leaf_boxes, numpy_group_boxes(tree))


@njit(cache=True)
def _meeting(box, o, d, limits, kz):
    """lanes_meeting_box for lanes with origins o, directions d (3, L), set up as packet_setup does, and
    limits (tmin, best) (L,) each."""
    lanes32 = np.zeros(ROWS32 * L, np.float32)
    ov = (S.load(o[0], 0), S.load(o[1], 0), S.load(o[2], 0))
    inv = (S.reciprocal(S.load(d[0], 0)), S.reciprocal(S.load(d[1], 0)), S.reciprocal(S.load(d[2], 0)))
    tmin, best = S.load(limits[0], 0), S.load(limits[1], 0)
    _fill_rows32(lanes32, ov, inv, tmin, best)
    return lanes_meeting_box(lanes32, box, 0, (1 << L) - 1, kz, (tmin, best))


def line_meets(box, o, d):
    """Whether the line o + t d (any t) meets the closed box, in exact rationals."""
    lo = hi = None
    for k in range(3):
        a = (Fraction(float(box[k])) - Fraction(float(o[k]))) / Fraction(float(d[k]))
        b = (Fraction(float(box[k + 3])) - Fraction(float(o[k]))) / Fraction(float(d[k]))
        lo = min(a, b) if lo is None else max(lo, min(a, b))
        hi = max(a, b) if hi is None else min(hi, max(a, b))
    return lo <= hi


@pytest.mark.parametrize("scale, offset", [(1.0, 0.0), (1e-6, 0.0), (1e6, 0.0), (1.0, 1e5), (1e-3, 1e7)])
def test_box_test_keeps_every_line_that_meets_the_box(scale, offset):
    """Rays aimed at points of the box's faces, edges and corners (and beside them), from near and far:
    every lane whose line meets the box in exact arithmetic is kept; most lines aimed clearly beside it
    are left out (the test is not vacuous)."""
    rng = np.random.default_rng(int(scale * 1e6) % 1000 + int(offset) % 997)
    kept_misses, misses = 0, 0
    for _ in range(60):
        lo = (rng.uniform(-1, 1, 3) * scale + offset).astype(np.float32)
        box = np.concatenate([lo, (lo + rng.uniform(0, 1, 3) * scale * (rng.random(3) < 0.8)).astype(np.float32)])
        box = box.reshape(1, 6)
        corner = np.where(rng.random((L, 3)) < 0.5, box[0, :3], box[0, 3:]).astype(np.float64)
        inside = box[0, :3] + rng.random((L, 3)) * (box[0, 3:] - box[0, :3])
        targets = np.where(rng.random((L, 3)) < 0.6, corner, inside)  # on faces, edges and corners
        beside = rng.random(L) < 0.3
        step = 0.05 * scale + 2.0 ** -16 * offset  # beyond the float32 bounds' widening far out
        targets[beside] += rng.choice([-1.0, 1.0], (beside.sum(), 3)) * step
        o = targets + rng.normal(size=(L, 3)) * scale * 10.0 ** rng.uniform(-2, 2, (L, 1))
        d = targets - o
        d[d == 0.0] = scale * 1e-3
        limits = (np.zeros(L), np.full(L, np.inf))
        got = _meeting(box, np.ascontiguousarray(o.T), np.ascontiguousarray(d.T), limits, -1)
        for lane in range(L):
            meets, kept = line_meets(box[0], o[lane], d[lane]), bool((got >> lane) & 1)
            assert kept or not meets, (box, o[lane], d[lane])
            if not meets and beside[lane]:
                misses += 1
                kept_misses += kept
    assert misses > 20 and kept_misses < misses / 2


def _single_ray_hits(tris, o, d):
    """(t float64, prim) of the single-ray kernel, closest hits over the triangles (one leaf)."""
    tree = core.build_kdtree(tris, max_depth=0)
    n = len(o)
    out = [np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n)]
    trace_rays(tree.arrays, o, d, np.zeros(n), np.full(n, np.inf), False, *out)
    return out[0], out[1]


def _triangle_and_ray(rng, sliver):
    """A triangle and a ray towards a point on it. A sliver is a few float32 ulps wide across y, long
    along z, and the ray runs along z, grazing y: its computed t strays furthest from the exact one."""
    if not sliver:
        tri = rng.normal(size=(3, 3)).astype(np.float32)
        direction = rng.normal(size=3)
    else:
        y0 = np.float32(rng.choice([1.0, 1e-3, 1e3]) * rng.uniform(0.5, 2))
        ys = y0 + np.spacing(y0) * np.array([0, rng.integers(1, 4), rng.integers(-3, 4)])
        zs = np.array([0.0, 1.0, rng.uniform(-1, 1)]) * 10.0 ** rng.uniform(-2, 6)
        tri = np.stack([np.full(3, rng.choice([0.0, 1e-6, 1.0]) * rng.uniform(-2, 2)), ys, zs], 1).astype(np.float32)
        direction = rng.normal(size=3)
        direction[2] = rng.choice([-1, 1]) * rng.uniform(1, 2)
        direction[1] *= 10.0 ** rng.uniform(-12, 0)
    point = rng.dirichlet([1, 1, 1]) @ tri.astype(np.float64)
    return tri, point - direction * 10.0 ** rng.uniform(-3, 3), direction


@pytest.mark.parametrize("sliver", [False, True])
def test_box_test_keeps_every_lane_whose_hit_the_triangle_test_accepts(sliver):
    """With the range tested on the depth axis, a lane is kept whenever the triangle test accepts a t in
    [tmin, best]: here tmin and best are the computed t's neighbouring doubles, and the triangles include
    slivers seen edge on, whose computed t lies far (in float32 ulps) from the exact one."""
    rng = np.random.default_rng(11 + sliver)
    checked = 0
    for _ in range(1500):
        tri, o, d = _triangle_and_ray(rng, sliver)
        t, prim = _single_ray_hits(tri[None], o[None], d[None])
        if prim[0] < 0:
            continue
        box = np.concatenate([tri.min(axis=0), tri.max(axis=0)]).reshape(1, 6)
        limits = (np.full(L, np.nextafter(t[0], 0.0)), np.full(L, np.nextafter(t[0], np.inf)))
        got = _meeting(box, np.tile(o[:, None], L), np.tile(d[:, None], L), limits, int(ray_shear(d)[2]))
        assert got == (1 << L) - 1, (tri, o, d, t[0])
        checked += 1
    assert checked > 1000


def large_leaf_tree(tris):
    """A tree whose leaves hold more than GROUPED_LEAF triangles, so packets test them group by group."""
    tree = core.build_kdtree(tris, max_depth=4)
    assert tree.count.max() > GROUPED_LEAF
    return tree


def test_camera_packets_through_large_leaves_equal_intersect():
    rng = np.random.default_rng(5)
    tree = large_leaf_tree(random_soup(rng, 3000))
    for eye in ([2.5, -3.0, 1.5], [0.1, 0.2, -0.1]):
        o, d = grid_rays(eye, [0.0, 0.0, 0.0], 64, 48, fov=1.2)
        hits, _ = assert_same_as_intersect(tree, o, d, 64)
        assert (hits.prim >= 0).mean() > 0.1
        assert_same_as_intersect(tree, o, d, 64, 0.5, 2.0)  # ranges cut on both sides


@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_large_leaves_through_exact_vertices_and_edges(offset):
    """The subdivided cube from inside, far from the origin too: rays through exact vertices and edges,
    each hitting once, as single rays do."""
    tris = (subdivided_cube(16) + offset).astype(np.float32)
    tree = large_leaf_tree(tris)
    o, d = grid_rays(np.full(3, offset), np.array([1.0, 0.25, 0.5]) + offset, 32, 16, fov=1.0)
    d = np.round(d * 64) / 64
    d[~d.any(axis=1)] = 1.0
    hits, _ = assert_same_as_intersect(tree, o, d, 32)
    assert (hits.prim >= 0).all()


def test_any_hit_packets_through_large_leaves_equal_single_rays():
    rng = np.random.default_rng(6)
    tris = random_soup(rng, 3000)
    tree = large_leaf_tree(tris)
    o, d = ao_rays(rng, rng.uniform(-1, 1, (200, 3)), zero_every=7)
    got = assert_same_as_single_rays(tree, o, d, 0.0, 0.3)
    assert 0.1 < got.mean() < 0.9


def test_packets_through_two_meshes_with_large_leaves_equal_single_rays():
    """Two meshes side by side in a two-level scene, each with large leaves: each mesh's packets read its
    own column groups (the packed boxes' offsets), as the single-ray scene kernel's hits show."""
    from core.render.camera import tiled_packets
    from core.scene.ray_visibility import CAMERA_RAYS
    from core.scene.scene_packets import trace_camera_packets
    from core.scene.scene_queries import trace_valid_rays
    from core.scene.two_level import build_two_level
    from tests.test_scene_packets import camera_rays

    rng = np.random.default_rng(7)
    trees = [large_leaf_tree(random_soup(rng, n)) for n in (1001, 2003)]  # column counts not multiples of 4
    matrices = np.stack([np.eye(4), np.eye(4)])
    matrices[1, :3, 3] = [0.3, 0.2, 0.0]
    scene = build_two_level(trees, [0, 1], matrices)
    assert len(scene.arrays.leaf_boxes) == sum(len(t.leaf_boxes) for t in trees)
    o, d, lo, hi = camera_rays([2.5, -3.0, 1.5], [0.0, 0.0, 0.0], 48, 40)
    got = trace_camera_packets(scene, o, d, lo, hi, tiled_packets(48, 40), 2, CAMERA_RAYS)
    want = trace_valid_rays(scene, o, d, lo, hi, False, 2, CAMERA_RAYS)
    for name, a, b in zip(("t", "instance", "prim", "u", "v"), got, want):
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert (got[1] == 1).sum() > 50 and (got[1] == 0).sum() > 50  # both meshes are hit


def test_a_sliver_hit_beyond_its_exact_distance_is_kept():
    """A sliver seen edge on, whose computed t differs from its exact t by more than float32 bounds
    widen, in a large leaf behind a triangle hit a hair further: packets find the sliver, as single
    rays do, and so does an occlusion query whose range ends between the exact and the computed t."""
    rng = np.random.default_rng(1)
    sliver = np.array([[0.0015998355811461806, 0.0, 0.0], [0.0015998356975615025, 0.0, 1.3237656354904175],
                       [0.001599835348315537, 0.0, -0.8730815052986145]], np.float32)
    o1 = np.array([0.004624106853505547, 2.362459852578012e-10, 1.0076862251889713])
    d1 = np.array([-0.48800599638147046, -3.8121401841543327e-08, -1.168728373756057])
    p = o1 + 0.0061971 * d1
    n = d1 / np.linalg.norm(d1)
    u = np.cross(n, [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    behind = np.array([p + 0.01 * u, p - 0.005 * u + 0.01 * v, p - 0.005 * u - 0.01 * v], np.float32)
    far = (rng.uniform(-2, 2, (36, 1, 3)) + rng.normal(size=(36, 3, 3)) * 1e-3).astype(np.float32)
    tree = core.build_kdtree(np.concatenate([behind[None], far[:3], np.repeat(sliver[None], 4, axis=0), far[3:]]),
                             max_depth=0)
    assert tree.count[0] > GROUPED_LEAF
    o, d = np.tile(o1, (L, 1)), np.tile(d1, (L, 1))
    hits, _ = assert_same_as_intersect(tree, o, d, 4)
    assert (hits.prim >= 4).all()  # the sliver, not the triangle behind it
    np.testing.assert_array_equal(assert_same_as_single_rays(tree, o, d, 0.0, 0.00619697), True)
