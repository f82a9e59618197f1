"""Tree invariants, statistics recomputed independently, options, pickling."""
import pickle

import numpy as np
import pytest

import core
from core.trace.layout import LEAF
from core.build.options import REFINE_RAYS_PER_TRIANGLE
from tests.core_helpers import BUILDERS, assert_same_as_brute
from tests.meshes import degenerate_mix, lattice, random_soup


def node_boxes(tree):
    """Box of every node, by walking down from the root (independent of the builder's bookkeeping)."""
    boxes = {0: tree.bounds.astype(np.float64)}
    depth = {0: 0}
    order = [0]
    for node in order:
        if tree.axis[node] == LEAF:
            continue
        a, c, s = tree.axis[node], tree.child[node], tree.split[node]
        left, right = boxes[node].copy(), boxes[node].copy()
        left[a + 3], right[a] = s, s
        boxes[c], boxes[c + 1] = left, right
        depth[c] = depth[c + 1] = depth[node] + 1
        order += [c, c + 1]
    return boxes, depth


def half_area(b):
    e = b[3:] - b[:3]
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]


@pytest.mark.parametrize("options", BUILDERS)
def test_structure_and_sah_cost(options):
    rng = np.random.default_rng(3)
    tris = np.concatenate([random_soup(rng, 1500), lattice(3), degenerate_mix(rng)])
    tree = core.build_kdtree(tris, **options)
    boxes, depth = node_boxes(tree)
    assert len(boxes) == tree.node_count  # every node reached exactly once
    leaves = [i for i in boxes if tree.axis[i] == LEAF]
    inner = [i for i in boxes if tree.axis[i] != LEAF]
    for i in inner:
        b = boxes[i]
        assert b[tree.axis[i]] < tree.split[i] < b[tree.axis[i] + 3]  # planes strictly inside
    for i in leaves:
        assert 0 <= tree.child[i] and tree.child[i] + tree.count[i] <= len(tree.leaf_prims)
    o = tree.options
    root = half_area(boxes[0])
    sah = (o.traversal_cost * sum(half_area(boxes[i]) for i in inner)
           + o.intersection_cost * sum(half_area(boxes[i]) * tree.count[i] for i in leaves)) / root
    s = tree.stats()
    assert s["sah_cost"] == pytest.approx(sah, rel=1e-9)
    assert s["nodes"] == tree.node_count and s["leaves"] == len(leaves)
    assert s["empty_leaves"] == sum(tree.count[i] == 0 for i in leaves)
    assert s["max_depth"] == max(depth.values()) <= o.depth_for(len(tris))
    assert s["references"] == len(tree.leaf_prims) == sum(tree.count[i] for i in leaves)
    t32 = tris.astype(np.float32).astype(np.float64)  # what the tree holds
    area = np.linalg.norm(np.cross(t32[:, 1] - t32[:, 0], t32[:, 2] - t32[:, 0]), axis=1)
    kept = set(np.flatnonzero(area > 0))
    assert set(tree.leaf_prims.tolist()) == kept  # every triangle with area, nothing else
    for i in leaves:
        prims = tree.leaf_prims[tree.child[i]:tree.child[i] + tree.count[i]]
        assert len(set(prims.tolist())) == len(prims)  # no triangle twice in one leaf


def leaves_containing(tree, point):
    """All leaves whose closed box contains the point (a point on a plane is in both children)."""
    found, stack = [], [0]
    while stack:
        node = stack.pop()
        if tree.axis[node] == LEAF:
            found.append(node)
            continue
        a, s, c = tree.axis[node], tree.split[node], tree.child[node]
        if point[a] <= s:
            stack.append(c)
        if point[a] >= s:
            stack.append(c + 1)
    return found


