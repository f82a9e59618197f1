"""The preview image keeps its pixels through undo, redo, and saving and reopening the .blend.

Without image_keeping.py, bpy 5.0 regenerates the image black on redo, removes it when undo goes
back past the first render, and a reopened file holds a black image: the tests of those fail that way.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.addon_support import half_plane_scene, preview_pixels

import bpy  # noqa: E402

from kd_addon import image_keeping, output  # noqa: E402
from kd_addon.output import IMAGE_NAME, IMAGE_TAG  # noqa: E402


def image_editor() -> bpy.types.Area:
    area = bpy.context.window.screen.areas[0]
    area.type = "IMAGE_EDITOR"
    return area


def rendered() -> np.ndarray:
    assert bpy.ops.kdpreview.render() == {"FINISHED"}
    return preview_pixels()


def push_undo(message: str) -> None:
    bpy.ops.ed.undo_push(message=message)


def test_undo_past_the_first_render_and_redo_keep_the_last_frame(addon):
    scene = half_plane_scene()
    area = image_editor()
    push_undo("before any render")
    first = rendered()
    push_undo("rendered")
    scene.objects["Box"].location.x = -1.0  # another frame: the image must follow the last render
    push_undo("moved")
    last = rendered()
    assert np.abs(last - first).max() > 0.1
    push_undo("rendered again")
    for _ in range(3):
        assert bpy.ops.ed.undo() == {"FINISHED"}
        assert np.array_equal(preview_pixels(), last)  # undo's image: regenerated, or gone at step 1
    assert bpy.context.scene.objects["Box"].location.x != -1.0  # undo itself did its work (scene re-read)
    assert area.spaces.active.image == bpy.data.images[IMAGE_NAME]  # the editor shows it again
    for _ in range(3):
        assert bpy.ops.ed.redo() == {"FINISHED"}
        assert np.array_equal(preview_pixels(), last)
    assert len([im for im in bpy.data.images if im.get(IMAGE_TAG)]) == 1


def test_undo_leaves_an_editor_showing_another_image_alone(addon):
    half_plane_scene()
    area = image_editor()
    bpy.data.images.new("Mine", 4, 4).use_fake_user = True
    push_undo("before any render")
    rendered()
    push_undo("rendered")
    area.spaces.active.image = bpy.data.images["Mine"]
    assert bpy.ops.ed.undo() == {"FINISHED"}  # the preview image is removed and re-created
    assert IMAGE_NAME in bpy.data.images and area.spaces.active.image == bpy.data.images["Mine"]


def test_a_saved_file_reopens_with_the_last_frame(addon, tmp_path):
    scene = half_plane_scene()
    image_editor()
    first = rendered()
    path = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert np.array_equal(preview_pixels(), first)
    assert bpy.data.images[IMAGE_NAME].packed_file is not None
    # The packed image is written into again (not replaced), and saved again.
    scene = bpy.context.scene
    scene.objects["Box"].location.x = -1.0
    second = rendered()
    assert np.abs(second - first).max() > 0.1
    assert [im.name for im in bpy.data.images if im.get(IMAGE_TAG)] == [IMAGE_NAME]
    bpy.ops.wm.save_mainfile()
    bpy.ops.wm.open_mainfile(filepath=path)
    assert np.array_equal(preview_pixels(), second)


def test_an_image_no_editor_shows_is_not_packed(addon, tmp_path):
    """The file would not keep it (no users): packing it would only cost the save its time."""
    half_plane_scene()
    rendered()
    image = bpy.data.images[IMAGE_NAME]
    assert image.users == 0
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    assert image.packed_file is None


def test_an_unchanged_image_is_not_packed_again(addon, tmp_path):
    half_plane_scene()
    image_editor()
    rendered()
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    packed = bpy.data.images[IMAGE_NAME].packed_file
    assert packed is not None
    bpy.ops.wm.save_mainfile()
    assert bpy.data.images[IMAGE_NAME].packed_file == packed  # same packed data: no new EXR written


def test_loading_a_file_forgets_the_last_frame(addon):
    """Another file's undo must not bring this file's preview into it."""
    half_plane_scene()
    rendered()
    bpy.ops.wm.read_homefile(use_empty=True)
    push_undo("new file")
    bpy.context.scene.name = "Renamed"
    push_undo("renamed")
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert IMAGE_NAME not in bpy.data.images
    assert output.restore_last_frame() is None


@pytest.mark.parametrize("kind", ["undo_post", "redo_post", "save_pre", "load_post"])
def test_handlers_are_registered_once_and_removed(addon, kind):
    def ours():
        return [h for h in getattr(bpy.app.handlers, kind) if h.__module__ == "kd_addon.image_keeping"]
    assert len(ours()) == 1
    image_keeping.register()
    assert len(ours()) == 1
    image_keeping.unregister()
    assert ours() == []
    image_keeping.register()  # for the fixture's unregister


def test_a_copy_of_the_preview_is_the_users_and_the_next_render_goes_to_the_preview(addon):
    """A snapshot made by copying the image (Image.copy, as the editor's duplicate) carries the add-on's
    tag too; named to sort first, it took the next frame and the preview stayed stale."""
    scene = half_plane_scene()
    before = rendered()
    snapshot = bpy.data.images[IMAGE_NAME].copy()
    snapshot.name = "A before"
    kept = preview_pixels("A before").copy()  # (bpy regenerates a generated image's copy: not `before`)
    scene.objects["Box"].location.x = -1.0
    after = rendered()
    assert np.abs(after - before).max() > 0.1
    assert np.array_equal(preview_pixels("A before"), kept)
    assert [im.name for im in bpy.data.images if im.get(IMAGE_TAG)] == [IMAGE_NAME]


@pytest.mark.parametrize("how", ["unpacked", "saved"])
def test_a_preview_saved_to_a_file_is_the_users_and_one_new_preview_takes_later_renders(addon, tmp_path, how):
    """Once the user unpacks the preview (saving the .blend packs it) or saves it as a file, it is theirs:
    the next render makes one new preview, which later renders reuse (each render made another)."""
    scene = half_plane_scene()
    first = rendered()
    image = bpy.data.images[IMAGE_NAME]
    image.use_fake_user = True
    if how == "unpacked":
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
        image = bpy.data.images[IMAGE_NAME]
        assert image.packed_file is not None
        image.unpack(method="WRITE_LOCAL")
    else:
        image.filepath_raw, image.file_format = str(tmp_path / "mine.exr"), "OPEN_EXR"
        image.save()
    users = image.name
    for seed in (1, 2, 3):
        scene.kd_preview.seed = seed
        rendered()
    ours = [im.name for im in bpy.data.images if im.get(IMAGE_TAG)]
    assert len(ours) == 1 and ours[0] != users and len(bpy.data.images) == 2
    assert np.allclose(preview_pixels(users), first, atol=1e-3)  # the user's image left as it was
