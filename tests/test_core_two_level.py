"""Two-level scenes against the flat tree over the same world triangles, and reuse across frames.

Reference: one flat kd-tree (and a brute-force Moller-Trumbore) over the instances' world triangles.
Exact equality is not expected: the flat tree stores world triangles rounded to float32 while the
two-level scene keeps object-space triangles and transforms rays in float64. So t is compared within
1e-5 relative to t, or 1e-5 absolute (1e-6 of the scenes' size of ~10): a hit at t = 0.07 on a world
triangle whose vertices (~8 units out) were rounded to float32 moves by ~1e-6.
"""
import numpy as np
import pytest

import core
from core.scene.scene_policy import (OVERLAP_LIMIT, PRECISION_RATIO, SMALL_OBJECT, overlap_depth, plan_soup, soup_zones,
                                     sparse_mesh)
from tests.meshes import icosphere
from tests.oracles import moller_trumbore


def _random_matrix(rng, mirror=False, spread=6.0):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    scale = rng.uniform(0.4, 2.5, 3)  # non-uniform
    if mirror:
        scale[rng.integers(3)] *= -1.0
    m = np.eye(4)
    m[:3, :3] = q * scale
    m[:3, 3] = rng.uniform(-spread, spread, 3)
    return m


def _blob(rng, n=150):
    """A small closed-ish cloud of triangles around the origin (object space)."""
    centres = rng.normal(size=(n, 1, 3)) * 0.6
    return (centres + rng.normal(size=(n, 3, 3)) * 0.25).astype(np.float32)


def _instanced_scene(rng, n_meshes=3, n_instances=12):
    meshes = [_blob(rng, 100 + 40 * i) for i in range(n_meshes)]
    mesh_of = rng.integers(0, n_meshes, n_instances).astype(np.int32)
    mats = np.stack([_random_matrix(rng, mirror=(i % 3 == 0)) for i in range(n_instances)])
    return meshes, mesh_of, mats


def _world(meshes, mesh_of, mats):
    return np.concatenate([meshes[m].astype(np.float64) @ mats[i, :3, :3].T + mats[i, :3, 3]
                           for i, m in enumerate(mesh_of)])


def _global_prim(meshes, mesh_of, inst, prim):
    starts = np.concatenate([[0], np.cumsum([len(meshes[m]) for m in mesh_of])])
    return np.where(prim >= 0, starts[np.maximum(inst, 0)] + prim, -1)


def _rays(rng, n, spread=8.0):
    return rng.uniform(-spread, spread, (n, 3)), rng.normal(size=(n, 3))


