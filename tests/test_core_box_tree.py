"""The top level's box builder (core/build/box_tree.py) against brute force over every instance.

Reference: each ray carried into every instance's object space with the traversal's own float64
arithmetic (instance_traversal._to_object's sums, in numpy) and tested against all of the instance's
triangles with the core's triangle test (oracles.brute_watertight), the closest kept. No tree, top or
bottom, is involved, and the arithmetic is the same, so the scene's hits must be identical: the same t,
the same triangle, and an instance among those at that t (identical instances tie; coplanar overlapping
instances may differ in t's last bits, and either may be found, whatever the top level).
"""
import numpy as np
import pytest

import core
from core.build import box_tree
from core.scene import two_level
from tests.oracles import brute_watertight


def _brute_scene(meshes, mesh_of, mats, origins, directions):
    """(closest t (R,), t (R, I) and prim (R, I) per instance) by brute force."""
    w2o = two_level.world_to_object(np.asarray(mats, np.float64))
    ts, prims = [], []
    for inst, m in enumerate(mesh_of):
        a = w2o[inst]
        o = np.stack([a[k, 0] * origins[:, 0] + a[k, 1] * origins[:, 1] + a[k, 2] * origins[:, 2] + a[k, 3]
                      for k in range(3)], 1)
        d = np.stack([a[k, 0] * directions[:, 0] + a[k, 1] * directions[:, 1] + a[k, 2] * directions[:, 2]
                      for k in range(3)], 1)
        t, p, _ = brute_watertight(meshes[m], o, d)
        ts.append(t)
        prims.append(p)
    ts, prims = np.stack(ts, 1), np.stack(prims, 1)
    return ts.min(axis=1), ts, prims


def _assert_brute(meshes, mesh_of, mats, origins, directions, **options):
    scene = core.build_two_level([core.build_kdtree(m) for m in meshes], mesh_of, mats, **options)
    hits = core.intersect_scene(scene, origins, directions)
    best, ts, prims = _brute_scene(meshes, mesh_of, mats, origins, directions)
    hit = np.isfinite(best)
    np.testing.assert_array_equal(hits.prim >= 0, hit)
    np.testing.assert_array_equal(hits.t[hit], best[hit].astype(np.float32))
    rows = np.flatnonzero(hit)
    chosen = ts[rows, hits.instance[rows]]
    # the closest instance, or one whose t differs from it only by rounding (coplanar overlapping quads)
    assert (chosen <= best[rows] * (1 + 1e-12)).all(), "a hit names an instance that is not the closest"
    np.testing.assert_array_equal(hits.prim[rows], prims[rows, hits.instance[rows]])
    return scene, hits


def _blob(rng, n=24):
    centres = rng.normal(size=(n, 1, 3)) * 0.5
    return (centres + rng.normal(size=(n, 3, 3)) * 0.2).astype(np.float32)


def _matrices(rng, n, spread, scale=(0.3, 1.5)):
    mats = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        mats[i, :3, :3] = q * rng.uniform(*scale, 3)
    mats[:, :3, 3] = rng.uniform(-spread, spread, (n, 3))
    return mats


def _rays(rng, n, spread, centre=0.0):
    origins = rng.uniform(-spread, spread, (n, 3)) + centre
    targets = rng.uniform(-spread, spread, (n, 3)) * 0.5 + centre
    return origins, targets - origins


@pytest.fixture
def parallel_top(monkeypatch):
    """The parallel top levels from 64 boxes on, so small scenes exercise them (box_tree._split_top)."""
    monkeypatch.setattr(box_tree, "PARALLEL_MIN_REFS", 64)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("spread", [2.0, 12.0])  # overlapping boxes, then a scatter
def test_random_instances_hit_as_brute_force(seed, spread, parallel_top):
    rng = np.random.default_rng(seed)
    meshes = [_blob(rng, 16 + 8 * i) for i in range(3)]
    n = 400
    mesh_of = rng.integers(0, 3, n).astype(np.int32)
    mats = _matrices(rng, n, spread)
    scene, hits = _assert_brute(meshes, mesh_of, mats, *_rays(rng, 1500, spread + 2.0), threads=2)
    assert (hits.prim >= 0).mean() > 0.3
    stats = scene.stats()
    assert stats["top_nodes"] > 50  # a real tree, not one leaf
    assert stats["top_references"] <= 2 * two_level.TOP_LEVEL_DUPLICATION * n  # the budget bounds duplication


