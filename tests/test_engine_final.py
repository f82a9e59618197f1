"""Final renders through the KD_PREVIEW render engine (bpy.ops.render.render, as F12 / Ctrl-F12 / `-E`).

The reference for pixels is the sidebar panel's render of the same frame (kd_addon.operators through the
viewport's depsgraph, a path the engine shares only the tracer with): with the camera, size and settings
equal, both images must be equal. Files are read back with the tests' own EXR reader, not Blender.
"""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from kd_addon import engine_final, kernel_warmup, pipeline, tree_cache
from tests import bpy_scenes as scenes
from tests.addon_support import (add_quad, add_sun, check_half_plane_image, exr_channels, half_plane_scene,
                                 preview_pixels)


def engine_scene(tmp_path, *, exr=True, name="frame"):
    """half_plane_scene (64 x 32 at 100 %) on the engine, writing an uncompressed RGBA EXR (or PNG), with
    Film > Transparent on: alpha is the hit coverage, as in the panel's image."""
    scene = half_plane_scene()
    scene.render.engine = "KD_PREVIEW"
    scene.render.film_transparent = True
    scene.render.resolution_percentage = 100
    settings = scene.render.image_settings
    if exr:
        settings.file_format, settings.color_mode, settings.exr_codec = "OPEN_EXR", "RGBA", "NONE"
    else:
        settings.file_format = "PNG"
    scene.render.filepath = str(tmp_path / name)
    return scene


def read_rgba(path) -> np.ndarray:
    """(H, W, 4), row 0 at the top, of a single-layer EXR."""
    channels = exr_channels(str(path))
    return np.stack([channels[c] for c in "RGBA"], axis=-1)


def panel_image(scene, **settings) -> np.ndarray:
    """The sidebar panel's render of the scene at its scene resolution (kd_preview.resolution_percentage
    set to the scene's), with `settings` set for it and put back afterwards; nothing reused."""
    settings = {"rebuild_all": True} | settings  # its own trees and image, none kept from the engine's frames
    kept = {name: getattr(scene.kd_preview, name) for name in settings}
    for name, value in settings.items():
        setattr(scene.kd_preview, name, value)
    scene.kd_preview.resolution_percentage = scene.render.resolution_percentage
    try:
        assert bpy.ops.kdpreview.render() == {"FINISHED"}
        return preview_pixels()
    finally:
        for name, value in kept.items():
            setattr(scene.kd_preview, name, value)


@pytest.fixture
def results(monkeypatch):
    """The FrameResults of the engine's frames, in order (spied on its stats line)."""
    seen = []
    original = engine_final.stats_line

    def spy(result):
        seen.append(result)
        return original(result)

    monkeypatch.setattr(engine_final, "stats_line", spy)
    return seen


def test_engine_is_listed_and_its_panels_poll_on_it(addon):
    scene = bpy.context.scene
    assert bpy.types.RenderEngine.bl_rna_get_subclass_py("KD_PREVIEW").bl_label == "KD Preview"
    with pytest.raises(TypeError):  # the engine list refuses an engine not in it...
        scene.render.engine = "KD_PREVIEW_NOT_REGISTERED"
    scene.render.engine = "KD_PREVIEW"  # ... and takes this one
    assert scene.render.engine == "KD_PREVIEW"
    panel = bpy.types.KDPREVIEW_PT_render_settings
    assert panel.bl_context == "render" and panel.COMPAT_ENGINES == {"KD_PREVIEW"}
    assert "KD_PREVIEW" in bpy.types.RENDER_PT_color_management.COMPAT_ENGINES
    assert hasattr(bpy.types, "KDPREVIEW_PT_panel")  # the sidebar panel stays
    addon.unregister()
    assert bpy.types.RenderEngine.bl_rna_get_subclass_py("KD_PREVIEW") is None
    assert "KD_PREVIEW" not in bpy.types.RENDER_PT_color_management.COMPAT_ENGINES


def test_still_render_writes_the_panels_image_to_the_output_path(addon, tmp_path, results):
    scene = engine_scene(tmp_path)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    written = read_rgba(tmp_path / "frame.exr")
    check_half_plane_image(written)
    assert np.array_equal(written, panel_image(scene))
    assert results[0].rays > 0 and results[0].triangles == 14


