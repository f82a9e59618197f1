"""Any-hit packets for runs of rays sharing an origin (core.occluded, occlusion_packets.py) against the
single-ray any-hit kernel and the brute-force oracle.

The packets' lanes differ in direction sign and shear axes; their answers must equal the single-ray
kernel's for every ray, exactly: rays in every octant, axis-parallel and negative-zero components,
origins on split planes and on lattice planes, rays through exact vertices and edges, far from the
origin, per-ray limits, runs of every length, lazy trees.
"""
import numpy as np
import pytest

import core
from core.trace.occlusion_packets import L, origin_runs
from core.trace.traversal import trace_rays
from tests.core_helpers import BUILDERS, oracle_once
from tests.meshes import icosphere, lattice, mesh_triangles, random_soup, subdivided_cube
from tests.oracles import brute_watertight


def single_ray_occluded(tree, o, d, tmin=0.0, tmax=np.inf):
    """The single-ray any-hit kernel on every ray (what core.occluded did before packets)."""
    n = len(o)
    out = [np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n)]
    trace_rays(tree.arrays, o, d, np.broadcast_to(np.float64(tmin), n).copy(),
               np.broadcast_to(np.float64(tmax), n).copy(), True, *out)
    return out[1] >= 0


def ao_rays(rng, points, per_point=L, zero_every=0):
    """per_point rays in random directions (every octant) from each point, consecutive; every
    zero_every-th component set to +0 or -0 when given."""
    o = np.repeat(points, per_point, axis=0)
    d = rng.normal(size=o.shape)
    if zero_every:
        flat = d.reshape(-1)
        flat[::zero_every] = np.where(rng.random(len(flat[::zero_every])) < 0.5, 0.0, -0.0)
        d[~d.any(axis=1)] = 1.0
    return o, d


def assert_same_as_single_rays(tree, o, d, tmin=0.0, tmax=np.inf):
    got = core.occluded(tree, o, d, tmin, tmax)
    want = single_ray_occluded(tree, o, d, tmin, tmax)
    np.testing.assert_array_equal(got, want)
    return got


def assert_same_as_brute(tris, o, d, got, tmin=0.0, tmax=np.inf):
    """Occlusion equals the brute force's, except where the origin lies on the hit triangle (rounding
    decides there: core_helpers._origin_on_hit_triangle)."""
    t, prim, _ = oracle_once(brute_watertight, tris, o, d, tmin, tmax)
    keep = ~(np.isfinite(t) & (t - tmin < 1e-12 * (1.0 + np.abs(o).max(axis=1))))
    np.testing.assert_array_equal(got[keep], (prim >= 0)[keep])


def test_origin_runs_cut_runs_into_packets_and_leave_ones_alone():
    lengths = [1, 2, 9, 1, 3, 16, 17, 1]  # runs start at rays 0, 1, 3, 12, 13, 16, 32, 49
    origins = np.repeat(np.arange(len(lengths), dtype=float)[:, None] * [1.0, 0.0, 0.0], lengths, axis=0)
    origins[origins == 0.0] = -0.0
    origins[4, 1] = 0.0  # +0 and -0: one origin (packet_setup._one_origin)
    single = np.zeros(len(origins), np.uint8)
    order = origin_runs(origins, single).reshape(-1, L)
    want = [range(1, 3), range(3, 11), range(13, 16), range(16, 24), range(24, 32), range(32, 40), range(40, 48)]
    assert [list(row[row >= 0]) for row in order] == [list(r) for r in want]
    assert (order[0, 2:] == -1).all()
    assert list(np.flatnonzero(single)) == [0, 11, 12, 48, 49]
    assert len(origin_runs(np.arange(12.0).reshape(4, 3), np.zeros(4, np.uint8))) == 0


@pytest.mark.parametrize("options", BUILDERS[:2] + BUILDERS[4:6])
def test_ao_rays_in_every_octant_equal_single_rays_and_brute_force(options):
    rng = np.random.default_rng(31)
    tris = random_soup(rng, 3000)
    tree = core.build_kdtree(tris, **options)
    o, d = ao_rays(rng, rng.uniform(-1.2, 1.2, (300, 3)))
    for tmax in (0.05, 0.3, np.inf):
        got = assert_same_as_single_rays(tree, o, d, 0.0, tmax)
        assert 0 < got.mean() < 1
        assert_same_as_brute(tris, o, d, got, 0.0, tmax)


