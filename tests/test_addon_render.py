"""Operators, pipeline and live update in background mode, on scenes with a known answer.

half_plane_scene: an orthographic camera sees a plane over exactly the left half of the image
(x in [-4, 0] of an 8 x 4 view) with a 1 x 1 x 1 cube standing on it, so the hit mask and the
places where AO must be 1 (open plane, cube top) or below 1 (plane next to the cube) are known.
"""

from __future__ import annotations

import json
import math

import pytest

from tests.addon_support import exr_channels, half_plane_scene, preview_pixels

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from kd_addon import live_update, output, pipeline  # noqa: E402
from kd_addon.config import make_config  # noqa: E402
from kd_addon.errors import Cancelled, PreviewError  # noqa: E402
from kd_addon.output import IMAGE_NAME, save_frame  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402


def column_of(x, width=64):
    """Pixel column whose centre is at world x (view x in [-4, 4])."""
    return int((x + 4.0) / 8.0 * width)


def check_half_plane_image(img):
    """Alpha exactly on the left half; AO in [0, 1]; 1 on open ground and on the cube's top."""
    assert img.shape == (32, 64, 4) and img.dtype == np.float32
    assert (img[:, :32, 3] == 1.0).all() and (img[:, 32:, 3] == 0.0).all()
    assert (img[:, 32:, :3] == 0.0).all()
    ao = img[:, :32, 0]
    assert (ao >= 0.0).all() and (ao <= 1.0).all()
    assert (img[..., 0] == img[..., 1]).all() and (img[..., 1] == img[..., 2]).all()  # grey AO
    assert ao[16, column_of(-3.9)] == 1.0  # ground 1.4 from the cube: nothing within ao_distance 1
    assert ao[16, column_of(-2.0)] == 1.0  # centre of the cube's top face
    assert ao[16, column_of(-2.6)] < 0.9  # ground right beside the cube's wall


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
    (outside QA: both lit the floor and halved the real light's share of S, where Cycles' image is the
    sun's alone): Blender takes them all. Mode ao ignores lights; the shadow modes leave such lights
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
    """Outside QA: a sun whose Emission Strength is animated 1 -> 0 -> 1 stopped the whole animation at
    frame 2 ("needs a light"). Frame 2 now renders black with a warning (Cycles' image is black too),
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
    the error says so instead of "no render-visible light" (outside QA)."""
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


def test_animation_writes_frames_and_report(addon, tmp_path):
    scene = half_plane_scene()
    box = bpy.data.objects["Box"]
    box.keyframe_insert("location", frame=1)
    box.location.x = -1.0
    box.keyframe_insert("location", frame=3)
    scene.frame_start, scene.frame_end, scene.frame_current = 1, 3, 2
    scene.kd_preview.output_dir = str(tmp_path / "seq")
    scene.kd_preview.output_format = "OPEN_EXR"
    assert bpy.ops.kdpreview.render_animation() == {"FINISHED"}
    assert scene.frame_current == 2  # put back
    names = sorted(p.name for p in (tmp_path / "seq").iterdir())
    assert names == ["frame_0001.exr", "frame_0002.exr", "frame_0003.exr", "report.json"]
    report = json.loads((tmp_path / "seq" / "report.json").read_text())
    assert [row["frame"] for row in report["frames"]] == [1, 2, 3]
    for row in report["frames"]:
        for key in ("triangles", "objects", "extract_ms", "build_ms", "trace_ms", "total_ms", "rays",
                    "mrays_per_s", "tree", "file"):
            assert key in row, key
        assert row["total_ms"] >= row["extract_ms"] + row["build_ms"] + row["trace_ms"]
        assert "build_ms" not in row["tree"]  # the trees' own build times, kept ones included: not this frame's
    assert report["settings"]["output_format"] == "OPEN_EXR" and report["resolution"] == [64, 32]
    assert report["totals"]["frames"] == 3 and report["totals"]["rays"] == sum(r["rays"] for r in report["frames"])
    exr = bpy.data.images.load(str(tmp_path / "seq" / "frame_0003.exr"))
    pixels = np.empty(64 * 32 * 4, np.float32)
    exr.pixels.foreach_get(pixels)
    img = pixels.reshape(32, 64, 4)[::-1]
    assert (img[:, :32, 3] == 1.0).all() and (img[:, 32:, 3] == 0.0).all()
    assert img[16, column_of(-1.0), 0] == pytest.approx(1.0, abs=1e-3)  # box moved to x = -1: its top is open


def test_exr_frames_hold_the_linear_values(tmp_path):
    """The EXR holds the image's own (linear) floats: Image.save() would store 0.5 as 0.7354 (sRGB)."""
    scenes.reset()
    image = np.zeros((3, 5, 4), np.float32)
    image[..., 0] = np.linspace(0.0, 1.0, 5)
    image[..., 1], image[..., 2], image[..., 3] = 0.25, 0.5, 1.0
    image[2, 4] = 0.0  # one background pixel, bottom right
    save_frame(image, tmp_path / "f.exr", "OPEN_EXR")
    channels = exr_channels(tmp_path / "f.exr")
    stored = np.stack([channels[c] for c in "RGBA"], axis=-1)
    assert np.array_equal(stored, image)
    assert [s.name for s in bpy.data.scenes] == ["Scene"]  # the scratch scene for the settings is gone


@pytest.mark.parametrize("file_format, name", [("PNG", "f.png"), ("OPEN_EXR", "f.exr")])
def test_a_frame_that_fails_to_save_leaves_the_earlier_file_whole(tmp_path, monkeypatch, file_format, name):
    """Frames are written beside their name and renamed over it, so a save that fails (or a run killed)
    halfway leaves the earlier run's file as it was, and no partial file."""
    from kd_addon import output
    scenes.reset()
    image = np.full((3, 5, 4), 0.5, np.float32)
    path = save_frame(image, tmp_path / name, file_format)
    before = path.read_bytes()

    def half_written(_image, partial, *args):
        partial.write_bytes(before[: len(before) // 2])
        raise OSError("disk full")

    monkeypatch.setattr(output, "_save_linear_exr" if file_format == "OPEN_EXR" else "_save_png", half_written)
    with pytest.raises(OSError, match="disk full"):
        save_frame(np.zeros((3, 5, 4), np.float32), path, file_format)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_a_report_that_fails_on_the_last_frame_is_written_when_the_sequence_closes(addon, tmp_path,
                                                                                     monkeypatch):
    """A signal (or a full disk) while the last frame's report is written: close() writes it (review:
    the folder held both frames and the report listed one, incomplete). Reports while the sequence
    runs are best effort: the first frame's failing report does not stop it."""
    from kd_addon import sequence
    scene = half_plane_scene()
    real = sequence.write_report
    calls = []

    def flaky(out_dir, scene_name, config, results, *rest):
        calls.append(len(results))
        if len(calls) <= 2:  # frame 1's report (disk full), then frame 2's (a signal)
            raise (PreviewError("disk full") if len(calls) == 1 else KeyboardInterrupt)
        return real(out_dir, scene_name, config, results, *rest)

    monkeypatch.setattr(sequence, "write_report", flaky)
    job = sequence.SequenceJob(scene, make_config(scene.kd_preview), [1, 2], tmp_path / "seq",
                               lambda _scene: bpy.context.evaluated_depsgraph_get())
    with pytest.raises(KeyboardInterrupt):
        while not job.tick():
            pass
    job.close()
    assert calls == [1, 2, 2]
    report = json.loads((tmp_path / "seq" / "report.json").read_text())
    assert report["complete"] is True and [f["file"] for f in report["frames"]] == ["frame_0001.png", "frame_0002.png"]
    assert sorted(p.name for p in (tmp_path / "seq").iterdir()) == ["frame_0001.png", "frame_0002.png", "report.json"]


def _fail_at_frame_3(scene):
    """Key the camera's clip end below its clip start at frame 3: frames 1 and 2 render, 3 stops the run."""
    camera = scene.camera.data
    camera.clip_start = 0.1
    for frame, value in ((2, 100.0), (3, 0.05)):
        camera.clip_end = value
        camera.keyframe_insert("clip_end", frame=frame)
    scene.frame_start, scene.frame_end = 1, 3


def test_a_failed_animation_puts_the_preview_and_its_figures_back(addon, tmp_path):
    """Outside review: an animation that failed at frame 3 left frame 2 in the preview image (its frames
    pass through it on their way to disk) under the panel's figures of the render before. The frames
    written stay on disk; the preview is the one before the run."""
    scene = half_plane_scene()
    _fail_at_frame_3(scene)
    scene.frame_set(1)
    scene.kd_preview.ao_distance = 0.2
    bpy.ops.kdpreview.render()
    before, state = preview_pixels().copy(), bpy.context.window_manager.kd_preview_state
    last_run = state.last_run
    scene.kd_preview.ao_distance = 3.0  # frames of the animation differ from the preview
    scene.kd_preview.output_dir = str(tmp_path)
    with pytest.raises(RuntimeError, match="frame 3.*clip start 0.1 is not below clip end 0.05"):
        bpy.ops.kdpreview.render_animation()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frame_0001.png", "frame_0002.png", "report.json"]
    assert np.array_equal(preview_pixels(), before) and state.last_run == last_run
    assert scene.frame_current == 1


def test_a_failed_first_animation_leaves_no_preview_image(addon, tmp_path):
    scene = half_plane_scene()
    _fail_at_frame_3(scene)
    scene.kd_preview.output_dir = str(tmp_path)
    with pytest.raises(RuntimeError, match="clip start"):
        bpy.ops.kdpreview.render_animation()
    assert IMAGE_NAME not in bpy.data.images and len(list(tmp_path.iterdir())) == 3


def test_animation_needs_a_saved_file_for_relative_output(addon):
    half_plane_scene()
    with pytest.raises(RuntimeError, match="relative to the .blend file, which is not saved"):
        bpy.ops.kdpreview.render_animation()


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
    """Outside QA (Blender 5.2.2): a setting set from Python makes no depsgraph update, so Live Update
    did not render it; nor did switching Live Update on. Settings now schedule the render themselves."""
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


def test_a_users_image_named_kd_preview_is_left_alone(addon):
    """Found by outside QA: a user's own (byte) image called "KD Preview" was silently renamed."""
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
