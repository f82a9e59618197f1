"""The renderer far from the origin and at extreme scales: no leaks through thin gaps, no acne."""
import numpy as np
import pytest

import core
from tests.meshes import icosphere, mesh_triangles
from tests.render_scenes import box, floor, hit_mask, look_at, look_down


@pytest.mark.parametrize("offset", [0.0, 1e3, 1e4, 1e5])
def test_nothing_leaks_under_a_thin_roof_far_from_the_origin(offset):
    """A floor with a roof 0.2 above it, the sun straight overhead: shadow 0 and AO (h/r)^2 under it,
    wherever the porch stands. Offsetting ray starts by 256 float32 ulps of the hit point (0.3 units
    at 1e4) carried shadow and AO rays through the roof: fully lit, AO 1."""
    h, r = 0.2, 0.4
    tris = np.concatenate([floor(0.0, half=50.0), floor(h, half=50.0)]) + offset
    camera = look_down(np.array([0.0, 0.0, 0.1]) + offset, fov=1.0)
    tree = core.build_kdtree(tris)
    sun = core.Light.sun((0.1, 0.0, -1.0))
    shadow = core.render_preview(tree, camera, 12, 12, mode="shadow", samples=4, lights=[sun])
    ao = core.render_preview(tree, camera, 12, 12, samples=256, ao_distance=r)
    assert hit_mask(shadow).all() and (shadow[..., :3] == 0.0).all()
    assert ao[..., 0].mean() == pytest.approx((h / r) ** 2, abs=0.01)


@pytest.mark.parametrize("center", [(0.0, 0.0), (5e5, 0.0), (3e5, 4e6)])
def test_a_hair_thin_gap_far_out_in_x_and_y_stays_closed(center):
    """A floor at z = 0 with a roof 1e-4 above it, far from the origin in x and y only (georeferenced
    coordinates), in a flat world-space tree. z stays near 0, so float32 holds the gap exactly, and
    what puts a hit point off its plane is the rounding of its z, not of its x: ray starts offset by
    2^-32 of max |p_k| would rise 1.2e-4 at x = 5e5, above the roof (fully lit, AO 1). Shadow 0
    under a sun; AO (h/r)^2 with r = 1e-3."""
    h, r = float(np.float32(1e-4)), 1e-3
    tris = np.concatenate([floor(0.0, half=50.0, center=center), floor(h, half=50.0, center=center)])
    m = np.eye(4)
    m[:3, 3] = (center[0], center[1], h / 2)
    camera = core.Camera(m, ortho_scale=1.0)
    tree = core.build_kdtree(tris)
    shadow = core.render_preview(tree, camera, 12, 12, mode="shadow", samples=4, lights=[core.Light.sun((0.1, 0.2, -1.0))])
    ao = core.render_preview(tree, camera, 16, 16, samples=256, ao_distance=r)
    assert hit_mask(shadow).all() and (shadow[..., :3] == 0.0).all()
    assert ao[..., 0].mean() == pytest.approx((h / r) ** 2, abs=0.002)


def test_a_thin_gap_under_a_rotated_scaled_instance_stays_closed():
    """The same gap inside an instance that is rotated, scaled unevenly and moved 1e5 away: the
    projection onto the triangle's plane works in object space, whose rounding the ray start's offset
    must also cover, seen along the world normal."""
    h, r = 0.05, 0.1
    mesh = np.concatenate([floor(0.0, half=2.0), floor(h, half=2.0)]).reshape(-1, 3)
    c, s = np.cos(0.7), np.sin(0.7)
    matrix = np.array([[3.0 * c, -0.5 * s, 0.0, 1e5], [3.0 * s, 0.5 * c, 0.0, -2e5], [0.0, 0.0, 0.01, 10.0],
                       [0.0, 0.0, 0.0, 1.0]])
    scene = core.build_scene([(mesh, np.arange(len(mesh)).reshape(-1, 3))], [0], matrix[None], layout="two_level")
    m = np.eye(4)
    m[:3, 3] = matrix[:3, 3] + (0.0, 0.0, 0.01 * h / 2)
    camera = core.Camera(m, ortho_scale=0.5)
    ao = core.render_preview(scene, camera, 16, 16, samples=256, ao_distance=0.01 * r)
    shadow = core.render_preview(scene, camera, 12, 12, mode="shadow", samples=4, lights=[core.Light.sun((0.1, 0.2, -1.0))])
    assert hit_mask(ao).all() and (shadow[..., :3] == 0.0).all()
    assert ao[..., 0].mean() == pytest.approx((h / r) ** 2, abs=0.01)


