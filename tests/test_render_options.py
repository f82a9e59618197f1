"""RenderOptions: the render settings as one frozen, validated object; PreviewRender and render_preview
take it (options=) and/or its fields as keywords."""
import dataclasses

import numpy as np
import pytest

import core

CAMERA = core.Camera(np.array([[1.0, 0, 0, 0.2], [0, 1, 0, 0.1], [0, 0, 1, 3], [0, 0, 0, 1]]), 0.9)
LIGHTS = [core.Light.point((0.0, 0.0, 2.0))]


@pytest.fixture(scope="module")
def tree():
    tris = np.array([[[-1, -1, 0], [1, -1, 0], [0, 1, 0]], [[-1, -1, 0.5], [1, -1, 0.5], [0, 1, 0.5]]], np.float32)
    return core.build_kdtree(tris)


def test_defaults_and_frozen():
    o = core.RenderOptions()
    assert (o.mode, o.samples, o.ao_distance, o.lights, o.seed, o.sampler) == ("ao", 16, 1.0, (), 0, "sobol")
    assert (o.error_target, o.min_samples, o.ambient, o.threads) == (None, 8, 0.25, None)
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.samples = 4


@pytest.mark.parametrize("settings, message", [
    (dict(mode="normals"), "mode must be one of"), (dict(mode=["ao"]), r"mode must be one of .* got \[.ao.\]"),
    (dict(samples=0), "samples must be an integer >= 1"),
    (dict(ao_distance=-1.0), "ao_distance must be finite and >= 0"), (dict(sampler="halton"), "sampler must be"),
    (dict(error_target=0.0), "error_target must be None or > 0"), (dict(min_samples=1), "min_samples must be"),
    (dict(ambient=1.5), r"ambient must be in \[0, 1\]"), (dict(seed=0.5), "seed must be an integer"),
    (dict(threads=0), "threads must be None or an integer >= 1"), (dict(mode="shadow"), "needs at least one light"),
    (dict(mode="shadow", lights=LIGHTS[0]), r"pass \[light\]"),
])
def test_each_setting_is_checked_when_made(settings, message):
    with pytest.raises(ValueError, match=message):
        core.RenderOptions(**settings)


def test_keywords_build_or_amend_the_options(tree):
    options = core.RenderOptions(mode="ao+shadow", samples=2, lights=LIGHTS, seed=5)
    by_options = core.PreviewRender(tree, CAMERA, 9, 7, options)
    by_keywords = core.PreviewRender(tree, CAMERA, 9, 7, mode="ao+shadow", samples=2, lights=LIGHTS, seed=5)
    assert by_options.options == by_keywords.options == options
    amended = core.PreviewRender(tree, CAMERA, 9, 7, options=options, samples=3)
    assert amended.options.samples == 3 and amended.options.seed == 5 and options.samples == 2
    np.testing.assert_array_equal(core.render_preview(tree, CAMERA, 9, 7, options=options),
                                  core.render_preview(tree, CAMERA, 9, 7, mode="ao+shadow", samples=2,
                                                      lights=LIGHTS, seed=5))
    with pytest.raises(ValueError, match="options must be a core.RenderOptions"):
        core.PreviewRender(tree, CAMERA, 9, 7, {"samples": 2})
    with pytest.raises(TypeError):
        core.PreviewRender(tree, CAMERA, 9, 7, sample=2)
