"""The bulk instance path (kd_addon/bulk_instances.py) and the per-entry walk render the same image."""
from __future__ import annotations

import bpy
import numpy as np
import pytest

from kd_addon import bulk_instances
from kd_addon.extract import extract_scene
from tests.test_extract_bulk import _ScatterScene

pytestmark = pytest.mark.skipif(not bulk_instances.AVAILABLE, reason="bpy has no Object.evaluated_geometry()")


@pytest.mark.parametrize("seed", [3, 11])
def test_both_paths_render_the_same_image(addon, monkeypatch, seed):
    """ao+shadow through the render operator: the bulk path's image is the walk's, pixel for pixel."""
    from kd_addon import tree_cache
    from tests.addon_support import add_sun, floor_scene, preview_pixels

    scene = floor_scene(48, 32)
    bpy.context.scene.camera.location = (0, -14, 9)
    bpy.context.scene.camera.rotation_euler = (0.9, 0, 0)
    add_sun(rotation=(0.5, 0.3, 0.0))
    scene.kd_preview.mode = "ao+shadow"
    _ScatterScene(seed).build()
    images, paths = [], []
    for enabled in (True, False):
        monkeypatch.setattr(bulk_instances, "ENABLED", enabled)
        tree_cache.clear()  # no tree or image kept from the other path
        assert bpy.ops.kdpreview.render() == {"FINISHED"}
        images.append(preview_pixels())
        paths.append(extract_scene().path)
    assert paths == ["bulk", "walk"]
    assert images[0][..., 3].any()
    assert np.array_equal(images[0], images[1])