@pytest.mark.parametrize("world", [True, False])
def test_film_not_transparent_puts_the_worlds_viewport_colour_behind(addon, tmp_path, world):
    """Film > Transparent off, as Cycles, EEVEE and Workbench: alpha 1 everywhere, and where nothing is hit
    the world's viewport colour (what Workbench shows; the preview reads no world shader), black without
    a world. Hit pixels keep the transparent render's values."""
    scene = engine_scene(tmp_path)
    bpy.ops.render.render(write_still=True)
    transparent = read_rgba(tmp_path / "frame.exr")
    scene.render.film_transparent = False
    scene.world = bpy.data.worlds.new("Sky") if world else None
    if world:
        scene.world.color = (0.2, 0.3, 0.4)
    scene.render.filepath = str(tmp_path / "opaque")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    opaque = read_rgba(tmp_path / "opaque.exr")
    hit = transparent[..., 3] == 1.0
    assert hit.any() and not hit.all() and (opaque[..., 3] == 1.0).all()
    assert np.array_equal(opaque[hit], transparent[hit])
    expected = np.float32([0.2, 0.3, 0.4]) if world else np.zeros(3, np.float32)
    assert (opaque[~hit][:, :3] == expected).all()


def test_an_animation_puts_each_frames_keyed_world_colour_behind(addon, tmp_path):
    """A keyed world colour is the frame's in an animation render too (read from the evaluated world:
    the original one keeps the colour of the frame the render started at)."""
    scene = engine_scene(tmp_path)
    scene.render.film_transparent = False
    scene.world = bpy.data.worlds.new("Keyed")
    for frame, colour in ((1, (0.1, 0.1, 0.1)), (3, (0.8, 0.2, 0.1))):
        scene.world.color = colour
        scene.world.keyframe_insert("color", frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(1)
    scene.render.filepath = str(tmp_path / "anim_")
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    for frame in (1, 2, 3):
        scene.frame_set(frame)
        expected = np.float32(scene.world.color[:3])
        background = read_rgba(tmp_path / f"anim_{frame:04d}.exr")[0, -1]  # top right: nothing hit there
        assert background[3] == 1.0 and np.allclose(background[:3], expected, atol=1e-6), frame
    assert not np.allclose(read_rgba(tmp_path / "anim_0001.exr")[0, -1], read_rgba(tmp_path / "anim_0003.exr")[0, -1])


def test_film_not_transparent_with_a_holdout_stays_transparent_and_says_so(addon, tmp_path, monkeypatch):
    """Cycles keeps a holdout's pixels at alpha 0 over an opaque film; the image cannot tell them from the
    background's, so the frame is written as with Film > Transparent on, and a warning says why."""
    scene = engine_scene(tmp_path)
    bpy.data.objects["Box"].is_holdout = True
    bpy.ops.render.render(write_still=True)
    transparent = read_rgba(tmp_path / "frame.exr")
    scene.render.film_transparent = False
    reported = []
    monkeypatch.setattr(engine_final.FinalRender, "_report_warning", lambda self, text: reported.append(text))
    scene.render.filepath = str(tmp_path / "opaque")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert np.array_equal(read_rgba(tmp_path / "opaque.exr"), transparent)
    assert (transparent[..., 3] == 0.0).sum() > 32 * 32  # the right half and the box's top
    assert any("Film > Transparent off is not applied to a frame with holdout objects" in text for text in reported)


def test_png_and_the_scenes_resolution_percentage(addon, tmp_path):
    scene = engine_scene(tmp_path, exr=False)
    scene.render.resolution_percentage = 50
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    image = bpy.data.images.load(str(tmp_path / "frame.png"))
    assert tuple(image.size) == (32, 16)


@pytest.mark.parametrize("crop", [True, False])
def test_render_region_renders_the_frames_pixels_there(addon, tmp_path, crop):
    """The region's pixels are the whole frame's there: the same surfaces hit (alpha, exact) and, as the
    samples of a pixel depend on its index in the image, AO equal in the mean. A strip over the top right
    breaks the symmetry in y. (engine_final.crop_camera's rays are checked exactly in test_engine_camera.py.)"""
    scene = engine_scene(tmp_path)
    scene.kd_preview.samples = 32
    add_quad("Strip", 2.0, 0.75, location=(2.0, 1.25, 0.0))  # x in [0, 4], y in [0.5, 2]: rows 0-11, right half
    bpy.ops.render.render(write_still=True)
    whole = read_rgba(tmp_path / "frame.exr")
    assert whole[:12, 40:, 3].all() and not whole[12:, 40:, 3].any()
    render = scene.render
    render.use_border, render.use_crop_to_border = True, crop
    render.border_min_x, render.border_max_x, render.border_min_y, render.border_max_y = 0.25, 0.7, 0.2, 0.9
    scene.render.filepath = str(tmp_path / "region")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    region = read_rgba(tmp_path / "region.exr")
    x, y, w, h = engine_final.border_region(render, 64, 32)
    assert (x, y, w, h) == (16, 4, 28, 22)  # 0.9 * 32 = 28.8 -> 28 (from the bottom), 0.2 * 32 -> 6
    inside = region if crop else region[y:y + h, x:x + w]
    assert inside.shape == (h, w, 4)
    assert np.array_equal(inside[..., 3], whole[y:y + h, x:x + w, 3])
    assert abs(inside[..., 0].mean() - whole[y:y + h, x:x + w, 0].mean()) < 0.01
    if not crop:
        outside = np.ones((32, 64), bool)
        outside[y:y + h, x:x + w] = False
        assert (region[outside] == 0.0).all()


def test_animation_writes_the_frame_range_by_step_and_reuses_trees(addon, tmp_path, results):
    scene = engine_scene(tmp_path, name="anim_")
    box = bpy.data.objects["Box"]
    box.location.x = -2.5
    box.keyframe_insert("location", frame=1)
    box.location.x = -1.5
    box.keyframe_insert("location", frame=5)
    scene.frame_start, scene.frame_end, scene.frame_step = 1, 5, 2
    tree_cache.clear()
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim_0001.exr", "anim_0003.exr", "anim_0005.exr"]
    assert [r.frame for r in results] == [1, 3, 5]
    assert results[0].objects_rebuilt == 2
    # moved, not edited: once the builder knows the box moves (core.SceneBuilder), both trees are kept,
    # and so are the pixels whose rays cannot reach the box
    assert (results[2].objects_rebuilt, results[2].objects_reused) == (0, 2)
    assert results[2].pixels_reused > 0
    first, last = read_rgba(tmp_path / "anim_0001.exr"), read_rgba(tmp_path / "anim_0005.exr")
    assert not np.array_equal(first, last)
    scene.frame_set(5)
    assert np.array_equal(last, panel_image(scene))  # a kept pixel is the pixel a fresh render makes


def test_an_animation_follows_keyed_ray_visibility_and_holdout(addon, tmp_path):
    """A render's own depsgraph animates its evaluated objects only, not the originals the viewport's
    flags are read from: an animation through the engine (Ctrl-F12, `-a`) takes each frame's keyed
    Ray Visibility > Camera and Holdout, as the panel's render of that frame does."""
    scene = engine_scene(tmp_path, name="anim_")
    box = bpy.data.objects["Box"]
    for frame, camera, holdout in ((1, True, False), (2, False, False), (3, True, True)):
        box.visible_camera, box.is_holdout = camera, holdout
        box.keyframe_insert("visible_camera", frame=frame)
        box.keyframe_insert("is_holdout", frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(1)  # the originals hold frame 1's flags while the engine renders frames 2 and 3
    tree_cache.clear()
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    frames = [read_rgba(tmp_path / f"anim_{frame:04d}.exr") for frame in (1, 2, 3)]
    box_pixels = frames[0][..., 3] - frames[2][..., 3] == 1.0  # the holdout's hole in frame 3
    assert box_pixels.any() and not np.array_equal(frames[0], frames[1])
    for frame, image in zip((1, 2, 3), frames):
        scene.frame_set(frame)
        assert np.array_equal(image, panel_image(scene)), f"frame {frame}"


def test_an_animation_follows_a_light_instancers_keyed_diffuse_visibility(addon, tmp_path):
    """An instanced sun whose instancer's Ray Visibility > Diffuse is keyed off on frame 2 lights no
    diffuse surface there (Cycles ANDs the flags): the shadow term is 0 on that frame of an engine
    animation, as in the panel's render of it."""
    scene = engine_scene(tmp_path, name="anim_")
    scene.kd_preview.mode = "shadow"
    sun = bpy.data.objects["Sun"]
    source = scenes.new_collection("Lamps", exclude=True)
    scene.collection.objects.unlink(sun)
    source.objects.link(sun)
    instancer = scenes.add_collection_instance("LampRig", source)
    for frame, diffuse in ((1, True), (2, False)):
        instancer.visible_diffuse = diffuse
        instancer.keyframe_insert("visible_diffuse", frame=frame)
    scene.frame_start, scene.frame_end = 1, 2
    scene.frame_set(1)
    tree_cache.clear()
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    frames = [read_rgba(tmp_path / f"anim_{frame:04d}.exr") for frame in (1, 2)]
    assert frames[0][..., 0].max() > 0.0 and frames[1][..., :3].max() == 0.0
    for frame, image in zip((1, 2), frames):
        scene.frame_set(frame)
        assert np.array_equal(image, panel_image(scene)), f"frame {frame}"



def render_multilayer_exr(scene, folder):
    """F12 into an uncompressed multilayer EXR (the scene writes `frame.exr` in `folder`): its channels."""
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):  # Blender 5.0 on
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format, settings.exr_codec = "OPEN_EXR_MULTILAYER", "NONE"
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    return exr_channels(str(folder / "frame.exr"))

def test_passes_reach_the_render_result_and_a_multilayer_exr(addon, tmp_path):
    scene = engine_scene(tmp_path)
    layer = scene.view_layers[0]
    layer.use_pass_ambient_occlusion = layer.use_pass_shadow = layer.use_pass_z = True
    scene.kd_preview.mode = "ao+shadow"
    channels = render_multilayer_exr(scene, tmp_path)
    prefix = f"{layer.name}."

    def rgb(name):
        return np.stack([channels[f"{prefix}{name}.{c}"] for c in "RGB"], axis=-1)

    combined = np.stack([channels[f"{prefix}Combined.{c}"] for c in "RGBA"], axis=-1)
    assert np.array_equal(combined, panel_image(scene))
    assert np.array_equal(rgb("AO"), panel_image(scene, mode="ao")[..., :3])
    assert np.array_equal(rgb("Shadow"), panel_image(scene, mode="shadow")[..., :3])
    depth = channels[f"{prefix}Depth.Z"]
    hit = combined[..., 3] > 0
    # camera at z = 10 looking down: the ground (z = 0) at 10, the box's top (z = 1) at 9, nothing else
    assert np.allclose(depth[hit][np.abs(depth[hit] - 9.0) > 1e-3], 10.0, atol=1e-4)
    assert (np.abs(depth[hit] - 9.0) < 1e-3).any()
    assert (depth[~hit] == engine_final.NO_HIT_DEPTH).all()
    assert not np.array_equal(rgb("AO"), rgb("Shadow"))


class FakeEngine:
    """The RenderEngine calls FinalRender makes, recorded; test_break True from its `breaks_at`-th poll."""

    def __init__(self, width, height, breaks_at):
        self.resolution_x, self.resolution_y, self.breaks_at = width, height, breaks_at
        self.polls, self.calls = 0, []

    def test_break(self):
        self.polls += 1
        return self.polls >= self.breaks_at

    def __getattr__(self, name):  # update_stats, update_progress, report, begin_result, ...
        return lambda *args, **kwargs: self.calls.append(name)


@pytest.mark.parametrize("breaks_at", [1, 2, 4])
def test_cancel_mid_frame_hands_blender_no_result(addon, tmp_path, breaks_at):
    """test_break is polled between the frame's short ticks (scene read, build, each sample); once it
    says stop, no result is opened, so Blender has nothing to write (with Esc it writes nothing at all:
    its own break flag is set), and the scene is as it was."""
    scene = engine_scene(tmp_path)
    scene.kd_preview.samples = 64
    objects_before = sorted(ob.name for ob in scene.objects)
    fake = FakeEngine(64, 32, breaks_at)
    engine_final.FinalRender(fake, bpy.context.evaluated_depsgraph_get()).run()
    assert fake.polls == breaks_at
    assert "begin_result" not in fake.calls and "end_result" not in fake.calls and "report" not in fake.calls
    assert sorted(ob.name for ob in scene.objects) == objects_before
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}  # the cancelled job left no claim behind
    check_half_plane_image(read_rgba(tmp_path / "frame.exr"))


