"""Watertightness: rays from inside closed meshes never escape, and never hit twice.

Rays are aimed exactly at vertices, along edges and at random; a ray through an edge or vertex shared
by several triangles must be owned by exactly one of them (the tie rule in triangle_test.py).
"""
import numpy as np
import pytest
from numba import njit

import core
from core.trace.layout import LEAF
from core.build.leaf_triangles import leaf_triangles
from core.trace.triangle_test import LEAF_CHUNK, intersect_triangle, leaf_candidates, ray_shear
from tests.core_helpers import BUILDERS, assert_same_as_brute
from tests.meshes import icosphere, mesh_triangles, subdivided_cube
from tests.oracles import brute_watertight


def jittered_icosphere(rng):
    verts, faces = icosphere(5)  # 20,480 triangles
    verts = verts * (1.0 + rng.uniform(-2e-3, 2e-3, (len(verts), 1)))
    verts += rng.uniform(-1e-3, 1e-3, verts.shape)
    return verts.astype(np.float32).astype(np.float64), faces


def targets_on_mesh(rng, verts, faces, n):
    """Exact vertices, points along edges (midpoints and random), and random surface points."""
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    k = n // 4
    e = edges[rng.integers(0, len(edges), 2 * k)]
    f = rng.uniform(0, 1, (2 * k, 1))
    f[:k] = 0.5
    along = verts[e[:, 0]] * (1 - f) + verts[e[:, 1]] * f
    w = rng.dirichlet([1, 1, 1], n - 3 * k)
    surface = np.einsum("nk,nkj->nj", w, verts[faces[rng.integers(0, len(faces), n - 3 * k)]])
    return np.concatenate([verts[rng.integers(0, len(verts), k)], along, surface])


@pytest.mark.parametrize("options", BUILDERS)
def test_icosphere_no_ray_escapes(options):
    rng = np.random.default_rng(5)
    verts, faces = jittered_icosphere(rng)
    tris = mesh_triangles(verts, faces)
    tree = core.build_kdtree(tris, **options)
    targets = targets_on_mesh(rng, verts, faces, 100_000)
    origins = np.where(rng.random((len(targets), 1)) < 0.5, 0.0, rng.uniform(-0.5, 0.5, targets.shape))
    hits = core.intersect(tree, origins, targets - origins)
    escaped = np.flatnonzero(hits.prim < 0)
    assert len(escaped) == 0, f"{len(escaped)} of {len(targets)} rays escaped, e.g. {targets[escaped[:3]]}"
    assert core.occluded(tree, origins, targets - origins).all()


@pytest.mark.slow
def test_icosphere_every_ray_from_centre_hits_exactly_once():
    """From the centre the jittered sphere is star-shaped, so each ray crosses the surface once."""
    rng = np.random.default_rng(6)
    verts, faces = jittered_icosphere(rng)
    tris = mesh_triangles(verts, faces)
    targets = targets_on_mesh(rng, verts, faces, 20_000)
    origins = np.zeros_like(targets)
    _, _, count = brute_watertight(tris, origins, targets)
    assert (count == 1).all(), f"hit counts {np.bincount(count)}"


@pytest.mark.parametrize("options", BUILDERS)
def test_subdivided_cube_exact_vertices_and_edges(options):
    """Grid coordinates k/8 are exact, so rays really pass exactly through vertices and along edges,
    including axis-parallel rays with zero (and negative-zero) direction components."""
    tris = subdivided_cube(16)
    tree = core.build_kdtree(tris, **options)
    g = np.arange(-8, 9) / 8.0
    rng = np.random.default_rng(8)
    n = 30_000
    face_axis = rng.integers(0, 3, n)
    side = rng.choice([-1.0, 1.0], n)
    targets = rng.choice(g, (n, 3))
    on_edge = rng.random(n) < 0.5
    targets[on_edge, 0] = rng.uniform(-1, 1, on_edge.sum())  # along a grid line, not only at vertices
    targets[np.arange(n), face_axis] = side
    origins = rng.choice(np.arange(-4, 5) / 8.0, (n, 3))
    directions = targets - origins
    directions[(directions == 0) & (rng.random((n, 3)) < 0.5)] = -0.0
    hits = core.intersect(tree, origins, directions)
    assert (hits.prim >= 0).all(), f"{(hits.prim < 0).sum()} rays escaped the cube"
    _, _, count = brute_watertight(tris, origins[:5000], directions[:5000])
    assert (count == 1).all(), f"hit counts {np.bincount(count)}"


