"""The viewport's Rendered shading without a GPU: update handling, progressive samples, reuse on navigation
and edits (kd_addon/engine_viewport.py). The drawing needs a GPU context, which the bpy module has none of:
its test skips with the reason."""

from __future__ import annotations

import time
from types import SimpleNamespace

import bpy
import numpy as np
import pytest
from mathutils import Matrix

from kd_addon import engine, tree_cache
from kd_addon.config import make_config
from kd_addon.engine_viewport import ViewportSession, camera_from_matrices, changes_image, update_rows
from kd_addon.pipeline import FrameJob, FrameView, run_job
from tests.addon_support import half_plane_scene, preview_pixels
from tests.test_engine_camera import orthographic_window, perspective_window, viewport_view_matrix


def view_of(window, width=48, height=30) -> FrameView:
    return FrameView(width, height, camera_from_matrices(viewport_view_matrix(), window, width, height))


def top_view(width=48, height=24, left=-5.0) -> FrameView:
    """An orthographic view straight down on half_plane_scene, like its camera's."""
    view = Matrix.Translation((0.0, 0.0, 10.0)).inverted()
    window = orthographic_window(left, left + 8.0, -2.0, 2.0, -50.0, 50.0)
    return FrameView(width, height, camera_from_matrices(view, window, width, height))


def run_session(session, view, config, timeout=900.0):
    """advance() until it says done (a cold kernel cache compiles for minutes); the samples shown after
    each call."""
    shown = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        working = session.advance(bpy.context.evaluated_depsgraph_get(), view, config)
        shown.append(session.samples_shown)
        if not working:
            return shown
    raise AssertionError("the viewport session never finished")


def reference_image(scene, view, config) -> np.ndarray:
    """The same frame through a plain FrameJob with its own trees."""
    job = FrameJob(scene, bpy.context.evaluated_depsgraph_get(), config, view=view, group="reference")
    run_job(job)
    return job.result().image


@pytest.mark.parametrize("rows,changes", [
    ([], False),
    ([("MATERIAL", False, False)], False),
    ([("MATERIAL", False, False), ("IMAGE", False, False)], False),
    ([("OBJECT", False, True)], True),
    ([("MESH", True, False)], True),
    ([("MATERIAL", False, False), ("OBJECT", True, False)], True),
    ([("SCENE", False, False)], True),  # a setting: KD Preview's own, the frame, the camera
    ([("LIGHT", False, False)], True),
])
def test_which_updates_change_the_image(rows, changes):
    assert changes_image(rows) is changes


def test_updates_of_real_edits(addon):
    """Rows read from depsgraph_update_post's depsgraph: a move changes the image. A material's colour
    updates its objects and meshes too (no geometry or transform flag): those count (an object's ray
    visibility updates it the same way), and the new job finds the image unchanged and keeps it."""
    half_plane_scene()
    box = bpy.data.objects["Box"]
    box.data.materials.append(bpy.data.materials.new("Paint"))
    bpy.context.view_layer.update()
    seen = []

    def handler(scene, depsgraph):
        seen.append(update_rows(depsgraph))

    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        box.location.x += 0.25
        bpy.context.view_layer.update()
        moved = list(seen)
        seen.clear()
        bpy.data.materials["Paint"].diffuse_color = (1.0, 0.0, 0.0, 1.0)
        bpy.context.view_layer.update()
        painted = list(seen)
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
    assert moved and any(changes_image(rows) for rows in moved)
    assert painted and all(("MATERIAL", False, False) in rows for rows in painted)
    session, view = ViewportSession(bpy.context.scene), top_view()
    config = make_config(bpy.context.scene.kd_preview)
    run_session(session, view, config)
    bpy.data.materials["Paint"].diffuse_color = (0.0, 1.0, 0.0, 1.0)
    session.scene_changed()
    run_session(session, view, config)
    assert session.result.image_reused and session.result.rays == 0


def test_samples_accumulate_to_the_frames_image(addon):
    """Each draw shows the samples so far; the last shown is the frame a FrameJob renders."""
    scene = half_plane_scene()
    config = make_config(scene.kd_preview)  # 8 samples
    session = ViewportSession(scene)
    view = top_view()
    shown = run_session(session, view, config)
    progress = sorted(set(shown) - {0})
    assert progress[-1] == 8 and len(progress) >= 2  # more than one image on the way
    assert shown == sorted(shown)  # never fewer samples shown than before
    assert session.image.shape == (24, 48, 4)
    assert np.array_equal(session.image, reference_image(scene, view, config))
    assert session.result.samples == 8 and "8 samples" in session.status


def test_navigation_restarts_sampling_on_the_kept_trees(addon):
    scene = half_plane_scene()
    config = make_config(scene.kd_preview)
    session = ViewportSession(scene)
    tree_cache.clear()
    run_session(session, top_view(), config)
    assert session.result.objects_rebuilt == 2
    moved_view = top_view(left=-4.0)
    shown = run_session(session, moved_view, config)
    assert shown[0] == 0  # sampling starts again for the new view
    assert (session.result.objects_rebuilt, session.result.objects_reused) == (0, 2)
    assert np.array_equal(session.image, reference_image(scene, moved_view, config))
    run_session(session, view_of(perspective_window(-0.3, 0.5, -0.2, 0.3, 0.01, 100.0)), config)
    assert session.result.objects_rebuilt == 0  # a perspective view, the same trees


