"""Render operator and pipeline in background mode, on scenes with a known answer.

half_plane_scene (tests/addon_support.py): an orthographic camera sees a plane over exactly the left
half of the image (x in [-4, 0] of an 8 x 4 view) with a 1 x 1 x 1 cube standing on it, so the hit
mask and the places where AO must be 1 (open plane, cube top) or below 1 (plane next to the cube)
are known.
"""

from __future__ import annotations

import json
import math

import bpy
import numpy as np
import pytest

from kd_addon import output, pipeline, sampling_steps
from kd_addon.config import make_config
from kd_addon.errors import Cancelled, PreviewError
from kd_addon.output import IMAGE_NAME
from tests import bpy_scenes as scenes
from tests.addon_support import check_half_plane_image, column_of, half_plane_scene, preview_pixels


def test_render_operator_fills_the_preview_image(addon):
    half_plane_scene()
    assert bpy.ops.kdpreview.render() == {"FINISHED"}
    check_half_plane_image(preview_pixels())
    image = bpy.data.images[IMAGE_NAME]
    assert image.is_float and tuple(image.size) == (64, 32)
    state = bpy.context.window_manager.kd_preview_state
    last = json.loads(state.last_run)
    assert (last["triangles"], last["objects"], last["lights"], last["samples"]) == (14, 2, 1, 8)
    assert last["rays"] > 64 * 32 and last["tree"]["nodes"] >= 1 and last["tree"]["sah_cost"] > 0
    assert not state.running and state.status.startswith("KD Preview: 64x32")
    assert "redraws" not in state.status  # synchronous: no redraws between ticks to add


def test_invoke_in_background_runs_synchronously(addon):
    half_plane_scene()
    assert bpy.ops.kdpreview.render("INVOKE_DEFAULT") == {"FINISHED"}
    check_half_plane_image(preview_pixels())


def test_far_from_origin_gives_the_same_image(addon):
    """Tracing relative to the camera: 100 km away the image matches the one at the origin."""
    half_plane_scene()
    bpy.ops.kdpreview.render()
    near = preview_pixels()
    scenes_root = bpy.context.scene.collection
    for obj in scenes_root.objects:
        obj.location = obj.location + type(obj.location)((1e5, -1e5, 1e4))
    bpy.ops.kdpreview.render()
    far = preview_pixels()
    assert (near[..., 3] == far[..., 3]).all()
    assert np.abs(near - far).max() < 1e-5


def test_modes_with_lights(addon):
    scene = half_plane_scene()
    for mode in ("shadow", "ao+shadow"):
        scene.kd_preview.mode = mode
        assert bpy.ops.kdpreview.render() == {"FINISHED"}
        img = preview_pixels()
        assert (img[:, :32, 3] == 1.0).all() and (img[..., :3] >= 0).all() and (img[..., :3] <= 1).all()
        assert img[16, column_of(-3.9), 0] > 0.5  # lit open ground