@pytest.mark.parametrize("options", BUILDERS)
def test_every_point_of_every_triangle_is_in_a_leaf_holding_it(options):
    """The builder never loses a part of a triangle: sampled points (vertices, edge points, interior)
    lie in at least one leaf that lists the triangle. Catches clipping and planar-triangle mistakes."""
    rng = np.random.default_rng(4)
    tris = np.concatenate([random_soup(rng, 800), lattice(3)]).astype(np.float32)
    tree = core.build_kdtree(tris, **options)
    weights = np.concatenate([np.eye(3), [[0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5]],
                              rng.dirichlet([1, 1, 1], 4)])
    for prim in range(len(tris)):
        for p in weights @ tris[prim].astype(np.float64):
            holders = [tree.leaf_prims[tree.child[l]:tree.child[l] + tree.count[l]]
                       for l in leaves_containing(tree, p)]
            assert any(prim in h for h in holders), f"triangle {prim} lost at {p}"


def test_builders_quality_order():
    """The exact sweep is the quality reference; binned stays close to it and beats the median."""
    rng = np.random.default_rng(9)
    from tests.meshes import icosphere, mesh_triangles
    tris = np.concatenate([mesh_triangles(*icosphere(5)), random_soup(rng, 5000, 0.03)])
    sah = {b: core.build_kdtree(tris, builder=b).stats()["sah_cost"] for b in ("binned", "exact", "median")}
    assert sah["exact"] <= sah["binned"] * 1.02
    assert sah["binned"] <= sah["exact"] * 1.10
    assert sah["binned"] < sah["median"]


def test_stats_fields_and_pickle():
    rng = np.random.default_rng(2)
    tris = random_soup(rng, 500)
    tree = core.build_kdtree(tris)
    s = tree.stats()
    for key in ("triangles", "nodes", "leaves", "empty_leaves", "max_depth", "references", "sah_cost",
                "build_ms"):
        assert key in s
    assert s["triangles"] == 500 and s["build_ms"] > 0
    clone = pickle.loads(pickle.dumps(tree))
    o, d = rng.normal(size=(100, 3)), rng.normal(size=(100, 3))
    a, b = core.intersect(tree, o, d), core.intersect(clone, o, d)
    np.testing.assert_array_equal(a.prim, b.prim)
    np.testing.assert_array_equal(a.t, b.t)


def test_default_max_depth_follows_seed_003():
    assert core.BuildOptions().depth_for(1_000_000) == int(1.2 * np.log2(1_000_000) + 2)
    assert core.BuildOptions(max_depth=7).depth_for(10**6) == 7


@pytest.mark.parametrize("bad, message", [
    ({"builder": "fast"}, "builder"),
    ({"bins": 1}, "bins"),
    ({"leaf_size": 0}, "leaf_size"),
    ({"max_depth": 61}, "max_depth"),
    ({"empty_bonus": 1.0}, "empty_bonus"),
    ({"intersection_cost": 0}, "intersection_cost"),
    ({"traversal_cost": -1}, "traversal_cost"),
    ({"threads": 0}, "threads"),
    ({"clip": "yes"}, "clip"),
    ({"top": "random"}, "top"),
    ({"split_axes": "x"}, "split_axes"),
    ({"rays": 0}, "rays"),
    ({"rays": 2.5}, "rays"),
    ({"rays": True}, "rays"),
    ({"traversal_cost": float("inf")}, "'traversal_cost' must be a finite number, got inf"),
    ({"cost_ratio": float("inf")}, "'cost_ratio' must be a finite number"),
    ({"intersection_cost": float("nan")}, "'intersection_cost' must be a finite number"),
    ({"duplication_budget": float("inf")}, "'duplication_budget' must be a finite number"),
])
def test_bad_options_are_named(bad, message):
    with pytest.raises(ValueError, match=message):
        core.build_kdtree(np.zeros((1, 3, 3)), **bad)


def test_options_take_numpy_scalars_and_name_a_list():
    """BuildOptions itself, not only build_kdtree, takes numpy scalars as the values they hold; a list
    where a name is wanted is named, not a bare TypeError."""
    opts = core.BuildOptions(bins=np.int64(8), intersection_cost=np.float32(0.5), clip=np.True_)
    assert (opts.bins, opts.intersection_cost, opts.clip) == (8, 0.5, True) and type(opts.bins) is int
    with pytest.raises(ValueError, match=r"build option 'builder' must be one of .* got \['binned'\]"):
        core.BuildOptions(builder=["binned"])


def test_unknown_option_is_named():
    with pytest.raises(TypeError, match="colour"):
        core.build_kdtree(np.zeros((1, 3, 3)), colour="red")


