"""The renderer against cases with a known answer: ambient occlusion, the camera and the image."""
import numpy as np
import pytest

import core
from core.render.camera import tiled_pixels
from core.trace.packet_traversal import L, TILE_SHAPE
from tests.render_scenes import floor, hit_mask, look_at, look_down, quad, render


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
    bw, bh = TILE_SHAPE
    block = tile * 64 + ((rows % 8) // bh) * (8 // bw) + (cols % 8) // bw
    assert (np.diff(block) >= 0).all()  # packet block by packet block inside a tile, row-major
    within = np.diff(rows * width + cols)[np.diff(block) == 0]
    assert (within > 0).all()  # row-major inside a block
    for first in np.flatnonzero(np.r_[True, np.diff(block) != 0]):  # a whole block's pixels are L in a row
        whole = (rows[first] // 8 * 8 + 8 <= height) and (cols[first] // 8 * 8 + 8 <= width)
        if whole:
            x, y = cols[first:first + L], rows[first:first + L]
            assert x.max() - x.min() == bw - 1 and y.max() - y.min() == bh - 1
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
