"""Lazy (on-demand) builds: identical results to the eager tree, and only the needed subtrees built."""
import pickle

import numpy as np
import pytest

import core
from tests.byte_counts import MIB
from tests.meshes import degenerate_mix, icosphere, lattice, mesh_triangles, random_soup, subdivided_cube
from tests.render_scenes import floor, look_at, quad

BUILDERS = [pytest.param({}, id="binned"), pytest.param({"builder": "exact"}, id="exact"),
            pytest.param({"builder": "median"}, id="median"),
            pytest.param({"rays": 20_000}, id="binned-rays"),  # a ray count ends subtrees sooner
            # ... and, few a triangle, refines less; at the SAH's former intersection cost, whose deeper trees
            # still split these small scenes into subtrees for so few rays
            pytest.param({"rays": 1000, "intersection_cost": 1.5}, id="binned-few-rays"),
            # a budget that binds: deferred subtrees must carry their room (subtree.py)
            pytest.param({"duplication_budget": 2.0}, id="binned-tight-budget")]
SMALL = 16  # deferred subtrees of at most this many references, so small test scenes defer many


def lazy_and_eager(tris, **options):
    return (core.build_kdtree(tris, lazy=True, lazy_subtree_size=SMALL, **options),
            core.build_kdtree(tris, **options))