def _assert_matches_flat(scene, world, o, d, tmin=0.0, tmax=np.inf, global_prim=None):
    flat = core.build_kdtree(world)
    ref = core.intersect(flat, o, d, tmin, tmax)
    hits = core.intersect_scene(scene, o, d, tmin, tmax)
    hit = ref.prim >= 0
    np.testing.assert_array_equal(hits.prim >= 0, hit)
    np.testing.assert_allclose(hits.t[hit], ref.t[hit], rtol=1e-5, atol=1e-5)
    if global_prim is not None:
        assert (global_prim(hits.instance, hits.prim)[hit] == ref.prim[hit]).mean() > 0.995
    np.testing.assert_array_equal(core.occluded_scene(scene, o, d, tmin, tmax), hit)
    return hits, ref


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_instances_match_flat_tree_and_brute_force(seed):
    rng = np.random.default_rng(seed)
    meshes, mesh_of, mats = _instanced_scene(rng)
    scene = core.build_two_level([core.build_kdtree(m) for m in meshes], mesh_of, mats)
    world = _world(meshes, mesh_of, mats)
    o, d = _rays(rng, 3000)
    hits, _ = _assert_matches_flat(scene, world, o, d,
                                   global_prim=lambda i, p: _global_prim(meshes, mesh_of, i, p))
    t_bf, prim_bf = moller_trumbore(world, o, d)
    hit = prim_bf >= 0
    assert ((hits.prim >= 0) != hit).sum() <= 2  # float32 world rounding at edges aside
    both = hit & (hits.prim >= 0)
    np.testing.assert_allclose(hits.t[both], t_bf[both], rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("layout", ["auto", "flat", "two_level"])
def test_scene_hits_name_the_callers_instance_and_triangle_in_every_layout(layout):
    """build_scene merges small static meshes into one soup tree ("auto") or everything ("flat") and
    puts instances with their own tree first; hits still name the caller's instance and the triangle
    of that instance's mesh. Meshes of 60-260 triangles, some placed once (soup candidates in "auto")."""
    rng = np.random.default_rng(11)
    meshes = [_blob(rng, 60 + 40 * i) for i in range(6)]
    mesh_of = np.array([0, 1, 2, 2, 3, 4, 5, 5, 1], np.int32)
    mats = np.stack([_random_matrix(rng, mirror=(i % 4 == 1)) for i in range(len(mesh_of))])
    indexed = [(m.reshape(-1, 3), np.arange(3 * len(m)).reshape(-1, 3)) for m in meshes]
    scene = core.build_scene(indexed, mesh_of, mats, layout=layout)
    world = _world(meshes, mesh_of, mats)
    o, d = _rays(rng, 3000)
    _assert_matches_flat(scene, world, o, d, global_prim=lambda i, p: _global_prim(meshes, mesh_of, i, p))
    if layout == "auto":
        assert scene.instance_count < len(mesh_of)  # some meshes did go into the soup


def test_limited_intervals_and_overlapping_instances():
    rng = np.random.default_rng(5)
    mesh = _blob(rng, 200)
    mats = np.stack([_random_matrix(rng, spread=0.5) for _ in range(8)])  # heavily overlapping
    mesh_of = np.zeros(8, np.int32)
    scene = core.build_two_level([core.build_kdtree(mesh)], mesh_of, mats)
    o, d = _rays(rng, 2000, spread=3.0)
    tmin, tmax = rng.uniform(0, 0.5, 2000), rng.uniform(0.5, 4.0, 2000)
    _assert_matches_flat(scene, _world([mesh], mesh_of, mats), o, d, tmin, tmax)


def test_many_instances_of_one_mesh():
    rng = np.random.default_rng(7)
    mesh = _blob(rng, 40)
    n = 3000
    mats = np.stack([_random_matrix(rng, spread=40.0) for _ in range(n)])
    scene = core.build_two_level([core.build_kdtree(mesh)], np.zeros(n, np.int32), mats)
    assert scene.stats()["top_nodes"] > n // 4  # a real top-level tree, not one big leaf
    o, d = _rays(rng, 2000, spread=45.0)
    _assert_matches_flat(scene, _world([mesh], np.zeros(n, np.int32), mats), o, d)


def test_far_from_origin_keeps_precision():
    """Instance 1e5 units away, camera next to it: the scene shifted by the camera position finds the
    same hits as a flat tree built around the camera."""
    rng = np.random.default_rng(3)
    mesh = _blob(rng, 100)
    far = _random_matrix(rng)
    far[:3, 3] += 1e5
    scene = core.build_scene([(mesh.reshape(-1, 3), np.arange(300).reshape(-1, 3))], [0], far[None],
                             origin=far[:3, 3] + 3.0, layout="two_level")
    shifted = far.copy()
    shifted[:3, 3] = -3.0
    o, d = _rays(rng, 2000, spread=3.0)
    _assert_matches_flat(scene, _world([mesh], [0], shifted[None]), o, d)


# Small spheres (320 triangles, soup-sized) on a ground 2e5 wide, far from the soup's centre against their size.
SMALL_SPHERES = [((5000.0, 0.0, 0.02), 0.01), ((-31000.0, 12000.0, 0.05), 0.03), ((77.0, -4e4, 0.003), 0.002)]


def _ground_and_small_spheres():
    verts, faces = icosphere(2)
    ground = (np.array([[-1e5, -1e5, 0], [1e5, -1e5, 0], [1e5, 1e5, 0], [-1e5, 1e5, 0]], np.float32),
              np.array([[0, 1, 2], [0, 2, 3]]))
    meshes = [ground] + [((verts * r).astype(np.float32), faces) for _, r in SMALL_SPHERES]
    mats = np.stack([np.eye(4)] * len(meshes))
    for i, (centre, _) in enumerate(SMALL_SPHERES, 1):
        mats[i, :3, 3] = centre
    return meshes, mats


@pytest.mark.parametrize("layout", ["auto", "flat"])
def test_small_soup_members_far_from_its_centre_keep_their_shape(layout):
    """A 1 cm sphere 5,000 units from the centre of a soup that also holds a ground 2e5 wide lost a fifth
    of its radius in float32 in a soup anchored at that centre; "auto" gives such members zones anchored
    near them, and "flat" (one soup, no zones) anchors it at the point of its box nearest the camera, here
    beside each sphere (docs/choices.md#one-soup-anchored-nearest-the-camera; measured before: 1.1 radii).
    Reference: the exact world triangles (float64 from the float32 object-space vertices), tested
    relative to the camera; rays through the central half of each sphere's disc, not grazing it."""
    meshes, mats = _ground_and_small_spheres()
    rng = np.random.default_rng(5)
    worst = []
    for i, (centre, radius) in enumerate(SMALL_SPHERES, 1):
        cam = np.array(centre) + (0.3 * radius, -4 * radius, 1.5 * radius)
        scene = core.build_scene(meshes, np.arange(len(meshes)), mats, origin=cam, layout=layout)
        assert scene.stats()["instances"] == (len(SMALL_SPHERES) + 1 if layout == "auto" else 1)
        target = np.array(centre) + rng.uniform(-0.35, 0.35, (500, 3)) * radius
        d = target - cam
        world = meshes[i][0].astype(np.float64)[meshes[i][1]] + centre - cam
        t_ref, _ = moller_trumbore(world, np.zeros((500, 3)), d)
        assert np.isfinite(t_ref).all()
        hits = core.intersect_scene(scene, np.zeros((500, 3)), d)
        hit_sphere = hits.instance == i  # hits name the caller's instance in every layout
        error = np.where(hit_sphere, np.abs(hits.t - t_ref) * np.linalg.norm(d, axis=1), np.inf)
        worst.append(error.max() / radius)
    assert max(worst) < 5e-3, worst  # auto: vertices within 2^-10 of the diagonal (1.7e-3 radii); two_level: 2e-7


@pytest.mark.parametrize("layout", ["auto", "flat", "two_level"])
def test_a_loose_vertex_far_away_does_not_move_the_mesh(layout):
    """A 2 cm box with one vertex 1e6 away that no triangle uses (a Blender mesh's stray vertex, which
    the add-on passes on): the soup's anchor came from the box around every vertex, 5e5 away, and
    float32 lost the box (every ray missed). Reference: the exact box faces."""
    corners = np.array([[x, y, z] for x in (-.01, .01) for y in (-.01, .01) for z in (-.01, .01)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    loose = np.vstack([corners, [[1e6, 1e6, 1e6]]])
    origins = np.array([[0.003, 0.002, 1.0], [0.0, 0.0, 1.0], [0.5, 0.5, 0.004]])
    directions = np.array([[0, 0, -1.0], [0, 0, -1.0], [-1.0, -1.0, 0]])
    scene = core.build_scene([(loose, faces)], [0], np.eye(4)[None], layout=layout)
    np.testing.assert_allclose(core.intersect_scene(scene, origins, directions).t, [0.99, 0.99, 0.49], rtol=1e-6)


def _grid_with_a_far_corner(distance):
    """(vertices, triangles) of a 3 x 3-vertex grid 3 wide in z = 0, its first corner moved to x = distance:
    six small triangles and two reaching out to it."""
    vertices = np.array([[x, y, 0.0] for y in (-1.5, 0.0, 1.5) for x in (-1.5, 0.0, 1.5)])
    vertices[0, 0] = distance
    quads = [(0, 1, 4, 3), (1, 2, 5, 4), (3, 4, 7, 6), (4, 5, 8, 7)]
    return vertices, np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))])