def test_lights_blender_accepts_but_that_emit_nothing_are_left_out_by_name(addon):
    """Negative power, zero area size, a zero-scale area light, a black light, a Cycles light portal
    (traced, some of them would light the floor and halve the real light's share of S, where Cycles'
    image is the sun's alone): Blender takes them all. Mode ao ignores lights; the shadow modes leave such lights
    out with a warning that names each, and stop (naming them) only when no light is left. A sun of
    Blender's largest angle (180 degrees) is usable."""
    scene = half_plane_scene()
    bpy.data.objects["Sun"].data.angle = math.pi
    bad = {}
    for name, kind in (("Negative", "POINT"), ("Flat", "AREA"), ("Squashed", "AREA"), ("Black", "POINT"),
                       ("Portal", "AREA"), ("Unlit", "SPOT")):
        light = bpy.data.lights.new(name, kind)
        bad[name] = scenes.link(bpy.data.objects.new(name, light))
        bad[name].location = (-2.0, 0.0, 3.0)
    bad["Negative"].data.energy = -100.0
    bad["Flat"].data.size = 0.0
    bad["Squashed"].scale = (1.0, 1.0, 0.0)
    bad["Black"].data.color = (0.0, 0.0, 0.0)
    bad["Portal"].data.cycles.is_portal = True
    scenes.light_nodes_on(bad["Unlit"].data)
    next(n for n in bad["Unlit"].data.node_tree.nodes if n.type == "EMISSION").inputs["Strength"].default_value = 0.0

    def frame(mode):
        scene.kd_preview.mode = mode
        return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))

    assert not frame("ao").warnings
    result = frame("shadow")
    assert result.lights == 1 and result.image[16, column_of(-3.9), 0] > 0.3  # the sun alone lights
    left_out = sorted(w for w in result.warnings if "left out" in w)
    assert [w.split("'")[1] for w in left_out] == ["Black", "Flat", "Negative", "Portal", "Squashed", "Unlit"]
    assert "colour is black" in left_out[0] and "power is -100" in left_out[2]
    assert "light portal" in left_out[3] and "zero Z axis" in left_out[4]
    assert "Emission node's Strength is 0" in left_out[5]
    ao = frame("ao").image
    bpy.data.objects.remove(bpy.data.objects["Sun"])  # no light emits: S = 0, as Cycles' image is black
    for mode, rgb in (("shadow", np.zeros_like(ao[..., :3])), ("ao+shadow", 0.25 * ao[..., :3])):  # core's ambient
        result = frame(mode)
        assert result.lights == 0 and "no light of scene 'Scene' emits on this frame" in result.warnings[-1]
        assert len([w for w in result.warnings if "left out" in w]) == 6
        np.testing.assert_array_equal(result.image[..., 3], ao[..., 3])
        np.testing.assert_allclose(result.image[..., :3], rgb, atol=1e-6)


def test_a_scenes_only_light_dimmed_to_nothing_darkens_that_frame_alone(addon):
    """A sun whose Emission Strength is animated 1 -> 0 -> 1 must not stop the whole animation at
    frame 2 ("needs a light"). Frame 2 renders black with a warning (Cycles' image is black too),
    and frame 3, lit again, renders anew and equals frame 1 (frame 2's image is not reused)."""
    scene = half_plane_scene()
    scene.kd_preview.mode = "shadow"
    sun = bpy.data.objects["Sun"]
    scenes.light_nodes_on(sun.data)
    strength = next(n for n in sun.data.node_tree.nodes if n.type == "EMISSION").inputs["Strength"]

    def frame(value):
        strength.default_value = value
        return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))

    lit, dark, lit_again = frame(1.0), frame(0.0), frame(1.0)
    assert lit.image[16, column_of(-3.9), 0] > 0.5 and not lit.warnings and lit.lights == 1
    assert dark.lights == 0 and not dark.image[..., :3].any()
    np.testing.assert_array_equal(dark.image[..., 3], lit.image[..., 3])
    assert dark.warnings == ["light 'Sun' left out: its Emission node's Strength is 0, so it emits no light",
                             "no light of scene 'Scene' emits on this frame: the shadow term is 0"]
    assert not dark.image_reused and not lit_again.image_reused
    np.testing.assert_array_equal(lit_again.image, lit.image)


def test_light_settings_the_preview_does_not_apply_are_named(addon):
    """Light and shadow linking and a light's shader nodes change Cycles' image; the preview lights and shadows
    every object regardless, so the shadow modes say so, naming light and setting. Nodes the preview applies
    (Blender's default Emission tree) are not named."""
    scene = half_plane_scene()
    sun = bpy.data.objects["Sun"]
    linked = scenes.new_collection("Hero")
    sun.light_linking.receiver_collection = linked
    sun.light_linking.blocker_collection = linked
    rim = scenes.link(bpy.data.objects.new("Rim", bpy.data.lights.new("Rim", "POINT")))
    rim.location = (0.0, 0.0, 3.0)
    scenes.light_nodes_on(rim.data)  # a Blackbody node feeds the Emission node's Color: not applied
    nodes = rim.data.node_tree.nodes
    emission = next(n for n in nodes if n.type == "EMISSION")
    rim.data.node_tree.links.new(nodes.new("ShaderNodeBlackbody").outputs[0], emission.inputs["Color"])
    fill = scenes.link(bpy.data.objects.new("Fill", bpy.data.lights.new("Fill", "POINT")))
    fill.location = (1.0, 0.0, 3.0)
    scenes.light_nodes_on(fill.data)  # Blender's default tree: applied, no warning

    def frame(mode):
        scene.kd_preview.mode = mode
        return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))

    assert not frame("ao").warnings
    assert sorted(frame("shadow").warnings) == [
        "light 'Rim': its shader nodes (only an Emission node's own Color and Strength are applied) not applied "
        "by the preview",
        "light 'Sun': light linking (collection 'Hero') not applied by the preview",
        "light 'Sun': shadow linking (collection 'Hero') not applied by the preview"]