def height_field(n=80, amplitude=0.3):
    """An n x n grid of quads over [-5, 5]^2 with a radial wave in z: vertex lines at every grid step."""
    xs = np.linspace(-5.0, 5.0, n + 1)
    x, y = np.meshgrid(xs, xs)
    v = np.stack([x, y, amplitude * np.sin(np.hypot(x, y) * 4.0)], axis=-1).reshape(-1, 3)
    i = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return v[np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])].astype(np.float32)


def test_snapping_splits_height_fields_on_their_vertex_lines():
    """Bin boundaries fall between a grid's vertex lines; snapping to the nearest box boundary puts
    the planes on them, so triangles are rarely cut (each cut costs a second reference), the SAH cost
    is lower, and the tree still answers exactly like brute force."""
    tris = height_field()
    snapped, binned = core.build_kdtree(tris), core.build_kdtree(tris, snap=False)
    s, b = snapped.stats(), binned.stats()
    # 1.06 against 1.60 references a triangle (1.28 against 3.31 at the intersection cost of 1.5,
    # whose deeper trees cut more)
    assert s["references_per_triangle"] < 1.15 and b["references_per_triangle"] > 1.4 * s["references_per_triangle"]
    assert s["sah_cost"] < b["sah_cost"]
    rng = np.random.default_rng(0)
    origins = np.concatenate([rng.uniform(-6, 6, (400, 2)), np.full((400, 1), 2.0)], axis=1)
    directions = np.concatenate([rng.normal(0, 0.3, (400, 2)), -np.ones((400, 1))], axis=1)
    directions[:50, :2] = 0.0  # straight down, along the vertex lines' planes
    origins[:50, :2] = rng.integers(-40, 41, (50, 2)) / 8.0  # exactly on vertex lines
    assert_same_as_brute(snapped, tris.astype(np.float64), origins, directions)


@pytest.mark.parametrize("seed", range(4))
def test_snap_candidates_and_their_counts_match_a_brute_force_count(seed):
    """The one-pass search for the box boundaries nearest the binned plane (split_binned) finds the
    same planes and the same left / right / planar counts as counting at each plane directly, with
    many ties and planar boxes (values on a coarse grid)."""
    from core.build.split_binned import _nearest_boundaries

    rng = np.random.default_rng(seed)
    lo = rng.integers(0, 40, 500) / 8.0
    hi = lo + rng.integers(0, 6, 500) / 8.0 * (rng.random(500) < 0.7)  # 30% planar
    boxes = np.zeros((500, 6), np.float32)
    boxes[:, 1], boxes[:, 4] = lo, hi
    for pos, step in [(np.float32(2.5), 0.3), (np.float32(2.55), 0.2), (np.float32(0.0), 0.5),
                      (np.float32(5.0), 0.05), (np.float32(3.1), 1.0)]:
        below, above = _nearest_boundaries(boxes, 0, 500, 1, pos, step)
        values = np.concatenate([lo, hi]).astype(np.float32)
        under, over = values[(values > pos - step) & (values < pos)], values[(values > pos) & (values < pos + step)]
        for (c, left, right, planar), found in ((below, under.max(initial=-np.inf)), (above, over.min(initial=np.inf))):
            if not np.isfinite(found):
                continue  # no boundary within the bin: the candidate is the bin edge, never taken
            assert c == found
            c = np.float32(c)
            lo32, hi32 = boxes[:, 1], boxes[:, 4]
            assert (left, right, planar) == ((lo32 < c).sum(), (hi32 > c).sum(), ((lo32 == c) & (hi32 == c)).sum())