def test_ctrl_c_in_a_script_writes_nothing_and_fails_the_render(addon, tmp_path, monkeypatch):
    """Ctrl-C while a script drives the bpy module raises KeyboardInterrupt where the frame polls its
    worker (FrameJob.tick). The engine reports it, so Blender keeps the last good file instead of writing
    an empty image over it, and the script's render call fails instead of going on."""
    scene = engine_scene(tmp_path)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    before = (tmp_path / "frame.exr").read_bytes()
    bpy.data.objects["Box"].location.x += 0.5
    ticks = []
    original = pipeline.FrameJob.tick

    def interrupted_tick(job):
        ticks.append(job)
        if len(ticks) == 2:
            raise KeyboardInterrupt
        return original(job)

    monkeypatch.setattr(pipeline.FrameJob, "tick", interrupted_tick)
    with pytest.raises(RuntimeError, match=r"interrupted \(Ctrl-C\): nothing written for this frame"):
        bpy.ops.render.render(write_still=True)
    assert (tmp_path / "frame.exr").read_bytes() == before
    monkeypatch.setattr(pipeline.FrameJob, "tick", original)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}  # no claim left behind
    assert (tmp_path / "frame.exr").read_bytes() != before


def test_ctrl_c_in_a_script_stops_an_animation_and_keeps_the_frames_written(addon, tmp_path, monkeypatch):
    scene = engine_scene(tmp_path, name="anim_")
    scene.frame_start, scene.frame_end = 1, 3
    original = pipeline.FrameJob.tick

    def tick(job):
        if scene.frame_current == 2:
            raise KeyboardInterrupt
        return original(job)

    monkeypatch.setattr(pipeline.FrameJob, "tick", tick)
    with pytest.raises(RuntimeError, match=r"KD Preview: frame 2: interrupted \(Ctrl-C\)"):  # the frame named
        bpy.ops.render.render(animation=True)
    assert sorted(path.name for path in tmp_path.iterdir()) == ["anim_0001.exr"]
    check_half_plane_image(read_rgba(tmp_path / "anim_0001.exr"))