def test_a_light_with_diffuse_ray_visibility_off_lights_nothing(addon):
    """Cycles lights no diffuse surface from a light whose Ray Visibility > Diffuse is off (its own or its
    instancer's), and N.L on diffuse surfaces is what the shadow modes show: such a light is left out, named,
    and the frame is the frame without it, bit for bit; switched back on, it lights again."""
    scene = half_plane_scene()

    def frame():
        return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))

    scene.kd_preview.mode = "shadow"
    without = frame()
    rim = scenes.link(bpy.data.objects.new("Rim", bpy.data.lights.new("Rim", "POINT")))
    rim.location = (0.0, 0.0, 3.0)
    lit = frame()
    assert not np.array_equal(lit.image, without.image)
    rim.visible_diffuse = False
    dark = frame()
    assert dark.warnings == ["light 'Rim' left out: its Ray Visibility > Diffuse is off, so it lights no diffuse "
                             "surface"]
    np.testing.assert_array_equal(dark.image, without.image)
    rim.visible_diffuse = True
    np.testing.assert_array_equal(frame().image, lit.image)


def test_object_ray_visibility_is_applied_and_changes_the_next_frame(addon):
    """Cycles' Ray Visibility: with camera rays off (or in an Indirect Only collection) the cube is not
    seen but still occludes the ground (inside its footprint, under its top and between its walls, AO
    is well below 1, where its open top is 1); with shadow rays off it is seen but the
    ground beside it is open. Each toggle renders anew (the last image is not reused), and a lazy
    build, one tree that cannot tell objects apart, names the cube instead."""
    scene = half_plane_scene()
    box = bpy.data.objects["Box"]

    def ao():
        result = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))
        return result.image[16, :, 0], result.warnings

    plain, _ = ao()
    box.visible_camera = False
    unseen, _ = ao()
    box.visible_camera = True
    homes = list(box.users_collection)
    indirect = scenes.new_collection("Indirect")
    bpy.context.view_layer.layer_collection.children["Indirect"].indirect_only = True
    for home in homes:
        home.objects.unlink(box)
    indirect.objects.link(box)
    indirect_only, warnings = ao()  # Cycles: the same image as camera rays off (render_visibility.py)
    np.testing.assert_array_equal(indirect_only, unseen)
    assert not warnings
    indirect.objects.unlink(box)
    for home in homes:
        home.objects.link(box)
    box.visible_shadow = False
    no_shadow, warnings = ao()
    assert plain[column_of(-2.0)] == 1.0 and unseen[column_of(-2.0)] < 0.6 and no_shadow[column_of(-2.0)] == 1.0
    assert plain[column_of(-2.6)] < 0.9 and unseen[column_of(-2.6)] < 0.9 and no_shadow[column_of(-2.6)] == 1.0
    assert not warnings
    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("Member", collection=source)
    scenes.add_collection_instance("FarInstancer", source, location=(100.0, 0.0, 0.0)).visible_camera = False
    scene.kd_preview.lazy = True
    lazy, warnings = ao()
    np.testing.assert_array_equal(lazy, plain)  # the instance is out of view
    assert warnings == [f"object '{name}': Ray Visibility and Holdout not applied with Lazy Build on (the scene is "
                        "traced as one tree)" for name in ("Box", "Member' instanced by 'FarInstancer")]


def test_holdout_leaves_its_pixels_empty_and_still_occludes(addon):
    """Cycles' Holdout: the cube's pixels are empty (alpha 0), the ground beside it is still occluded by
    it, and turning the holdout off renders the cube again (the last image is not reused)."""
    scene = half_plane_scene()
    box = bpy.data.objects["Box"]

    def render():
        return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))

    box.is_holdout = True
    cutout = render()
    row = cutout.image[16]
    assert (row[column_of(-2.0)] == 0.0).all() and row[column_of(-3.5), 3] == 1.0
    assert row[column_of(-2.6), 0] < 0.9 and row[column_of(-3.8), 0] == 1.0  # the ground beside it is occluded
    assert not cutout.warnings
    box.is_holdout = False
    shown = render()
    assert shown.image[16, column_of(-2.0), 3] == 1.0 and shown.image[16, column_of(-2.0), 0] == 1.0
    np.testing.assert_array_equal(shown.image[16, column_of(-2.6)], row[column_of(-2.6)])


