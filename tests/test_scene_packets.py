"""Camera rays in packets through two-level scenes (core.scene.scene_packets) against the single-ray
scene kernel (trace_valid_rays): the same t, instance, prim, u, v for every ray, on a flat tree, on one
rotated and scaled instance, far from the origin, with rays lying in split planes and with zero
components (left to single rays), on several instances (one at a time: instance_packets.py), and on
scenes the packets do not take (more than MOST_INSTANCES instances, lazy trees)."""
import numpy as np
import pytest

import core
from core.render.camera import tiled_packets, tiled_pixels
from core.scene.ray_visibility import CAMERA_RAYS, SHADOW_RAYS
from core.scene import instance_packets
from core.scene.instance_packets import MOST_INSTANCES
from core.scene.scene_packets import occluded_in_packets, packets_apply, trace_camera_packets
from core.scene.scene_queries import trace_valid_rays
from core.scene.two_level import build_two_level
from core.trace import packet_traversal
from core.trace.packet_traversal import L
from tests.meshes import icosphere, lattice, mesh_triangles, random_soup


def camera_rays(eye, target, width, height, fov=0.9):
    """Pinhole rays in tiled_pixels order, as the renderer traces them."""
    camera = core.Camera(_look_at(np.asarray(eye, float), np.asarray(target, float)), fov)
    o, d, lo, hi = camera.rays(width, height, tiled_pixels(width, height))
    return o, d, lo, hi


def _look_at(eye, target):
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0] if abs(forward[2]) < 0.9 else [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, -forward, eye
    return m


def assert_same_as_single_rays(scene, o, d, lo, hi, width, height, ray_mask=CAMERA_RAYS):
    got = trace_camera_packets(scene, o, d, lo, hi, tiled_packets(width, height), 2, ray_mask)
    want = trace_valid_rays(scene, o, d, lo, hi, False, 2, ray_mask)
    for name, a, b in zip(("t", "instance", "prim", "u", "v"), got, want):
        np.testing.assert_array_equal(a, b, err_msg=name)
    return got


def test_tiled_packets_cover_every_ray_once_in_pixel_tiles():
    width, height = 37, 21
    order = tiled_packets(width, height)
    assert len(order) % L == 0
    np.testing.assert_array_equal(np.sort(order[order >= 0]), np.arange(width * height))
    pixels = tiled_pixels(width, height)
    for packet in order.reshape(-1, L):
        x, y = pixels[packet[packet >= 0]] % width, pixels[packet[packet >= 0]] // width
        assert x.max() - x.min() < 4 and y.max() - y.min() < L // 4  # neighbouring pixels


def test_flat_tree_equals_single_rays():
    tris = random_soup(np.random.default_rng(21), 4000)
    o, d, lo, hi = camera_rays([2.5, -3.0, 1.5], [0.0, 0.0, 0.0], 48, 40)
    t, inst, prim, _, _ = assert_same_as_single_rays(core.build_kdtree(tris), o, d, lo, hi, 48, 40)
    assert (prim >= 0).any() and (inst[prim >= 0] == 0).all()


@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_one_transformed_instance_equals_single_rays(offset):
    verts, faces = icosphere(3)
    tree = core.build_kdtree(mesh_triangles(verts, faces))
    angle = 0.7
    m = np.eye(4)
    m[:3, :3] = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]) * 2.5
    m[:3, 3] = offset + np.array([0.3, -0.2, 0.1])
    scene = build_two_level([tree], [0], m[None])
    o, d, lo, hi = camera_rays(np.array([6.0, -7.0, 3.0]) + offset, np.full(3, offset), 40, 32)
    _, _, prim, _, _ = assert_same_as_single_rays(scene, o, d, lo, hi, 40, 32)
    assert (prim >= 0).mean() > 0.2


def test_rays_in_split_planes_and_zero_components():
    """A camera on an axis looking along another: its middle row and column have zero components (single
    rays); origins on the root's split plane."""
    tris = random_soup(np.random.default_rng(22), 3000)
    tree = core.build_kdtree(tris)
    a, pos = int(tree.axis[0]), float(tree.split[0])
    eye = np.zeros(3)
    eye[a] = pos
    eye[(a + 1) % 3] = -4.0
    target = eye.copy()
    target[(a + 1) % 3] = 0.0
    o, d, lo, hi = camera_rays(eye, target, 33, 33, fov=1.2)
    assert (d == 0.0).any()
    assert_same_as_single_rays(tree, o, d, lo, hi, 33, 33)


def _rotation(angle, scale=1.0):
    m = np.eye(4)
    m[:3, :3] = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]) * scale
    return m


