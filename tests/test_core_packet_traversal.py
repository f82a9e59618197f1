"""Packet traversal (core.packet_traversal) against core.intersect and the brute-force oracle.

Packet lanes make the single-ray traversal's decisions with its arithmetic, so hits must equal
core.intersect's exactly (t, prim, u, v), on coherent camera-like rays, on incoherent rays (most
fall back to single rays), and on the robustness cases of test_core_queries / test_core_watertight:
rays along axes, zero and negative-zero components, origins on split planes, exact vertices and edges,
far-from-origin scenes.
"""
import numpy as np
import pytest

import core
from core.trace.packet_traversal import L, TILE_SHAPE, intersect_packets, packet_order
from tests.core_helpers import BUILDERS, oracle_once, random_rays
from tests.meshes import icosphere, lattice, mesh_triangles, random_soup, subdivided_cube
from tests.oracles import brute_watertight


def grid_rays(eye, target, width, height, fov=0.8, jitter=0.0, rng=None):
    """Pinhole rays from eye towards target through a width x height grid, in image order."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0] if abs(forward[2]) < 0.9 else [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(fov / 2)
    x = ((np.arange(width) + 0.5) / width * 2 - 1) * half
    y = (1 - (np.arange(height) + 0.5) / height * 2) * half * height / width
    xx, yy = np.meshgrid(x, y)
    d = forward + xx.reshape(-1, 1) * right + yy.reshape(-1, 1) * up
    if jitter:
        d += rng.normal(scale=jitter, size=d.shape)
    return np.broadcast_to(eye, d.shape).copy(), d


def assert_same_as_intersect(tree, o, d, width, tmin=0.0, tmax=np.inf):
    stats = {}
    got = intersect_packets(tree, o, d, width, tmin, tmax, stats=stats)
    want = core.intersect(tree, o, d, tmin, tmax)
    for name in ("prim", "t", "u", "v"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    return got, stats


def test_packet_order_tiles_the_image():
    order = packet_order(10, 5)
    tw, th = TILE_SHAPE
    assert len(order) == -(-10 // tw) * -(-5 // th) * L
    np.testing.assert_array_equal(np.sort(order[order >= 0]), np.arange(50))
    np.testing.assert_array_equal(order[:L], [y * 10 + x for y in range(th) for x in range(tw)])
    with pytest.raises(ValueError):
        packet_order(10, 5, (3, 3))


@pytest.mark.parametrize("options", BUILDERS[:2] + BUILDERS[4:6])
def test_camera_rays_on_random_soup_equal_intersect_and_brute_force(options):
    rng = np.random.default_rng(11)
    tris = random_soup(rng, 3000)
    tree = core.build_kdtree(tris, **options)
    o, d = grid_rays([2.5, -3.0, 1.5], [0.0, 0.0, 0.0], 64, 48)
    hits, stats = assert_same_as_intersect(tree, o, d, 64)
    assert stats["single_rays"] < len(o) // 10  # coherent: most lanes stay in their packets
    t, prim, _ = oracle_once(brute_watertight, tris, o, d)
    np.testing.assert_array_equal(hits.prim, prim)
    np.testing.assert_array_equal(hits.t, t.astype(np.float32))


def test_incoherent_rays_fall_back_and_still_agree():
    rng = np.random.default_rng(12)
    tris = random_soup(rng, 2000)
    tree = core.build_kdtree(tris)
    o, d = random_rays(rng, 4000)
    _, stats = assert_same_as_intersect(tree, o, d, 40)
    assert stats["single_rays"] > 0 and stats["packets"] == 4000 // L


def test_per_ray_tmin_tmax_and_partial_tiles():
    rng = np.random.default_rng(13)
    tris = random_soup(rng, 2000)
    tree = core.build_kdtree(tris)
    o, d = grid_rays([0.0, -3.0, 0.3], [0.0, 0.0, 0.0], 37, 23)  # tiles cut by both image edges
    tmin = rng.uniform(0, 2.5, len(o))
    tmax = tmin + rng.uniform(0, 2, len(o))
    assert_same_as_intersect(tree, o, d, 37, tmin, tmax)


def test_every_packet_traced_once_on_each_thread_count():
    """The kernel runs one prange iteration a thread, each taking its share of the blocks
    (docs/choices.md#packet-scratch-once-a-thread): on 1 and 2 threads, and on an image with fewer
    packets than bands, every ray is traced, with the same hits as core.intersect."""
    rng = np.random.default_rng(19)
    tree = core.build_kdtree(random_soup(rng, 2000))
    for width, height in ((61, 47), (9, 5)):
        o, d = grid_rays([0.3, -3.0, 0.2], [0.0, 0.0, 0.0], width, height)
        want = core.intersect(tree, o, d)
        for threads in (1, 2):
            got = intersect_packets(tree, o, d, width, threads=threads)
            for name in ("prim", "t", "u", "v"):
                np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
        assert (want.prim >= 0).any() and (want.prim < 0).any()


def test_orthographic_rays_and_origins_differing_in_the_sign_of_zero():
    """Parallel rays from a grid of origins (an orthographic camera: the lanes share shear axes but not
    their origin) and pinhole rays whose origins differ only in the sign of zero (the one-origin leaf
    test takes them as one origin): hits equal core.intersect's and the oracle's."""
    rng = np.random.default_rng(17)
    tris = random_soup(rng, 3000)
    tree = core.build_kdtree(tris)
    xx, zz = np.meshgrid(np.linspace(-0.9, 0.9, 40), np.linspace(0.9, -0.9, 32))
    o = np.stack([xx.ravel(), np.full(xx.size, -3.0), zz.ravel()], axis=1)
    d = np.broadcast_to([0.05, 1.0, -0.03], o.shape).copy()
    hits, stats = assert_same_as_intersect(tree, o, d, 40)
    assert stats["single_rays"] == 0 and (hits.prim >= 0).any()
    o, d = grid_rays([0.0, -3.0, 0.0], [0.0, 0.0, 0.0], 32, 24)
    o[::2, 0], o[::3, 2] = -0.0, -0.0
    hits, _ = assert_same_as_intersect(tree, o, d, 32)
    t, prim, _ = oracle_once(brute_watertight, tris, o, d)
    np.testing.assert_array_equal(hits.prim, prim)


@pytest.mark.parametrize("options", BUILDERS[:1] + BUILDERS[4:6])
def test_lattice_axis_parallel_zero_components_and_lattice_starts(options):
    """Triangles in integer axis planes; rays along lattice lines with zero and negative-zero components
    (single rays) mixed with coherent grids starting on lattice planes (packets)."""
    rng = np.random.default_rng(14)
    tree = core.build_kdtree(lattice(4), **options)
    n = 2048
    o = rng.integers(-1, 6, (n, 3)).astype(float) + rng.choice([0.0, 0.5, 0.25], (n, 3))
    d = np.zeros((n, 3))
    d[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-1.0, 1.0], n)
    d[(d == 0) & (rng.random((n, 3)) < 0.5)] = -0.0
    assert_same_as_intersect(tree, o, d, 32)
    go, gd = grid_rays([2.0, -1.0, 2.0], [2.0, 2.0, 2.0], 32, 32, fov=1.2)  # from a lattice plane
    go[:, 0] = 2.0
    assert_same_as_intersect(tree, go, gd, 32)
    t, prim, _ = oracle_once(brute_watertight, lattice(4), go, gd)
    hits = intersect_packets(tree, go, gd, 32)
    keep = ~(np.isfinite(t) & (t < 1e-12))  # origin on the hit triangle: rounding decides (core_helpers)
    np.testing.assert_array_equal(hits.prim[keep], prim[keep])


@pytest.mark.parametrize("options", BUILDERS[:1] + BUILDERS[4:5])
def test_rays_starting_on_split_planes(options):
    """Packets whose origins all lie on one inner node's split plane, looking across and along it."""
    rng = np.random.default_rng(15)
    tris = random_soup(rng, 2000)
    tree = core.build_kdtree(tris, **options)
    inner = np.flatnonzero(tree.axis < 3)
    for node in rng.choice(inner, 12):
        a, pos = int(tree.axis[node]), float(tree.split[node])
        eye = rng.uniform(-1, 1, 3)
        eye[a] = pos
        target = rng.uniform(-1, 1, 3)
        o, d = grid_rays(eye, target, 16, 8, fov=1.5)
        o[:, a] = pos
        assert_same_as_intersect(tree, o, d, 16)


@pytest.mark.parametrize("offset", [1e5, 1e7])
@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_far_from_origin_and_extreme_scales(offset, scale):
    rng = np.random.default_rng(16)
    size = scale * max(1.0, offset * 1e-4)
    tris = (random_soup(rng, 2000) * size + offset).astype(np.float32)
    tree = core.build_kdtree(tris)
    o, d = grid_rays(np.array([2.5, -3.0, 1.0]) * size + offset, np.full(3, offset), 32, 24)
    hits, _ = assert_same_as_intersect(tree, o, d, 32)
    t, prim, _ = oracle_once(brute_watertight, tris, o, d)
    np.testing.assert_array_equal(hits.prim, prim)


def test_subdivided_cube_exact_vertices_and_edges_from_inside():
    """Coherent grids from inside the cube through exact grid vertices and edges: every ray hits once,
    the packets' hits are single rays' hits."""
    tris = subdivided_cube(16)
    tree = core.build_kdtree(tris)
    for eye, target in (((0.0, 0.0, 0.0), (1.0, 0.25, 0.5)), ((0.125, -0.5, 0.25), (-1.0, 0.0, 0.0)),
                        ((0.0, 0.0, 0.0), (0.5, 0.5, -1.0))):
        o, d = grid_rays(eye, target, 32, 16, fov=1.0)
        o, d = o, np.round(d * 64) / 64  # directions on a grid: many rays through exact vertices and edges
        d[~d.any(axis=1)] = 1.0
        hits, _ = assert_same_as_intersect(tree, o, d, 32)
        assert (hits.prim >= 0).all()
        _, _, count = brute_watertight(tris, o, d)
        assert (count == 1).all()


def test_jittered_icosphere_no_ray_escapes():
    rng = np.random.default_rng(17)
    verts, faces = icosphere(4)
    verts = verts * (1.0 + rng.uniform(-2e-3, 2e-3, (len(verts), 1)))
    tris = mesh_triangles(verts.astype(np.float32).astype(np.float64), faces)
    tree = core.build_kdtree(tris)
    for target in ((1.0, 0.0, 0.0), (0.3, -0.4, 0.8), (-1.0, -1.0, -1.0)):
        o, d = grid_rays([0.05, -0.02, 0.01], target, 64, 32, fov=2.0)
        hits, _ = assert_same_as_intersect(tree, o, d, 64)
        assert (hits.prim >= 0).all()


def test_lazy_tree_is_traced_as_single_rays():
    rng = np.random.default_rng(18)
    tris = random_soup(rng, 5000)
    tree = core.build_kdtree(tris, lazy=True, lazy_subtree_size=256)
    o, d = grid_rays([2.5, -3.0, 1.5], [0.0, 0.0, 0.0], 32, 16)
    got = intersect_packets(tree, o, d, 32)
    want = core.intersect(core.build_kdtree(tris), o, d)
    np.testing.assert_array_equal(got.prim, want.prim)
    np.testing.assert_array_equal(got.t, want.t)


def test_inputs_are_checked():
    tree = core.build_kdtree(random_soup(np.random.default_rng(19), 10))
    with pytest.raises(ValueError):
        intersect_packets(tree, np.zeros((10, 3)), np.ones((10, 3)), 4)  # 10 rays are not rows of 4
    with pytest.raises(ValueError):
        intersect_packets(tree, np.zeros((8, 3)), np.zeros((8, 3)), 4)  # zero directions


@pytest.mark.parametrize("scale, offset", [(1e-18, 0.0), (2.0 ** -30, 0.0), (1.0, 0.0), (2.0 ** 30, 0.0), (1e20, 0.0),
                                           (1.0, 1e6), (2.0 ** 10, 1e6)])
def test_rays_through_vertices_and_edges_at_extreme_scales(scale, offset):
    """Rays from inside a closed subdivided cube aimed exactly at its grid vertices and edge midpoints,
    scaled and moved far from the origin: every ray hits, as core.intersect (the float32 node bounds
    must not lose a cell). Beyond float32's safe range (OUTSIDE_FLOAT32) the lanes are single rays."""
    half = 8 * scale
    tris = (subdivided_cube(8, half) + offset).astype(np.float32)
    tree = core.build_kdtree(tris)
    centre = np.float32(offset).astype(np.float64)
    g = np.linspace(-half, half, 17)  # vertices and edge midpoints of the +x face's grid
    yy, zz = np.meshgrid(g, g[::-1])
    targets = np.stack([np.full(yy.size, half), yy.ravel(), zz.ravel()], axis=1) + offset
    targets = targets.astype(np.float32).astype(np.float64)
    o = np.full((len(targets), 3), centre)
    hits, _ = assert_same_as_intersect(tree, o, targets - o, 17)
    assert (hits.prim >= 0).all()