@pytest.mark.parametrize("seed", range(6))
def test_a_lone_convex_object_has_ao_one_under_random_transforms(seed):
    """Nothing can occlude a convex object's own surface: AO exactly 1 on every hit pixel of a sphere
    and a box under random instance matrices (rotation, scales 1e-2 to 1e3 per axis, 1 to 3e6 from
    the origin), in both layouts, with the ray starts offset by their error scale (hit_frames._error_scale)."""
    rng = np.random.default_rng(seed)
    sphere = mesh_triangles(*icosphere(3))
    cube = box((0, 0, 0), (1, 1, 1)).reshape(-1, 3, 3) - 0.5
    hits = 0
    for tris in (sphere, cube):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        m = np.eye(4)
        m[:3, :3] = q * 10 ** rng.uniform(-2, 3, size=3)
        m[:3, 3] = rng.normal(size=3) / np.sqrt(3) * 10 ** rng.uniform(0, 6.5)
        size = np.abs(m[:3, :3]).sum(axis=1).max()  # the object lies within size of its centre on every axis
        away = rng.normal(size=3)
        camera = look_at(m[:3, 3] + away / np.linalg.norm(away) * 2.0 * np.sqrt(3) * size, m[:3, 3], fov=1.0)
        mesh = (tris.reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3))
        for layout in ("flat", "two_level"):
            scene = core.build_scene([mesh], [0], m[None], layout=layout)
            img = core.render_preview(scene, camera, 24, 24, samples=16, ao_distance=10 * size)
            hits += hit_mask(img).sum()
            assert (img[..., 0][hit_mask(img)] == 1.0).all()
    assert hits > 0


@pytest.mark.parametrize("stretch", [1e5, 1e6])
def test_a_plane_stretched_along_its_own_normal_has_no_acne(stretch):
    """A flat surface on x + 2y + 3z = 0 (a triangle about 2 wide and a fan of 2^-33 ones around the
    origin, every float32 vertex exactly on the plane) under an instance that stretches along the
    plane's normal, as a child rotated under a parent scaled along one axis does: the world surface is
    the same plane. Projecting a hit point onto its plane in object space rounds (q - v0) . n_o, which
    the stretch magnifies along the world normal; without that term in the offset, rays started under
    the plane and the tiny neighbours caught them (AO 0.53-0.70). AO exactly 1."""
    n = np.array([1.0, 2.0, 3.0])
    u = n / np.linalg.norm(n)
    e1, e2, z, k = np.array([1.0, 1.0, -1.0]), np.array([-2.0, 1.0, 0.0]), np.zeros(3), 2.0 ** -33
    verts = np.array([v for tri in [(e1, e2, z), (z, k * e2, -k * e1), (z, -k * e1, -k * e2), (z, -k * e2, k * e1)]
                      for v in tri], np.float32)
    assert (verts.astype(np.float64) @ n == 0).all()
    matrix = np.eye(4)
    matrix[:3, :3] += (stretch - 1.0) * np.outer(u, u)
    scene = core.build_scene([(verts, np.arange(len(verts)).reshape(-1, 3))], [0], matrix[None], layout="two_level")
    t1 = np.cross(u, [0.0, 0.0, 1.0])
    t1 /= np.linalg.norm(t1)
    cam = np.eye(4)
    cam[:3, 0], cam[:3, 1], cam[:3, 2], cam[:3, 3] = t1, np.cross(u, t1), u, u
    img = core.render_preview(scene, core.Camera(cam, ortho_scale=4 * k), 24, 24, samples=64, ao_distance=10.0)
    assert hit_mask(img).sum() > 300
    assert (img[..., 0][hit_mask(img)] == 1.0).all()


