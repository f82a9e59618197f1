"""The renderer against cases with a known answer."""
import numpy as np
import pytest

import core
from core.render.camera import tiled_pixels
from core.render.lights import DELTA
from tests.meshes import icosphere, mesh_triangles
from tests.render_scenes import box, floor, hit_mask, look_at, look_down, quad


def render(tris, camera, size=32, **settings):
    tree = core.build_kdtree(tris)
    return core.render_preview(tree, camera, size, size, **settings)


@pytest.mark.parametrize("offset", [0.0, 1e3, 1e5])
def test_lone_plane_is_fully_unoccluded_even_far_from_origin(offset):
    """No self-intersection ("acne") anywhere on a large floor, also far from the origin."""
    tris = floor(z=offset, center=(offset, offset))
    img = render(tris, look_down((offset + 0.3, offset - 0.2, offset + 2.0)), samples=64, ao_distance=10.0)
    assert hit_mask(img).all()
    assert (img[..., :3] == 1.0).all()


def test_parallel_planes_within_and_beyond_their_gap():
    """Floor at z=0, ceiling at z=d, camera between them looking down. A cosine-weighted direction at
    angle theta reaches the ceiling at distance d/cos(theta), so AO = 1 when ao_distance R < d and
    AO = P(cos(theta) < d/R) = (d/R)^2 when R > d."""
    d = 1.0
    tris = np.concatenate([floor(0.0), floor(d)])
    camera = look_down((0.0, 0.0, 0.5))
    near = render(tris, camera, samples=16, ao_distance=0.99 * d)
    assert hit_mask(near).all() and (near[..., 0] == 1.0).all()
    for r in (1.5, 3.0):
        img = render(tris, camera, size=48, samples=256, ao_distance=r)
        assert img[..., 0].mean() == pytest.approx((d / r) ** 2, abs=0.01)


def test_point_in_box_corner():
    """On the floor of a corner formed by two infinite walls, directions toward either wall are
    blocked: a quarter of the cosine-weighted hemisphere stays open (AO = 1/4) at any distance."""
    big = 1e4
    tris = np.concatenate([floor(0.0, half=big, center=(big, big)),
                           quad((0.0, big, big), (0, big, 0), (0, 0, big)),
                           quad((big, 0.0, big), (big, 0, 0), (0, 0, big))])
    camera = look_at((0.6, 0.6, 0.6), (0.1, 0.1, 0.0), fov=0.2)
    img = render(tris, camera, size=16, samples=1024, ao_distance=1e6)
    floor_pixels = img[..., 0][hit_mask(img)]
    assert floor_pixels.mean() == pytest.approx(0.25, abs=0.01)


def test_floor_under_large_occluder_is_fully_shadowed():
    tris = np.concatenate([floor(0.0, half=50), quad((0, 0, 1.0), (10, 0, 0), (0, 10, 0))])
    camera = look_at((0.0, -0.5, 0.5), (0.0, 0.0, 0.0), fov=0.6)
    lights = [core.Light.point((0.5, 0.2, 3.0), radius=0.3), core.Light.sun((0.1, 0.1, -1.0), angle=0.05)]
    img = render(tris, camera, samples=16, mode="shadow", lights=lights)
    assert hit_mask(img).all()
    assert (img[..., :3] == 0.0).all()


def test_point_light_cosine_falloff():
    """A bare floor lit by a point light at height h: value = N.L = h / sqrt(r^2 + h^2)."""
    h = 2.0
    light = core.Light.point((0.3, -0.1, h))
    camera = look_down((0.0, 0.0, 3.0), fov=1.2)
    tree = core.build_kdtree(floor(0.0))
    size = 24
    img = core.render_preview(tree, camera, size, size, samples=1, mode="shadow", lights=[light])
    origins, directions, _, _ = camera.rays(size, size)
    p = origins + directions * 3.0  # the floor is 3 units below the camera along the view axis
    r2 = (p[:, 0] - 0.3) ** 2 + (p[:, 1] + 0.1) ** 2
    expected = (h / np.sqrt(r2 + h * h)).reshape(size, size)
    np.testing.assert_allclose(img[..., 0], expected, rtol=1e-6)


