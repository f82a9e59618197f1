"""Scene extraction of geometry against analytic expectations: meshes, modifiers, animation,
instancing and non-mesh objects (bpy module, no UI)."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from kd_addon.extract import extract_scene
from tests import bpy_scenes as scenes
from tests.extract_support import bounds, triangles_of

pytestmark = pytest.mark.usefixtures("extraction_path")  # each test on the walk and the bulk path

CUBE = np.array(scenes.CUBE_VERTS)


def sorted_points(points: np.ndarray) -> np.ndarray:
    """Unique points in lexicographic order, for set-like comparisons."""
    pts = np.unique(np.round(points.reshape(-1, 3), 5), axis=0)
    return pts[np.lexsort(pts.T[::-1])]


# --- plain meshes and modifiers ----------------------------------------------


def test_plain_cube_world_positions(scene):
    scenes.add_cube("Box", location=(1, 2, 3))
    result = extract_scene()
    assert result.object_names == ["Box"]
    assert result.triangle_count == 12 and result.object_count == 1
    tris = result.world_triangles()
    assert tris.dtype == np.float32 and tris.shape == (12, 3, 3)
    np.testing.assert_allclose(sorted_points(tris), sorted_points(CUBE + (1, 2, 3)))
    assert result.extract_ms > 0 and result.warnings == []


def test_objects_in_edit_mode_give_their_edited_triangles(scene):
    """An object in Edit Mode evaluates to a wrapper around its edit mesh, which has no "position"
    attribute to read: the object being modelled must not vanish, nor fail with a modifier (KeyError).
    The edit, not yet written back to the mesh, must show, as in Cycles."""
    plain = scenes.add_cube("Plain", location=(0, 0, 0))
    smooth = scenes.add_cube("Smooth", location=(5, 0, 0))
    subdivision = smooth.modifiers.new("Subdivision", "SUBSURF")
    subdivision.levels = subdivision.render_levels = 1  # a render's evaluation differs otherwise (named)
    for ob in (plain, smooth):
        ob.select_set(True)
    bpy.context.view_layer.objects.active = plain
    bpy.ops.object.mode_set(mode="EDIT")  # both, as multi-object editing does
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.transform.translate(value=(0.0, 0.0, 1.0))  # lives in the edit meshes until Object Mode
    assert plain.data.vertices[0].co.z == CUBE[0, 2]  # the original mesh does not have it yet
    edited = extract_scene()
    bpy.ops.object.mode_set(mode="OBJECT")
    flushed = extract_scene()
    assert edited.triangle_count == flushed.triangle_count == 12 + 48 and edited.warnings == []
    for name in ("Plain", "Smooth"):
        np.testing.assert_array_equal(triangles_of(edited, name), triangles_of(flushed, name))
    np.testing.assert_allclose(sorted_points(triangles_of(edited, "Plain")), sorted_points(CUBE + (0, 0, 1)))


def test_array_mirror_with_object_transform(scene):
    # Cube spanning x in [1,3]; Array x2 (relative offset 1) -> x in [1,5];
    # Mirror X -> x in [-5,-1] U [1,5]; 4 cubes = 48 triangles. The object is
    # rotated 90 degrees about Z (x,y -> -y,x) and lifted by 3.
    obj = scenes.add_cube("Arr", offset=(2, 0, 0))
    arr = obj.modifiers.new("Array", "ARRAY")
    arr.count = 2
    obj.modifiers.new("Mirror", "MIRROR")
    obj.rotation_euler = (0, 0, math.pi / 2)
    obj.location = (0, 0, 3)
    result = extract_scene()
    tris = result.world_triangles()
    assert result.triangle_count == 48
    lo, hi = bounds(tris)
    np.testing.assert_allclose(lo, (-1, -5, 2), atol=1e-5)
    np.testing.assert_allclose(hi, (1, 5, 4), atol=1e-5)
    assert np.all(np.abs(tris[..., 1]) >= 1 - 1e-5)  # nothing in the mirror gap


def test_subdivision_counts_and_stays_inside_cage(scene):
    obj = scenes.add_cube("Smooth")
    obj.modifiers.new("Sub", "SUBSURF").levels = 2
    result = extract_scene()
    # 6 quads -> 6 * 4**2 quads -> 2 triangles each.
    assert result.triangle_count == 6 * 16 * 2
    radius = np.linalg.norm(result.world_triangles().reshape(-1, 3), axis=1)
    assert radius.max() <= math.sqrt(3) + 1e-5 and radius.min() > 0.5


# --- animation: armature and shape keys --------------------------------------


def test_armature_deformation_follows_bone_rotation(scene):
    _, skin = scenes.add_armature_rig("Rig")
    quad = np.array([(1, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0)], float)
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)  # Rz(90 deg)
    for frame, expected in ((1, quad), (10, quad @ rot.T)):
        scene.frame_set(frame)
        result = extract_scene(bpy.context.evaluated_depsgraph_get())
        assert result.object_names == [skin.name] and result.frame == frame
        np.testing.assert_allclose(
            sorted_points(result.world_triangles()), sorted_points(expected), atol=1e-5
        )


def test_shape_key_value_keyed_over_frames(scene):
    scenes.add_shape_key_plane("Keyed", lift=2.0)
    heights = {}
    for frame in (1, 10):
        scene.frame_set(frame)
        tris = extract_scene().world_triangles()
        heights[frame] = np.unique(np.round(tris[..., 2], 5))
    np.testing.assert_array_equal(heights[1], [0.0])
    np.testing.assert_array_equal(heights[10], [2.0])


# --- instancing --------------------------------------------------------------


def test_collection_instances_count_and_offsets(scene):
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Unit", scale=0.5, collection=source)
    source.instance_offset = (1, 0, 0)  # subtracted from every instance
    offsets = [(0, 0, 0), (5, 0, 0), (0, 7, 1)]
    for i, off in enumerate(offsets):
        scenes.add_collection_instance(f"Inst{i}", source, location=off)
    result = extract_scene()
    assert result.triangle_count == len(offsets) * 12
    assert len(result.geometries) == 1  # the mesh is read once
    assert all(i.is_instance and i.name == "Unit" for i in result.instances)
    assert sorted(i.instancer for i in result.instances) == ["Inst0", "Inst1", "Inst2"]
    expected = np.concatenate([0.5 * CUBE + off - (1, 0, 0) for off in offsets])
    np.testing.assert_allclose(
        sorted_points(result.world_triangles()), sorted_points(expected), atol=1e-5
    )


def test_geometry_nodes_instances(scene):
    scenes.add_gn_instancer("Host", count=4, offset=(2, 0, 0), cube_size=1.0, location=(0, 0, 5))
    result = extract_scene()
    assert result.object_count == 4 and result.triangle_count == 48
    assert len(result.geometries) == 1
    tris = result.world_triangles()
    ids = result.triangle_object_ids()
    centers = sorted(tuple(np.round(tris[ids == k].reshape(-1, 3).mean(axis=0), 5)) for k in range(4))
    assert centers == [(2.0 * i, 0.0, 5.0) for i in range(4)]
    lo, hi = bounds(tris)
    np.testing.assert_allclose(lo, (-0.5, -0.5, 4.5), atol=1e-5)
    np.testing.assert_allclose(hi, (6.5, 0.5, 5.5), atol=1e-5)


def test_hidden_source_of_particle_instances_still_renders(scene):
    emitter = scenes.add_mesh("Emitter", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
    source = scenes.add_cube("Pebble", scale=0.1, location=(50, 0, 0))
    source.hide_render = True
    emitter.modifiers.new("Particles", "PARTICLE_SYSTEM")
    settings = emitter.particle_systems[0].settings
    settings.count, settings.frame_start, settings.frame_end = 5, 1, 1
    settings.physics_type, settings.render_type = "NO", "OBJECT"
    settings.instance_object = source
    settings.particle_size = 1.0
    emitter.show_instancer_for_render = False  # emitter hidden, particles shown
    result = extract_scene()
    assert result.object_names == ["Pebble"] * 5
    assert {i.instancer for i in result.instances} == {"Emitter"}
    lo, hi = bounds(result.world_triangles())
    assert np.all(lo >= (-0.1 - 1e-5, -0.1 - 1e-5, -0.1 - 1e-5))
    assert np.all(hi <= (1.1 + 1e-5, 1.1 + 1e-5, 0.1 + 1e-5))


# --- non-mesh objects --------------------------------------------------------


def test_bevel_curve_is_a_tube(scene):
    scenes.add_bevel_curve("Tube", length=4.0, radius=0.5, location=(0, 0, 1))
    result = extract_scene()
    assert result.object_names == ["Tube"] and result.triangle_count > 0
    pts = result.world_triangles().reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    np.testing.assert_allclose(lo, (0, -0.5, 0.5), atol=1e-4)
    np.testing.assert_allclose(hi, (4, 0.5, 1.5), atol=1e-4)
    np.testing.assert_allclose(np.hypot(pts[:, 1], pts[:, 2] - 1), 0.5, atol=1e-4)


def test_text_object_has_plausible_bounds(scene):
    scenes.add_text("Label", "Hi", extrude=0.1, location=(0, 0, 2))
    result = extract_scene()
    assert result.object_names == ["Label"] and result.triangle_count > 20
    lo, hi = bounds(result.world_triangles())
    np.testing.assert_allclose((lo[2], hi[2]), (1.9, 2.1), atol=1e-5)
    assert -0.1 < lo[0] < 0.3 and 0.5 < hi[0] < 2.0  # two glyphs, size 1
    assert -0.1 < lo[1] < 0.2 and 0.4 < hi[1] < 1.2


def test_metaball_and_surface_are_tessellated(scene):
    scenes.add_metaball("Blob", radius=1.0, location=(0, 0, 0))
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=1.0, location=(5, 0, 0))
    result = extract_scene()
    assert sorted(result.object_names) == ["Blob", "SurfSphere"]
    for name, center in (("Blob", (0, 0, 0)), ("SurfSphere", (5, 0, 0))):
        tris = triangles_of(result, name)
        assert len(tris) > 50
        radius = np.linalg.norm(tris.reshape(-1, 3) - center, axis=1)
        assert 0.3 < radius.min() and radius.max() < 1.5
    # A curve-type object is also yielded with its own type; it must not be
    # counted a second time next to its mesh component.
    assert len(result.geometries) == 2
