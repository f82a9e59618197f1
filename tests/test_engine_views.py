"""A final render's views (Output > Views > Stereo 3D): each eye is rendered through its own camera.

The reference is Cycles rendering the same stereo frame: with its pixel filter at the minimum width it
takes each pixel at its centre, as the preview's one camera ray a pixel does, so both engines must hit
the same pixels in each eye (silhouette pixels aside, where the filter's 0.01 px reaches past the edge).
"""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from kd_addon import corelib, engine_final, memory_limit, render_views, tree_cache
from tests import bpy_scenes as scenes
from tests.addon_support import add_sun, exr_channels
from tests.byte_counts import MIB

SIZE = (80, 60)


def stereo_scene(tmp_path, convergence_mode):
    """A floor and two boxes seen from above at an angle, an exaggerated interocular distance (so the
    eyes differ by many pixels), each view written to its own RGBA EXR."""
    scene = scenes.reset()
    scenes.add_mesh("Floor", [(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)], [(0, 1, 2, 3)])
    scenes.add_cube("Box", location=(0.0, 0.0, 1.0))
    scenes.add_cube("Small", scale=0.5, location=(2.5, 1.5, 0.5))
    camera = scenes.add_camera("Cam")
    camera.location, camera.rotation_euler = (0.0, -8.0, 5.0), (math.radians(60), 0.0, 0.0)
    camera.data.stereo.convergence_mode = convergence_mode
    camera.data.stereo.interocular_distance = 1.0
    scene.camera = camera
    render = scene.render
    render.resolution_x, render.resolution_y = SIZE
    render.resolution_percentage = 100
    render.film_transparent = True
    render.use_multiview, render.views_format = True, "STEREO_3D"
    settings = render.image_settings
    settings.file_format, settings.color_mode, settings.exr_codec = "OPEN_EXR", "RGBA", "NONE"
    settings.views_format = "INDIVIDUAL"
    scene.kd_preview.mode, scene.kd_preview.samples = "ao", 1
    scene.cycles.samples, scene.cycles.use_denoising, scene.cycles.use_adaptive_sampling = 1, False, False
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BLACKMAN_HARRIS", 0.01  # a pixel's centre
    return scene


def eye_masks(scene, engine, path) -> dict:
    """{"L": (H, W) bool, "R": ...}: the pixels `engine` hits in each eye's image."""
    scene.render.engine = engine
    scene.render.filepath = str(path)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    return {eye: exr_channels(f"{path}_{eye}.exr")["A"] > 0.5 for eye in "LR"}


@pytest.mark.parametrize("convergence_mode", ["OFFAXIS", "PARALLEL", "TOE"])
def test_each_stereo_eye_hits_the_pixels_cycles_hits(addon, tmp_path, convergence_mode):
    scene = stereo_scene(tmp_path, convergence_mode)
    ours = eye_masks(scene, "KD_PREVIEW", tmp_path / "kd")
    cycles = eye_masks(scene, "CYCLES", tmp_path / "cycles")
    assert (ours["L"] ^ ours["R"]).sum() > 100  # the eyes see differently: the check below can tell them apart
    for eye in "LR":
        assert ours[eye].sum() > 1000
        assert (ours[eye] ^ cycles[eye]).sum() <= 4, eye


def test_multiview_renders_each_view_through_its_suffixed_camera(addon, tmp_path):
    """Multi-View: view "left" (suffix _L) and "right" (_R) are seen by the cameras named with those
    suffixes, their placement and lens both (Cycles takes them from RenderEngine.camera_override)."""
    scene = stereo_scene(tmp_path, "OFFAXIS")
    left = scene.camera
    left.name = left.data.name = "Cam_L"
    right = scenes.add_camera("Cam_R")
    right.location, right.rotation_euler = (2.0, -7.0, 4.0), (math.radians(65), 0.0, math.radians(10))
    right.data.lens = 28.0
    scene.render.views_format = "MULTIVIEW"
    assert [(v.name, v.camera_suffix) for v in scene.render.views] == [("left", "_L"), ("right", "_R")]
    ours = eye_masks(scene, "KD_PREVIEW", tmp_path / "kd")
    cycles = eye_masks(scene, "CYCLES", tmp_path / "cycles")
    assert (ours["L"] ^ ours["R"]).sum() > 300  # the cameras see very differently
    for eye in "LR":
        assert (ours[eye] ^ cycles[eye]).sum() <= 4, eye