@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_a_point_light_on_the_ceilings_plane_lights_the_floor(offset):
    """Outside review: a light lying on a surface's plane was blocked by it (every shadow ray ends where
    the surface is met, within rounding), so a room came out black. The ray now stops a step short of
    the light (shading.short_of_light), as Cycles' does: the floor gets the bare N.L falloff."""
    h = 3.0
    shift = np.array([offset, -offset, 0.0])
    tris = np.concatenate([floor(0.0, half=50, center=shift[:2]), floor(h, half=50, center=shift[:2])])
    light = core.Light.point((0.3 + offset, -0.1 - offset, h))
    camera = look_down((offset, -offset, 2.5), fov=1.2)
    size = 24
    img = render(tris, camera, size, samples=1, mode="shadow", lights=[light])
    origins, directions, _, _ = camera.rays(size, size)
    p = origins + directions * 2.5
    r2 = (p[:, 0] - 0.3 - offset) ** 2 + (p[:, 1] + 0.1 + offset) ** 2
    expected = (h / np.sqrt(r2 + h * h)).reshape(size, size)
    np.testing.assert_allclose(img[..., 0], expected, rtol=1e-5)


@pytest.mark.parametrize("wall", [False, True])
def test_an_area_light_flush_with_a_surface_lights_as_one_just_off_it(wall):
    """An area light flush with the ceiling (emitting down) or with a wall (emitting into the room)
    lights the floor as the same light moved 1e-6 off the surface does (the review measured a black
    floor and a speckled one: 0.39-0.97 of the moved light's value)."""
    tris = np.concatenate([floor(0.0, half=5), floor(3.0, half=5),
                           quad((-5.0, 0.0, 1.5), (0.0, 5.0, 0.0), (0.0, 0.0, 1.5))])  # the wall at x = -5
    camera = look_down((0.0, 0.0, 2.9), fov=1.0)
    tree = core.build_kdtree(tris)
    images = []
    for gap in (0.0, 1e-6):
        m = np.eye(4)
        if wall:  # its -Z along world +X, into the room
            m[:3, :3] = [[0, 0, -1], [0, 1, 0], [1, 0, 0]]
            m[:3, 3] = (-5.0 + gap, 0.0, 1.5)
        else:
            m[:3, 3] = (0.3, 0.2, 3.0 - gap)
        light = core.Light.area(m, size=1.0)
        images.append(core.render_preview(tree, camera, 32, 24, samples=16, mode="shadow", lights=[light])[..., 0])
    flush, moved = images
    assert moved.mean() > 0.2
    np.testing.assert_allclose(flush, moved, atol=1e-5)


def test_an_occluder_just_under_a_light_still_shadows():
    """The step short of the light is tiny: a slab 1e-4 under a point light still hides it."""
    tris = np.concatenate([floor(0.0, half=50), quad((0.3, -0.1, 3.0 - 1e-4), (0.5, 0, 0), (0, 0.5, 0))])
    light = core.Light.point((0.3, -0.1, 3.0))
    img = render(tris, look_down((0.0, 0.0, 2.5), fov=1.2), 24, samples=1, mode="shadow", lights=[light])
    assert hit_mask(img).all()
    assert (img[..., :3] == 0.0).all()


def test_light_behind_surface_and_spot_cone_send_no_rays():
    tree = core.build_kdtree(floor(0.0))
    camera = look_down((0.0, 0.0, 1.0))
    below = core.Light.point((0.0, 0.0, -1.0))
    r = core.PreviewRender(tree, camera, 16, 16, samples=4, mode="shadow", lights=[below])
    r.step(4)
    assert r.rays_traced == r.camera_rays  # N.L <= 0: no shadow rays at all
    assert (r.image()[..., :3] == 0).all()
    spot = core.Light.spot((0, 0, 2.0), (1.0, 0.0, 0.0), spot_size=0.3)  # points sideways
    r = core.PreviewRender(tree, camera, 16, 16, samples=4, mode="shadow", lights=[spot])
    r.step(4)
    assert r.rays_traced == r.camera_rays


