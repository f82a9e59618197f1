"""The renderer's lights against cases with a known answer: falloff, cones, areas, suns, shadows."""
import numpy as np
import pytest

import core
from core.render.lights import DELTA, POINT
from core.scene.two_level import build_two_level
from tests.render_scenes import box, floor, hit_mask, look_at, look_down, quad, render


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
    """A light lying on a surface's plane must not be blocked by it (every shadow ray would end where
    the surface is met, within rounding, and a room come out black). The ray stops a step short of
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
    exact only for orthogonal axes, puts the cone elsewhere (checked against Cycles: 1,457 of
    6,912 pixels differ; the inverse matches Cycles' mask up to the edge pixels)."""
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


def test_sun_of_blenders_largest_angle_lights_a_floor_by_half():
    """Blender allows a sun angle of 180 degrees: directions uniform over the hemisphere around the
    sun's axis. Pointing straight down on a bare floor, the mean of N.L over that hemisphere is 1/2."""
    tree = core.build_kdtree(floor(0.0))
    sun = core.Light.sun((0.0, 0.0, -1.0), angle=np.pi)
    img = core.render_preview(tree, look_down((0.0, 0.0, 1.0)), 16, 16, samples=1024, mode="shadow", lights=[sun])
    assert hit_mask(img).all()
    assert img[..., 0].mean() == pytest.approx(0.5, abs=0.005)
    with pytest.raises(ValueError, match="sun angle must be at most pi"):
        core.Light.sun((0.0, 0.0, -1.0), angle=3.2)


def test_a_light_of_power_zero_emits_nothing():
    """The preview does not weight power, but a light of power 0 emits nothing (as Blender's does), as a
    black one: alone it leaves the shadow term 0; beside another light it changes nothing, where counted
    in the lights' mean it would halve the term."""
    tree = core.build_kdtree(floor(0.0))
    camera = look_down((0.0, 0.0, 3.0), fov=1.6)
    lit = core.Light.point((0.0, 0.0, 2.0))
    lit_only = core.render_preview(tree, camera, 16, 16, samples=1, mode="shadow", lights=[lit])
    assert hit_mask(lit_only).all() and lit_only[..., 0].min() > 0.0
    for dark in (core.Light.point((0.5, 0.0, 2.0), power=0.0), core.Light.sun((0, 0, -1), color=(0, 0, 0))):
        alone, beside = (core.render_preview(tree, camera, 16, 16, samples=1, mode="shadow", lights=lights)
                         for lights in ([dark], [dark, lit]))
        assert hit_mask(alone).all() and (alone[..., :3] == 0.0).all()
        np.testing.assert_array_equal(beside, lit_only)


def test_spot_of_blenders_largest_size_lights_what_a_point_light_does():
    """Blender's largest Spot Size, 180 degrees, is stored as float32 pi, a hair above np.pi. Pointing
    down from above a floor with no blend, its cone holds the whole lower half-space: every floor pixel
    gets what a point light at the same place gives it."""
    tree = core.build_kdtree(floor(0.0))
    camera = look_down((0.0, 0.0, 3.0), fov=1.6)
    largest = float(np.float32(np.pi))
    assert largest > np.pi
    spot = core.Light.spot((0.0, 0.0, 2.0), (0.0, 0.0, -1.0), spot_size=largest, spot_blend=0.0)
    point = core.Light.point((0.0, 0.0, 2.0))
    images = [core.render_preview(tree, camera, 16, 16, samples=1, mode="shadow", lights=[light])
              for light in (spot, point)]
    assert hit_mask(images[1]).all() and images[1][..., 0].min() > 0.0
    np.testing.assert_allclose(images[0], images[1], rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="spot_size must be at most pi"):
        core.Light.spot((0.0, 0.0, 2.0), (0.0, 0.0, -1.0), spot_size=3.2)
    with pytest.raises(ValueError, match="spot_size must be finite and > 0"):
        core.Light.spot((0.0, 0.0, 2.0), (0.0, 0.0, -1.0), spot_size=0.0)