def test_per_ray_limits_runs_of_every_length_and_zero_components():
    """Runs of 1 to 20 rays, per-ray tmin and tmax, components +0 and -0 (those lanes leave to single
    rays, the rest of their packet stays)."""
    rng = np.random.default_rng(32)
    tris = random_soup(rng, 2000)
    tree = core.build_kdtree(tris)
    points = rng.uniform(-1, 1, (200, 3))
    counts = rng.integers(1, 21, len(points))
    o = np.repeat(points, counts, axis=0)
    d = rng.normal(size=o.shape)
    d.reshape(-1)[::7] = np.where(rng.random(len(d.reshape(-1)[::7])) < 0.5, 0.0, -0.0)
    d[~d.any(axis=1)] = [0.0, -1.0, 0.0]
    tmin = rng.uniform(0, 0.2, len(o))
    tmax = tmin + rng.uniform(0, 1.5, len(o))
    got = assert_same_as_single_rays(tree, o, d, tmin, tmax)
    assert_same_as_brute(tris, o, d, got, tmin, tmax)


@pytest.mark.parametrize("options", BUILDERS[:1] + BUILDERS[4:5])
def test_origins_on_split_planes_with_rays_along_and_across_them(options):
    rng = np.random.default_rng(33)
    tris = random_soup(rng, 2000)
    tree = core.build_kdtree(tris, **options)
    inner = np.flatnonzero(tree.axis < 3)
    for node in rng.choice(inner, 12):
        a, pos = int(tree.axis[node]), float(tree.split[node])
        points = rng.uniform(-1, 1, (16, 3))
        points[:, a] = pos
        o, d = ao_rays(rng, points)
        d[::3, a] = 0.0  # in the plane
        d[1::3, a] = np.where(np.arange(len(d[1::3])) % 2, -0.0, 0.0)
        got = assert_same_as_single_rays(tree, o, d)
        assert_same_as_single_rays(tree, o, d, 0.0, 0.2)
        assert_same_as_brute(tris, o, d, got)


@pytest.mark.parametrize("options", BUILDERS[:1] + BUILDERS[4:6])
def test_lattice_starts_and_rays_through_exact_vertices_and_edges(options):
    """Origins on lattice points and planes, directions with small integer components of every sign:
    rays run along planes and through exact vertices and edges, where the tie rule decides."""
    rng = np.random.default_rng(34)
    tris = lattice(4)
    tree = core.build_kdtree(tris, **options)
    points = rng.integers(0, 5, (150, 3)).astype(float) + rng.choice([0.0, 0.5], (150, 3))
    o = np.repeat(points, L, axis=0)
    d = rng.integers(-2, 3, o.shape).astype(float)
    d[~d.any(axis=1)] = [1.0, -1.0, 1.0]
    for tmax in (0.75, 1.0, np.inf):
        got = assert_same_as_single_rays(tree, o, d, 0.0, tmax)
        assert_same_as_brute(tris, o, d, got, 0.0, tmax)


def test_closed_cube_and_icosphere_from_inside_block_every_ray():
    rng = np.random.default_rng(35)
    cube = subdivided_cube(16)
    verts, faces = icosphere(4)
    verts = verts * (1.0 + rng.uniform(-2e-3, 2e-3, (len(verts), 1)))
    sphere = mesh_triangles(verts.astype(np.float32).astype(np.float64), faces)
    for tris in (cube, sphere):
        tree = core.build_kdtree(tris)
        o, d = ao_rays(rng, rng.uniform(-0.3, 0.3, (200, 3)))
        o[:L] = 0.0
        d[:L] = np.round(d[:L] * 4) / 4  # through exact cube vertices and edges
        d[~d.any(axis=1)] = 1.0
        assert assert_same_as_single_rays(tree, o, d).all()


@pytest.mark.parametrize("offset", [1e5, 1e7])
@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_far_from_origin_and_extreme_scales(offset, scale):
    rng = np.random.default_rng(36)
    size = scale * max(1.0, offset * 1e-4)
    tris = (random_soup(rng, 2000) * size + offset).astype(np.float32)
    tree = core.build_kdtree(tris)
    o, d = ao_rays(rng, rng.uniform(-1, 1, (150, 3)) * size + offset)
    got = assert_same_as_single_rays(tree, o, d, 0.0, 0.3 * size)
    assert_same_as_brute(tris, o, d, got, 0.0, 0.3 * size)


def test_lazy_tree_takes_single_rays_with_the_same_answers():
    rng = np.random.default_rng(37)
    tris = random_soup(rng, 5000)
    lazy = core.build_kdtree(tris, lazy=True, lazy_subtree_size=256)
    o, d = ao_rays(rng, rng.uniform(-1, 1, (200, 3)))
    got = core.occluded(lazy, o, d, tmax=0.3)
    np.testing.assert_array_equal(got, single_ray_occluded(core.build_kdtree(tris), o, d, 0.0, 0.3))