def test_spot_cone_and_area_light_side():
    tree = core.build_kdtree(floor(0.0))
    camera = look_down((0.0, 0.0, 4.0), fov=1.4)
    spot = core.Light.spot((0, 0, 2.0), (0, 0, -1.0), spot_size=np.radians(40), spot_blend=0.0)
    img = core.render_preview(tree, camera, 40, 40, samples=1, mode="shadow", lights=[spot])
    o, d, _, _ = camera.rays(40, 40)
    p = o + 4.0 * d
    inside = (np.degrees(np.arctan2(np.hypot(p[:, 0], p[:, 1]), 2.0)) < 20).reshape(40, 40)
    assert (img[..., 0][~inside] == 0).all() and (img[..., 0][inside] > 0).all()
    m = np.eye(4)
    m[:3, 3] = (0, 0, 1.0)
    facing_down = core.Light.area(m, size=0.5)
    m2 = m.copy()
    m2[:3, 2] *= -1
    m2[:3, 1] *= -1
    facing_up = core.Light.area(m2, size=0.5)
    lit = core.render_preview(tree, camera, 16, 16, samples=4, mode="shadow", lights=[facing_down])
    dark = core.render_preview(tree, camera, 16, 16, samples=4, mode="shadow", lights=[facing_up])
    assert lit[..., 0].min() > 0 and (dark[..., :3] == 0).all()


@pytest.mark.parametrize("scale", [(2.0, 1.0, 1.0), (1.5, 0.75, 0.75), (1.0, 1.0, 1.0)])
def test_scaled_spot_cone_is_elliptical_as_in_cycles(scale):
    """Cycles measures a spot's cone in the light object's own frame (spot_light_to_local): with
    object scale (sx, sy, sz) a floor point (x, y) at depth h below it is inside when
    h/sz / |(x/sx, y/sy, h/sz)| > cos(size/2), i.e. (x/sx)^2 + (y/sy)^2 < (h/sz)^2 tan^2(size/2)."""
    h, size = 2.0, np.radians(40)
    tree = core.build_kdtree(floor(0.0))
    camera = look_down((0.0, 0.0, 4.0), fov=1.4)
    axes = np.diag(scale)  # Blender's default light faces down its -Z
    spot = core.Light.spot((0, 0, h), (0, 0, -1.0), spot_size=size, spot_blend=0.0, axes=axes)
    img = core.render_preview(tree, camera, 48, 48, samples=1, mode="shadow", lights=[spot])
    o, d, _, _ = camera.rays(48, 48)
    p = o + 4.0 * d
    sx, sy, sz = scale
    ellipse = (p[:, 0] / sx) ** 2 + (p[:, 1] / sy) ** 2 - (h / sz * np.tan(size / 2)) ** 2
    lit = img[..., 0].ravel() > 0
    assert (lit[ellipse < -1e-9] == 1).all() and (lit[ellipse > 1e-9] == 0).all()
    assert lit.sum() > 20


def test_sheared_spot_cone_follows_the_inverse_of_its_axes():
    """A spot under a non-uniformly scaled parent, rotated: its axes are not orthogonal. Cycles takes a
    direction into the light's frame with the inverse transform (spot_light_to_local), so a floor point
    p is inside when z / |l| > cos(size/2) for l = A^-1 (p - c) with z = -l_z. The scaled-axes shortcut,
    exact only for orthogonal axes, put the cone elsewhere (outside review against Cycles: 1,457 of
    6,912 pixels differed; the inverse matched Cycles' mask up to the edge pixels)."""
    size, c = np.radians(40), np.array([0.0, 0.0, 2.0])
    parent = np.diag([2.5, 1.0, 1.0])
    ry, rz = np.radians(30), np.radians(40)
    rot_y = np.array([[np.cos(ry), 0, np.sin(ry)], [0, 1, 0], [-np.sin(ry), 0, np.cos(ry)]])
    rot_z = np.array([[np.cos(rz), -np.sin(rz), 0], [np.sin(rz), np.cos(rz), 0], [0, 0, 1]])
    axes = parent @ rot_z @ rot_y  # Blender's XYZ Euler (0, 30, 40) under the parent's scale
    assert abs(np.dot(axes[:, 0], axes[:, 2])) > 0.1  # really sheared
    direction = -axes[:, 2] / np.linalg.norm(axes[:, 2])
    tree = core.build_kdtree(floor(0.0))
    camera = look_down((0.0, 0.0, 4.0), fov=1.6)
    spot = core.Light.spot(c, direction, spot_size=size, spot_blend=0.0, axes=axes)
    img = core.render_preview(tree, camera, 64, 64, samples=1, mode="shadow", lights=[spot])
    o, d, _, _ = camera.rays(64, 64)
    local = (o + 4.0 * d - c) @ np.linalg.inv(axes).T
    margin = -local[:, 2] / np.linalg.norm(local, axis=1) - np.cos(size / 2)
    lit = img[..., 0].ravel() > 0
    assert (lit[margin > 1e-9] == 1).all() and (lit[margin < -1e-9] == 0).all()
    assert 50 < lit.sum() < 64 * 64 - 50