def test_views_a_render_makes():
    render = scenes.reset().render
    assert render_views.view_names(render) == [""]
    render.use_multiview = True
    assert render_views.view_names(render) == ["left", "right"]
    render.views_format = "MULTIVIEW"
    render.views["right"].use = False
    extra = render.views.new("centre")
    assert render_views.view_names(render) == ["left", extra.name]
    render.views_format = "STEREO_3D"  # only the left and right views count there
    assert render_views.view_names(render) == ["left"]


def test_views_no_longer_rendered_drop_their_kept_pixels(addon, tmp_path):
    """Each view keeps its last pixels for the next frame (its tree_cache lane); once a render no longer
    makes a view, its lane is dropped, so its pixels are not held for good. The panel's lane stays."""
    scene = stereo_scene(tmp_path, "OFFAXIS")
    left, right = (render_views.lane_of("ViewLayer", name) for name in ("left", "right"))
    assert bpy.ops.kdpreview.render() == {"FINISHED"}  # the panel's image: lane ""
    eye_masks(scene, "KD_PREVIEW", tmp_path / "stereo")
    assert {left, right, ""} <= lanes_of(scene)
    only_left(scene, tmp_path / "left")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert right not in lanes_of(scene) and {left, ""} <= lanes_of(scene)


def test_other_views_kept_pixels_count_towards_the_memory_limit(addon, tmp_path):
    """While one eye renders, the other eye's last pixels are held: the frame's memory check counts them
    (tree_cache.held_bytes), so a limit that one view's frame fits, but not with the other's pixels
    kept, refuses the frame and says why. A frame that no longer renders the other eye does not count
    them: its lanes are dropped before the check, so a refused frame cannot keep refusing later ones."""
    scene = stereo_scene(tmp_path, "OFFAXIS")
    scene.render.resolution_x, scene.render.resolution_y = 320, 240
    eye_masks(scene, "KD_PREVIEW", tmp_path / "first")
    held = tree_cache.held_bytes(scene, "", render_views.lane_of("ViewLayer", "left"))
    image_and_depth = 320 * 240 * (4 * 4 + 4)  # float32 RGBA and depth: a floor under the pixel state too
    assert image_and_depth < held < corelib.load_core().memory.render_bytes(320, 240, keeps_previous=True)
    geometry, pixels = memory_limit.frame_bytes(26, 320, 240, "binned", keeps_previous=True)
    scene.kd_preview.memory_limit_mb = math.ceil((geometry + pixels + held / 2) / MIB)
    scene.render.filepath = str(tmp_path / "second")
    with pytest.raises(RuntimeError, match="of which [0-9]+ MiB other views' and passes' kept pixels"):
        bpy.ops.render.render(write_still=True)
    only_left(scene, tmp_path / "left")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    scene.kd_preview.memory_limit_mb = 0


def test_each_view_layer_keeps_its_own_pass_lanes(addon, tmp_path, monkeypatch):
    """Blender renders each view layer in its own call: one without the AO pass must not drop the lanes
    of another that has it (its AO pass would lose its kept pixels every frame)."""
    rendered = []
    original = engine_final.FinalRender.run
    monkeypatch.setattr(engine_final.FinalRender, "run",
                        lambda self: rendered.append(self.depsgraph.view_layer.name) or original(self))
    scene = stereo_scene(tmp_path, "OFFAXIS")
    scene.render.use_multiview, scene.render.engine = False, "KD_PREVIEW"
    scene.kd_preview.mode = "shadow"
    add_sun("Sun", rotation=(0.3, 0.2, 0.0))
    first = scene.view_layers[0]
    first.use_pass_ambient_occlusion = True
    second = scene.view_layers.new("Second")
    assert not second.use_pass_ambient_occlusion
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert rendered == [first.name, second.name]  # the layer without the pass rendered last
    assert render_views.lane_of(first.name, "", "ao") in lanes_of(scene)


def test_one_layers_final_lanes_never_begin_another_layers():
    """keep_lanes drops by prefix: layer "A"'s must not take layer "A|B"'s lanes (names may hold any
    character)."""
    for kept, other in (("A", "A|B"), ("A|B", "A"), ("", "x"), ("x", "")):
        assert not render_views.lane_of(other, "left", "ao").startswith(render_views.final_lanes(kept))
        assert render_views.lane_of(kept, "left", "ao").startswith(render_views.final_lanes(kept))


def only_left(scene, path) -> None:
    """Multi-View with the left view alone, through the scene camera; the file written to `path`."""
    scene.render.views["right"].use = False
    scene.render.views_format = "MULTIVIEW"
    scene.render.views["left"].camera_suffix = ""
    scene.render.filepath = str(path)


def lanes_of(scene) -> set:
    return {lane for uid, group, lane in tree_cache._states if uid == scene.session_uid and group == ""}