def test_passes_the_engine_does_not_make_are_named_in_a_warning(addon, tmp_path, monkeypatch):
    """Blender makes only the passes an engine registers: the others a view layer asks for (here Normal,
    Mist, Cryptomatte Object and an AOV) are missing from the file, and a warning names them."""
    scene = engine_scene(tmp_path)
    layer = bpy.context.view_layer
    layer.use_pass_normal = layer.use_pass_mist = layer.use_pass_cryptomatte_object = layer.use_pass_z = True
    layer.aovs.add().name = "Mask"
    reported = []
    monkeypatch.setattr(engine_final.FinalRender, "_report_warning", lambda self, text: reported.append(text))
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    left_out = [text for text in reported if "passes this engine does not make are left out" in text]
    assert len(left_out) == 1
    for name in ("Normal", "Mist", "Cryptomatte Object", "AOV Mask"):
        assert name in left_out[0]
    assert "Depth, " not in left_out[0].split("(")[0] and "Cryptomatte Accurate" not in left_out[0]
    for switch in ("use_pass_normal", "use_pass_mist", "use_pass_cryptomatte_object", "use_pass_z"):
        setattr(layer, switch, False)
    layer.aovs.remove(layer.aovs[0])
    reported.clear()
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert not any("left out" in text for text in reported)