def test_spot_axes_must_match_the_direction():
    with pytest.raises(ValueError, match="minus the Z axis"):
        core.Light.spot((0, 0, 2), (0, 0, -1.0), spot_size=1.0, axes=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="zero-length axis"):
        core.Light.spot((0, 0, 2), (0, 0, -1.0), spot_size=1.0, axes=np.diag([0.0, 1.0, 1.0]))


def moved_up(z):
    m = np.eye(4)
    m[2, 3] = z
    return m


@pytest.mark.parametrize("make", [lambda **k: core.Light.sun((0.3, 0.0, -1.0), **k),
                                  lambda **k: core.Light.point((0.5, 0.0, 3.0), **k),
                                  lambda **k: core.Light.spot((0.5, 0, 3.0), (0, 0, -1.0), spot_size=3.0, **k),
                                  lambda **k: core.Light.area(moved_up(3.0), size=1.0, **k)])
def test_light_without_shadows_lights_the_occluded_floor(make):
    """Blender's Cast Shadow off: the floor under a large occluder gets N.L as if nothing were
    there (and no shadow ray is traced), while the same light with shadows leaves it dark."""
    tris = np.concatenate([floor(0.0), floor(1.0, half=0.6)])
    camera = look_down((0.0, 0.0, 0.5), fov=0.5)
    shadowed = render(tris, camera, size=16, samples=4, mode="shadow", lights=[make()])
    r = core.PreviewRender(core.build_kdtree(tris), camera, 16, 16, samples=4, mode="shadow",
                           lights=[make(cast_shadow=False)])
    r.step(4)
    assert (shadowed[..., :3] == 0).all()
    assert r.rays_traced == r.camera_rays
    open_floor = render(floor(0.0), camera, size=16, samples=4, mode="shadow", lights=[make()])
    np.testing.assert_array_equal(r.image(), open_floor)


@pytest.mark.parametrize("light, no_extent", [
    (core.Light.point((0.5, 0.0, 3.0)), True), (core.Light.point((0.5, 0.0, 3.0), radius=0.3), False),
    (core.Light.sun((0.3, 0.0, -1.0)), True), (core.Light.sun((0.3, 0.0, -1.0), angle=1e-9), True),
    (core.Light.sun((0.3, 0.0, -1.0), angle=0.2), False),
    (core.Light.spot((0.5, 0, 3.0), (0, 0, -1.0), spot_size=3.0), True),
    (core.Light.spot((0.5, 0, 3.0), (0, 0, -1.0), spot_size=3.0, radius=0.3), False),
    (core.Light.area(moved_up(3.0), size=1.0), False)])
def test_a_light_without_extent_draws_no_sample_numbers_and_loses_nothing(light, no_extent):
    """Points and spots of radius 0 and suns whose half angle's cosine rounds to 1 are flagged: their
    shadow rays skip the sampler. The flag must be set exactly where the sample numbers do not move
    the ray: the same render with the flag cleared (every sample drawn) is bit-identical."""
    tris = np.concatenate([floor(0.0), floor(1.0, half=0.3)])
    camera = look_down((0.0, 0.0, 0.5), fov=1.2)
    tree = core.build_kdtree(tris)
    flagged, drawn = (core.PreviewRender(tree, camera, 24, 24, samples=8, mode="ao+shadow", lights=[light])
                      for _ in range(2))
    assert flagged.lights[0, DELTA] == float(no_extent)
    drawn.lights[:, DELTA] = 0.0
    flagged.step(8)
    drawn.step(8)
    np.testing.assert_array_equal(flagged.image(), drawn.image())
    assert 0.0 < flagged.image()[..., 0][hit_mask(flagged.image())].mean() < 1.0  # lit and shadowed pixels


