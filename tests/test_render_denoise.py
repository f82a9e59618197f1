"""The edge-avoiding à-trous denoiser (core/render/denoise.py): it removes noise, keeps edges, never touches the
background, does not care about the scene's scale, and fails on no corner case."""
import numpy as np
import pytest

import core
from core.render.denoise import SOBOL_VARIANCE_DECAY
from tests.render_scenes import floor, hit_mask, look_at, look_down, quad


def box_on_floor(scale=1.0):
    """A unit box standing on a floor: occlusion darkens the floor around it and its lower sides."""
    s = scale
    tris = [floor(0.0, half=20 * s)]
    for axis in range(3):
        for sign in (-1.0, 1.0):
            c = np.zeros(3)
            c[axis] = sign * 0.5 * s
            c[2] += 0.5 * s
            u, v = np.zeros(3), np.zeros(3)
            u[(axis + 1) % 3], v[(axis + 2) % 3] = 0.5 * s, 0.5 * s
            tris.append(quad(c, u, v))
    return np.concatenate(tris)


def box_camera(scale=1.0):
    return look_at((2.2 * scale, -1.7 * scale, 1.9 * scale), (0.0, 0.0, 0.3 * scale), fov=0.9)


def box_render(samples, scale=1.0, size=48, sampler="sobol", seed=0):
    tree = core.build_kdtree(box_on_floor(scale))
    r = core.PreviewRender(tree, box_camera(scale), size, size, samples=samples, ao_distance=1.0 * scale,
                           sampler=sampler, seed=seed)
    r.step(samples)
    return r


def rmse(img, ref):
    mask = hit_mask(ref)
    return float(np.sqrt(np.mean((img[..., 0][mask] - ref[..., 0][mask]) ** 2)))


def test_constant_image_stays_constant_and_background_stays_zero():
    """A floating square with nothing near it: AO is exactly 1 on every hit pixel, so the filter (a
    weighted mean) must give 1, and the background around the square must neither change nor bleed in."""
    tree = core.build_kdtree(quad((0, 0, 0), (0.5, 0, 0), (0, 0.5, 0)))
    r = core.PreviewRender(tree, look_down((0.1, 0.0, 2.0), fov=1.0), 32, 32, samples=4)
    r.step(4)
    raw, den = r.image(), r.image(denoise=True)
    assert den.dtype == np.float32 and den.shape == raw.shape
    mask = hit_mask(raw)
    assert 0 < mask.sum() < mask.size
    np.testing.assert_array_equal(den[..., 3], raw[..., 3])
    assert (den[~mask] == 0).all()
    np.testing.assert_allclose(den[mask][:, :3], 1.0, rtol=0, atol=1e-6)


@pytest.fixture(scope="module")
def box_reference():
    return box_render(2048).image()


def test_noisy_render_gets_much_closer_to_the_converged_one(box_reference):
    for samples, sampler in ((1, "sobol"), (4, "sobol"), (4, "random"), (16, "random")):
        r = box_render(samples, sampler=sampler, seed=7)
        before, after = rmse(r.image(), box_reference), rmse(r.image(denoise=True), box_reference)
        assert after < 0.6 * before, (samples, sampler, before, after)


@pytest.mark.parametrize("sampler", ["sobol", "random"])
def test_converged_image_is_not_made_worse(sampler, box_reference):
    """The luminance weight allows a few standard errors of difference, and those shrink with the sample
    count: the filter fades out as the image converges. Measured (box scene, 256 spp, against 4096):
    Sobol RMSE 0.0034 raw, 0.0038 denoised; the bound leaves room for the reference's own noise."""
    r = box_render(256, sampler=sampler, seed=5)
    raw, den = rmse(r.image(), box_reference), rmse(r.image(denoise=True), box_reference)
    assert den < 1.3 * raw + 5e-4, (raw, den)
    worst_raw = np.abs(r.image() - box_reference).max()
    assert np.abs(r.image(denoise=True) - box_reference).max() < worst_raw + 0.01