def test_an_error_is_reported_not_raised_and_writes_nothing(addon, tmp_path):
    scene = engine_scene(tmp_path)
    bpy.data.objects.remove(bpy.data.objects["Sun"])
    scene.kd_preview.mode = "shadow"
    try:
        bpy.ops.render.render(write_still=True)
    except RuntimeError as error:  # Blender turns the engine's ERROR report into the operator's error
        assert "needs a light" in str(error) and "Traceback" not in str(error)
    assert not (tmp_path / "frame.exr").exists()


def _occluder_scene(tmp_path, mode):
    """engine_scene with a wall beside the box that casts a shadow and darkens the ground's AO."""
    scene = engine_scene(tmp_path)
    scene.kd_preview.mode = mode
    wall = scenes.add_cube("Wall", scale=0.5, location=(-3.2, 0.0, 0.5))
    wall.scale = (0.2, 1.5, 1.0)
    bpy.data.objects["Sun"].rotation_euler = (0.0, 0.8, 0.0)
    return scene, wall


@pytest.mark.parametrize("mode", ["ao", "shadow"])
def test_an_object_disabled_in_viewports_is_in_the_final_render(addon, tmp_path, mode):
    """The panel reads the viewport's depsgraph, which has no such object; the engine reads the render's."""
    scene, wall = _occluder_scene(tmp_path, mode)
    with_wall = panel_image(scene)
    wall.hide_viewport = True
    without_wall = panel_image(scene)
    assert not np.array_equal(with_wall, without_wall)  # the wall changes the image (its shadow, its AO)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert np.array_equal(read_rgba(tmp_path / "frame.exr"), with_wall)


