"""The 8-byte node records the single-ray traversal reads (layout.pack_nodes) against the builder's node
arrays they are packed from: eager, lazy (before and after on-demand rounds) and two-level trees."""
import numpy as np
import pytest

import core
from core.trace.layout import KIND_SHIFT, LEAF, LOW_MASK, UNBUILT, UNBUILT_COUNT, pack_nodes
from tests.meshes import icosphere, mesh_triangles, random_soup


def unpack(nodes):
    """(axis, split, child, count) decoded from records in NumPy, UNBUILT where the count field says so."""
    words, low = nodes[0::2], nodes[1::2] & LOW_MASK
    kind = (nodes[1::2] >> KIND_SHIFT).astype(np.int8)
    leaf = kind == LEAF
    axis = np.where(leaf & (low == UNBUILT_COUNT), UNBUILT, kind).astype(np.int8)
    child = np.where(leaf, words, low).astype(np.int32)
    count = np.where(axis == LEAF, low, 0).astype(np.int32)
    return axis, words.view(np.float32), child, count


def assert_records_match(nodes, axis, split, child, count):
    got_axis, got_split, got_child, got_count = unpack(nodes)
    np.testing.assert_array_equal(got_axis, axis)
    inner = axis < LEAF
    np.testing.assert_array_equal(got_split[inner].view(np.uint32), split[inner].view(np.uint32))  # bit for bit
    np.testing.assert_array_equal(got_child, child)
    np.testing.assert_array_equal(got_count[axis == LEAF], count[axis == LEAF])


@pytest.mark.parametrize("options", [{}, {"builder": "exact"}, {"builder": "median"}])
def test_records_hold_the_node_arrays(options):
    tree = core.build_kdtree(random_soup(np.random.default_rng(3), 3000), **options)
    assert tree.nodes.dtype == np.uint32 and tree.nodes.shape == (2 * tree.node_count,)
    assert_records_match(tree.nodes, tree.axis, tree.split, tree.child, tree.count)


def test_lazy_records_follow_the_rounds():
    """Unbuilt nodes are packed as such, and a round's splice is repacked."""
    tris = mesh_triangles(*icosphere(4))
    tree = core.build_kdtree(tris, lazy=True, lazy_subtree_size=16)
    assert (tree.axis == UNBUILT).any()
    assert_records_match(tree.nodes, tree.axis, tree.split, tree.child, tree.count)
    rng = np.random.default_rng(5)
    d = rng.standard_normal((200, 3))
    core.intersect(tree, np.zeros((200, 3)), d)
    assert tree.stats()["subtrees_built"] > 0
    assert_records_match(tree.nodes, tree.axis, tree.split, tree.child, tree.count)


def test_two_level_records_are_the_meshes_side_by_side():
    a = core.build_kdtree(mesh_triangles(*icosphere(2)))
    b = core.build_kdtree(random_soup(np.random.default_rng(1), 500))
    scene = core.build_two_level([a, b], np.array([0, 1, 1], np.int32),
                                 np.stack([np.eye(4), np.eye(4), np.diag([2.0, 2.0, 2.0, 1.0])]))
    s = scene.arrays
    np.testing.assert_array_equal(s.nodes, np.concatenate([a.nodes, b.nodes]))
    np.testing.assert_array_equal(s.node_split.view(np.uint32), s.nodes)
    assert_records_match(s.top_nodes, s.top_axis, s.top_split, s.top_child, s.top_count)


def test_limits_are_named():
    axis, split = np.array([LEAF], np.int8), np.zeros(1, np.float32)
    child, count = np.zeros(1, np.int32), np.array([UNBUILT_COUNT], np.int32)
    with pytest.raises(ValueError, match="leaf holds"):
        pack_nodes(axis, split, child, count, 2 ** 31)
    with pytest.raises(ValueError, match="references"):
        pack_nodes(axis, split, child, np.zeros(1, np.int32), 2 ** 32)