@pytest.mark.parametrize("distance", [3e4, 1e6, 1e8, 1e10])
@pytest.mark.parametrize("layout", ["auto", "two_level"])
def test_a_mesh_with_one_far_vertex_keeps_its_small_triangles(layout, distance):
    """A small grid one of whose corners lies far away (a stray vertex a triangle uses), beside a box: in
    the soup, float32 relative to an anchor near the middle of its huge box rounded the small triangles
    away (hundreds of rays missed or hit wrongly at 1e8). Such a mesh keeps its own tree
    (scene_policy.sparse_mesh). Reference: Moller-Trumbore on the world triangles (origin at the camera)."""
    grid = _grid_with_a_far_corner(distance)
    box = (np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float),
           np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                     [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]))
    mats = np.stack([np.eye(4), np.eye(4)])
    mats[0, 0, 3], mats[1, 0, 3] = 2.0, 6.0
    camera = np.array([0.0, 0.0, 20.0])
    scene = core.build_scene([grid, box], [0, 1], mats, origin=camera, layout=layout)
    xs, ys = np.meshgrid(np.linspace(-1.37, 1.41, 23), np.linspace(-1.43, 1.39, 23))
    kept = (xs > 0) | (ys > 0)  # the corner square went with its vertex
    targets = np.stack([xs[kept] + 2.0, ys[kept], np.zeros(kept.sum())], axis=1)
    origins, directions = targets + (0.0, 0.0, 5.0) - camera, np.tile([0.0, 0.0, -1.0], (len(targets), 1))
    world = np.concatenate([mesh[0][mesh[1]] + m[:3, 3] for mesh, m in zip((grid, box), mats)]) - camera
    with np.errstate(invalid="ignore"):  # rays in the plane of the box's sides
        t_ref, prim_ref = moller_trumbore(world, origins, directions)
    assert (prim_ref >= 0).all()  # every ray meets the grid's small triangles
    hits = core.intersect_scene(scene, origins, directions)
    assert (hits.instance == 0).all()
    np.testing.assert_allclose(hits.t, t_ref, rtol=1e-6)


