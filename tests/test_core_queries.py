"""Closest-hit and any-hit queries against brute force, for every builder, on ordinary and hard scenes."""
import numpy as np
import pytest

import core
from tests.core_helpers import BUILDERS, assert_same_as_brute, assert_same_as_moller_trumbore, random_rays
from tests.meshes import degenerate_mix, icosphere, lattice, mesh_triangles, random_soup, subdivided_cube


@pytest.fixture
def rng():
    """The same generator state for every test: the builder variants of one test then meet the same rays,
    and the brute-force reference is computed once for all of them (core_helpers.oracle_once)."""
    return np.random.default_rng(1234)


@pytest.mark.parametrize("options", BUILDERS)
def test_random_soup_matches_moller_trumbore(options, rng):
    tris = random_soup(rng, 3000)
    tree = core.build_kdtree(tris, **options)
    assert_same_as_moller_trumbore(tree, tris, *random_rays(rng, 3000))


@pytest.mark.parametrize("options", BUILDERS)
def test_large_soup_uses_parallel_top_and_matches(options):
    """Big enough for the parallel top levels (> 16384 references) to run."""
    rng = np.random.default_rng(7)
    tris = random_soup(rng, 40000, size=0.02)
    tree = core.build_kdtree(tris, **options)
    assert_same_as_brute(tree, tris, *random_rays(rng, 2000))


@pytest.mark.parametrize("options", BUILDERS)
def test_closed_meshes_match_brute(options, rng):
    sphere = mesh_triangles(*icosphere(4))
    cube = subdivided_cube(8) * 0.5 + 1.5
    tris = np.concatenate([sphere, cube])
    tree = core.build_kdtree(tris, **options)
    o, d = random_rays(rng, 3000, extent=3.0)
    assert_same_as_moller_trumbore(tree, tris, o, d)


@pytest.mark.parametrize("options", BUILDERS)
def test_lattice_with_axis_parallel_and_lattice_rays(options, rng):
    """Every triangle lies in an axis plane at an integer coordinate; rays run along lattice lines,
    start on lattice planes, and have exact zero and negative-zero direction components."""
    tris = lattice(4)
    tree = core.build_kdtree(tris, **options)
    n = 3000
    o = rng.integers(-1, 6, (n, 3)).astype(float) + rng.choice([0.0, 0.5, 0.25], (n, 3))
    d = np.zeros((n, 3))
    axis = rng.integers(0, 3, n)
    d[np.arange(n), axis] = rng.choice([-1.0, 1.0], n)
    d[(d == 0) & (rng.random((n, 3)) < 0.5)] = -0.0
    mixed = rng.random(n) < 0.4
    d[mixed] = rng.integers(-2, 3, (mixed.sum(), 3)).astype(float)
    d[mixed & ~(d != 0).any(axis=1)] = [1.0, 1.0, 1.0]
    assert_same_as_brute(tree, tris, o, d)


@pytest.mark.parametrize("options", BUILDERS)
def test_degenerate_triangles(options, rng):
    """Needles, slivers, zero-area triangles and stacked coplanar duplicates."""
    tris = degenerate_mix(rng)
    tree = core.build_kdtree(tris, **options)
    o, d = random_rays(rng, 3000)
    hits = assert_same_as_brute(tree, tris, o, d)
    t32 = tris.astype(np.float32).astype(np.float64)
    area = np.linalg.norm(np.cross(t32[:, 1] - t32[:, 0], t32[:, 2] - t32[:, 0]), axis=1)
    assert not np.isin(hits.prim[hits.prim >= 0], np.flatnonzero(area == 0)).any()
    assert tree.stats()["degenerate_dropped"] == (area == 0).sum() >= 50


@pytest.mark.parametrize("offset", [1e5, 1e7])
@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_far_from_origin_and_extreme_scales(offset, scale, rng):
    base = random_soup(rng, 2000)
    tris = (base * scale * max(1.0, offset * 1e-4) + offset).astype(np.float32)
    tree = core.build_kdtree(tris)
    o, d = random_rays(rng, 2000)
    o = o * scale * max(1.0, offset * 1e-4) + offset
    assert_same_as_brute(tree, tris, o, d)