def test_a_hard_light_is_traced_once_a_pixel_and_its_samples_repeat_it():
    """A light without extent gives every sample the same shadow ray: sample 0 traces it, later
    samples repeat its bit, whether the samples come one step at a time (as the add-on takes them) or
    in one batch. The image is bit-identical to tracing every sample (the flag cleared); the count of
    rays is one shadow ray a pixel, which frame_ray_count tells the builder; an error target's saved
    rays still add up to the full render's."""
    tris = np.concatenate([floor(0.0), floor(1.0, half=0.3)])
    camera = look_down((0.0, 0.0, 0.5), fov=1.2)
    tree = core.build_kdtree(tris)
    hard = core.Light.point((0.5, 0.0, 3.0))
    settings = dict(samples=8, mode="ao+shadow", lights=[hard], ao_distance=0.3)
    stepped, drawn = (core.PreviewRender(tree, camera, 24, 24, **settings) for _ in range(2))
    drawn.lights[:, DELTA] = 0.0
    for _ in range(8):
        stepped.step(1)
    drawn.step(8)
    np.testing.assert_array_equal(stepped.image(), drawn.image())
    pixels = 24 * 24
    assert hit_mask(stepped.image()).all()  # every pixel hits the floor, which faces the light
    assert drawn.rays_traced == pixels * (1 + 8 * 2)
    assert stepped.rays_traced == pixels * (1 + 8 + 1) == core.frame_ray_count(24, 24, **{
        k: settings[k] for k in ("mode", "samples", "lights")})
    full = core.PreviewRender(tree, camera, 24, 24, **{**settings, "samples": 64})
    full.step(64)
    capped = core.PreviewRender(tree, camera, 24, 24, **{**settings, "samples": 64}, error_target=0.05)
    capped.step(64)
    assert capped.rays_saved > 0
    assert capped.rays_traced + capped.rays_saved == full.rays_traced


def test_background_is_transparent_and_alpha_marks_hits():
    tris = quad((0, 0, 0), (0.5, 0, 0), (0, 0.5, 0))
    camera = look_down((0.0, 0.0, 2.0), fov=1.0)
    tree = core.build_kdtree(tris)
    r = core.PreviewRender(tree, camera, 32, 32, samples=4)
    r.step(4)
    img = r.image()
    o, d, _, _ = camera.rays(32, 32)
    p = o + 2.0 * d
    inside = ((np.abs(p[:, 0]) < 0.5) & (np.abs(p[:, 1]) < 0.5)).reshape(32, 32)
    np.testing.assert_array_equal(hit_mask(img), inside)
    assert (img[~inside] == 0).all()
    assert r.rays_traced == 32 * 32 + 4 * inside.sum()  # no secondary rays for background pixels


def test_image_orientation_row_zero_is_top():
    """A quad above the image centre (+Y in camera space) appears in the top rows."""
    tris = quad((0, 0.4, 0), (0.3, 0, 0), (0, 0.1, 0))
    img = render(tris, look_down((0.0, 0.0, 2.0), fov=1.0), size=20, samples=1)
    rows = np.flatnonzero(hit_mask(img).any(axis=1))
    assert rows.max() < 10