def test_sparse_meshes():
    vertices, triangles = _grid_with_a_far_corner(1.5)
    box = np.concatenate([vertices.min(axis=0), vertices.max(axis=0)])
    assert not sparse_mesh(vertices, triangles, box)
    vertices[0, 0] = 3e4  # median triangle 7e-5 of the diagonal: a zone anchor keeps them
    assert not sparse_mesh(vertices, triangles, np.concatenate([vertices.min(axis=0), vertices.max(axis=0)]))
    vertices[0, 0] = 1e6
    assert sparse_mesh(vertices, triangles, np.concatenate([vertices.min(axis=0), vertices.max(axis=0)]))
    sphere = icosphere(3)
    assert not sparse_mesh(*sphere, np.concatenate([sphere[0].min(axis=0), sphere[0].max(axis=0)]))
    assert not sparse_mesh(vertices, np.zeros((0, 3), np.int64), box)
    bounds, small = np.array([[-1, -1, -1, 1, 1, 1]], np.float32), np.array([SMALL_OBJECT // 2])
    assert plan_soup("auto", small, bounds, np.zeros(1, np.int64), np.eye(4)[None], np.zeros(1, bool))[0]
    assert not plan_soup("auto", small, bounds, np.zeros(1, np.int64), np.eye(4)[None], np.zeros(1, bool),
                         sparse=np.ones(1, bool))[0]
    assert plan_soup("flat", small, bounds, np.zeros(1, np.int64), np.eye(4)[None], np.zeros(1, bool),
                     sparse=np.ones(1, bool))[0]


def test_a_small_convex_soup_member_far_from_the_soups_centre_is_unoccluded():
    """AO of the first small sphere seen from above, ao_distance well under its height over the ground:
    1 on every pixel (the view is filled by the sphere's top). Before zones: 0.984 on 16 of 1,024 pixels."""
    meshes, mats = _ground_and_small_spheres()
    (centre, radius) = SMALL_SPHERES[0]
    view = np.eye(4)
    view[:3, 3] = np.array(centre) + (0, 0, 6 * radius)
    scene = core.build_scene(meshes, np.arange(len(meshes)), mats, origin=view[:3, 3])
    camera = core.Camera(view, 0.3).translated(scene.origin)
    image = core.render_preview(scene, camera, 32, 32, samples=64, ao_distance=0.4 * radius)
    assert (image[..., 3] == 1).all()
    assert image[..., 0].min() == 1.0


def test_soup_zones_bound_each_members_distance_to_its_anchor():
    """Every member within PRECISION_RATIO of its own diagonals of its zone's anchor, over sizes of six
    decades spread across 1e5; members of like size and place stay in the one main zone (no change
    for ordinary scenes), as does everything in the "flat" layout."""
    rng = np.random.default_rng(2)
    size = 10.0 ** rng.uniform(-3, 3, 400)
    centre = rng.uniform(-5e4, 5e4, (400, 3))
    boxes = np.concatenate([centre - size[:, None] / 2, centre + size[:, None] / 2], axis=1)
    boxes[7] = (np.inf,) * 3 + (-np.inf,) * 3  # an empty mesh
    zones = soup_zones(boxes)
    rows = np.concatenate([r for r, _ in zones])
    assert sorted(rows.tolist()) == list(range(400))
    assert 7 in zones[0][0] and len(zones) > 10
    for r, anchor in zones:
        filled = r[r != 7]
        corners = np.stack([np.where([(c >> k) & 1 for k in range(3)], boxes[filled, 3:], boxes[filled, :3])
                            for c in range(8)], axis=1)
        reach = np.linalg.norm(corners - anchor, axis=2).max(axis=1)
        assert (reach <= PRECISION_RATIO * np.linalg.norm(boxes[filled, 3:] - boxes[filled, :3], axis=1)).all()
    assert len(soup_zones(boxes, split=False)) == 1
    ordinary = np.concatenate([centre[:50] / 1e3, centre[:50] / 1e3 + rng.uniform(0.05, 5, (50, 3))], axis=1)
    assert len(soup_zones(ordinary)) == 1 and len(soup_zones(ordinary)[0][0]) == 50


def test_soup_zones_of_an_unchanged_soup_are_the_same_next_frame():
    """Given its own main anchor as last frame's, a soup gets the same zones, members and anchors: else an
    unchanged scene rebuilt soups on its second frame and lost kept pixels (review: 3 of 300 random
    soups, whose main zone had shed members its final anchor was near enough for)."""
    rng = np.random.default_rng(0)
    for _ in range(300):
        n, scale = int(rng.integers(1, 60)), 10.0 ** rng.uniform(-2, 7)
        size, centre = 10.0 ** rng.uniform(-4, 4, n), rng.uniform(-scale, scale, (n, 3))
        boxes = np.concatenate([centre - size[:, None] / 2, centre + size[:, None] / 2], axis=1)
        zones = soup_zones(boxes)
        again = soup_zones(boxes, zones[0][1])
        assert [r.tolist() for r, _ in again] == [r.tolist() for r, _ in zones]
        assert all(np.array_equal(a, b) for (_, a), (_, b) in zip(again, zones))


def test_zones_stay_within_float32_and_lazy_builds_stay_one_tree():
    """A main anchor kept from last frame is dropped where a new member would lie beyond float32's range
    of it (the build failed naming a triangle); a lazy build, which has to be one tree, gets no zones."""
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    a = core.MeshInput("a", np.array([[-3.4e38, 0, 0], [-3.3e38, 0, 0], [-3.3e38, 1e37, 0], [-3.4e38, 1e37, 0]],
                                     np.float32), quad, 0)
    b = core.MeshInput("b", np.array([[3.3e38, 0, 0], [3.4e38, 0, 0], [3.4e38, 1e37, 0], [3.3e38, 1e37, 0]],
                                     np.float32), quad, 0)
    builder = core.SceneBuilder()
    builder.build([a], [0], np.eye(4)[None])
    scene, _ = builder.build([a, b], [0, 1], np.stack([np.eye(4)] * 2))
    hits = core.intersect_scene(scene, np.array([[3.35e38, 1e36, 1.0], [-3.35e38, 1e36, 1.0]]), [[0, 0, -1.0]] * 2)
    assert hits.instance.tolist() == [1, 0] and np.allclose(hits.t, 1.0)
    meshes, mats = _ground_and_small_spheres()
    scene = core.build_scene(meshes, np.arange(len(meshes)), mats, lazy=True)
    assert scene.stats()["instances"] == 1 and scene.lazy_tree is not None


def test_degenerate_inputs():
    rng = np.random.default_rng(0)
    tree = core.build_kdtree(_blob(rng, 20))
    empty = core.build_two_level([tree], np.zeros(0, np.int32), np.zeros((0, 4, 4)))
    o, d = _rays(rng, 10)
    assert (core.intersect_scene(empty, o, d).prim == -1).all()
    flat_mesh = core.build_kdtree(np.zeros((4, 3, 3), np.float32))  # zero-area only: nothing to hit
    scene = core.build_two_level([flat_mesh, tree], np.array([0, 1]), np.stack([np.eye(4)] * 2))
    _assert_matches_flat(scene, _blob(np.random.default_rng(0), 20), o, d)
    singular = np.eye(4)
    singular[2, 2] = 0.0
    with pytest.raises(ValueError, match="instance 1 has a singular matrix"):
        core.build_two_level([tree], np.zeros(2, np.int32), np.stack([np.eye(4), singular]))
    with pytest.raises(ValueError, match="instance 0 names mesh 3"):
        core.build_two_level([tree], np.array([3]), np.eye(4)[None])
    with pytest.raises(ValueError, match="non-finite"):
        core.build_two_level([tree], np.array([0]), np.full((1, 4, 4), np.nan))


@pytest.mark.parametrize("triangles", ["blob", "far", "negative_zero", "zero_area", "none"])
def test_a_flat_tree_as_a_scene_equals_its_identity_instance(triangles):
    """as_two_level's shortcut for a flat tree gives build_two_level's arrays for the identity instance,
    its checks and matrix algebra included: dtypes, shapes and bytes."""
    from core.scene.two_level import as_two_level
    rng = np.random.default_rng(3)
    negative_zero = np.array([[[-0.0, -0.0, -0.0], [1, 2, 0.5], [2, 0.5, 1]]], np.float32)  # a box from -0.0
    tris = {"blob": _blob(rng, 60), "far": _blob(rng, 60) * 3.0 + np.float32(-2e5), "negative_zero": negative_zero,
            "zero_area": np.zeros((4, 3, 3), np.float32), "none": np.zeros((0, 3, 3), np.float32)}[triangles]
    tree = core.build_kdtree(tris)
    fast = as_two_level(tree)
    full = core.build_two_level([tree], np.zeros(1, np.int32), np.eye(4)[None], threads=1)
    pairs = [(name, getattr(fast, name), getattr(full, name))
             for name in ("mesh_of", "object_to_world", "world_to_object", "world_boxes", "visibility")]
    for name, a, b in [*zip(fast.arrays._fields, fast.arrays, full.arrays), *pairs]:
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), name  # signs of zero too


@pytest.mark.parametrize("layout", ["two_level", "auto"])
def test_instance_boxes_on_one_line_build_one_leaf(layout):
    """Ten instances of a triangle scaled by 1e-17 along a line: in float64 their boxes have no extent
    across it, so the top level's root box has no area, which the SAH divides by (a ZeroDivisionError
    unless handled). They make one leaf; with a unit-size instance added the top level splits as usual."""
    triangle = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]]), np.array([[0, 1, 2]]))
    mats = np.stack([np.eye(4)] * 11)
    mats[:10, :3, :3] *= 1e-17
    mats[:10, 0, 3], mats[:10, 1, 3], mats[:10, 2, 3] = np.arange(1, 11), 1.0, 1.0
    mats[10, :3, 3] = (0, 0, 5)
    origins, directions = np.array([[0.2, 0.2, 10.0], [5.0, 1.0, 3.0]]), np.array([[0, 0, -1.0], [0, 0, -1.0]])
    line = core.build_scene([triangle], np.zeros(10, int), mats[:10], layout=layout)
    assert (core.intersect_scene(line, origins, directions).prim == -1).all()
    both = core.build_scene([triangle], np.zeros(11, int), mats, layout=layout)
    hits = core.intersect_scene(both, origins, directions)
    assert hits.t[0] == pytest.approx(5.0) and hits.prim[1] == -1