@pytest.mark.parametrize("options", BUILDERS)
def test_rays_leaving_lattice_faces_hit_the_next_plane(options, rng):
    """Analytic reference: inside the lattice every integer plane is a wall, so a ray starting on
    one (on a face, an edge or a vertex) first hits the nearest integer plane strictly ahead of it,
    never the face it leaves (t is in the open interval (0, tmax)). Without the triangle test's rounding
    bound ~1 ray in 1000 reports its own face at t ~ 1e-17, sometimes instead of its true hit
    (docs/reliability.md#property-tests)."""
    n_cells = 4
    tree = core.build_kdtree(lattice(n_cells), **options)
    n = 20000
    o = rng.uniform(0.5, n_cells - 0.5, (n, 3))
    snapped = rng.random((n, 3)) < [[1.0, 0.5, 0.3]]  # on a face, often an edge, sometimes a vertex
    o[snapped] = np.round(o[snapped])
    o = rng.permuted(o, axis=1)
    d = rng.normal(size=(n, 3))
    ahead = np.where(d > 0, np.floor(o) + 1, np.ceil(o) - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        expected = np.where(d != 0, (ahead - o) / d, np.inf).min(axis=1)
    hits = core.intersect(tree, o, d)
    np.testing.assert_allclose(hits.t, expected.astype(np.float32), rtol=1e-6)
    assert not core.occluded(tree, o, d, tmax=0.5 * expected).any()


@pytest.mark.parametrize("length", [1.0, 1e-8, 2.0 ** -52])
def test_tiny_directions_keep_real_hits_far_from_t_zero(length):
    """The t rounding bound scales with the direction's length (a far hit at t = 1.35e15 for a ray
    along 2^-52 (0, -1, 0) was once rejected by a bound with the shear measured in scaled z; the
    second triangle is hit exactly on its edge, the case hypothesis found)."""
    wall = np.array([[[-1.0, -0.3, -1.0], [1.0, -0.3, -1.0], [0.0, -0.3, 1.0]]])
    edge = np.array([[[0.0, 1.5, 0.5], [2.0, -1.5, 0.0], [-0.5, 0.0, 0.0]]])
    for tris, t in ((wall, 0.3), (edge, 0.3)):
        hits = core.intersect(core.build_kdtree(tris), np.zeros((1, 3)), np.array([[0.0, -length, 0.0]]))
        np.testing.assert_allclose(hits.t, np.float32(t / length), rtol=1e-6)


@pytest.mark.parametrize("options", BUILDERS)
def test_rays_starting_on_triangles_and_split_planes(options, rng):
    tris = random_soup(rng, 2000)
    tree = core.build_kdtree(tris, **options)
    n = 2000
    w = rng.dirichlet([1, 1, 1], n)
    on_tri = np.einsum("nk,nkj->nj", w, tris[rng.integers(0, len(tris), n)].astype(np.float32).astype(float))
    inner = np.flatnonzero(tree.axis < 3)
    pick = rng.choice(inner, n)
    on_plane = rng.uniform(-1, 1, (n, 3))
    on_plane[np.arange(n), tree.axis[pick]] = tree.split[pick]
    o = np.concatenate([on_tri, on_plane])
    d = rng.normal(size=(2 * n, 3))
    flat = rng.random(2 * n) < 0.3  # some rays lie in their plane: zero component on the split axis
    d[np.flatnonzero(flat[n:]) + n, tree.axis[pick[flat[n:]]]] = 0.0
    assert_same_as_brute(tree, tris, o, d)


def test_tmin_tmax_per_ray(rng):
    tris = random_soup(rng, 2000)
    tree = core.build_kdtree(tris)
    o, d = random_rays(rng, 2000)
    tmin = rng.uniform(0, 0.5, 2000)
    tmax = tmin + rng.uniform(0, 2, 2000)
    assert_same_as_brute(tree, tris, o, d, tmin, tmax)
    assert_same_as_moller_trumbore(tree, tris, o, d, tmin, tmax)


def test_barycentrics_reconstruct_hit_point(rng):
    tris = random_soup(rng, 1000).astype(np.float32)
    tree = core.build_kdtree(tris)
    o, d = random_rays(rng, 2000)
    h = core.intersect(tree, o, d)
    hit = h.prim >= 0
    tri = tris[h.prim[hit]].astype(float)
    u, v = h.u[hit, None], h.v[hit, None]
    p_bary = (1 - u - v) * tri[:, 0] + u * tri[:, 1] + v * tri[:, 2]
    p_ray = o[hit] + h.t[hit, None] * d[hit]
    np.testing.assert_allclose(p_bary, p_ray, atol=1e-5)
    assert (h.u[hit] >= 0).all() and (h.v[hit] >= 0).all() and (h.u[hit] + h.v[hit] <= 1 + 1e-6).all()


def test_empty_tree_misses_everything():
    tree = core.build_kdtree(np.zeros((0, 3, 3), np.float32))
    h = core.intersect(tree, np.zeros((4, 3)), np.ones((4, 3)))
    assert (h.prim == -1).all() and np.isinf(h.t).all()
    assert not core.occluded(tree, np.zeros((4, 3)), np.ones((4, 3))).any()
    assert tree.stats()["triangles"] == 0


def test_only_degenerate_triangles_give_empty_tree():
    tris = np.zeros((5, 3, 3), np.float32)
    tree = core.build_kdtree(tris)
    assert not core.occluded(tree, np.full((3, 3), -1.0), np.ones((3, 3))).any()


@pytest.mark.parametrize("options", BUILDERS)
def test_ray_lying_in_split_plane_finds_closest_hit_in_either_child(options):
    """Found by hypothesis: a ray in the plane z=0 visits both children, which cover the same interval;
    a hit in the first must not stop the search before the closer one in the second."""
    tris = np.zeros((46, 3, 3))
    tris[0] = [[0.5, -0.5, 0], [0, 0.5, 0], [0, 0, 0.5]]
    tris[1] = [[0.5, 0, 0], [0, 0, 0], [0, 0, 0.5]]
    tris[23] = [[0.5, 0, 0.5], [0, -0.5, 0], [0, 0, -1.0]]
    tree = core.build_kdtree(tris, leaf_size=1, **options)
    hits = assert_same_as_brute(tree, tris, np.zeros((2, 3)), np.array([[1.0, 0, 0], [0, 0, 1.0]]))
    assert hits.t[0] == np.float32(0.25) and hits.prim[0] == 0
