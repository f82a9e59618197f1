"""Rendering-level fuzz: generated triangle soups, cameras, scales, offsets and settings through
core.render_preview. Whatever the scene, the image is finite and in [0, 1], its alpha is exactly the
brute-force camera-ray hit mask, the background is black, and ao_distance 0 gives AO exactly 1.

A fast subset runs in CI; HYPOTHESIS_PROFILE=long runs many more cases.
"""
import os

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from tests.strategies import draw_soup, grid

import core
from tests.oracles import brute_watertight
from tests.render_scenes import look_at

EXAMPLES = 2000 if os.environ.get("HYPOTHESIS_PROFILE") == "long" else 20
WIDTH, HEIGHT = 8, 6



@st.composite
def render_cases(draw):
    tris = draw_soup(draw, 40)
    scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    offset = np.array(draw(st.sampled_from([(0, 0, 0), (1e5, 0, 0), (-3e5, 2e5, 1e6)])), np.float64)
    position = np.array(draw(st.lists(st.floats(-6, 6, width=32), min_size=3, max_size=3)))
    if np.linalg.norm(position) < 0.5:
        position = position + np.array([0.0, -4.0, 2.0])
    target = np.array(draw(st.lists(grid, min_size=3, max_size=3)))
    if np.linalg.norm(position - target) < 1e-3:
        target = target + 1.0
    options = dict(mode=draw(st.sampled_from(["ao", "shadow", "ao+shadow"])), samples=draw(st.integers(1, 4)),
                   ao_distance=draw(st.sampled_from([0.0, 0.3, 1.0, 1e6])) * scale, seed=draw(st.integers(0, 99)))
    return tris * scale + offset, position * scale + offset, target * scale + offset, options


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=render_cases())
def test_generated_renders_are_sane_and_hit_what_brute_force_hits(case):
    tris, position, target, options = case
    tris = tris.astype(np.float32)
    camera = look_at(position, target)
    tree = core.build_kdtree(tris)
    lights = [core.Light.sun((0.3, 0.2, -1.0), angle=0.1)]
    image = core.render_preview(tree, camera, WIDTH, HEIGHT, lights=lights, **options)
    assert image.shape == (HEIGHT, WIDTH, 4) and np.isfinite(image).all()
    assert (image >= 0).all() and (image <= 1).all()
    origins, directions, tmin, tmax = camera.rays(WIDTH, HEIGHT)
    _, prim, _ = brute_watertight(tris, origins, directions, tmin, tmax)
    hit = (prim >= 0).reshape(HEIGHT, WIDTH)
    np.testing.assert_array_equal(image[..., 3], hit.astype(np.float32))
    assert (image[~hit][:, :3] == 0).all()
    if options["ao_distance"] == 0 and options["mode"] == "ao":
        assert (image[hit][:, :3] == 1).all()
