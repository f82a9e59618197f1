"""Live Update: re-rendering on frame changes and on edits, in background mode.

half_plane_scene (tests/addon_support.py): an orthographic camera sees a plane over exactly the left
half of the image (x in [-4, 0] of an 8 x 4 view) with a 1 x 1 x 1 cube standing on it, so the hit
mask and the places where AO must be 1 (open plane, cube top) or below 1 (plane next to the cube)
are known.
"""

from __future__ import annotations

import json

import bpy
import pytest

from kd_addon import live_update, pipeline
from kd_addon.output import IMAGE_NAME
from tests.addon_support import check_half_plane_image, column_of, half_plane_scene, preview_pixels


def test_live_update_renders_on_frame_change_only_when_enabled(addon):
    scene = half_plane_scene()
    scene.frame_set(2)
    assert IMAGE_NAME not in bpy.data.images
    scene.kd_preview.live_update = True
    scene.frame_set(3)
    check_half_plane_image(preview_pixels())
    assert json.loads(bpy.context.window_manager.kd_preview_state.last_run)["frame"] == 3
    handlers = [h for h in bpy.app.handlers.frame_change_post if h.__name__ == "kd_preview_frame_change"]
    assert handlers == [live_update.kd_preview_frame_change]


@pytest.mark.parametrize("engine", ["BLENDER_WORKBENCH", "KD_PREVIEW"])
def test_live_update_stays_out_of_a_blocking_render(addon, tmp_path, monkeypatch, engine):
    """A file saved with Live Update on, rendered by a script or a farm (`blender -b -a`): the render
    blocks, so bpy.app.is_job_running("RENDER") is False in the frame handler, which rendered a preview
    of every frame beside the real render. Blender's render handlers now say it renders; afterwards a
    frame change renders the preview again."""
    scene = half_plane_scene()
    scene.render.engine = engine
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.filepath = str(tmp_path / "frame_")
    scene.kd_preview.live_update = True
    previews = []
    original = live_update.render_frame
    monkeypatch.setattr(live_update, "render_frame",
                        lambda s, *args, **kwargs: previews.append(s.frame_current) or original(s, *args, **kwargs))
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert previews == [] and len(list(tmp_path.glob("frame_*"))) == 4
    scene.frame_set(2)
    assert previews == [2]
    # A render that fails before its first frame (Blender refuses 4 x 4 at 1 %) fires render_init but
    # neither render_complete nor render_cancel: Live Update must still follow the frames after it.
    scene.render.resolution_x = scene.render.resolution_y = 4
    scene.render.resolution_percentage = 1
    with pytest.raises(RuntimeError, match="too small"):
        bpy.ops.render.render(animation=True)
    scene.frame_set(3)
    assert previews == [2, 3]


def test_live_update_renders_an_edit_once_edits_pause(addon):
    """Each depsgraph update (re)starts a timer (EDIT_DELAY); when it fires, the Render operator renders
    the edit. Timers never fire in background mode, so the test calls the timer's function itself."""
    timers = bpy.app.timers
    scene = half_plane_scene()
    scene.kd_preview.live_update = True
    bpy.context.view_layer.update()
    if timers.is_registered(live_update.render_edits):
        timers.unregister(live_update.render_edits)
    bpy.data.objects["Box"].location.x = -1.0
    bpy.context.view_layer.update()
    assert timers.is_registered(live_update.render_edits)  # scheduled, not rendered yet
    assert IMAGE_NAME not in bpy.data.images
    timers.unregister(live_update.render_edits)
    assert live_update.render_edits() is None  # what the timer does when it fires
    img = preview_pixels()
    assert img[16, column_of(-1.0), 0] == pytest.approx(1.0, abs=1e-3)  # the moved box's open top
    assert img[16, column_of(-2.0), 0] < 0.9  # where the box stood is ground beside it now
    bpy.context.view_layer.update()  # the preview's own image write is no edit: nothing scheduled
    assert not timers.is_registered(live_update.render_edits)


def test_live_update_renders_settings_set_by_a_script_and_its_own_switching_on(addon):
    """A setting set from Python makes no depsgraph update (Blender 5.2.2), so Live Update would not
    render it, nor would switching Live Update on: settings schedule the render themselves."""
    timers = bpy.app.timers
    scene = half_plane_scene()
    if timers.is_registered(live_update.render_edits):
        timers.unregister(live_update.render_edits)
    scene.kd_preview.samples = 4  # Live Update off: nothing
    assert not timers.is_registered(live_update.render_edits)
    scene.kd_preview.live_update = True  # switching it on renders the scene as it is
    assert timers.is_registered(live_update.render_edits)
    timers.unregister(live_update.render_edits)
    assert live_update.render_edits() is None
    far_ground = (slice(None), slice(0, column_of(-3.5)))  # over 1.0 from the box
    assert (preview_pixels()[far_ground][..., 0] == 1.0).all()  # AO Distance 1: nothing occludes it
    scene.kd_preview.ao_distance = 3.0  # no depsgraph update (no view_layer.update() here either)
    assert timers.is_registered(live_update.render_edits)
    timers.unregister(live_update.render_edits)
    assert live_update.render_edits() is None
    assert preview_pixels()[far_ground][..., 0].mean() < 0.99  # AO Distance 3 reaches the box


def test_live_update_edits_wait_for_a_running_render_or_tool_and_need_the_option(addon, monkeypatch):
    timers = bpy.app.timers
    scene = half_plane_scene()
    bpy.data.objects["Box"].location.x = -1.0
    bpy.context.view_layer.update()
    assert not timers.is_registered(live_update.render_edits)  # live update off
    scene.kd_preview.live_update = True
    token = object()
    pipeline.claim(token)  # another render runs
    try:
        assert live_update.render_edits() == live_update.EDIT_DELAY  # tries again later
        assert IMAGE_NAME not in bpy.data.images
    finally:
        pipeline.release(token)
    assert live_update.render_edits() is None and IMAGE_NAME in bpy.data.images
    bpy.data.images.remove(bpy.data.images[IMAGE_NAME])
    interactive = live_update.interactive_tool_running
    assert interactive(["TRANSFORM_OT_translate"]) and interactive(["sculpt.brush_stroke"])
    assert not interactive([]) and not interactive(["KDPREVIEW_OT_render", "WM_OT_modal_timer_operator"])
    monkeypatch.setattr(live_update, "interactive_tool_running", lambda idnames: True)  # a grab in progress
    assert live_update.render_edits() == live_update.EDIT_DELAY and IMAGE_NAME not in bpy.data.images
    monkeypatch.setattr(live_update, "interactive_tool_running", interactive)
    assert live_update.render_edits() is None and IMAGE_NAME in bpy.data.images
    bpy.data.objects.remove(bpy.data.objects["Cam"])  # an edit the preview cannot render
    assert live_update.render_edits() is None  # no traceback from the timer: the status says why
    assert bpy.context.window_manager.kd_preview_state.status.startswith("Error:")
    scene.kd_preview.live_update = False
    bpy.data.images.remove(bpy.data.images[IMAGE_NAME])
    assert live_update.render_edits() is None and IMAGE_NAME not in bpy.data.images  # switched off since