@pytest.mark.parametrize("spread_degrees", [10.0, 60.0, 120.0])
def test_an_area_lights_spread_narrows_it_as_cycles_soft_box_does(spread_degrees):
    """A tiny area light at height h over a bare floor, Spread s: light leaving it at angle a from
    its normal is weighted max(0, 1 - tan a / tan(s/2)) (Cycles' soft-box grid, normalised to 1 along
    the normal), so a floor point at distance r from its foot gets N.L times that, a = atan(r / h).
    With Spread 180 degrees (the default) it is N.L alone. (Checked against Cycles: a 10-degree spread
    lights a spot, not the whole floor.)"""
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


def _hard_shadow_scene():
    """A floor, and a box and a slanted roof over it casting shadows, whose sides the camera sees facing
    away from some lights: lit, shadowed and unlit pixels (two parts, for the two-instance scene)."""
    roof = np.array([[[-0.9, -0.2, 0.0], [-0.3, -0.2, 0.6], [-0.3, 0.5, 0.6]],
                     [[-0.3, -0.2, 0.6], [0.2, -0.2, 0.0], [0.2, 0.5, 0.0]]])
    return floor(0.0, half=2.0), np.concatenate([box((0.4, 0.3, 0.3), (0.2, 0.25, 0.3)), roof])


@pytest.mark.parametrize("mode", ["ao", "shadow", "ao+shadow"])
@pytest.mark.parametrize("lights", [
    [core.Light.point((-0.6, 1.5, 1.5))],
    [core.Light.sun((0.3, -0.6, -1.0))],
    [core.Light.spot((0.3, 1.2, 2.0), (-0.1, -0.3, -1.0), spot_size=0.9)],
    [core.Light.area(moved_up(2.0), size=0.5), core.Light.point((-0.6, 1.5, 1.5), color=(0.5, 1.0, 0.25))]],
    ids=["point", "sun", "spot", "area+point"])
def test_the_hard_shadow_pass_gives_the_images_of_single_shadow_rays(mode, lights):
    """A flat tree's lights without extent have their shadow rays traced in packets before the first
    sample (PreviewRender._trace_hard_shadows: only the rays of pixels facing the light, read in place).
    A two-instance scene takes that pass through its instances one at a time (instance_packets.py) with
    the same answers; the flat tree with the lights' flag cleared does not (every sample traces its own
    ray): all three images are bit-identical, in every mode, with lit, shadowed and unlit pixels."""
    ground, objects = _hard_shadow_scene()
    camera = look_at((0.3, -2.2, 2.4), (0.0, 0.1, 0.2), fov=1.0)
    settings = dict(samples=4, mode=mode, lights=lights, ao_distance=0.5)
    flat = core.PreviewRender(core.build_kdtree(np.concatenate([ground, objects])), camera, 32, 24, **settings)
    drawn = core.PreviewRender(core.build_kdtree(np.concatenate([ground, objects])), camera, 32, 24, **settings)
    drawn.lights[:, DELTA] = 0.0
    two = build_two_level([core.build_kdtree(ground), core.build_kdtree(objects)], np.arange(2, dtype=np.int32),
                          np.stack([np.eye(4)] * 2))
    separate = core.PreviewRender(two, camera, 32, 24, **settings)
    for render in (flat, drawn, separate):
        render.step(4)
    np.testing.assert_array_equal(flat.image(), separate.image())
    np.testing.assert_array_equal(flat.image(), drawn.image())
    if "shadow" in mode:  # the last light is the one without extent
        pretraced = flat.pretraced[:, -1]
        assert (pretraced == 1).any() and (pretraced == 0).any() and (pretraced == -1).any()  # -1: no ray
        np.testing.assert_array_equal(separate.pretraced, flat.pretraced)
        assert (drawn.pretraced == -1).all()
        weights = flat.pretraced_weights[:, -1]  # what the sampling kernel takes instead of making the ray
        assert (weights[pretraced >= 0] > 0.0).all() and (weights[pretraced == -1] == 0.0).all()
        np.testing.assert_array_equal(separate.pretraced_weights, flat.pretraced_weights)
        assert drawn.pretraced_weights.shape[0] == 0
        if lights[-1].kind == POINT:  # cos(N, L) towards the light's position: an independent weight
            towards = lights[-1].params["position"] - flat.points
            cosine = (flat.normals * towards).sum(axis=1) / np.linalg.norm(towards, axis=1)
            np.testing.assert_allclose(weights, np.maximum(cosine, 0.0), rtol=1e-9, atol=1e-12)