def _two_region_case(right_depth, right_normal, n=4, size=32, seed=1):
    """Synthetic accumulators: a pinhole view of the left half of the image on a plane at depth 1 facing
    the camera with AO 0.2, the right half at `right_depth` facing `right_normal` with AO 0.9, each
    pixel n Bernoulli samples."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:size, 0:size]
    u, v = (xs.ravel() + 0.5) / size - 0.5, 0.5 - (ys.ravel() + 0.5) / size
    right = xs.ravel() >= size // 2
    depth = np.where(right, right_depth, 1.0)
    points = np.stack([u * depth, v * depth, -depth], axis=1)
    normals = np.where(right[:, None], np.asarray(right_normal, float)[None], np.array([[0.0, 0.0, 1.0]]))
    p_true = np.where(right, 0.9, 0.2)
    hits = rng.binomial(n, p_true).astype(np.float64)
    sums = np.repeat(hits[:, None], 3, axis=1)
    counts = np.full(size * size, n, np.int64)
    pixels = np.arange(size * size, dtype=np.int64)
    img = core.denoise_pixels(size, size, pixels, points, normals, sums, hits, counts)
    return img[..., 0], right.reshape(size, size)


@pytest.mark.parametrize("right_depth, right_normal", [(100.0, (0.0, 0.0, 1.0)), (1.0, (1.0, 0.0, 0.0)),
                                                       (1e-3, (0.0, 0.0, 1.0))])
def test_surfaces_at_other_depths_or_facing_elsewhere_are_not_blended(right_depth, right_normal):
    img, right = _two_region_case(right_depth, right_normal)
    left_edge, right_edge = img[:, right.shape[1] // 2 - 1], img[:, right.shape[1] // 2]
    assert left_edge.mean() == pytest.approx(0.2, abs=0.06)
    assert right_edge.mean() == pytest.approx(0.9, abs=0.06)
    assert img[~right].mean() == pytest.approx(0.2, abs=0.03)
    assert img[right].mean() == pytest.approx(0.9, abs=0.03)


def test_the_edge_test_is_sensitive():
    """Control for the test above: the same values on one continuous plane do get blended at the seam
    (only the luminance weight separates them, and at 4 samples it lets some through)."""
    img, right = _two_region_case(1.0, (0.0, 0.0, 1.0))
    left_edge = img[:, right.shape[1] // 2 - 1]
    assert left_edge.mean() > 0.3


def test_deterministic_and_independent_of_thread_count():
    r = box_render(2, size=40)
    a, b = r.image(denoise=True), r.image(denoise=True)
    np.testing.assert_array_equal(a, b)
    c = core.denoise_pixels(r.width, r.height, r.pixels, r.points, r.normals, r.sums, r.sq_sums, r.counts,
                            variance_decay=SOBOL_VARIANCE_DECAY, threads=1)
    np.testing.assert_array_equal(a, c)


@pytest.mark.parametrize("scale", [1e-3, 1e3, 1e4])
def test_filter_is_scale_invariant(scale):
    """The same accumulators with every hit point scaled give the same image (weights compare lengths
    with the pixel footprint only), also moved far from the origin."""
    r = box_render(2, size=40)
    base = r.image(denoise=True)
    for offset in (0.0, 1e3 * scale):
        img = core.denoise_pixels(r.width, r.height, r.pixels, r.points * scale + offset, r.normals, r.sums,
                                  r.sq_sums, r.counts, variance_decay=SOBOL_VARIANCE_DECAY)
        np.testing.assert_allclose(img, base, rtol=0, atol=1e-5)


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_scaled_scene_renders_the_same_denoised_image(scale):
    """End to end: scene, camera and AO distance scaled together. The raw images agree up to the odd
    sample that tracing at another scale rounds differently; the denoised ones agree as closely."""
    a, b = box_render(4, size=40), box_render(4, scale=scale, size=40)
    raw_diff = np.abs(a.image() - b.image()).mean()
    den_diff = np.abs(a.image(denoise=True) - b.image(denoise=True)).mean()
    assert raw_diff < 2e-3 and den_diff < 2e-3, (raw_diff, den_diff)


def test_corner_cases_give_no_nan():
    tree = core.build_kdtree(floor(0.0))
    for size in ((1, 1), (1, 7), (5, 1)):  # 1-pixel images and strips, all hits
        img = core.render_preview(tree, look_down((0, 0, 2.0)), *size, samples=2, denoise=True)
        assert np.isfinite(img).all() and (img[..., 0] == 1.0).all()
    # one hit pixel in an otherwise empty image (a tiny square straight below the centre pixel)
    tiny = core.build_kdtree(quad((0, 0, 0), (1e-3, 0, 0), (0, 1e-3, 0)))
    r = core.PreviewRender(tiny, look_down((0, 0, 2.0), fov=0.5), 5, 5, samples=2)
    r.step(2)
    assert r.hit_pixels == 1
    np.testing.assert_array_equal(r.image(denoise=True), r.image())
    # nothing hit at all
    empty = core.PreviewRender(tiny, look_down((5, 5, 2.0)), 4, 4, samples=1)
    empty.step(1)
    assert empty.hit_pixels == 0 and (empty.image(denoise=True) == 0).all()
    # before any sample: hit pixels have alpha 1 and value 0, as in the raw image
    fresh = core.PreviewRender(tree, look_down((0, 0, 2.0)), 6, 6, samples=4)
    np.testing.assert_array_equal(fresh.image(denoise=True), fresh.image())


def test_zero_variance_pixels_next_to_noisy_ones():
    """Shadow mode under a sun: lit floor samples are all exactly equal (zero variance), the box's
    penumbra is noisy; no NaN, lit pixels unchanged, background zero."""
    tree = core.build_kdtree(box_on_floor())
    sun = core.Light.sun((0.3, 0.2, -1.0), angle=0.2)
    r = core.PreviewRender(tree, box_camera(), 40, 40, samples=4, mode="shadow", lights=[sun])
    r.step(4)
    raw, den = r.image(), r.image(denoise=True)
    assert np.isfinite(den).all()
    lit = r.sq_sums * r.counts == r.sums.mean(axis=1) ** 2  # every sample the same value
    assert lit.any()
    rgb = den.reshape(-1, 4)[r.pixels, :3]
    assert (rgb >= 0).all() and (rgb <= 1 + 1e-6).all()
    np.testing.assert_array_equal(den[..., 3], raw[..., 3])