def test_identical_boxes_and_identical_instances(parallel_top):
    """Instances repeated exactly (identical boxes, hits tied between them) and others with the same
    box but turned mesh (the same box, different triangles)."""
    rng = np.random.default_rng(3)
    cube = _blob(rng, 30)
    mats = _matrices(rng, 40, 6.0)
    mats = np.concatenate([mats, mats, mats[:10]])  # 90 instances, 50 boxes
    mesh_of = np.zeros(len(mats), np.int32)
    mesh_of[80:] = 1
    flipped = cube.copy()
    flipped[:, :, 0] = cube[:, :, 0].max() + cube[:, :, 0].min() - cube[:, :, 0]  # mirrored in its own box
    _assert_brute([cube, flipped], mesh_of, mats, *_rays(rng, 1500, 8.0), threads=2)


def test_flat_instance_boxes(parallel_top):
    """Flat instances (a quad in z = const) in several planes and orientations: boxes with no extent on
    one axis, many lying in the same plane, which a split plane can hit exactly."""
    rng = np.random.default_rng(4)
    quad = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], np.float32)
    n = 300
    mats = np.tile(np.eye(4), (n, 1, 1))
    mats[:, :3, 3] = np.column_stack([rng.integers(-8, 8, (n, 2)), rng.integers(-2, 3, n)]).astype(np.float64)
    turned = rng.integers(0, 3, n)  # some quads stood up in x = const or y = const
    for i in np.flatnonzero(turned == 1):
        mats[i, :3, :3] = [[0, 0, 1], [0, 1, 0], [1, 0, 0]]
    for i in np.flatnonzero(turned == 2):
        mats[i, :3, :3] = [[1, 0, 0], [0, 0, 1], [0, 1, 0]]
    mats[:, :3, :3] *= rng.uniform(0.5, 2.0, (n, 1, 1))
    _assert_brute([quad], np.zeros(n, np.int32), mats, *_rays(rng, 2000, 9.0), threads=2)


def test_boxes_far_from_the_origin(parallel_top):
    """Instances 1e5 out, in a cluster a few units wide: float32 boxes and planes with coarse steps."""
    rng = np.random.default_rng(5)
    mesh = _blob(rng, 20)
    mats = _matrices(rng, 200, 5.0)
    mats[:, :3, 3] += (1e5, -2e5, 5e4)
    _assert_brute([mesh], np.zeros(200, np.int32), mats, *_rays(rng, 1500, 7.0, centre=np.array([1e5, -2e5, 5e4])),
                  threads=2)


@pytest.mark.parametrize("n", [1, 2])
def test_one_and_two_instances(n):
    rng = np.random.default_rng(6)
    mesh = _blob(rng, 40)
    _assert_brute([mesh], np.zeros(n, np.int32), _matrices(rng, n, 1.5), *_rays(rng, 2000, 3.0))


def test_deterministic(parallel_top):
    """The same boxes give the same tree, build after build (threads race only over whole subtrees)."""
    rng = np.random.default_rng(7)
    tree = core.build_kdtree(_blob(rng, 20))
    mats = _matrices(rng, 3000, 20.0)
    tops = [core.build_two_level([tree], np.zeros(3000, np.int32), mats, threads=2).top for _ in range(3)]
    for top in tops[1:]:
        for a, b in zip(tops[0], top):
            np.testing.assert_array_equal(a, b)


def test_box_tree_leaves_hold_every_box_they_overlap():
    """Each leaf cell of build_box_tree over random boxes lists every box overlapping the cell's interior
    (the kd-tree's invariant that the traversal relies on), and nothing outside it."""
    rng = np.random.default_rng(8)
    lo = rng.uniform(-10, 10, (5000, 3)).astype(np.float32)
    boxes = np.concatenate([lo, lo + rng.uniform(0.0, 2.0, (5000, 3)).astype(np.float32)], 1)
    bounds = np.concatenate([boxes[:, :3].min(0), boxes[:, 3:].max(0)]).astype(np.float32)
    params = core.BuildOptions(clip=False, intersection_cost=1.5, duplication_budget=3.0).params(5000, bounds)
    axis, split, child, count, leaf = box_tree.build_box_tree(boxes, bounds, params, 2)
    stack, leaves = [(0, bounds.copy())], 0
    while stack:
        node, cell = stack.pop()
        if axis[node] == two_level.LEAF:
            leaves += 1
            inside = ((boxes[:, :3] < cell[3:]) & (boxes[:, 3:] > cell[:3])).all(axis=1)
            held = np.zeros(len(boxes), bool)
            held[leaf[child[node]:child[node] + count[node]]] = True
            missing = np.flatnonzero(inside & ~held)
            assert len(missing) == 0, f"leaf {node} misses box {missing[:3]}"
            touching = ((boxes[:, :3] <= cell[3:]) & (boxes[:, 3:] >= cell[:3])).all(axis=1)
            assert not (held & ~touching).any(), f"leaf {node} holds a box outside its cell"
            continue
        a, pos = axis[node], split[node]
        left, right = cell.copy(), cell.copy()
        left[a + 3], right[a] = pos, pos
        stack += [(child[node], left), (child[node] + 1, right)]
    assert leaves > 500