def test_render_of_instanced_scene_matches_flat_render():
    rng = np.random.default_rng(11)
    meshes, mesh_of, mats = _instanced_scene(rng, n_meshes=2, n_instances=6)
    scene = core.build_two_level([core.build_kdtree(m) for m in meshes], mesh_of, mats)
    flat = core.build_kdtree(_world(meshes, mesh_of, mats))
    cam = np.eye(4)
    cam[:3, 3] = (0.0, 0.0, 15.0)
    camera = core.Camera(cam, 0.9)
    settings = dict(mode="ao+shadow", samples=8, ao_distance=2.0, lights=[core.Light.sun((0.3, 0.2, -1.0))])
    a = core.render_preview(scene, camera, 48, 48, **settings)
    b = core.render_preview(flat, camera, 48, 48, **settings)
    np.testing.assert_array_equal(a[..., 3], b[..., 3])
    assert b[..., 3].mean() > 0.15
    rmse = np.sqrt(np.mean((a[..., :3] - b[..., :3]) ** 2))
    assert rmse < 0.01, rmse


def test_policy():
    big, small = SMALL_OBJECT * 2, SMALL_OBJECT // 2
    bounds = np.array([[-1, -1, -1, 1, 1, 1]] * 4, np.float32)
    apart = np.stack([np.eye(4)] * 4)
    apart[:, 0, 3] = [0, 10, 20, 30]
    tri_counts = np.array([big, big, small, big])
    dynamic = np.array([False, False, False, True])
    soup = plan_soup("auto", tri_counts, bounds, np.arange(4), apart, dynamic)
    np.testing.assert_array_equal(soup, [False, False, True, False])  # only the small static one
    together = apart.copy()
    together[:, 0, 3] = 0.0
    soup = plan_soup("auto", tri_counts, bounds, np.arange(4), together, dynamic)
    np.testing.assert_array_equal(soup, [True, True, True, False])  # overlap merges; dynamic stays out
    shared = plan_soup("auto", tri_counts, bounds, np.zeros(4, np.int64), together, np.zeros(4, bool))
    assert not shared.any()  # a mesh with several instances keeps its tree
    assert overlap_depth(np.array([[0, 0, 0, 1, 1, 1], [2, 0, 0, 3, 1, 1]], float)) < 0.01
    assert overlap_depth(np.array([[0, 0, 0, 1, 1, 1]] * 3, float)) > OVERLAP_LIMIT


