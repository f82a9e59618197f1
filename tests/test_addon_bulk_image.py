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


def test_moved_instances_rebuild_only_the_top_level(addon):
    """Issue 50: instances moved by their points keep every mesh tree (only the top level is built
    anew) and give the image a render from nothing gives."""
    from types import SimpleNamespace

    from kd_addon import tree_cache
    from kd_addon.config import make_config
    from kd_addon.pipeline import render_frame
    from tests import bpy_scenes as scenes
    from tests.addon_support import floor_scene

    scene = floor_scene(48, 32)
    host = scenes.add_gn_instancer("Host", count=40, offset=(0.25, 0.1, 0), cube_size=0.2, location=(-4, -2, 0.3))
    config = make_config(SimpleNamespace(mode="ao", samples=2, resolution_percentage=100))
    tree_cache.clear()
    first = render_frame(scene, bpy.context.evaluated_depsgraph_get(), config)
    line = next(n for n in host.modifiers["GN"].node_group.nodes if n.bl_idname == "GeometryNodeMeshLine")
    line.inputs["Offset"].default_value = (0.2, 0.15, 0)
    moved = render_frame(scene, bpy.context.evaluated_depsgraph_get(), config)
    tree_cache.clear()
    fresh = render_frame(scene, bpy.context.evaluated_depsgraph_get(), config)
    assert extract_scene().path == "bulk"
    assert (moved.objects_rebuilt, moved.objects_reused) == (0, first.objects_rebuilt)
    assert not moved.image_reused and fresh.objects_reused == 0
    assert not np.array_equal(first.image, moved.image)
    assert np.array_equal(moved.image, fresh.image)