def test_edits_rebuild_only_what_changed(addon):
    scene = half_plane_scene()
    config = make_config(scene.kd_preview)
    session, view = ViewportSession(scene), top_view()
    run_session(session, view, config)
    untouched = run_session(session, view, config)
    assert untouched == [8]  # nothing changed: no new job, the image stays
    box = bpy.data.objects["Box"]
    for _ in range(2):  # its first move takes the box out of the static soup (core.SceneBuilder)
        box.location.x += 0.25
        session.scene_changed()
        run_session(session, view, config)
    assert (session.result.objects_rebuilt, session.result.image_reused) == (0, False)  # moved: no tree built
    box.data.vertices[0].co.z += 0.3
    box.data.update()
    session.scene_changed()
    run_session(session, view, config)
    assert (session.result.objects_rebuilt, session.result.objects_reused) == (1, 1)
    assert np.array_equal(session.image, reference_image(scene, view, config))


def test_a_setting_change_restarts_and_an_error_is_shown_not_raised(addon):
    scene = half_plane_scene()
    session, view = ViewportSession(scene), top_view()
    run_session(session, view, make_config(scene.kd_preview))
    scene.kd_preview.samples = 4
    assert run_session(session, view, make_config(scene.kd_preview))[-1] == 4
    bpy.data.objects.remove(bpy.data.objects["Sun"])
    scene.kd_preview.mode = "shadow"
    run_session(session, view, make_config(scene.kd_preview))
    assert "needs a light" in session.error and session.status.startswith("KD Preview: ")


def test_drawing_needs_a_gpu_context(addon):
    """engine.draw_image uploads the image as a GPUTexture and draws it through the display-space shader.
    It needs a GPU context: Blender's window has one; the bpy module has none before 5.3, whose gpu.init()
    makes an offscreen (EGL) one, so the test runs there and skips elsewhere."""
    import gpu

    def texture():  # what draw_image needs: a buffer may be made without a context, a texture not
        gpu.types.GPUTexture((1, 1), format="RGBA16F", data=gpu.types.Buffer("FLOAT", 4, [0.0] * 4))

    try:
        texture()
    except (SystemError, RuntimeError) as error:
        if not any(word in str(error) for word in ("context", "background mode")):
            raise  # another failure of the texture draw_image makes: the test's to report
        try:
            gpu.init()  # bpy 5.3 on; an AttributeError before
            texture()
        except (AttributeError, SystemError, RuntimeError):
            reason = f"no GPU context here ({error})"
            print(f"SKIPPED drawing test: {reason}")
            pytest.skip(reason)

    class Engine:
        texture = None

        def bind_display_space_shader(self, scene):
            pass

        def unbind_display_space_shader(self):
            pass

    fake_engine = Engine()
    image = np.random.default_rng(0).random((6, 8, 4)).astype(np.float32)
    engine.draw_image(fake_engine, bpy.context.scene, image, 16, 12)
    texture = fake_engine.texture[1]
    assert fake_engine.texture[0] is image and (texture.width, texture.height) == (8, 6)


def test_view_draw_glue_without_drawing(addon, monkeypatch):
    """KDPreviewRenderEngine.view_update / view_draw on stand-ins for the engine and a region (the GPU
    upload replaced): the region's size at the tab's Resolution %, its matrices as the camera, redraws
    asked for until the image has all its samples, the status in the stats line."""
    scene = half_plane_scene()
    scene.kd_preview.resolution_percentage = 50
    drawn, stats, redraws = [], [], []
    monkeypatch.setattr(engine, "draw_image", lambda eng, sc, image, w, h: drawn.append((image.shape, w, h)))
    fake = SimpleNamespace(session=None, update_stats=lambda a, b: stats.append(b),
                           tag_redraw=lambda: redraws.append(1))
    view = Matrix.Translation((0.0, 0.0, 10.0)).inverted()
    window = Matrix(orthographic_window(-4.0, 4.0, -2.0, 2.0, -50.0, 50.0))
    context = SimpleNamespace(region=SimpleNamespace(width=96, height=48),
                              region_data=SimpleNamespace(view_matrix=view, window_matrix=window))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    engine.KDPreviewRenderEngine.view_update(fake, context, depsgraph)
    deadline = time.monotonic() + 900.0
    while fake.session.job is not None or not drawn:
        assert time.monotonic() < deadline
        engine.KDPreviewRenderEngine.view_draw(fake, context, bpy.context.evaluated_depsgraph_get())
    assert drawn[-1] == ((24, 48, 4), 96, 48)
    assert redraws and "8 samples" in stats[-1]
    # the same view as half_plane_scene's camera: the panel's image of it
    scene.kd_preview.resolution_percentage = 100
    scene.render.resolution_x, scene.render.resolution_y = 48, 24
    assert bpy.ops.kdpreview.render() == {"FINISHED"}
    panel = preview_pixels()
    assert np.array_equal(fake.session.image[..., 3], panel[..., 3])
    assert np.abs(fake.session.image - panel).max() < 1e-4