def _frame_inputs(rng_seed, frame):
    """Frame `frame` of a small animation: a static mesh, a rigidly moving one, a deforming one and a
    mesh with 4 instances."""
    rng = np.random.default_rng(rng_seed)
    static, mover, wave, shared = (_blob(rng, SMALL_OBJECT + 50) for _ in range(4))
    wave = wave + np.float32(0.05 * frame) * np.sin(wave)
    meshes = [core.MeshInput(name, tris.reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3),
                             hash(tris.tobytes()))
              for name, tris in (("static", static), ("mover", mover), ("wave", wave), ("shared", shared))]
    mats = np.stack([np.eye(4)] * 7)
    mats[:, 0, 3] = [0, 5, 10, 15, 20, 25, 30]
    mats[1, 1, 3] = 0.5 * frame  # the mover
    return meshes, np.array([0, 1, 2, 3, 3, 3, 3]), mats


def test_builder_reuses_static_and_moved_meshes_and_rebuilds_deforming_ones():
    builder = core.SceneBuilder()
    reference = core.SceneBuilder()
    rng = np.random.default_rng(2)
    o, d = _rays(rng, 2000, spread=30.0)
    reports = []
    for frame in range(4):
        meshes, mesh_of, mats = _frame_inputs(0, frame)
        scene, report = builder.build(meshes, mesh_of, mats, origin=(1.0, 2.0, 3.0))
        fresh, fresh_report = reference.build(meshes, mesh_of, mats, origin=(1.0, 2.0, 3.0), reuse=False)
        reports.append(report)
        assert fresh_report.meshes_reused == 0 and fresh_report.meshes_rebuilt == 4
        a, b = core.intersect_scene(scene, o, d), core.intersect_scene(fresh, o, d)
        np.testing.assert_array_equal(a.t, b.t)  # reuse gives exactly the rebuilt scene's hits
        world = _world([m.vertices[m.triangles] for m in meshes], mesh_of, mats - _shift((1.0, 2.0, 3.0)))
        _assert_matches_flat(scene, world, o, d)
    assert reports[0].meshes_rebuilt == 4
    # frame 1: only the deforming mesh changed geometry; the mover keeps its tree
    assert (reports[1].meshes_rebuilt, reports[1].meshes_reused) == (1, 3)
    assert (reports[3].meshes_rebuilt, reports[3].meshes_reused) == (1, 3)