def test_a_render_only_subdivision_level_is_traced(addon, tmp_path, results):
    scene = engine_scene(tmp_path)
    box = bpy.data.objects["Box"]
    subsurf = box.modifiers.new("Subdivision", "SUBSURF")
    subsurf.levels, subsurf.render_levels = 0, 2
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert results[0].triangles == 2 + 6 * 16 * 2  # ground quad + the cube's 6 faces at level 2
    assert not any("viewport" in w for w in results[0].warnings)
    panel_image(scene)
    last = bpy.context.window_manager.kd_preview_state.last_run
    assert '"triangles": 14' in last  # the panel traces the viewport's level 0


def test_a_render_only_modifier_and_sun_light(addon, tmp_path, results):
    """A modifier shown in renders only (Solidify here) is applied by the final render."""
    engine_scene(tmp_path)
    ground = bpy.data.objects["Ground"]
    solidify = ground.modifiers.new("Solidify", "SOLIDIFY")
    solidify.show_viewport, solidify.show_render = False, True
    add_sun("Sun2")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert results[0].triangles > 14


def test_every_view_layer_enabled_for_rendering_gets_its_own_image(addon, tmp_path):
    """Blender renders each view layer with its own depsgraph: a layer excluding the box's collection
    shows no box, the other does, each in its own layer of the multilayer EXR."""
    scene = engine_scene(tmp_path)
    boxes = scenes.new_collection("Boxes")
    box = bpy.data.objects["Box"]
    for collection in box.users_collection:
        collection.objects.unlink(box)
    boxes.objects.link(box)
    second = scene.view_layers.new("NoBox")
    second.layer_collection.children["Boxes"].exclude = True
    channels = render_multilayer_exr(scene, tmp_path)
    first = channels[f"{scene.view_layers[0].name}.Combined.R"]
    without = channels["NoBox.Combined.R"]
    box_top = (slice(14, 18), slice(14, 18))  # the box's top face, AO 1 there; open ground too without it
    ground_beside = (slice(14, 18), slice(20, 22))  # ground beside the box's wall: darker with the box
    assert first[ground_beside].mean() < without[ground_beside].mean() - 0.05
    assert np.array_equal(channels["NoBox.Combined.A"], channels[f"{scene.view_layers[0].name}.Combined.A"])
    assert first[box_top].min() > 0.0