def test_a_ray_count_trims_the_tree_and_answers_stay_exact():
    """Told how many rays it will answer, the builder stops where a split would cost more to build
    than it saves them (sah.beats_leaf): fewer rays, fewer nodes; rays beyond any build cost, the
    default tree exactly; every tree answers like brute force."""
    tris = random_soup(np.random.default_rng(11), 3000).astype(np.float32)
    default = core.build_kdtree(tris)
    many = core.build_kdtree(tris, rays=10**15)
    for name in ("axis", "split", "child", "count", "leaf_prims"):
        assert np.array_equal(getattr(many, name), getattr(default, name)), name
    nodes = [len(core.build_kdtree(tris, rays=r).axis) for r in (10**6, 10**4, 10**2)]
    assert len(default.axis) >= nodes[0] >= nodes[1] >= nodes[2]
    assert nodes[2] < len(default.axis) / 4  # a hundred rays do not pay for a deep tree
    rng = np.random.default_rng(3)
    origins = rng.uniform(-2, 2, (500, 3))
    directions = rng.normal(size=(500, 3))
    for rays in (10**4, 10**2):
        assert_same_as_brute(core.build_kdtree(tris, rays=rays), tris.astype(np.float64), origins, directions)


def _wavy_grid(cells, rng):
    """A jittered, gently waved grid over the unit square: triangles cut by many split planes."""
    g = np.linspace(0.0, 1.0, cells + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    x = x + rng.uniform(-0.3, 0.3, x.shape) / cells
    y = y + rng.uniform(-0.3, 0.3, y.shape) / cells
    p = np.stack([x, y, 0.02 * np.sin(5 * x) * np.cos(3 * y)], axis=-1)
    p00, p10, p01, p11 = p[:-1, :-1], p[1:, :-1], p[:-1, 1:], p[1:, 1:]
    return np.concatenate([np.stack([p00, p10, p11], -2).reshape(-1, 3, 3),
                           np.stack([p00, p11, p01], -2).reshape(-1, 3, 3)]).astype(np.float32)


def test_a_tree_for_few_rays_a_triangle_neither_clips_nor_snaps_and_bins_one_axis():
    """Clipping straddlers, snapping planes to box boundaries and searching all three axes pay for
    their build work only when the tree serves many rays (options.REFINE_RAYS_PER_TRIANGLE): told
    fewer rays a triangle, the tree is the one built with clip and snap off and split_axes "longest";
    told that many, the one with them on, which on this grid differs in each of the three. Every
    tree answers like brute force."""
    tris = _wavy_grid(64, np.random.default_rng(5))
    names = ("axis", "split", "child", "count", "leaf_prims")

    def same(a, b):
        return all(np.array_equal(getattr(a, n), getattr(b, n)) for n in names)

    enough = REFINE_RAYS_PER_TRIANGLE * len(tris)
    plain = dict(clip=False, snap=False, split_axes="longest")
    few, few_plain = core.build_kdtree(tris, rays=enough - 1), core.build_kdtree(tris, rays=enough - 1, **plain)
    many, many_plain = core.build_kdtree(tris, rays=enough), core.build_kdtree(tris, rays=enough, **plain)
    assert same(few, few_plain)
    assert not same(many, many_plain)
    for one_off in ({"clip": False}, {"snap": False}, {"split_axes": "longest"}):
        assert not same(core.build_kdtree(tris, rays=enough, **one_off), many), one_off
    rng = np.random.default_rng(8)
    origins = np.column_stack([rng.uniform(0, 1, (400, 2)), np.full(400, 1.0)])
    directions = np.column_stack([rng.normal(0, 0.3, (400, 2)), np.full(400, -1.0)])
    for tree in (few, many):
        assert_same_as_brute(tree, tris.astype(np.float64), origins, directions)


def _cylinder_along_x(segments, length=10.0):
    """An open cylinder of radius 0.5 along x, one quad a segment running its whole length: the
    longest axis of every cell it fills offers no plane that separates anything."""
    a = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    y, z = 0.5 * np.cos(a), 0.5 * np.sin(a)
    p0 = np.stack([np.zeros(segments + 1), y, z], axis=1)
    p1 = p0 + [length, 0.0, 0.0]
    quads = [np.stack([p0[:-1], p1[:-1], p1[1:]], 1), np.stack([p0[:-1], p1[1:], p0[1:]], 1)]
    return np.concatenate(quads).astype(np.float32)


def test_split_axes_longest_falls_back_to_all_axes_where_the_longest_cannot_split():
    """A cylinder of full-length triangles along x: no plane across x helps, so the builder searches
    y and z after all and the tree is as good as the all-axes one (without the fallback it is one leaf
    of every triangle, and a few-ray build traces 50x slower)."""
    tris = _cylinder_along_x(256)
    longest = core.build_kdtree(tris, split_axes="longest", threads=1).stats()
    everything = core.build_kdtree(tris, split_axes="all", threads=1).stats()
    assert longest["nodes"] > 100
    assert longest["sah_cost"] <= 1.25 * everything["sah_cost"]
    few = core.build_kdtree(tris, rays=len(tris)).stats()
    assert few["sah_cost"] <= 1.25 * core.build_kdtree(tris, rays=len(tris), split_axes="all").stats()["sah_cost"]


def test_split_axes_longest_splits_nodes_on_their_longest_axis():
    """With split_axes "longest" the binned SAH searches the node's longest axis (the first of equal
    ones) and the other two only where it offers no plane better than a leaf (the test above), so
    nearly every inner node splits its longest axis, far more than with "all". Boxes are rebuilt
    from the root, extents in float32 as the builder computes them; one thread: no parallel top
    levels, which search all three axes."""
    tris = random_soup(np.random.default_rng(4), 3000)
    share = {}
    for split_axes in ("longest", "all"):
        tree = core.build_kdtree(tris, split_axes=split_axes, threads=1)
        boxes, _ = node_boxes(tree)
        inner = [node for node in boxes if tree.axis[node] != LEAF]
        longest = [int(np.argmax(np.float32(boxes[k][3:]) - np.float32(boxes[k][:3]))) for k in inner]
        assert len(inner) > 1000
        share[split_axes] = np.mean(np.array([tree.axis[k] for k in inner]) == np.array(longest))
    assert share["longest"] >= 0.85 and share["longest"] > share["all"] + 0.1, share


def flat_overlapping_cards(rng, n):
    """n small triangles (~0.05 across) scattered over the unit square, all in the plane z = 0, so they
    overlap densely: cards or decals lying on a floor."""
    tris = rng.random((n, 1, 3)) + 0.05 * rng.standard_normal((n, 3, 3))
    return (tris * [1.0, 1.0, 0.0]).astype(np.float32)


@pytest.mark.parametrize("options", [pytest.param({}, id="binned"), pytest.param({"threads": 1}, id="binned-1thread"),
                                     pytest.param({"builder": "exact"}, id="exact"),
                                     pytest.param({"builder": "median"}, id="median")])
def test_densely_overlapping_flat_triangles_stay_within_the_duplication_budget(options):
    """A flat node's children share its area exactly, so the SAH finds every split of such cards
    worth it and, without a budget, split on towards max_depth (1,246 references a
    triangle and 3.5 GB for 50,000 cards; docs/choices.md#duplication-budget-16). The budget holds the leaves to at most twice its
    references a triangle, and the tree still answers exactly (brute force)."""
    rng = np.random.default_rng(11)
    tris = flat_overlapping_cards(rng, 3000)
    unbounded = core.build_kdtree(tris, duplication_budget=None, **options).stats()["references_per_triangle"]
    for budget in (2.0, 4.0):
        tree = core.build_kdtree(tris, duplication_budget=budget, **options)
        per_triangle = tree.stats()["references_per_triangle"]
        assert per_triangle <= 2 * budget < unbounded
        o = np.concatenate([rng.uniform(-0.2, 1.2, (400, 3)) * [1, 1, 0] + [0, 0, 1], rng.uniform(-1, 2, (400, 3))])
        d = np.concatenate([rng.normal(size=(400, 3)) * 0.3 + [0, 0, -1], rng.normal(size=(400, 3))])
        assert_same_as_brute(tree, tris, o, d)


def test_a_duplication_budget_that_binds_nowhere_changes_nothing_and_bad_ones_are_named():
    rng = np.random.default_rng(5)
    tris = random_soup(rng, 3000)
    a, b = core.build_kdtree(tris), core.build_kdtree(tris, duplication_budget=None)
    for name in ("axis", "split", "child", "count", "leaf_prims"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for bad in (0.5, float("nan"), "16"):
        with pytest.raises(ValueError, match="duplication_budget"):
            core.build_kdtree(tris, duplication_budget=bad)
