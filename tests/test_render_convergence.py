"""The error target (core/render/convergence.py): its standard-error estimate against a brute-force one,
stopped pixels holding exactly the fixed render's estimate at their sample count, and the adaptive image
against analytic AO and a converged reference: unbiased, stopped pixels within the target."""
import numpy as np
import pytest

import core
from core.render.convergence import checks, is_check, next_check, sample_variances, standard_errors
from tests.render_scenes import floor, hit_mask, look_at, look_down
from tests.test_render_reference import boxes_on_floor


def brute_force_errors(width, height, pixels, sums, sq_sums, counts, decay):
    """convergence.standard_errors written out pixel by pixel from its definition."""
    where = {int(p): i for i, p in enumerate(pixels)}
    out = np.empty(len(pixels))
    own = np.zeros(len(pixels))
    for i in range(len(pixels)):
        n = counts[i]
        if n >= 2:
            mean = sums[i].mean() / n
            own[i] = max(sq_sums[i] / n - mean * mean, 0.0) * n / (n - 1)
    for i, p in enumerate(pixels):
        y, x = divmod(int(p), width)
        pooled, sampled, samples = 0.0, 0, 0
        for yy in range(y - 2, y + 3):
            for xx in range(x - 2, x + 3):
                j = where.get(yy * width + xx) if 0 <= yy < height and 0 <= xx < width else None
                if j is not None:
                    pooled += own[j]
                    sampled += counts[j] > 0
                    samples += counts[j]
        q = 1.0 / (samples + 2.0)
        var = max(own[i], pooled / max(sampled, 1), q * (1.0 - q))
        out[i] = np.sqrt(var / max(counts[i], 1) ** (1.0 + decay))
    return out


def test_standard_errors_match_their_definition():
    rng = np.random.default_rng(5)
    width, height = 13, 9
    pixels = np.sort(rng.choice(width * height, 80, replace=False))
    counts = rng.choice([0, 1, 4, 8, 16], len(pixels))
    values = rng.random((len(pixels), 16)) < rng.random((len(pixels), 1))  # 0/1 samples, a rate per pixel
    taken = np.arange(16) < counts[:, None]
    grey = (values & taken).sum(1).astype(np.float64)
    sums = np.repeat(grey[:, None], 3, axis=1)
    for decay in (0.0, 0.5):
        got = standard_errors(width, height, pixels, sample_variances(sums, grey.copy(), counts), counts, decay)
        np.testing.assert_allclose(got, brute_force_errors(width, height, pixels, sums, grey, counts, decay),
                                   rtol=1e-12)


def test_checks_at_powers_of_two_from_min_samples():
    assert [n for n in range(1, 70) if is_check(n, 8)] == [8, 16, 32, 64]
    assert [n for n in range(1, 40) if is_check(n, 12)] == [16, 32]
    assert [next_check(n, 8) for n in (0, 7, 8, 9, 16, 40)] == [8, 8, 16, 16, 32, 64]
    assert next_check(0, 2) == 2 and next_check(2, 2) == 4
    assert checks(8, 100) == [8, 16, 32, 64] and checks(12, 16) == [16] and checks(8, 4) == []


def test_stopped_pixels_hold_the_fixed_estimate_at_their_count():
    """Stopping changes how many samples a pixel takes, never which: every pixel's value equals the
    fixed render's at its own sample count (same sequence), so the adaptive image has no bias of its own."""
    tree = core.build_kdtree(boxes_on_floor())
    camera = look_at((1.8, -2.2, 1.6), (0.0, 0.2, 0.2))
    settings = dict(ao_distance=0.6, seed=4)
    render = core.PreviewRender(tree, camera, 32, 32, samples=64, error_target=0.03, **settings)
    while not render.done:
        render.step(5)  # batches across the checks: the same samples
    counts = render.sample_counts()
    mask = hit_mask(render.image())
    stops = set(np.unique(counts[mask]).tolist())
    assert stops > {8, 64} or len(stops) >= 3, stops
    for n in stops:
        fixed = core.render_preview(tree, camera, 32, 32, samples=n, **settings)
        at_n = mask & (counts == n)
        np.testing.assert_array_equal(render.image()[at_n], fixed[at_n])


def test_adaptive_ao_between_planes_is_unbiased():
    """Floor and ceiling d apart, ao_distance 2d: AO = (d / 2d)^2 = 0.25 at every pixel (analytic, see
    test_render_analytic). No pixel is uniform, so none may stop at min_samples; every pixel ends within
    a few targets of the analytic value and their mean carries no bias."""
    tris = np.concatenate([floor(0.0), floor(1.0)])
    target = 0.02
    render = core.PreviewRender(core.build_kdtree(tris), look_down((0.0, 0.0, 0.5)), 24, 24, samples=256,
                                ao_distance=2.0, error_target=target)
    render.step(256)
    ao = render.image()[..., 0]
    counts = render.sample_counts()
    assert counts.min() > 8 and counts.max() < 256  # stopped by their variance, not by the floor or the cap
    assert np.abs(ao - 0.25).max() < 3 * target
    assert abs(ao.mean() - 0.25) < target / 4


@pytest.mark.parametrize("target", [0.03, 0.015])
def test_stopped_pixels_are_within_the_target(target):
    """Against a converged image: the pixels the target stopped have an RMS error below it, their mean
    signed error is far below it (no bias from stopping on low variance), and few are 3 targets off."""
    tree = core.build_kdtree(boxes_on_floor())
    camera = look_at((1.8, -2.2, 1.6), (0.0, 0.2, 0.2))
    ref = core.render_preview(tree, camera, 40, 40, samples=2048, ao_distance=0.6, seed=99)
    render = core.PreviewRender(tree, camera, 40, 40, samples=256, ao_distance=0.6, error_target=target, seed=3)
    render.step(256)
    stopped = hit_mask(ref) & (render.sample_counts() < 256)
    err = (render.image()[..., 0] - ref[..., 0])[stopped]
    assert stopped.mean() > 0.3
    assert np.sqrt(np.mean(err ** 2)) < target
    assert abs(err.mean()) < target / 5
    assert (np.abs(err) > 3 * target).mean() < 0.01


def test_adaptive_beats_fixed_at_equal_rays():
    """What the target is for: the adaptive image is closer to the converged one than a fixed render that
    traces at least as many rays (fixed counts compared by their rays: every pixel 1 + samples)."""
    tree = core.build_kdtree(boxes_on_floor())
    camera = look_at((1.8, -2.2, 1.6), (0.0, 0.2, 0.2))
    ref = core.render_preview(tree, camera, 40, 40, samples=2048, ao_distance=0.6, seed=99)
    mask = hit_mask(ref)
    render = core.PreviewRender(tree, camera, 40, 40, samples=128, ao_distance=0.6, error_target=0.01, seed=3)
    render.step(128)
    rmse = lambda img: np.sqrt(np.mean((img[..., 0] - ref[..., 0])[mask] ** 2))  # noqa: E731
    n = int(np.ceil(render.counts.mean()))
    fixed = core.PreviewRender(tree, camera, 40, 40, samples=n, ao_distance=0.6, seed=3)
    fixed.step(n)
    assert fixed.rays_traced >= render.rays_traced
    assert rmse(render.image()) < rmse(fixed.image())
