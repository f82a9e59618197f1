"""Bad and extreme scenes through the add-on (bpy module): each case asserts the outcome and the message.

The reference is the same scene without the problem (objects that must be skipped, far away, scaled,
linked from a library), rendered with the same seed, so most comparisons are exact.
"""

from __future__ import annotations

import math

import pytest

from tests.addon_support import (add_quad, add_top_camera, floor_scene, half_plane_scene,
                                 preview_pixels)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from kd_addon import cli, corelib, memory_limit, pipeline  # noqa: E402
from kd_addon.config import make_config  # noqa: E402
from kd_addon.errors import PreviewError  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402
from tests.byte_counts import MIB  # noqa: E402


def render(scene=None):
    scene = scene or bpy.context.scene
    return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))


def cli_render(tmp_path, blend, *extra):
    return cli.execute(["render", str(blend), "--out", str(tmp_path / "out"), "--frames", "1", *extra])


# -- headless exit codes ---------------------------------------------------------------------


def test_zero_resolution_exits_nonzero_with_the_message(tmp_path, capsys):
    floor_scene(4, 30)  # Blender's smallest width is 4
    blend = tmp_path / "tiny.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli_render(tmp_path, blend, "--resolution", "10") == 1
    assert "the preview would be 0x3 pixels: render resolution 4x30 at 10% is too small" in capsys.readouterr().err
    assert not (tmp_path / "out" / "frame_0001.png").exists()


def test_memory_limit_exits_nonzero_before_rendering(tmp_path, capsys):
    floor_scene(400, 300)
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli_render(tmp_path, blend, "--resolution", "100", "--memory-limit", "1") == 1
    geometry, pixels = memory_limit.frame_bytes(2, 400, 300, "binned")
    err = capsys.readouterr().err
    assert f"frame 1: this frame needs about {(geometry + pixels) / MIB:,.0f} MiB (2 triangles" in err
    assert "400x300 pixels" in err and "above the memory limit of 1 MiB" in err and "raise the memory limit" in err
    assert not (tmp_path / "out" / "frame_0001.png").exists()
    assert cli_render(tmp_path, blend, "--resolution", "100", "--memory-limit", "64") == 0  # fits: renders


def test_a_frame_beyond_the_machines_memory_is_refused_without_a_limit(addon, tmp_path, capsys, monkeypatch):
    """No memory limit set: a frame whose pixel buffers are above the machine's physical memory is
    refused with a message before anything is built (not after building the tree, by core's own check
    as a traceback; docs/choices.md#without-a-memory-limit-only-the-pixel-buffers-are-checked). The machine is made small so the test is cheap."""
    floor_scene(400, 300)
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    core_memory = corelib.load_core().memory
    monkeypatch.setattr(core_memory, "physical_memory", lambda: MIB)
    assert cli_render(tmp_path, blend, "--resolution", "100") == 1
    err = capsys.readouterr().err
    assert "this frame's 400x300 pixels need about" in err and "above this machine's memory of 1 MiB" in err
    assert "lower the resolution" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "frame_0001.png").exists()
    with pytest.raises(PreviewError, match="above this machine's memory"):
        render()
    monkeypatch.setattr(core_memory, "physical_memory", lambda: None)  # unknown: nothing to check against
    assert cli_render(tmp_path, blend, "--resolution", "100", "--samples", "1") == 0


def test_non_finite_object_warns_on_the_command_line_and_the_rest_renders(tmp_path, capsys):
    scenes.reset()
    add_quad("Floor", 5, 5)
    add_top_camera()
    scenes.add_mesh("Broken", [(0, 0, 1), (1, 0, 1), (math.inf, 1, 1)], [(0, 1, 2)])
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 40, 30
    blend = tmp_path / "broken.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli_render(tmp_path, blend, "--resolution", "100", "--samples", "2") == 0
    assert "warning: frame 1: object 'Broken' has non-finite vertex coordinates; left out" in capsys.readouterr().err
    assert (tmp_path / "out" / "frame_0001.png").is_file()


# -- objects that are left out -------------------------------------------------------------


# Four triangles in view above the ground, around vertex 0; vertex 4 is used by the last two only.
FAN_VERTS = [(0.0, 0.0, 0.0), (0.4, 0.0, 0.0), (0.0, 0.4, 0.0), (-0.4, 0.0, 0.0), (0.0, -0.4, 0.0), (0.3, -0.3, 0.1)]
FAN_FACES = [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)]