def _crowd(offset=0.0):
    """Instances whose world boxes overlap: a lattice (triangles in split planes) twice at the same place
    (every hit on it an exact tie between two instances), a sphere scaled and rotated in front of it, soups
    around, one seen by shadow rays only, one behind the camera; all moved by `offset`."""
    rng = np.random.default_rng(25)
    verts, faces = icosphere(3)
    trees = [core.build_kdtree(lattice(3)), core.build_kdtree(mesh_triangles(verts, faces)),
             core.build_kdtree(random_soup(rng, 800)), core.build_kdtree(random_soup(rng, 800))]
    placements = [(0, np.eye(4)), (0, np.eye(4)), (1, _rotation(0.7, 1.3)), (2, _rotation(0.3)),
                  (3, _rotation(-1.1, 0.5)), (2, _rotation(2.0, 2.0)), (3, np.eye(4))]
    placements[2][1][:3, 3] = (3.5, -1.5, 1.0)
    placements[3][1][:3, 3] = (-1.0, 2.5, 0.5)
    placements[4][1][:3, 3] = (0.0, -1.5, 3.5)
    placements[5][1][:3, 3] = (0.5, 3.0, 2.5)
    placements[6][1][:3, 3] = (9.0, -12.0, 3.0)  # behind the camera
    matrices = np.stack([m for _, m in placements])
    matrices[:, :3, 3] += offset
    visibility = np.full(len(placements), CAMERA_RAYS | SHADOW_RAYS, np.uint8)
    visibility[5] = SHADOW_RAYS
    return build_two_level(trees, [m for m, _ in placements], matrices, visibility=visibility)


@pytest.mark.parametrize("offset, batch", [(0.0, None), (2.0 ** 18, None), (0.0, 7)])
def test_several_instances_in_packets_equal_single_rays(offset, batch, monkeypatch):
    """Several instances (instance_packets.py): every ray's t, instance, prim, u, v as the single-ray
    scene kernel gives them, with exact ties between two instances (the first its top-level walk meets
    wins), rays in the lattice's split planes, an instance only shadow rays see, far from the origin,
    and with the packets in batches of 7 (the last one shorter)."""
    if batch is not None:
        monkeypatch.setattr(instance_packets, "BATCH_PACKETS", batch)
    scene = _crowd(offset)
    assert packets_apply(scene, CAMERA_RAYS)
    o, d, lo, hi = camera_rays(np.array([6.0, -7.0, 4.0]) + offset, np.array([1.0, 1.0, 1.0]) + offset, 48, 40)
    _, inst, prim, _, _ = assert_same_as_single_rays(scene, o, d, lo, hi, 48, 40)
    seen = set(inst[prim >= 0].tolist())
    assert {0, 2, 3, 4} <= seen and 5 not in seen


@pytest.mark.parametrize("wide_first", [False, True])
def test_exact_ties_go_where_the_top_level_walk_sends_them(wide_first):
    """Two instances of the same lattice at the same place, one of them with a triangle behind the
    camera, so its world box holds the camera and the packets take it first; the single-ray kernel's
    walk decides which instance wins each tie, in both index orders. A pass searching only up to the best
    hit (not one float past it) would give every tie to the wide instance."""
    walls = lattice(3)
    behind = np.array([[[9.0, -11.0, 6.0], [9.5, -11.0, 6.0], [9.0, -10.5, 6.0]]])
    trees = [core.build_kdtree(walls), core.build_kdtree(np.concatenate([walls, behind]))]
    meshes = [1, 0] if wide_first else [0, 1]
    scene = build_two_level(trees, meshes, np.stack([np.eye(4)] * 2))
    o, d, lo, hi = camera_rays([6.0, -7.0, 4.0], [1.5, 1.5, 1.5], 40, 32)
    order = instance_packets._nearest_first(scene.arrays, np.array([0, 1]), o, tiled_packets(40, 32))
    assert meshes[order[0]] == 1  # the wide instance's box holds the camera: the packets take it first
    _, inst, prim, _, _ = assert_same_as_single_rays(scene, o, d, lo, hi, 40, 32)
    assert (prim >= 0).mean() > 0.1
    assert len(np.unique(inst[prim >= 0])) == 1  # every hit a tie, all won by one instance