@pytest.mark.parametrize("options", BUILDERS)
def test_negligible_direction_components_do_not_slip_through(options):
    """Rays from split planes x = 0 and z = 0 (the subdivided cube's) with a subnormal or tiny x
    component: 1 / d[x] overflows, the shear term underflows to 0 on one side of the plane only,
    and a ray along (-5e-324, 1, 0) could pass through the near face to the far one. Such
    components are made 0; every ray hits the near face y = -1 at t = 2, as the one-leaf tree says."""
    cube = subdivided_cube(8)
    tree = core.build_kdtree(cube, **options)
    tiny = [5e-324, -5e-324, 1e-310, -1e-310, 1e-300, 2.0 ** -601]
    d = np.array([[x, 1.0, 0.0] for x in tiny] + [[0.0, 1.0, x] for x in tiny])
    o = np.tile([0.0, -3.0, -0.75], (len(d), 1))
    o[len(tiny):] = (0.5, -3.0, 0.0)
    hits = core.intersect(tree, o, d)
    assert (hits.t == 2.0).all(), hits.t
    np.testing.assert_array_equal(hits.prim, core.intersect(core.build_kdtree(cube, max_depth=0), o, d).prim)
    assert core.occluded(tree, o, d, tmax=3.0).all()


@pytest.mark.parametrize("builder", ["binned", "median"])
@pytest.mark.parametrize("tiny", [-5e-324, 5e-324, -1e-310])
def test_a_camera_axis_with_a_negligible_component_does_not_slip_through(tiny, builder):
    """The same ray from a camera: an orthographic camera looking along (tiny, 1, 0) from the split
    plane x = 0 sends its centre ray there (uncleaned, the renderer's camera ray takes the far
    face, t = 4). Its axes are cleaned like query rays; the first hit is the near face, depth 2."""
    cube = subdivided_cube(8)
    scene = core.build_scene([(cube.reshape(-1, 3), np.arange(3 * len(cube)).reshape(-1, 3))], [0], np.eye(4)[None],
                             layout="flat", builder=builder)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = (1, 0, 0), (0, 0, 1), (-tiny, -1, 0), (0.0, -3.0, -0.75)
    render = core.PreviewRender(scene, core.Camera(m, ortho_scale=0.1), 3, 3, samples=1)
    assert render.depths[list(render.pixels).index(4)] == 2.0