def test_errors_leave_the_previous_image_and_report(addon):
    scene = half_plane_scene()
    bpy.ops.kdpreview.render()
    before = preview_pixels().copy()
    camera, scene.camera = scene.camera, None
    with pytest.raises(RuntimeError, match="has no active camera"):
        bpy.ops.kdpreview.render()
    scene.camera = camera
    scene.kd_preview.mode = "shadow"
    bpy.data.objects.remove(bpy.data.objects["Sun"])
    with pytest.raises(RuntimeError, match="needs a light"):
        bpy.ops.kdpreview.render()
    state = bpy.context.window_manager.kd_preview_state
    assert state.status.startswith("Error: mode 'shadow' needs a light") and not state.running
    assert (preview_pixels() == before).all()


def test_a_light_hidden_in_the_viewport_is_named(addon):
    """The viewport's depsgraph does not evaluate a light hidden there, so the preview cannot use it
    (a final render does): a warning names it in modes with lights, and when it was the only light
    the error says so instead of "no render-visible light"."""
    scene = half_plane_scene()
    scene.kd_preview.mode = "shadow"
    config = make_config(scene.kd_preview)
    scenes.link(bpy.data.objects.new("Hidden", bpy.data.lights.new("Hidden", "SUN"))).hide_set(True)
    result = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), config)
    assert result.lights == 1
    assert ("light 'Hidden' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): "
            "the preview leaves it out, a final render uses it") in result.warnings
    bpy.data.objects["Sun"].hide_set(True)
    with pytest.raises(PreviewError, match="has no light the preview can see: light '") as error:
        pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), config)
    assert "light 'Hidden' is hidden in the viewport" in str(error.value)
    assert "light 'Sun' is hidden in the viewport" in str(error.value)
    scene.kd_preview.mode = "ao"  # lights do not matter: no warning
    ao = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))
    assert not any("light" in w for w in ao.warnings)


def test_nothing_renderable_is_a_transparent_frame_with_a_warning_and_zero_size_is_named(addon):
    scene = half_plane_scene()
    for obj in ("Ground", "Box"):
        bpy.data.objects[obj].hide_render = True
    result = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))
    assert result.image.shape == (32, 64, 4) and (result.image == 0.0).all() and result.triangles == 0
    assert any(w.startswith("nothing to render at frame 1") for w in result.warnings)
    scene.render.resolution_x = 4
    scene.kd_preview.resolution_percentage = 10
    with pytest.raises(PreviewError, match="would be 0x3 pixels"):
        pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))


def test_cancel_callback_leaves_previous_image(addon):
    """A cancel after the tree is built (between trace steps) raises Cancelled; nothing is written."""
    scene = half_plane_scene()
    bpy.ops.kdpreview.render()
    before = preview_pixels().copy()
    scene.kd_preview.ao_distance = 3.0  # would change the image
    calls, fractions = [], []
    cancel = lambda: len(calls) >= 3 or calls.append(1)  # noqa: E731  (False twice, then True)
    with pytest.raises(Cancelled):
        pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview),
                              cancel=cancel, progress=lambda f, s: fractions.append(f))
    assert 0 < len(fractions) < 8 and fractions == sorted(fractions)
    assert (preview_pixels() == before).all() and not pipeline.job_running()


def test_one_job_at_a_time(addon):
    half_plane_scene()
    token = object()
    pipeline.claim(token)
    try:
        with pytest.raises(RuntimeError, match="already running"):
            bpy.ops.kdpreview.render()
    finally:
        pipeline.release(token)
    assert bpy.ops.kdpreview.render() == {"FINISHED"}