def test_shadow_rays_through_several_instances_occluded_as_any_hit_rays():
    """occluded_in_packets through several instances: from the camera hits towards one point, each ray
    occluded exactly when the single-ray any-hit query says so; some occluded, some clear, and the
    shadow-only instance occludes some."""
    scene = _crowd()
    o, d, lo, hi = camera_rays([6.0, -7.0, 4.0], [1.0, 1.0, 1.0], 48, 40)
    t, _, prim, _, _ = trace_valid_rays(scene, o, d, lo, hi, False, 2, CAMERA_RAYS)
    hit = prim >= 0
    points = o[hit] + t[hit, None] * d[hit]
    towards = np.array([1.0, 3.5, 6.0]) - points
    length = np.linalg.norm(towards, axis=1)
    towards /= length[:, None]
    starts = np.ascontiguousarray(points + 1e-6 * towards)
    order = np.full(-(-len(starts) // L) * L, -1, np.int64)
    order[:len(starts)] = np.arange(len(starts))
    lows, tmax = np.zeros(len(starts)), length * (1.0 - 1e-6)
    got = occluded_in_packets(scene, starts, towards, lows, tmax, order, 2, SHADOW_RAYS)
    want = trace_valid_rays(scene, starts, towards, lows, tmax, True, 2, SHADOW_RAYS)
    np.testing.assert_array_equal(got, want[2] >= 0)
    assert 0 < got.sum() < len(got) and (want[1] == 5).any()


def test_several_instances_take_empty_orders_and_skip_empty_meshes():
    """No rays (a frame whose hits all face away from the light gives the shadow pass none): empty
    answers. An empty mesh's instance (an inverted world box, which the top level leaves out) is not one
    the rays see, so it neither costs a pass nor counts towards MOST_INSTANCES."""
    scene = _crowd()
    o, d, lo, hi = camera_rays([6.0, -7.0, 4.0], [1.0, 1.0, 1.0], 8, 8)
    empty = np.zeros(0, np.int64)
    got = trace_camera_packets(scene, o[:0], d[:0], lo[:0], hi[:0], empty, 2, CAMERA_RAYS)
    assert all(len(a) == 0 for a in got)
    assert len(occluded_in_packets(scene, o[:0], d[:0], lo[:0], hi[:0], empty, 2, SHADOW_RAYS)) == 0
    rng = np.random.default_rng(26)
    trees = [core.build_kdtree(np.zeros((0, 3, 3), np.float32)), core.build_kdtree(random_soup(rng, 300))]
    with_empty = build_two_level(trees, [0, 1], np.stack([np.eye(4)] * 2))
    np.testing.assert_array_equal(instance_packets.visible_instances(with_empty.arrays, CAMERA_RAYS), [1])
    assert_same_as_single_rays(with_empty, o, d, lo, hi, 8, 8)


def test_scenes_packets_do_not_take_are_traced_as_before():
    """More than MOST_INSTANCES instances the rays see, and lazy trees, go to single rays."""
    rng = np.random.default_rng(23)
    trees = [core.build_kdtree(random_soup(rng, 200)) for _ in range(2)]
    count = MOST_INSTANCES + 1
    m = np.repeat(np.eye(4)[None], count, axis=0)
    m[:, 0, 3] = np.linspace(-4.0, 4.0, count)
    scene = build_two_level(trees, np.arange(count) % 2, m)
    assert not packets_apply(scene, CAMERA_RAYS)
    o, d, lo, hi = camera_rays([0.0, -9.0, 1.0], [0.0, 0.0, 0.0], 32, 24)
    assert_same_as_single_rays(scene, o, d, lo, hi, 32, 24)
    lazy = core.build_kdtree(random_soup(rng, 3000), lazy=True, lazy_subtree_size=256)
    got = trace_camera_packets(lazy, o, d, lo, hi, tiled_packets(32, 24), 2, CAMERA_RAYS)
    want = trace_valid_rays(lazy, o, d, lo, hi, False, 2, CAMERA_RAYS)
    np.testing.assert_array_equal(got[2], want[2])


def test_instance_invisible_to_the_ray_kind_is_missed():
    tree = core.build_kdtree(random_soup(np.random.default_rng(24), 500))
    scene = build_two_level([tree], [0], np.eye(4)[None], visibility=np.array([SHADOW_RAYS], np.uint8))
    o, d, lo, hi = camera_rays([2.5, -3.0, 1.5], [0.0, 0.0, 0.0], 16, 16)
    _, inst, prim, _, _ = assert_same_as_single_rays(scene, o, d, lo, hi, 16, 16)
    assert (prim == -1).all() and (inst == -1).all()


@pytest.mark.parametrize("matrix", [np.eye(4), np.diag([2.0, 0.5, 1.5, 1.0])])
def test_shadow_rays_to_one_point_occluded_as_any_hit_rays(matrix):
    """occluded_in_packets (the renderer's shadow rays of a light without extent): from the camera hits
    of a soup towards one point, ending short of it, every ray occluded exactly when the single-ray
    any-hit query says so, on a flat tree and on one scaled instance; some rays occluded, some clear."""
    tris = random_soup(np.random.default_rng(5), 3000)
    o, d, lo, hi = camera_rays([2.5, -3.0, 1.5], [0.0, 0.0, 0.0], 48, 40)
    scene = build_two_level([core.build_kdtree(tris)], [0], matrix[None])
    t, _, prim, _, _ = trace_valid_rays(scene, o, d, lo, hi, False, 2, CAMERA_RAYS)
    hit = prim >= 0
    points = o[hit] + t[hit, None] * d[hit]
    towards = np.array([0.3, -2.0, 2.5]) - points
    length = np.linalg.norm(towards, axis=1)
    towards /= length[:, None]
    starts = np.ascontiguousarray(points + 1e-6 * towards)
    tmax = length * (1.0 - 1e-6)
    order = np.full(-(-len(starts) // L) * L, -1, np.int64)
    order[:len(starts)] = np.arange(len(starts))
    got = occluded_in_packets(scene, starts, towards, np.zeros(len(starts)), tmax, order, 2, SHADOW_RAYS)
    want = trace_valid_rays(scene, starts, towards, np.zeros(len(starts)), tmax, True, 2, SHADOW_RAYS)[2] >= 0
    np.testing.assert_array_equal(got, want)
    assert 0 < want.sum() < len(want)


@pytest.mark.parametrize("builder, offset", [("binned", 0.0), ("median", 0.0), ("binned", 2.0 ** 20)])
def test_shadow_rays_of_mixed_signs_from_lattice_points_occluded_as_any_hit_rays(builder, offset):
    """Shadow packets are any-hit packets (a lane stops at its first hit, lanes of both signs share a
    packet): rays from many distinct points of a lattice (every triangle in a split plane, starts on
    split planes, half-integer and integer coordinates) towards a point inside it, so a packet's lanes
    point in both directions on some axis, many rays lie in split planes, some components are +-0.
    Every ray is occluded exactly when the single-ray any-hit query says so, also far from the origin
    (every coordinate offset by 2^20, where float32 keeps the lattice exact)."""
    tris = lattice(3) + offset
    grid = np.stack(np.meshgrid(*[np.arange(0.0, 3.01, 0.5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) + offset
    light = np.array([1.5, 1.0, 2.0]) + offset
    grid = grid[np.linalg.norm(grid - light, axis=1) > 0]
    rng = np.random.default_rng(11)
    starts = np.ascontiguousarray(np.concatenate([grid, grid + rng.normal(scale=1e-3, size=grid.shape)]))
    towards = light - starts
    length = np.linalg.norm(towards, axis=1)
    towards /= length[:, None]
    towards[::7] *= -1.0  # some rays away from the light: both signs inside most packets
    scene = build_two_level([core.build_kdtree(tris, builder=builder)], [0], np.eye(4)[None])
    order = np.full(-(-len(starts) // L) * L, -1, np.int64)
    order[:len(starts)] = np.arange(len(starts))
    for lo in (0.0, 1e-9):
        lows = np.full(len(starts), lo)
        got = occluded_in_packets(scene, starts, towards, lows, length, order, 2, SHADOW_RAYS)
        want = trace_valid_rays(scene, starts, towards, lows, length, True, 2, SHADOW_RAYS)[2] >= 0
        np.testing.assert_array_equal(got, want)
        assert 0 < want.sum() < len(want)
    signs = np.sign(towards[order[:len(starts) // L * L]].reshape(-1, L, 3))
    assert ((signs > 0).any(axis=1) & (signs < 0).any(axis=1)).any(axis=1).mean() > 0.5


def test_orders_a_caller_made_take_the_renderers_compiled_version():
    """The renderer's packet orders are read-only; a writable order of a caller's own is taken as a
    read-only view (left writable for the caller), so each packet kernel compiles one version
    (docs/choices.md#one-compiled-version-of-each-kernel)."""
    o, d, lo, hi = camera_rays([6.0, -7.0, 4.0], [1.0, 1.0, 1.0], 16, 16)
    order = np.array(tiled_packets(16, 16))
    assert order.flags.writeable
    for scene in (core.build_kdtree(random_soup(np.random.default_rng(27), 300)), _crowd()):
        trace_camera_packets(scene, o, d, lo, hi, order, 2, CAMERA_RAYS)
        occluded_in_packets(scene, o, d, lo, hi, order, 2, SHADOW_RAYS)
    assert order.flags.writeable
    orders = [sig[1].types[-1] for sig in packet_traversal.trace_packets.signatures]  # PacketRays.order
    orders += [sig[2].types[-1] for sig in instance_packets._enter_instance.signatures]
    orders += [kind for sig in instance_packets._take_hits.signatures for kind in sig[2].types]
    assert orders and not any(kind.mutable for kind in orders), orders