@pytest.mark.parametrize("scale", [1.0, 1e-3, 1e-6])
def test_ao_between_planes_is_right_at_tiny_scales(scale):
    """AO (h/r)^2 between two planes at any scale: no absolute floor on the ray offset biases it
    (2^-16 units made the AO 0.4796 instead of 0.5102 at scale 1e-3)."""
    h, r = 0.5, 0.7
    tris = np.concatenate([floor(0.0, half=1e3), floor(h, half=1e3)]) * scale
    camera = look_down(np.array([0.0, 0.0, 0.25]) * scale, fov=1.0)
    img = core.render_preview(core.build_kdtree(tris), camera, 16, 16, samples=256, ao_distance=r * scale)
    assert hit_mask(img).all()
    assert img[..., 0].mean() == pytest.approx((h / r) ** 2, abs=0.01)


@pytest.mark.parametrize("half", [1.0, 1e4, 1e5])
@pytest.mark.parametrize("view", [1e-2, 1e-3])
def test_huge_triangles_seen_up_close_have_no_acne(half, view):
    """Two triangles half x half wide seen `view` across (plus one far away, so the tree's box is not
    flat): the triangle test's t carries rounding of the vertices' size, and an offset scaled by the
    hit point's magnitude alone lets AO rays hit the floor they left (AO 0.83-0.87 for
    half / view >= 1e7). Open floor: AO exactly 1; a ceiling view/2 above: AO (h/r)^2."""
    far = np.array([[[500, 500, 50], [501, 500, 50], [500, 501, 50]]], float)
    camera = core.Camera(np.eye(4) + np.pad([[view / 4]], ((2, 1), (3, 0))), ortho_scale=view)
    open_floor = core.build_kdtree(np.concatenate([floor(0.0, half=half), far]))
    img = core.render_preview(open_floor, camera, 16, 16, samples=64, ao_distance=view)
    assert hit_mask(img).all() and (img[..., :3] == 1.0).all()
    h, r = view / 2, view
    gap = core.build_kdtree(np.concatenate([floor(0.0, half=half), floor(h, half=half), far]))
    ao = core.render_preview(gap, camera, 16, 16, samples=256, ao_distance=r)
    assert ao[..., 0].mean() == pytest.approx((h / r) ** 2, abs=0.01)


@pytest.mark.parametrize("length", [1e3, 1e5, 1e6])
@pytest.mark.parametrize("layout", ["flat", "two_level"])
def test_long_thin_box_is_fully_unoccluded(length, layout):
    """Nothing can occlude a convex object's own surface, so a lone box has AO exactly 1. A box
    `length` long and 0.7 wide: its hit points, computed as o + t d, carried t's error of about
    eps length^2 / width and sat below their face by more than the offset, so AO rays started inside
    the box (dark speckles from length 3e4 on, in the world-space tree). "flat" puts the
    long triangles in world space; "two_level" keeps a unit cube under a scaling matrix. At 1e7 the
    float64 triangle test's own t error (~0.03) puts a few camera hits on the wrong face: its limit."""
    matrix = np.diag([length, 0.35, 0.35, 1.0])
    matrix[:3, 3] = (-2.0, -2.0, 0.35)
    unit = box((0, 0, 0), (1, 1, 1)).reshape(-1, 3)
    scene = core.build_scene([(unit, np.arange(36).reshape(-1, 3))], [0], matrix[None], layout=layout)
    img = core.render_preview(scene, look_at((8, -8, 6), (0, 0, 0.5), fov=0.8), 64, 48, samples=32,
                              ao_distance=1.0)
    assert hit_mask(img).sum() > 300
    assert (img[..., :3][hit_mask(img)] == 1.0).all()