def assert_same_queries(lazy, eager, o, d, tmin=0.0, tmax=np.inf):
    """intersect and occluded give bit-identical arrays on both trees."""
    for a, b in zip(core.intersect(lazy, o, d, tmin, tmax), core.intersect(eager, o, d, tmin, tmax)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(core.occluded(lazy, o, d, tmin, tmax),
                                  core.occluded(eager, o, d, tmin, tmax))


def built(tree):
    return tree.stats()["subtrees_built"]


def two_clusters(rng, n=1500):
    """Two soups far apart on x, so rays aimed at one need none of the other's subtrees."""
    a = random_soup(rng, n, size=0.05, extent=0.5)
    return np.concatenate([a - [3.0, 0, 0], a + [3.0, 0, 0]])


def rays_at(rng, target, n, spread=0.4):
    """Rays from a ring around `target` (in the y-z plane, away from the other cluster) towards it."""
    angle = rng.uniform(0, 2 * np.pi, n)
    o = np.asarray(target) + np.stack([np.zeros(n), 3 * np.cos(angle), 3 * np.sin(angle)], 1)
    aim = np.asarray(target) + rng.uniform(-spread, spread, (n, 3))
    return o, aim - o


SCENES = {
    "soup": lambda rng: random_soup(rng, 2000),
    "degenerate": degenerate_mix,
    "lattice": lambda rng: lattice(4),
    "sphere": lambda rng: mesh_triangles(*icosphere(3)),
    "cube": lambda rng: subdivided_cube(8),
}


@pytest.mark.parametrize("options", BUILDERS)
@pytest.mark.parametrize("scene", sorted(SCENES))
def test_lazy_queries_identical_to_eager(scene, options):
    rng = np.random.default_rng(7)
    tris = SCENES[scene](rng)
    lazy, eager = lazy_and_eager(tris, **options)
    assert lazy.stats()["subtrees_total"] > 1
    o, d = rays_at(rng, (0.3, 0.2, 0.1), 300)
    assert_same_queries(lazy, eager, o, d)  # first rays: only part of the tree exists
    o, d = rng.uniform(-2, 2, (1500, 3)), rng.normal(size=(1500, 3))
    o[:100] = tris[rng.integers(0, len(tris), 100), 0]  # rays starting on vertices
    assert_same_queries(lazy, eager, o, d, tmin=1e-4, tmax=rng.uniform(0.1, 3.0, 1500))
    assert_same_queries(lazy, eager, o, d)


def test_only_needed_subtrees_are_built_and_more_as_more_rays_come():
    rng = np.random.default_rng(3)
    tris = two_clusters(rng)
    lazy, eager = lazy_and_eager(tris)
    total = lazy.stats()["subtrees_total"]
    assert built(lazy) == 0
    o, d = rays_at(rng, (-3.0, 0, 0), 50, spread=0.1)
    assert_same_queries(lazy, eager, o, d)
    first = built(lazy)
    assert 0 < first < total // 2  # one cluster, and only near its centre
    o, d = rays_at(rng, (-3.0, 0, 0), 400)
    assert_same_queries(lazy, eager, o, d)
    second = built(lazy)
    assert first < second < total // 2 + 1  # still none of the other cluster
    o, d = rays_at(rng, (3.0, 0, 0), 400)
    assert_same_queries(lazy, eager, o, d)
    assert second < built(lazy) <= total
    assert lazy.node_count < eager.node_count or built(lazy) == total


def test_large_scene_with_parallel_top_levels():
    """Enough triangles for the parallel top levels; lazy keeps them and defers inside each task."""
    rng = np.random.default_rng(11)
    tris = random_soup(rng, 20000, size=0.02)
    lazy = core.build_kdtree(tris, lazy=True, lazy_subtree_size=256, threads=2)
    eager = core.build_kdtree(tris, threads=2)
    o, d = rays_at(rng, (0.5, 0.5, 0.5), 2000, spread=0.2)
    assert_same_queries(lazy, eager, o, d)
    s = lazy.stats()
    assert 0 < s["subtrees_built"] < s["subtrees_total"]
    assert s["nodes"] < eager.node_count


@pytest.mark.parametrize("options", BUILDERS)
def test_speculative_building_is_identical_and_builds_neighbours(options):
    rng = np.random.default_rng(5)
    tris = two_clusters(rng)
    plain = core.build_kdtree(tris, lazy=True, lazy_subtree_size=SMALL, **options)
    spec = core.build_kdtree(tris, lazy=True, lazy_subtree_size=SMALL, lazy_speculative=True, **options)
    eager = core.build_kdtree(tris, **options)
    o, d = rays_at(rng, (-3.0, 0, 0), 100, spread=0.2)
    assert_same_queries(spec, eager, o, d)
    assert_same_queries(plain, eager, o, d)
    assert built(plain) < built(spec) < spec.stats()["subtrees_total"]
    assert spec.stats()["lazy_rounds"] <= plain.stats()["lazy_rounds"]


def test_stats_fields_are_consistent():
    rng = np.random.default_rng(9)
    tris = two_clusters(rng)
    lazy, eager = lazy_and_eager(tris)
    e = eager.stats()
    assert (e["lazy"], e["subtrees_total"], e["subtrees_built"], e["lazy_build_ms"]) == (False, 0, 0, 0.0)
    s = lazy.stats()
    assert s["lazy"] and s["subtrees_built"] == 0 and s["lazy_rounds"] == 0 and s["lazy_build_ms"] == 0.0
    assert s["references"] + s["unbuilt_references"] >= len(tris)  # every triangle is somewhere
    assert s["nodes"] == lazy.node_count < eager.node_count
    core.occluded(lazy, *rays_at(rng, (-3.0, 0, 0), 200))
    s2 = lazy.stats()
    assert 0 < s2["subtrees_built"] < s2["subtrees_total"] == s["subtrees_total"]
    assert s2["nodes"] > s["nodes"] and s2["lazy_rounds"] >= 1 and s2["lazy_build_ms"] > 0.0
    assert s2["unbuilt_references"] < s["unbuilt_references"]
    core.occluded(lazy, rng.uniform(-4, 4, (5000, 3)), rng.normal(size=(5000, 3)))
    core.intersect(lazy, *rays_at(rng, (3.0, 0, 0), 2000, spread=1.0))
    core.intersect(lazy, *rays_at(rng, (-3.0, 0, 0), 2000, spread=1.0))
    full = lazy.stats()
    if full["subtrees_built"] == full["subtrees_total"]:  # the whole tree: the eager tree, node for node
        assert full["unbuilt_references"] == 0
        for key in ("nodes", "leaves", "empty_leaves", "max_depth", "references", "sah_cost", "leaf_sizes"):
            assert full[key] == e[key], key
    else:
        assert full["nodes"] < e["nodes"]
    assert "lazy: " in repr(lazy)


def test_partly_built_tree_pickles_and_keeps_building():
    rng = np.random.default_rng(2)
    tris = two_clusters(rng)
    lazy, eager = lazy_and_eager(tris)
    core.intersect(lazy, *rays_at(rng, (-3.0, 0, 0), 100))
    copy = pickle.loads(pickle.dumps(lazy))
    assert copy.stats()["subtrees_built"] == built(lazy)
    o, d = rays_at(rng, (3.0, 0, 0), 300)
    assert_same_queries(copy, eager, o, d)
    assert built(copy) > built(lazy)


def occluded_scene():
    """A sphere on a floor, a second sphere hidden behind a wall: rays never reach the hidden one."""
    sphere = mesh_triangles(*icosphere(2)) * 0.5
    wall = quad((0.0, 1.0, 1.0), (3.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    return np.concatenate([floor(0.0, half=3.0), sphere + [0, 0, 0.5], wall, sphere + [0.0, 2.0, 0.5]])


@pytest.mark.parametrize("mode", ["ao", "ao+shadow"])
def test_render_identical_to_eager(mode):
    tris = occluded_scene()
    camera = look_at((1.5, -3.0, 1.5), (0.0, 0.0, 0.5), fov=0.9)
    lights = [core.Light.point((2.0, -2.0, 3.0), radius=0.3), core.Light.sun((0.2, 0.4, -1.0), angle=0.1)]
    settings = dict(mode=mode, samples=8, ao_distance=0.6, lights=lights if mode != "ao" else (), seed=3)
    lazy, eager = lazy_and_eager(tris)
    reference = core.render_preview(eager, camera, 24, 24, **settings)
    np.testing.assert_array_equal(core.render_preview(lazy, camera, 24, 24, **settings), reference)
    s = lazy.stats()
    assert 0 < s["subtrees_built"] < s["subtrees_total"]  # the hidden sphere stays unbuilt
    spec = core.build_kdtree(tris, lazy=True, lazy_subtree_size=SMALL, lazy_speculative=True)
    np.testing.assert_array_equal(core.render_preview(spec, camera, 24, 24, **settings), reference)


def test_progressive_render_with_error_target_identical_to_eager():
    """Redone batches must not disturb the per-pixel bookkeeping (counts, rays, retirement)."""
    tris = occluded_scene()
    camera = look_at((1.5, -3.0, 1.5), (0.0, 0.0, 0.5), fov=0.9)
    renders = []
    for tree in lazy_and_eager(tris):
        render = core.PreviewRender(tree, camera, 16, 16, samples=24, ao_distance=0.6, error_target=0.05)
        while not render.done:
            render.step(3)
        renders.append(render)
    lazy, eager = renders
    np.testing.assert_array_equal(lazy.image(), eager.image())
    np.testing.assert_array_equal(lazy.sample_counts(), eager.sample_counts())
    assert lazy.rays_traced == eager.rays_traced and lazy.rays_saved == eager.rays_saved


def test_a_lazy_tree_keeps_its_memory_limit_while_it_grows():
    """With forced splits the eager build of these triangles stops at memory_limit; the lazy tree,
    building every subtree its rays reach, each within a 1 MB floor of its own, would grow to 46 MB
    under a 20 MiB limit. A round that would pass the limit is refused before it is
    spliced in; the tree still answers within it (fewer rays reach fewer subtrees)."""
    rng = np.random.default_rng(2)
    centres = rng.random((20000, 1, 3))
    tris = (centres + (rng.random((20000, 3, 3)) - 0.5) * 0.1).astype(np.float32)
    options = dict(cost_ratio=3.0, leaf_size=1, duplication_budget=None, max_depth=30, memory_limit=20 * MIB)
    with pytest.raises(core.MemoryLimitError):
        core.build_kdtree(tris, **options)
    tree = core.build_kdtree(tris, lazy=True, lazy_subtree_size=256, **options)
    o, d = rng.random((3000, 3)) * 1.4 - 0.2, rng.normal(size=(3000, 3))
    with pytest.raises(core.MemoryLimitError, match=r"lazy kd-tree over 20,000 triangles would outgrow memory_limit "
                                                    r"\(20.0 MB\)"):
        core.intersect(tree, o, d)
    assert tree.stats()["tree_bytes"] <= 20 * MIB
    few = core.build_kdtree(tris, lazy=True, lazy_subtree_size=256, **options)
    hits = core.intersect(few, o[:3], d[:3])  # three rays reach a few subtrees: within the limit
    assert few.stats()["tree_bytes"] <= 20 * MIB and few.stats()["subtrees_built"] < few.stats()["subtrees_total"]
    eager = core.build_kdtree(tris, cost_ratio=3.0, leaf_size=1, duplication_budget=None, max_depth=30)
    np.testing.assert_array_equal(hits.prim, core.intersect(eager, o[:3], d[:3]).prim)


def test_bad_lazy_options_are_named():
    with pytest.raises(ValueError, match="lazy_subtree_size"):
        core.build_kdtree(random_soup(np.random.default_rng(0), 10), lazy=True, lazy_subtree_size=0)
    with pytest.raises(ValueError, match="lazy_speculative"):
        core.build_kdtree(random_soup(np.random.default_rng(0), 10), lazy=True, lazy_speculative=1)


def test_empty_and_tiny_lazy_trees():
    empty = core.build_kdtree(np.zeros((0, 3, 3)), lazy=True)
    assert core.intersect(empty, np.zeros((1, 3)), np.ones((1, 3))).prim[0] == -1
    tris = random_soup(np.random.default_rng(4), 40)  # the whole tree is one deferred subtree
    lazy = core.build_kdtree(tris, lazy=True)
    eager = core.build_kdtree(tris)
    assert lazy.stats()["subtrees_total"] == 1 and lazy.node_count == 1
    rng = np.random.default_rng(4)
    assert_same_queries(lazy, eager, rng.uniform(-2, 2, (300, 3)), rng.normal(size=(300, 3)))
    assert built(lazy) == 1


def test_scene_queries_on_a_lazy_tree_build_what_they_reach_and_match_eager():
    """intersect_scene takes a KdTree as one identity instance: on a lazy tree the rays that stop at
    unbuilt subtrees are retraced after the build, so the answers are the eager tree's."""
    rng = np.random.default_rng(7)
    tris = two_clusters(rng)
    lazy, eager = lazy_and_eager(tris)
    o, d = rays_at(rng, np.array([-2.0, 0.0, 0.0]), 300)
    got, want = core.intersect_scene(lazy, o, d), core.intersect(eager, o, d)
    np.testing.assert_array_equal(got.prim, want.prim)
    np.testing.assert_array_equal(got.t, want.t)
    assert (got.instance[got.prim >= 0] == 0).all() and (got.instance[got.prim < 0] == -1).all()
    assert 0 < built(lazy) < lazy.stats()["subtrees_total"]


def test_two_level_scene_refuses_lazy_mesh_trees():
    tris = two_clusters(np.random.default_rng(3))
    lazy = core.build_kdtree(tris, lazy=True, lazy_subtree_size=8)
    with pytest.raises(ValueError, match="mesh 1 is a lazy tree"):
        core.build_two_level([core.build_kdtree(tris), lazy], np.array([0, 1]), np.stack([np.eye(4)] * 2))