def _shift(origin):
    s = np.zeros((4, 4))
    s[:3, 3] = origin
    return s


def test_builder_soup_leaves_dynamic_objects_out():
    rng = np.random.default_rng(4)
    small = [_blob(rng, 30) for _ in range(3)]
    builder = core.SceneBuilder()
    reports = []
    for frame in range(3):
        tris = [s + np.float32(0.1 * frame) if i == 0 else s for i, s in enumerate(small)]
        meshes = [core.MeshInput(i, t.reshape(-1, 3), np.arange(90).reshape(-1, 3), hash(t.tobytes()))
                  for i, t in enumerate(tris)]
        mats = np.stack([np.eye(4)] * 3)
        mats[:, 0, 3] = [0, 4, 8]
        scene, report = builder.build(meshes, np.arange(3), mats)
        reports.append(report)
        o, d = _rays(rng, 500, spread=9.0)
        _assert_matches_flat(scene, _world(tris, np.arange(3), mats), o, d)
    assert reports[0].soup_objects == 3 and reports[0].instanced_meshes == 0
    assert reports[1].soup_objects == 2 and reports[1].soup_rebuilt  # the changed one left the soup
    assert reports[2].soup_objects == 2 and not reports[2].soup_rebuilt
    assert (reports[2].meshes_rebuilt, reports[2].meshes_reused) == (1, 2)