@njit
def _screen_and_full_test(leaf_tris, triangles, origins, directions):
    """(kept, full_hit, any_kept) for every ray and triangle (any_kept per ray and chunk): the leaf
    screen's flag, whether the full test returns a finite t, and what the screen returned."""
    n_rays, n_tris = origins.shape[0], triangles.shape[0]
    kept = np.zeros((n_rays, n_tris), np.uint8)
    full_hit = np.zeros((n_rays, n_tris), np.bool_)
    flags = np.empty(LEAF_CHUNK, np.uint8)
    any_kept = np.zeros((n_rays, (n_tris + LEAF_CHUNK - 1) // LEAF_CHUNK), np.bool_)
    for r in range(n_rays):
        o, d = origins[r], directions[r]
        kx, ky, kz, sx, sy, sz = ray_shear(d)
        for lo in range(0, n_tris, LEAF_CHUNK):
            hi = min(n_tris, lo + LEAF_CHUNK)
            any_kept[r, lo // LEAF_CHUNK] = leaf_candidates(leaf_tris, lo, hi, o, kx, ky, kz, sx, sy, flags)
            for j in range(lo, hi):
                kept[r, j] = flags[j - lo]
                full_hit[r, j] = intersect_triangle(triangles[j], o, kx, ky, kz, sx, sy, sz)[0] < np.inf
    return kept, full_hit, any_kept


def test_leaf_screen_keeps_every_triangle_the_full_test_hits():
    """The vectorised edge-sign screen (triangle_test.leaf_candidates) never drops a triangle the full
    watertight test hits, including rays through shared vertices and edges (the tie rule decides those
    after the screen) and rays with zero or axis-parallel direction components; it drops triangles
    whose edge values straddle zero, most of them."""
    rng = np.random.default_rng(3)
    tris = subdivided_cube(4).astype(np.float32)  # grid coordinates k/2: rays pass exactly through vertices
    leaf_tris = leaf_triangles(tris, np.arange(len(tris), dtype=np.int32))   # and along edges
    n = 300
    targets = rng.choice(np.arange(-2, 3) / 2.0, (n, 3))
    targets[:, 0] = np.where(rng.random(n) < 0.5, targets[:, 0], rng.uniform(-1, 1, n))  # along grid lines
    targets[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-1.0, 1.0], n)
    origins = rng.choice(np.arange(-2, 3) / 2.0, (n, 3)) * 0.5  # inside, on the grid's lines scaled by half
    directions = targets - origins
    directions[(directions == 0) & (rng.random((n, 3)) < 0.5)] = -0.0  # zero components of both signs
    origins[:6] = 0.0
    directions[:6] = [[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, -0.0, 0.0], [-0.0, 0.0, -1.0], [-1.0, 0.0, 0.0],
                      [0.0, 1.0, -0.0]]  # along the axes from the centre: through the faces' centre vertices
    kept, full_hit, any_kept = _screen_and_full_test(leaf_tris, tris, origins, directions)
    chunks = np.arange(len(tris)) // LEAF_CHUNK
    np.testing.assert_array_equal(any_kept, np.stack([np.bincount(chunks, k) > 0 for k in kept]))
    assert (full_hit.sum(axis=1) >= 1).all()  # every ray leaves the closed cube: the check is not vacuous
    assert not np.any(full_hit & (kept == 0))
    assert kept.mean() < 0.2


def test_leaf_triangles_follow_the_leaves_also_after_lazy_growth():
    """Column j of the leaf-ordered copy is triangle leaf_prims[j], on an eager tree and on a lazy one
    after rays have built part of it (replace_nodes refreshes the copy)."""
    rng = np.random.default_rng(9)
    tris = mesh_triangles(*icosphere(3)).astype(np.float32)
    for tree in (core.build_kdtree(tris), core.build_kdtree(tris, lazy=True, lazy_subtree_size=16)):
        before = tree.node_count
        core.intersect(tree, np.zeros((50, 3)), rng.normal(size=(50, 3)))
        expected = tris[tree.leaf_prims].reshape(-1, 9).T
        np.testing.assert_array_equal(tree.leaf_triangles, expected)
        if tree.lazy:
            assert tree.node_count > before  # the copy was checked after the tree grew


def exact_grid_rays(rng, n):
    """Rays from points inside the cube of subdivided_cube(8) to its grid vertices and along its grid
    lines, with zero direction components of both signs."""
    g = np.arange(-4, 5) / 4.0
    targets = rng.choice(g, (n, 3))
    on_line = rng.random(n) < 0.5
    targets[on_line, 0] = rng.uniform(-1, 1, on_line.sum())
    targets[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-1.0, 1.0], n)
    origins = rng.choice(g[1:-1] / 2.0, (n, 3))
    directions = targets - origins
    directions[(directions == 0) & (rng.random((n, 3)) < 0.5)] = -0.0
    return origins, directions


def test_leaves_of_several_chunks_answer_like_brute_force():
    """Leaves of more than LEAF_CHUNK triangles are screened a chunk at a time: hits through shared
    vertices and edges still match brute force exactly."""
    tris = subdivided_cube(8).astype(np.float32)  # 768 triangles
    tree = core.build_kdtree(tris, leaf_size=400)
    assert tree.count[tree.axis == LEAF].max() > 2 * LEAF_CHUNK  # the check below crosses chunk boundaries
    origins, directions = exact_grid_rays(np.random.default_rng(4), 3000)
    hits = assert_same_as_brute(tree, tris, origins, directions)
    assert (hits.prim >= 0).all()


def test_meshes_packed_side_by_side_answer_like_brute_force():
    """In a two-level scene the meshes' leaf-ordered copies sit side by side, each mesh screened from
    its own first column: the cube cut into three meshes (two of them not first) answers like brute
    force over the whole cube, hit for hit, through the edges the meshes share."""
    tris = subdivided_cube(8).astype(np.float32)
    parts = [tris[:256], tris[256:512], tris[512:]]  # the faces across x, y and z
    meshes = [core.build_kdtree(p, leaf_size=40) for p in parts]
    scene = core.build_two_level(meshes, [2, 0, 1], np.repeat(np.eye(4)[None], 3, axis=0))
    origins, directions = exact_grid_rays(np.random.default_rng(6), 3000)
    directions[directions == 0] = 0.0  # the identity's product would turn -0.0 into 0.0: same rays both ways
    hits = core.intersect_scene(scene, origins, directions)
    t, prim, _ = brute_watertight(tris, origins, directions)
    first = np.array([0, 256, 512])[np.array([2, 0, 1])]  # first triangle of each instance's mesh
    assert (prim >= 0).all() and (hits.prim >= 0).all()
    np.testing.assert_array_equal(first[hits.instance] + hits.prim, prim)
    np.testing.assert_array_equal(hits.t, t.astype(np.float32))