def test_a_users_image_named_kd_preview_is_left_alone(addon):
    """A user's own (byte) image called "KD Preview" is not renamed or written over."""
    half_plane_scene()
    mine = bpy.data.images.new(IMAGE_NAME, 4, 4)
    mine.pixels[:] = [0.5] * 64
    bpy.ops.kdpreview.render()
    bpy.ops.kdpreview.render()
    assert mine.name == IMAGE_NAME and not mine.get("kd_preview_image")
    np.testing.assert_allclose(mine.pixels[:], 0.5, atol=1 / 255)
    ours = [im for im in bpy.data.images if im.get("kd_preview_image")]
    assert len(ours) == 1 and ours[0].is_float and ours[0] != mine  # found again by its tag, not duplicated
    check_half_plane_image(preview_pixels(ours[0].name))


def test_without_an_image_editor_a_render_opens_one_where_blender_shows_renders(addon, monkeypatch):
    """Found in a real Blender: the default Layout workspace has no Image Editor, so Render showed
    nothing. render.view_show cannot open anything in background mode (checked: it returns
    PASS_THROUGH), so it is stood in for here by what it does with Render In: Image Editor."""
    scene = half_plane_scene()
    assert output.image_editors() == [] and output.open_render_view() == []  # background: nothing opens
    opened = []

    def render_view():
        area = bpy.context.window.screen.areas[-1]
        area.type = "IMAGE_EDITOR"
        area.spaces.active.image = bpy.data.images.new("Render Result", 4, 4)  # what view_show shows
        opened.append(area)
        return output.image_editors()

    monkeypatch.setattr(output, "open_render_view", render_view)
    assert bpy.ops.kdpreview.render() == {"FINISHED"}
    assert len(opened) == 1 and opened[0].spaces.active.image == bpy.data.images[IMAGE_NAME]
    opened[0].spaces.active.image = None
    scene.kd_preview.rebuild_all = True
    assert bpy.ops.kdpreview.render() == {"FINISHED"}
    assert len(opened) == 1 and opened[0].spaces.active.image == bpy.data.images[IMAGE_NAME]  # reused
    opened[0].type = "VIEW_3D"
    scene.kd_preview.live_update = True
    scene.frame_set(2)  # live update renders, but never opens an editor during playback
    assert json.loads(bpy.context.window_manager.kd_preview_state.last_run)["frame"] == 2
    assert len(opened) == 1 and output.image_editors() == []


def test_preview_image_is_resized_in_place_and_shown_in_an_image_editor(addon):
    scene = half_plane_scene()
    area = bpy.context.window.screen.areas[0]
    area.type = "IMAGE_EDITOR"
    bpy.ops.kdpreview.render()
    image = bpy.data.images[IMAGE_NAME]
    assert area.spaces.active.image == image
    scene.kd_preview.resolution_percentage = 50
    bpy.ops.kdpreview.render()
    assert bpy.data.images[IMAGE_NAME] == image and tuple(image.size) == (32, 16)
    img = preview_pixels()
    assert (img[:, :16, 3] == 1.0).all() and (img[:, 16:, 3] == 0.0).all()


def test_sampling_steps_grow_toward_the_step_time_and_stop_short_of_a_compile():
    """sampling_steps.next_batch: one sample first, then what the last step's rate fits in the step time,
    at most STEP_GROWTH times its samples, never past the target, and as core's batch_without_compile
    cuts it (here: as while the packed version is not cached, under 8)."""
    from types import SimpleNamespace

    asked = []
    renderer = SimpleNamespace(target_samples=100, samples_done=0,
                               batch_without_compile=lambda n: asked.append(n) or min(n, 7))
    assert sampling_steps.next_batch(renderer, None, 0.25) == 1
    # 5 ms a sample: 50 would fit in 0.25 s, STEP_GROWTH allows 16
    assert sampling_steps.next_batch(renderer, (1, 5.0), 0.25) == 7 and asked == [sampling_steps.STEP_GROWTH]
    assert sampling_steps.next_batch(renderer, (7, 70.0), 0.25) == 7 and asked[-1] == 25  # 10 ms a sample
    renderer.samples_done = 90
    assert sampling_steps.next_batch(renderer, (7, 700.0), 0.25) == 2 and asked[-1] == 2  # 100 ms a sample
    assert sampling_steps.next_batch(renderer, (7, 1e-9), 0.25) == 7 and asked[-1] == 10  # too quick to time
    assert sampling_steps.next_batch(renderer, (1, 5000.0), 0.25) == 1  # slower than the step time
    assert sampling_steps.next_batch(renderer, (1, 10.0), 1.0) == 7 and asked[-1] == 10  # FrameJob's default
    assert pipeline.FrameJob(None, None, None).step_seconds == sampling_steps.STEP_SECONDS