def test_builder_builds_only_deforming_meshes_for_the_frames_rays():
    """Given the frame's ray count, a mesh seen deforming (rebuilt every frame) gets a tree trimmed
    for it; static, rigidly moving and shared meshes keep full trees (they serve many frames); every
    scene still answers like the flat tree. (Trees read from the builder's cache.)"""
    builder = core.SceneBuilder(layout="two_level")
    o, d = _rays(np.random.default_rng(5), 2000, spread=30.0)
    for frame in range(3):
        meshes, mesh_of, mats = _frame_inputs(0, frame)
        scene, _ = builder.build(meshes, mesh_of, mats, rays=100)
        _assert_matches_flat(scene, _world([m.vertices[m.triangles] for m in meshes], mesh_of, mats), o, d)
        nodes = {key: len(tree.axis) for key, (_, tree) in builder._trees.items()}
        full = {m.key: len(core.build_kdtree(m.vertices[m.triangles]).axis) for m in meshes}
        for key in ("static", "mover", "shared"):
            assert nodes[key] == full[key]
        assert (nodes["wave"] < full["wave"] / 2) == (frame >= 1)  # deforming from frame 1 on
    with pytest.raises(ValueError, match="rays"):
        builder.build(meshes, mesh_of, mats, rays=0)


def test_frame_ray_count_counts_camera_ao_and_shadow_rays():
    soft = [core.Light.point((0, 0, 1), radius=0.1)] * 3
    assert core.frame_ray_count(4, 3, "ao", 16) == 12 * (1 + 16)
    assert core.frame_ray_count(4, 3, "shadow", 2, soft) == 12 * (1 + 2 * 3)
    assert core.frame_ray_count(4, 3, "ao+shadow", 5, soft) == 12 * (1 + 5 * 4)
    hard = [core.Light.point((0, 0, 1)), core.Light.sun((0, 0, -1))]  # one ray a pixel each
    assert core.frame_ray_count(4, 3, "ao+shadow", 5, soft + hard) == 12 * (1 + 5 * 4 + 2)
    assert core.frame_ray_count(4, 3, "ao", 5, hard) == 12 * (1 + 5)
    assert core.frame_ray_count(4, 3, "shadow", 200, hard) == 12 * (1 + 200 * 2)  # too many bits to repeat
    with pytest.raises(ValueError, match="mode"):
        core.frame_ray_count(4, 3, "occlusion", 1)


@pytest.mark.parametrize("layout, lazy", [("flat", False), ("auto", True)])
def test_one_soup_keeps_small_triangles_beside_a_huge_mesh(layout, lazy):
    """The "flat" layout and lazy builds put every mesh in one soup. Anchored at the centre of a box that
    one huge mesh spans, far from the camera, float32 rounded a small box beside the camera away (a UV
    sphere scaled 1e16 around a scene rendered empty): the anchor is now the box's point nearest the
    camera, not the world origin (the scene lies 1e9 from it, inside the ground's box). Reference:
    Moller-Trumbore on the world triangles (origin at the camera)."""
    ground = (np.array([[-1e12, -1e12, -1.0], [3e12, -1e12, -1.0], [3e12, 3e12, -1.0], [-1e12, 3e12, -1.0]]),
              np.array([[0, 1, 2], [0, 2, 3]]))
    box = icosphere(2)
    offset = np.array([1e9, -1e9, 0.0])
    camera = offset + (0.3, -0.2, 10.0)
    mats = np.stack([np.eye(4), np.eye(4)])
    mats[:, :3, 3] = offset
    scene = core.build_scene([ground, box], [0, 1], mats, origin=camera, layout=layout, lazy=lazy)
    xs, ys = np.meshgrid(np.linspace(-0.6, 0.6, 9), np.linspace(-0.6, 0.6, 9))
    directions = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1) + offset - camera
    world = np.concatenate([mesh[0][mesh[1]] for mesh in (ground, box)]) + offset - camera
    t_ref, prim_ref = moller_trumbore(world, np.zeros_like(directions), directions)
    assert (prim_ref >= 2).all()  # every ray meets the small sphere first
    hits = core.intersect_scene(scene, np.zeros_like(directions), directions)
    np.testing.assert_allclose(hits.t, t_ref, rtol=1e-6)