def test_non_finite_objects_are_named_and_nothing_else_changes(addon):
    """Objects with a non-finite transform are left out; a mesh's triangles that use a NaN or infinite
    vertex are left out and the rest render, as Cycles does. Reference: the same scene with those
    triangles' mesh made without them."""
    scene = half_plane_scene()
    fan = [list(v) for v in FAN_VERTS]
    scenes.add_mesh("Kept", fan[:4], FAN_FACES[:2], location=(-2, 1, 1))
    reference = render(scene)
    bpy.data.objects.remove(bpy.data.objects["Kept"])
    scenes.add_mesh("NaNTri", [(-3, 0, 2), (-1, 0, 2), (math.nan, 1, 2)], [(0, 1, 2)])
    # One vertex at infinity, as a script or a broken modifier may leave it (setting vertex.co through
    # RNA would clamp inf to the largest float; from_pydata does not).
    fan[4] = (math.inf, -0.4, 0.0)
    scenes.add_mesh("Exploded", fan, FAN_FACES, location=(-2, 1, 1))
    # Transforms no placement can use, named by object (not core's "instance 1 has a non-finite
    # matrix" failing the whole frame): a NaN location, and an instancer's NaN rotation.
    scenes.add_cube("Lost", scale=0.3, location=(-2, 1, 1)).location.x = math.nan
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Member", scale=0.3, collection=source)
    scenes.add_collection_instance("Blown", source, location=(-2, 1, 1)).rotation_euler.z = math.nan
    result = render(scene)
    assert sorted(w for w in result.warnings if "non-finite" in w) == [
        "object 'Exploded' has non-finite vertex coordinates; the 2 of its 4 triangles that use them left out",
        "object 'Lost' has a non-finite transform (NaN or infinite location, rotation or scale); left out",
        "object 'Member' instanced by 'Blown': 1 instance with a non-finite transform (NaN or infinite location, "
        "rotation or scale) left out",
        "object 'NaNTri' has non-finite vertex coordinates; left out"]
    assert result.triangles == reference.triangles == 14 + 2
    np.testing.assert_array_equal(result.image, reference.image)


def test_objects_placed_beyond_float32s_range_are_named_and_left_out(addon):
    """A scale keyed to 3e38 on one frame must not stop the animation with core's traceback naming
    "instance 2". Such a placement is left out and named, as a non-finite one is, and the rest
    of the frame renders as it would without it."""
    scene = half_plane_scene()
    reference = render(scene)
    scenes.add_cube("Giant", scale=2.0, location=(-2, 1, 1)).scale = (3e38, 3e38, 3e38)  # corners at 6e38
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Member", scale=0.3, collection=source)
    # finite matrices (Blender makes its instances' in float32: further out they are inf, non-finite) whose
    # boxes reach past float32's range: 3.3e38 + 0.3 * 1e38, 3.3e38 + 0.25 * 1e38
    scenes.add_collection_instance("Far", source, location=(3.3e38, 0, 0)).scale = (1e38, 1, 1)
    row = scenes.add_gn_instancer("Row", count=2, offset=(0, 1, 0), cube_size=0.5, location=(3.3e38, 0, 0))
    row.scale = (1e38, 1, 1)  # two instances, one warning
    scenes.add_collection_instance("Near", source, location=(50, 50, -40))  # placeable: stays (out of view)
    result = render(scene)
    far = sorted(w for w in result.warnings if "float32" in w)
    assert far == [
        "object 'Giant' is placed beyond float32's range of the camera (a coordinate past 3.4e38 after its "
        "scale and location); left out",
        "object 'Member' instanced by 'Far' is placed beyond float32's range of the camera (a coordinate past "
        "3.4e38 after its scale and location); left out",
        "object 'Row' (2 instances) is placed beyond float32's range of the camera (a coordinate past 3.4e38 "
        "after its scale and location); left out"]
    assert not any("non-finite" in w for w in result.warnings)
    np.testing.assert_array_equal(result.image, reference.image)
    assert result.objects_rebuilt + result.objects_reused == 3  # ground, half plane, the near member


def test_faceless_flat_and_non_mesh_objects_are_skipped_quietly(addon):
    scene = half_plane_scene()
    reference = render(scene)
    scenes.add_mesh("Points", [(-2, 0, 3), (-1, 0, 3)], [])
    scenes.add_mesh("Wire", [(-2, 0, 3), (-1, 0, 3)], [], edges=[(0, 1)])
    scenes.add_mesh("Sliver", [(-3, -1, 2), (-2, -1, 2), (-1, -1, 2)], [(0, 1, 2)])  # collinear: zero area
    scenes.add_mesh("Dot", [(-3, 1, 2)] * 3, [(0, 1, 2)])  # one point: zero area
    scenes.add_empty("Nothing", location=(-2, 0, 2))
    scenes.add_light("Lamp")
    scenes.add_camera("SpareCam")
    result = render(scene)
    assert result.warnings == reference.warnings == []
    assert result.tree_stats["degenerate_dropped"] == 2 and result.triangles == 16
    np.testing.assert_array_equal(result.image, reference.image)


# -- cameras and placement -------------------------------------------------------------------


def test_camera_inside_a_closed_mesh(addon):
    """Every camera ray hits the inside of the box; within a long ao_distance every AO ray hits too."""
    scene = bpy.context.scene
    scenes.add_cube("Room", scale=2.0)
    cam = scenes.add_camera("Inside")
    cam.rotation_euler = (math.radians(70), 0.0, math.radians(30))
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 48, 32
    settings = scene.kd_preview
    settings.resolution_percentage, settings.samples = 100, 8
    settings.ao_distance = 10.0
    closed = render(scene).image
    assert (closed[..., 3] == 1.0).all() and (closed[..., :3] == 0.0).all()
    settings.ao_distance = 0.2
    open_ = render(scene).image
    assert np.isfinite(open_).all() and (open_[..., :3] >= 0).all() and (open_[..., :3] <= 1).all()
    assert np.median(open_[..., 0]) == 1.0 and open_[..., 0].min() < 0.8  # open walls, darker corners