def test_a_frame_steps_in_growing_batches_with_the_one_sample_images(addon, monkeypatch):
    """The batches a FrameJob asks the renderer for (one, then more) give the image of one-sample steps
    (core: any batching gives the same sums)."""
    from kd_addon import corelib, tree_cache

    scene = half_plane_scene()
    scene.kd_preview.samples = 12
    steps = {}  # renderer -> its steps (a process's first frame also runs the made-up frames that load kernels)
    preview_render = corelib.load_core().PreviewRender
    original = preview_render.step
    monkeypatch.setattr(preview_render, "step", lambda self, n=1: steps.setdefault(self, []).append(n) or
                        original(self, n))
    batched = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))
    frame_steps = list(steps.values())[-1]
    assert frame_steps[0] == 1 and len(frame_steps) < 12 and sum(frame_steps) == 12
    monkeypatch.setattr(sampling_steps, "STEP_GROWTH", 0)  # then max(1, ...): every step one sample
    steps.clear()
    tree_cache.clear()  # no kept image
    single = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))
    assert list(steps.values()) == [[1] * 12]
    np.testing.assert_array_equal(batched.image, single.image)


def test_a_frame_takes_the_camera_packets_once_their_kernels_are_cached(addon, monkeypatch):
    """The add-on's renderer never waits for the packets' compile (core's compile_packets=False): while
    core says their kernels are not ready, its camera rays go singly; once ready, in packets (the warm-up's
    second stage caches them); the same image both ways."""
    import importlib

    from kd_addon import corelib, tree_cache

    render_module = importlib.import_module(corelib.load_core().__name__ + ".render.preview_render")
    scene, calls, images = half_plane_scene(), [], []
    real = render_module.trace_camera_packets
    monkeypatch.setattr(render_module, "trace_camera_packets", lambda *a: calls.append(1) or real(*a))
    for ready in (False, True):
        monkeypatch.setattr(render_module, "_packet_kernels_ready", lambda: ready)
        tree_cache.clear()  # no kept image
        images.append(pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(),
                                            make_config(scene.kd_preview)).image)
        assert bool(calls) == ready
    np.testing.assert_array_equal(images[0], images[1])


def test_a_first_frame_without_the_warm_up_compiles_the_add_ons_camera_pass(addon, monkeypatch):
    """A process's first frame with the warm-up off compiles its kernels beside the build
    (core.rendering_kernels_alongside), whose camera pass takes packets as the frame's own renderer does:
    only once cached (packets=False), so it compiles no packet kernel the frame would not run."""
    import contextlib

    from kd_addon import corelib, kernel_warmup, tree_cache

    core, asked = corelib.load_core(), []
    monkeypatch.setattr(core, "rendering_kernels_alongside",
                        lambda *a, **k: asked.append(k) or contextlib.nullcontext())
    monkeypatch.setattr(pipeline, "_kernels_ready", False)
    monkeypatch.setattr(kernel_warmup, "_warmup", kernel_warmup._Warmup())  # none ran in this process
    monkeypatch.setenv(kernel_warmup.SWITCH, "0")
    scene = half_plane_scene()
    tree_cache.clear()
    pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))
    assert asked and all(k.get("packets") is False for k in asked)


@pytest.mark.parametrize("color", [(math.nan, 1.0, 1.0), (-math.inf, 0.0, 0.0)])
def test_a_light_colour_that_is_not_a_number_is_named_not_called_black(color):
    """A NaN or infinite colour (a driver dividing by zero) is core's to refuse, naming the colour; before,
    max() of such a colour was not above 0 and the light was said to be black."""
    import core
    from kd_addon import light_use
    from kd_addon.scene_input import LightInput

    light = LightInput("Lamp", "sun", {"direction": (0.0, 0.0, -1.0), "strength": 1.0, "color": color})
    with pytest.raises(ValueError, match="light color must be 3 finite") as raised:
        light_use.usable_light(core, light)
    assert not isinstance(raised.value, light_use.EmitsNothing)
    assert light_use.refused_lights(core, [light])[0][0] is light