@pytest.mark.parametrize("width, height", [(1, 1), (13, 7), (8, 16), (33, 9)])
def test_tiled_pixel_order_covers_every_pixel_once_tile_by_tile(width, height):
    order = tiled_pixels(width, height, tile=8)
    np.testing.assert_array_equal(np.sort(order), np.arange(width * height))
    rows, cols = order // width, order % width
    tile = (rows // 8) * ((width + 7) // 8) + cols // 8
    assert (np.diff(tile) >= 0).all()  # tile by tile
    within = np.diff(rows * width + cols)[np.diff(tile) == 0]
    assert (within > 0).all()  # row-major inside a tile
    camera = look_at((1.0, -2.0, 1.5), (0.0, 0.0, 0.0))
    everything = camera.rays(width, height)
    for full, subset in zip(everything, camera.rays(width, height, order)):
        np.testing.assert_array_equal(subset, full[order])
    for bad in ([width * height], [-1], [[0]], [0.5]):
        with pytest.raises(ValueError, match="camera pixels"):
            camera.rays(width, height, bad)


def test_the_order_pixels_are_traced_in_does_not_change_the_image(monkeypatch):
    """The renderer traces pixels tile by tile; rows (the plain order) give the same image, bit for bit,
    at a size that is no multiple of the tile, in every mode."""
    tris = np.concatenate([floor(half=3.0), quad((0.2, 0.1, 0.6), (0.5, 0, 0), (0, 0.4, 0.1))])
    tree = core.build_kdtree(tris)
    camera = look_at((2.0, -3.0, 2.5), (0.0, 0.0, 0.3))
    lights = [core.Light.point((1.0, -1.0, 3.0), radius=0.3)]
    images = {}
    for order in ("tiles", "rows"):
        if order == "rows":
            monkeypatch.setattr(core.render.preview_render, "tiled_pixels", lambda w, h: np.arange(w * h))
        images[order] = [core.render_preview(tree, camera, 37, 23, samples=4, mode=mode, lights=lights)
                         for mode in ("ao", "shadow", "ao+shadow")]
    for tiled, plain in zip(images["tiles"], images["rows"]):
        assert hit_mask(tiled).any() and not hit_mask(tiled).all()
        np.testing.assert_array_equal(tiled, plain)


def test_orthographic_camera_sees_parallel_projection():
    tris = quad((0, 0, 0), (0.25, 0, 0), (0, 0.25, 0))
    m = np.eye(4)
    m[:3, 3] = (0, 0, 5.0)
    img = render(tris, core.Camera(m, ortho_scale=1.0), size=40, samples=1)
    assert hit_mask(img).sum() == 20 * 20  # exactly half the width and height


def test_lens_shift_moves_the_image_plane():
    """Shift is measured in the larger image extent (Blender's shift_x/shift_y with sensor fit AUTO).
    Orthographic: a shift of (0.25, 0.25) of a 1-unit view moves the quad [0, 0.25]^2 from the upper
    right quarter's corner to columns 10-19, rows 20-29 of a 40-pixel image. Perspective: the shifted
    camera's rays are a window of the rays of a wider unshifted camera with the same pixel size."""
    tris = quad((0.125, 0.125, 0), (0.125, 0, 0), (0, 0.125, 0))
    m = np.eye(4)
    m[:3, 3] = (0, 0, 5.0)
    img = render(tris, core.Camera(m, ortho_scale=1.0, shift=(0.25, 0.25)), size=40, samples=1)
    expected = np.zeros((40, 40), bool)
    expected[20:30, 10:20] = True
    np.testing.assert_array_equal(hit_mask(img), expected)

    shifted = core.Camera(m, 2 * np.arctan(1.0), shift=(0.25, -0.125)).rays(40, 30)  # plane x in [-0.5, 1.5]
    wide = core.Camera(m, 2 * np.arctan(2.0)).rays(80, 80)  # the same pixel size, 0.05
    _, d_wide = (a.reshape(80, 80, 3) for a in wide[:2])
    window = d_wide[40 - 15 + 5:40 + 15 + 5, 30:70]  # rows of y in [-1, 0.5], columns of x in [-0.5, 1.5]
    np.testing.assert_allclose(shifted[1].reshape(30, 40, 3), window, atol=1e-12)
    with pytest.raises(ValueError, match="shift"):
        core.Camera(m, 1.0, shift=(np.nan, 0.0))


def test_pixel_aspect_stretches_the_image_plane_as_blender_does():
    """A pixel twice as tall as wide: a 40 x 20 image spans 40 by 40 pixel widths, a square, so the view
    extent is the fov's in both directions and a pixel covers twice the height of a square pixel's
    (Blender compares width and height times pixel aspect). Its rays are every other row of a square
    camera's 40 x 40, taken at the rows' middle. Taller than wide in that extent, the fov goes to y."""
    m = np.eye(4)
    m[:3, 3] = (0, 0, 5.0)
    fov = 2 * np.arctan(0.5)
    tall_pixels = core.Camera(m, fov, pixel_aspect=2.0)
    assert tall_pixels.image_plane(40, 20) == pytest.approx((-0.5, 0.5, -0.5, 0.5))
    _, d_square = core.Camera(m, fov).rays(40, 40)[:2]
    d_square = d_square.reshape(40, 40, 3)
    expected = (d_square[0::2] + d_square[1::2]) / 2  # pixel row i spans square rows 2i and 2i + 1
    np.testing.assert_allclose(tall_pixels.rays(40, 20)[1].reshape(20, 40, 3), expected, atol=1e-12)
    assert core.Camera(m, fov, pixel_aspect=4.0).image_plane(40, 20) == pytest.approx((-0.25, 0.25, -0.5, 0.5))
    assert core.Camera(m, ortho_scale=2.0, pixel_aspect=0.5).image_plane(40, 40) == pytest.approx((-1, 1, -0.5, 0.5))
    for bad in (0.0, -1.0, np.nan, np.inf, "2"):
        with pytest.raises(ValueError, match="pixel_aspect"):
            core.Camera(m, fov, pixel_aspect=bad)


def test_bad_settings_are_named():
    tree = core.build_kdtree(floor(0.0))
    cam = look_down((0, 0, 1.0))
    for kwargs, word in [({"mode": "x"}, "mode"), ({"samples": 0}, "samples"), ({"ao_distance": -1}, "ao_distance"),
                         ({"sampler": "halton"}, "sampler"), ({"error_target": 0}, "error_target"),
                         ({"mode": "shadow"}, "light")]:
        with pytest.raises(ValueError, match=word):
            core.render_preview(tree, cam, 8, 8, **kwargs)
    with pytest.raises(ValueError, match="width"):
        core.render_preview(tree, cam, 0, 8)
    with pytest.raises(ValueError, match="fov"):
        core.Camera(np.eye(4), fov=4.0)


def test_sun_of_blenders_largest_angle_lights_a_floor_by_half():
    """Blender allows a sun angle of 180 degrees: directions uniform over the hemisphere around the
    sun's axis. Pointing straight down on a bare floor, the mean of N.L over that hemisphere is 1/2."""
    tree = core.build_kdtree(floor(0.0))
    sun = core.Light.sun((0.0, 0.0, -1.0), angle=np.pi)
    img = core.render_preview(tree, look_down((0.0, 0.0, 1.0)), 16, 16, samples=1024, mode="shadow", lights=[sun])
    assert hit_mask(img).all()
    assert img[..., 0].mean() == pytest.approx(0.5, abs=0.005)
    with pytest.raises(ValueError, match="sun angle must be <= pi"):
        core.Light.sun((0.0, 0.0, -1.0), angle=3.2)


@pytest.mark.parametrize("spread_degrees", [10.0, 60.0, 120.0])
def test_an_area_lights_spread_narrows_it_as_cycles_soft_box_does(spread_degrees):
    """A tiny area light at height h over a bare floor, Spread s: light leaving it at angle a from
    its normal is weighted max(0, 1 - tan a / tan(s/2)) (Cycles' soft-box grid, normalised to 1 along
    the normal), so a floor point at distance r from its foot gets N.L times that, a = atan(r / h).
    With Spread 180 degrees (the default) it is N.L alone. (Outside QA: a 10-degree spread lit the
    whole floor, where Cycles lights a spot.)"""
    h, spread = 2.0, np.radians(spread_degrees)
    tree = core.build_kdtree(floor(0.0))
    camera = look_down((0.0, 0.0, 3.0), fov=1.6)
    size = 32
    o, d, _, _ = camera.rays(size, size)
    p = o + 3.0 * d
    tan_a = np.hypot(p[:, 0], p[:, 1]) / h
    n_dot_l = 1.0 / np.sqrt(1.0 + tan_a * tan_a)
    for angle, weight in [(spread, np.maximum(0.0, 1.0 - tan_a / np.tan(spread / 2.0))), (np.pi, 1.0)]:
        light = core.Light.area(moved_up(h), size=1e-4, spread=angle)
        img = core.render_preview(tree, camera, size, size, samples=4, mode="shadow", lights=[light])
        np.testing.assert_allclose(img[..., 0].ravel(), n_dot_l * weight, atol=2e-4)
    assert (img[..., 0] > 0).all()  # at 180 degrees every floor point is lit


def test_an_area_lights_spread_is_checked():
    for bad in (-0.1, 3.2, np.nan):
        with pytest.raises(ValueError, match="area light spread"):
            core.Light.area(np.eye(4), size=1.0, spread=bad)
    core.Light.area(np.eye(4), size=1.0, spread=float(np.float32(np.pi)))  # Blender's 180 degrees


def test_area_light_with_a_zero_scale_axis_is_named():
    for axis in range(3):
        m = np.eye(4)
        m[axis, axis] = 0.0
        with pytest.raises(ValueError, match=f"zero {'XYZ'[axis]} axis"):
            core.Light.area(m, size=1.0)


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
    2^-32 of max |p_k| rose 1.2e-4 at x = 5e5, above the roof (outside QA: fully lit, AO 1). Shadow 0
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
    the origin), in both layouts, with the ray starts offset by surface_error_scale."""
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
    the plane and the tiny neighbours caught them (outside review: AO 0.53-0.70). AO exactly 1."""
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
    hit point's magnitude alone let AO rays hit the floor they left (outside QA: AO 0.83-0.87 for
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
    the box (outside QA: dark speckles from length 3e4 on, in the world-space tree). "flat" puts the
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