def _composite_pass(scene, name):
    """The compositor's output: the Render Layers node's `name` socket (Blender 5.0 on: the scene's
    compositing node group's Group Output; before: the scene's node tree's Composite node)."""
    if hasattr(scene, "compositing_node_group"):
        tree = bpy.data.node_groups.new("KD Compositing", "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        scene.compositing_node_group = tree
        output = tree.nodes.new("NodeGroupOutput")
    else:
        scene.use_nodes = True
        tree = scene.node_tree
        tree.nodes.clear()
        output = tree.nodes.new("CompositorNodeComposite")
    layers = tree.nodes.new("CompositorNodeRLayers")
    layers.scene = scene
    tree.links.new(layers.outputs[name], output.inputs[0])
    scene.render.use_compositing = True


def test_the_compositor_reads_a_named_pass(addon, tmp_path):
    """update_render_passes names the AO pass for the Render Layers node: routed to the output, the
    written image is the AO term."""
    scene = engine_scene(tmp_path)
    scene.kd_preview.mode = "ao+shadow"
    scene.view_layers[0].use_pass_ambient_occlusion = True
    _composite_pass(scene, "AO")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    written = read_rgba(tmp_path / "frame.exr")
    ao = panel_image(scene, mode="ao")
    assert np.allclose(written[..., :3], ao[..., :3], atol=1e-6)
    assert not np.allclose(written[..., :3], panel_image(scene)[..., :3], atol=1e-3)  # not the Combined image


def test_warnings_are_reported_with_the_frame(addon, tmp_path, monkeypatch):
    """What the preview does not apply (here the camera's depth of field) is reported, and the frame is
    written."""
    scene = engine_scene(tmp_path)
    scene.camera.data.dof.use_dof = True
    reported = []
    monkeypatch.setattr(engine_final.FinalRender, "_report_warning",
                        lambda self, text: reported.append(text))
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert any("depth of field" in text for text in reported)
    assert (tmp_path / "frame.exr").is_file()


def test_a_background_render_says_once_that_it_waits_for_the_first_compile(addon, tmp_path, monkeypatch, capfd):
    """Blender shows no status line in a background render (blender -b, a bpy script), so a frame that
    waits for the kernels' first compile prints that wait, once while its counter ticks, and nothing
    once the kernels are ready."""
    real_status, seen = pipeline.FrameJob.status, []

    def status(job):
        seen.append(None)
        if len(seen) <= 3:  # the warm-up's counting status (kernel_warmup), as a first render sees it
            return f"compiling kernels (first use) {len(seen)}s" + pipeline.WARMUP_WAIT_NOTE
        return real_status.fget(job)

    monkeypatch.setattr(pipeline.FrameJob, "status", property(status))
    monkeypatch.setattr(kernel_warmup, "second_stage_cached", lambda: True)  # no note of the second stage
    engine_scene(tmp_path)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    said = [line for line in capfd.readouterr().out.splitlines() if line.startswith("KD Preview: ")]
    assert len(seen) > 3 and said == [
        "KD Preview: compiling kernels (first use) 1s: the render starts when they are ready "
        "(once per installation)"]


@pytest.mark.parametrize("cached", [False, True])
def test_a_background_render_names_the_compile_command_once_until_it_has_run(addon, tmp_path, monkeypatch, capfd,
                                                                            cached):
    """A background render starts no second warm-up stage: until its kernels are cached, the process's
    first frame says once that frames are slower until the compile command (the bpy module's form here)
    has run; nothing once they are cached."""
    monkeypatch.setattr(kernel_warmup, "second_stage_cached", lambda: cached)
    monkeypatch.setattr(engine_final, "_uncompiled_noted", False)
    engine_scene(tmp_path)
    for _ in range(2):
        assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    said = [line for line in capfd.readouterr().out.splitlines() if "compiled every kernel" in line]
    assert said == ([] if cached else [
        "KD Preview: note: camera rays go one by one and samples in small batches (the same images, slower) "
        "until `python -m kd_addon compile` has compiled every kernel once"])


@pytest.mark.parametrize("mode", ["ao", "auto"])
def test_a_shadow_pass_without_lights_is_black_and_says_what_to_do(addon, tmp_path, monkeypatch, mode):
    """An AO render (or "auto" without lights) with the Shadow pass on: the pass is black and the warning
    names the missing light and the pass, not the mode error's "use mode 'ao'" (the render is in it)."""
    scene = engine_scene(tmp_path)
    for ob in [ob for ob in scene.objects if ob.type == "LIGHT"]:
        bpy.data.objects.remove(ob)
    scene.kd_preview.mode = mode
    layer = scene.view_layers[0]
    layer.use_pass_shadow = True
    reported = []
    monkeypatch.setattr(engine_final.FinalRender, "_report_warning", lambda self, text: reported.append(text))
    channels = render_multilayer_exr(scene, tmp_path)
    shadow = np.stack([channels[f"{layer.name}.Shadow.{c}"] for c in "RGB"], axis=-1)
    assert (shadow == 0).all()
    said = [text for text in reported if "Shadow pass is left black" in text]
    assert len(said) == 1 and "scene 'Scene' has no render-visible light (add a light, or turn the Shadow pass " \
        "off)" in said[0] and "use mode" not in said[0], reported


def test_the_no_light_error_crosses_a_process_boundary_whole():
    """NoLightError keeps its reason and whether lights are hidden when pickled (a farm's worker)."""
    import pickle

    from kd_addon.errors import NoLightError

    error = pickle.loads(pickle.dumps(NoLightError("mode 'shadow' needs a light", "scene 'S' has none", True)))
    assert (str(error), error.why, error.hidden) == ("mode 'shadow' needs a light", "scene 'S' has none", True)