@pytest.mark.parametrize("distance", [1e6, 1e7])
def test_far_offsets_give_the_same_image(addon, distance):
    """1e6 and 1e7 units away (exactly representable in Blender's float32 locations)."""
    scenes.reset()
    near = render(half_plane_scene()).image
    scenes.reset()
    far = render(half_plane_scene(offset=(distance, -distance, 0.0))).image
    np.testing.assert_array_equal(near[..., 3], far[..., 3])
    assert np.sqrt(np.mean((near - far) ** 2)) < 1e-4 and np.abs(near - far).max() < 1e-3


def scaled_half_plane_scene(scale):
    """half_plane_scene with every length times `scale` (locations, sizes, view, clipping, AO distance)."""
    scene = half_plane_scene()
    for obj in scene.objects:
        obj.location = obj.location * scale
        obj.scale = obj.scale * scale
    cam = scene.camera.data
    cam.ortho_scale *= scale
    cam.clip_start, cam.clip_end = cam.clip_start * scale, cam.clip_end * scale
    scene.kd_preview.ao_distance *= scale
    return scene


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_tiny_and_huge_scenes_render_like_scale_one(addon, scale):
    near = render(half_plane_scene()).image
    scenes.reset()
    scaled = render(scaled_half_plane_scene(scale)).image
    np.testing.assert_array_equal(near[..., 3], scaled[..., 3])
    assert np.sqrt(np.mean((near - scaled) ** 2)) < 0.01


# -- many instances, linked data ---------------------------------------------------------------


@pytest.mark.slow
def test_a_hundred_thousand_instances_of_one_mesh(addon):
    """400 x 250 tiles seen from above: a quarter of each unit cell is covered, and nothing occludes a
    flat layer of tiles from above, so every hit pixel has AO exactly 1."""
    scene = bpy.context.scene
    host = scenes.add_mesh("Host", [], [])
    host.modifiers.new("Tiles", "NODES").node_group = scenes.tile_instances_group(400, 250)
    add_top_camera(location=(0, 0, 10), ortho_scale=40.0)  # sees 40 x 20 of the 400 x 250 field
    scene.render.resolution_x, scene.render.resolution_y = 160, 80  # 4 pixels per unit
    settings = scene.kd_preview
    settings.resolution_percentage, settings.samples = 100, 4
    result = render(scene)
    assert result.objects == 100_000 and result.triangles == 200_000
    hit = result.image[..., 3] == 1.0
    assert hit.mean() == pytest.approx(0.25, abs=0.02)
    assert (result.image[..., 0][hit] == 1.0).all()
    print(f"\n100,000 instances: extract {result.extract_ms:.0f} ms, build {result.build_ms:.0f} ms")


def write_library(path):
    """A .blend holding collection 'LibColl' with the half-plane scene's box (object 'LibBox')."""
    scenes.reset()
    coll = bpy.data.collections.new("LibColl")
    scenes.add_cube("LibBox", scale=0.5, location=(-2.0, 0.0, 0.5), collection=coll)
    bpy.data.libraries.write(str(path), {coll}, fake_user=True)


@pytest.mark.parametrize("how", ["object", "collection instance"])
def test_linked_library_data_renders_like_local_data(addon, tmp_path, how):
    reference = render(half_plane_scene()).image
    library = tmp_path / "library.blend"
    write_library(library)
    scene = half_plane_scene()
    bpy.data.objects.remove(bpy.data.objects["Box"])
    with bpy.data.libraries.load(str(library), link=True) as (source, target):
        if how == "object":
            target.objects = ["LibBox"]
        else:
            target.collections = ["LibColl"]
    if how == "object":
        linked = target.objects[0]
        scene.collection.objects.link(linked)
    else:
        linked = target.collections[0]
        scenes.add_collection_instance("LibInstance", linked)
    assert linked.library is not None and linked.library.filepath.endswith("library.blend")
    result = render(scene)
    assert result.triangles == 14 and result.warnings == []
    np.testing.assert_array_equal(result.image, reference)


def test_memory_limit_refuses_the_frame_and_keeps_the_previous_image(addon):
    scene = half_plane_scene()
    bpy.ops.kdpreview.render()
    before = preview_pixels().copy()
    scene.render.resolution_x, scene.render.resolution_y = 640, 320
    scene.kd_preview.memory_limit_mb = 1
    with pytest.raises(RuntimeError, match="above the memory limit of 1 MiB"):
        bpy.ops.kdpreview.render()
    with pytest.raises(PreviewError, match=r"14 triangles and their kd-tree: 0 MiB; 640x320 pixels: \d+ MiB"):
        render(scene)
    assert (preview_pixels() == before).all()
    scene.kd_preview.memory_limit_mb = 0  # no limit
    assert bpy.ops.kdpreview.render() == {"FINISHED"}
