"""Scene extraction against analytic expectations (bpy module, no UI)."""

from __future__ import annotations

import math
import zlib

import bpy

import numpy as np
import pytest

from kd_addon.extract import extract_scene
from kd_addon.mesh_reading import read_mesh
from kd_addon.scene_records import ExtractedScene, geometry_fingerprint
from tests import bpy_scenes as scenes

CUBE = np.array(scenes.CUBE_VERTS)


@pytest.fixture
def scene():
    return scenes.reset()


def triangles_of(result: ExtractedScene, name: str) -> np.ndarray:
    """World triangles (n,3,3) of every instance whose object is `name`."""
    ids = result.triangle_object_ids()
    keep = [i for i, n in enumerate(result.object_names) if n == name]
    return result.world_triangles()[np.isin(ids, keep)]


def bounds(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts = tris.reshape(-1, 3)
    return pts.min(axis=0), pts.max(axis=0)


def sorted_points(points: np.ndarray) -> np.ndarray:
    """Unique points in lexicographic order, for set-like comparisons."""
    pts = np.unique(np.round(points.reshape(-1, 3), 5), axis=0)
    return pts[np.lexsort(pts.T[::-1])]


# --- plain meshes and modifiers ---------------------------------------------


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
    """Outside QA: an object in Edit Mode evaluates to a wrapper around its edit mesh; the preview read
    no triangles from it (the object being modelled vanished) or, with a modifier, failed (KeyError:
    no "position" attribute). The edit, not yet written back to the mesh, must show, as in Cycles."""
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


# --- animation: armature and shape keys ----------------------------------


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


# --- instancing ---------------------------------------------------------------


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


# --- non-mesh objects -----------------------------------------------------


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


# --- visibility and robustness ----------------------------------------------


def test_render_hidden_and_non_renderable_objects_left_out(scene):
    scenes.add_cube("Shown")
    scenes.add_cube("HiddenRender").hide_render = True
    hidden_coll = scenes.new_collection("HiddenColl")
    hidden_coll.hide_render = True
    scenes.add_cube("InHiddenColl", collection=hidden_coll)
    ghost = scenes.add_cube("Ghost")
    ghost.visible_camera = ghost.visible_shadow = False
    shadow_only = scenes.add_cube("ShadowOnly")
    shadow_only.visible_camera = False
    scenes.add_mesh("EdgesOnly", [(0, 0, 0), (1, 0, 0)], [], edges=[(0, 1)])
    scenes.add_empty("Nothing")
    scenes.add_light()
    scenes.add_camera()
    # Collection instance of a collection holding a render-hidden object.
    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("SrcShown", collection=source)
    scenes.add_cube("SrcHidden", collection=source).hide_render = True
    scenes.add_collection_instance("SrcInst", source, location=(10, 0, 0))
    hidden_instancer = scenes.add_collection_instance("HiddenInst", source)
    hidden_instancer.hide_render = True
    result = extract_scene()
    assert sorted(result.object_names) == ["ShadowOnly", "Shown", "SrcShown"]
    assert result.warnings == []
    assert result.triangle_count == 36


@pytest.mark.parametrize("via_modifier_input", [False, True])
def test_collection_info_instances_follow_the_collection_rule(scene, via_modifier_input):
    """Measured with Cycles (README): a collection that a Collection Info node instances whole is
    expanded like a collection instance in a render, so its render-hidden members (own flag or a
    hidden child collection) are not rendered; with Separate Children on a child object is an object
    reference and is rendered, a child collection is expanded like a collection instance and its
    render-hidden members are not (QA: the preview drew them), and a hidden object that an Object
    Info node names is rendered."""
    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("Shown", collection=source)
    scenes.add_cube("Hidden", collection=source).hide_render = True
    hidden_child = scenes.new_collection("HiddenChild", parent=source)
    hidden_child.hide_render = True
    scenes.add_cube("InHiddenChild", collection=hidden_child)
    scenes.add_info_node_host("Whole", source, via_modifier_input=via_modifier_input)
    scenes.add_info_node_host("Separate", source, separate_children=True, location=(10, 0, 0))
    scenes.add_info_node_host("Named", bpy.data.objects["Hidden"], via_modifier_input=via_modifier_input,
                              location=(20, 0, 0))
    result = extract_scene()
    by_host = {}
    for inst in result.instances:
        by_host.setdefault(inst.instancer, []).append(inst.name)
    assert sorted(by_host["Whole"]) == ["Shown"]
    assert sorted(by_host["Separate"]) == ["Hidden", "Shown"]
    assert by_host["Named"] == ["Hidden"]
    assert result.warnings == []


def _instances_by_host(result: ExtractedScene) -> dict[str | None, list[str]]:
    by_host: dict[str | None, list[str]] = {}
    for inst in result.instances:
        by_host.setdefault(inst.instancer, []).append(inst.name)
    return by_host


def _mixed_collection():
    """Excluded collection 'Src': 'Shown', a render-hidden 'Hidden', a render-hidden child collection
    holding 'InHiddenChild', and a visible child collection holding a render-hidden
    'HiddenInVisChild' and 'VisInVisChild'. A final render of its collection instances shows
    'Shown' and 'VisInVisChild' only."""
    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("Shown", scale=0.2, collection=source)
    scenes.add_cube("Hidden", scale=0.2, collection=source).hide_render = True
    hidden_child = scenes.new_collection("HiddenChild", parent=source)
    hidden_child.hide_render = True
    scenes.add_cube("InHiddenChild", scale=0.2, collection=hidden_child)
    visible_child = scenes.new_collection("VisibleChild", parent=source)
    scenes.add_cube("HiddenInVisChild", scale=0.2, collection=visible_child).hide_render = True
    scenes.add_cube("VisInVisChild", scale=0.2, collection=visible_child)
    return source


def test_particles_rendering_a_whole_collection_follow_the_collection_rule(scene):
    """Measured with Cycles (QA part_whole.blend and /tmp checks): particles rendering a collection
    whole expand it like a collection instance, leaving out its render-hidden members (own flag, a
    hidden child collection, a hidden member of a visible child collection); the preview drew them.
    Particles rendering one render-hidden object still show it, as before."""
    source = _mixed_collection()
    pebble = scenes.add_cube("Pebble", scale=0.1, location=(50, 0, 0))
    pebble.hide_render = True
    scenes.add_particle_emitter("Whole", count=3, collection=source)
    scenes.add_particle_emitter("Single", count=2, obj=pebble, location=(20, 0, 0))
    result = extract_scene()
    by_host = _instances_by_host(result)
    assert sorted(by_host) == ["Single", "Whole"]
    assert sorted(by_host["Whole"]) == ["Shown"] * 3 + ["VisInVisChild"] * 3
    assert by_host["Single"] == ["Pebble"] * 2
    assert result.warnings == []


def test_particles_picking_collection_members_leave_render_hidden_ones_out_and_warn(scene):
    """With Whole Collection off each particle gets one member: the viewport picks among all the
    members it shows, a final render among the render-visible ones only (QA part_pick.blend: the
    preview drew render-hidden spheres where Cycles drew cubes on other particles). The preview
    cannot reproduce the render's pick: it leaves the render-hidden members out and says so. A pick
    among members that are all render-visible is the render's and stays quiet."""
    source = _mixed_collection()
    scenes.add_particle_emitter("Picker", count=40, collection=source, whole_collection=False)
    plain = scenes.new_collection("Plain", exclude=True)
    scenes.add_cube("Left", scale=0.2, collection=plain)
    scenes.add_cube("Right", scale=0.2, offset=(1, 0, 0), collection=plain)
    scenes.add_particle_emitter("Quiet", count=10, collection=plain, whole_collection=False, location=(30, 0, 0))
    result = extract_scene()
    by_host = _instances_by_host(result)
    assert by_host["Picker"] and set(by_host["Picker"]) <= {"Shown", "VisInVisChild"}
    assert len(by_host["Picker"]) < 40  # the viewport gave the other particles render-hidden members
    assert len(by_host["Quiet"]) == 10 and set(by_host["Quiet"]) <= {"Left", "Right"}
    assert result.warnings == [
        "object 'Picker': particle system 'Particles' gives each particle one object of collection 'Src', which a "
        "final render picks among the render-visible members only: the preview's particle-to-object assignment "
        "differs from a final render's (it leaves the render-hidden members' particles out)"]


def test_separated_child_collections_on_points_follow_the_collection_rule(scene):
    """Collection Info with Separate Children on, picked by Instance on Points (point i gets child i
    modulo 4): a final render expands a child collection like a collection instance, leaving out a
    render-hidden child collection and a render-hidden member of a visible one (QA
    gn_sep_child.blend, Cycles), while a render-hidden child object, an object reference, is drawn.
    The pick is over the unfiltered children in both, so the points keep their objects."""
    _mixed_collection()
    scenes.add_collection_points_host("Points", bpy.data.collections["Src"], count=8)
    result = extract_scene()
    assert sorted(result.object_names) == ["Hidden"] * 2 + ["Shown"] * 2 + ["VisInVisChild"] * 2
    assert {i.instancer for i in result.instances} == {"Points"}
    assert result.warnings == []


def test_viewport_hidden_and_non_triangle_objects_are_named(scene):
    """The viewport depsgraph does not evaluate objects hidden in the viewport, so the preview cannot
    show them although a final render does; it names them, and render-visible objects that are not
    triangles. Render-hidden ones stay quiet: no render shows them either."""
    scenes.add_cube("Shown")
    scenes.add_cube("EyeHidden", location=(3, 0, 0)).hide_set(True)
    scenes.add_cube("MonitorHidden", location=(6, 0, 0)).hide_viewport = True
    emitter = scenes.add_cube("HiddenEmitter", location=(12, 0, 0))
    emitter.modifiers.new("Particles", "PARTICLE_SYSTEM")
    emitter.hide_set(True)
    quiet = scenes.add_cube("RenderHiddenToo", location=(9, 0, 0))
    quiet.hide_viewport = quiet.hide_render = True
    hair = bpy.data.objects.new("Hair", bpy.data.hair_curves.new("Hair"))
    hair.data.add_curves([3])  # one strand: something a render shows (an empty one is not named)
    scenes.link(hair)
    scenes.link(bpy.data.objects.new("NoHair", bpy.data.hair_curves.new("NoHair")))
    result = extract_scene()
    assert result.object_names == ["Shown"]
    assert sorted(result.warnings) == [
        "object 'EyeHidden' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): "
        "the preview reads the viewport's scene and leaves it out, a final render shows it",
        "object 'Hair' is hair curves, not triangles: left out of the preview",
        "object 'HiddenEmitter' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): "
        "the preview reads the viewport's scene and leaves it and the instances it makes out, a final render shows it",
        "object 'MonitorHidden' is hidden in the viewport (eye icon, Disable in Viewports or a hidden "
        "collection): the preview reads the viewport's scene and leaves it out, a final render shows it"]


def test_hidden_instancers_and_viewport_disabled_members_are_named(scene):
    """A collection instancer hidden in the viewport takes its instances with it, and a member of an
    instanced collection disabled in viewports is not evaluated for the instances: a final render
    shows both, so the preview names them (outside QA: 970 triangles went missing in silence)."""
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Unit", collection=source)
    scenes.add_cube("Member", location=(2, 0, 0), collection=source).hide_viewport = True
    gone = scenes.add_cube("RenderHidden", location=(4, 0, 0), collection=source)
    gone.hide_viewport = gone.hide_render = True  # no render shows it: quiet
    scenes.add_collection_instance("Shown", source)
    scenes.add_collection_instance("EyeHidden", source, location=(0, 9, 0)).hide_set(True)
    result = extract_scene()
    assert result.object_names == ["Unit"] and result.instances[0].instancer == "Shown"
    assert sorted(result.warnings) == [
        "object 'EyeHidden' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): "
        "the preview leaves out the instances of collection 'Source' it makes, a final render shows them",
        "object 'Member' in collection 'Source' (instanced by 'Shown') is disabled in viewports: the preview "
        "leaves its instances out, a final render shows them"]


@pytest.mark.parametrize("host", ["particles", "collection instance"])
def test_members_no_render_makes_are_not_named_as_missing(scene, host):
    """Outside review against Cycles (hit masks equal): particles render a collection's objects but do
    not expand the collection instances among them (object_dupli.cc makes no nested instances for
    particles), and no render instances a metaball; the preview left both out, as a render does,
    yet warned that each 'is not instanced in the viewport ... a final render shows them'."""
    leaf_collection = scenes.new_collection("LeafC", exclude=True)
    scenes.add_cube("Leaf", scale=0.2, collection=leaf_collection)
    rendered = scenes.new_collection("Rendered", exclude=True)
    blob = scenes.add_metaball("Blob", radius=0.3)
    bpy.context.scene.collection.objects.unlink(blob)
    rendered.objects.link(blob)
    if host == "particles":
        scenes.add_collection_instance("Nest", leaf_collection, collection=rendered)
        scenes.add_particle_emitter("Emitter", count=2, collection=rendered)
    else:
        scenes.add_collection_instance("Top", rendered)
    result = extract_scene()
    assert result.object_names == [] and result.warnings == []


def test_a_viewport_disabled_member_is_named_when_any_instancer_shows_it(scene):
    """Two instancers of one collection, the first invisible to camera and shadow rays: the member a
    render shows through the second is named once, with that instancer (the first alone hid it)."""
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Unit", collection=source)
    scenes.add_cube("Member", location=(2, 0, 0), collection=source).hide_viewport = True
    ghost = scenes.add_collection_instance("Ghost", source)
    ghost.visible_camera = ghost.visible_shadow = False
    scenes.add_collection_instance("Seen", source, location=(0, 9, 0))
    assert extract_scene().warnings == [
        "object 'Member' in collection 'Source' (instanced by 'Seen') is disabled in viewports: the preview "
        "leaves its instances out, a final render shows them"]


def test_hidden_meshes_without_faces_are_not_named(scene):
    """A mesh with edges only (a rig widget, a guide) renders nothing anywhere: hidden in the viewport,
    as a scene object or as an instanced member, it needs no warning. With a modifier it might render
    something, so it is still named."""
    widget = scenes.add_mesh("Widget", [(0, 0, 0), (1, 0, 0), (1, 1, 0)], [], edges=[(0, 1), (1, 2)])
    widget.hide_viewport = True
    grown = scenes.add_mesh("Grown", [(0, 0, 0), (1, 0, 0)], [], edges=[(0, 1)], location=(0, 3, 0))
    grown.modifiers.new("Skin", "SKIN")
    grown.hide_viewport = True
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Unit", collection=source)
    scenes.add_mesh("Guide", [(0, 0, 0), (1, 0, 0)], [], edges=[(0, 1)], collection=source).hide_viewport = True
    scenes.add_collection_instance("Shown", source, location=(0, 9, 0))
    assert extract_scene().warnings == [
        "object 'Grown' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): the "
        "preview reads the viewport's scene and leaves it out, a final render shows it"]


def test_viewport_disabled_members_of_nested_collection_instances_are_named(scene):
    """A collection instanced inside an instanced collection: its member disabled in viewports is
    rendered by a final render through both instancers, left out by the viewport's depsgraph, so the
    preview names it with the chain of instancers."""
    deep = scenes.new_collection("Deep", exclude=True)
    scenes.add_cube("DeepUnit", scale=0.1, collection=deep)
    scenes.add_cube("DeepMember", scale=0.1, location=(0.3, 0, 0), collection=deep).hide_viewport = True
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Unit", scale=0.1, location=(0, 1, 0), collection=source)
    scenes.add_collection_instance("Inner", deep, collection=source)
    scenes.add_collection_instance("Top", source)
    result = extract_scene()
    assert sorted(_instances_by_host(result)["Top"]) == ["DeepUnit", "Unit"]
    assert result.warnings == [
        "object 'DeepMember' in collection 'Deep' (instanced by 'Top' through 'Inner') is disabled in viewports: "
        "the preview leaves its instances out, a final render shows them"]


def test_members_of_realized_collection_info_are_not_named(scene):
    """Realize Instances makes the members part of the host's mesh, never instances: no member may be
    named as missing from the instances (every one was, before the host's instances were checked).
    Nor when particles are shown in renders only."""
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Unit", scale=0.1, collection=source)
    scenes.add_cube("Member", scale=0.1, location=(0.3, 0, 0), collection=source).hide_viewport = True
    scenes.add_info_node_host("Host", source, realize=True)
    result = extract_scene()
    assert result.object_names == ["Host"] and len(triangles_of(result, "Host")) >= 12
    assert result.warnings == []
    emitter = scenes.add_particle_emitter("Emitter", count=3, collection=source, location=(9, 0, 0))
    emitter.modifiers[0].show_viewport = False  # particles in renders only: no member is the reason
    assert extract_scene().warnings == [  # ... that warning names the modifier only
        "the preview evaluates geometry as the viewport does, a final render with its own settings, which differ "
        "for 'Emitter' (modifier 'Particles' enabled only in renders)"]


@pytest.mark.parametrize("host", ["particles", "collection info", "separate children"])
def test_viewport_disabled_members_of_collections_rendered_whole_are_named(scene, host):
    """Particles and Collection Info nodes rendering a collection whole expand it like a collection
    instance, and so does Separate Children for a child collection: a member (or child collection)
    disabled in viewports but render-visible is not instanced by the viewport's depsgraph, while a
    final render shows it (checked with Cycles), so the preview names it and the host. A child object
    that Separate Children instances directly shows in the viewport too: no warning for it. A
    geometry-nodes host or emitter is trusted only for collections it instanced a member of, so a
    child collection that is disabled whole ('Child') goes unnamed when it is the instanced one."""
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Unit", scale=0.1, collection=source)
    scenes.add_cube("Member", scale=0.1, location=(0.3, 0, 0), collection=source).hide_viewport = True
    gone = scenes.add_cube("RenderHidden", scale=0.1, location=(0.6, 0, 0), collection=source)
    gone.hide_viewport = gone.hide_render = True  # no render shows it: quiet
    child = scenes.new_collection("Child", parent=source)
    scenes.add_cube("InChild", scale=0.1, location=(0.9, 0, 0), collection=child)
    child.hide_viewport = True
    second = scenes.new_collection("Second", parent=source)
    scenes.add_cube("SecondUnit", scale=0.1, location=(1.2, 0, 0), collection=second)
    scenes.add_cube("SecondMember", scale=0.1, location=(1.5, 0, 0), collection=second).hide_viewport = True
    if host == "particles":
        scenes.add_particle_emitter("Host", count=3, collection=source)
    else:
        scenes.add_info_node_host("Host", source, separate_children=host == "separate children")
    result = extract_scene()
    member = ("object 'Member' in collection 'Source' (instanced by 'Host') is disabled in viewports: the preview "
              "leaves its instances out, a final render shows them")
    second_member = member.replace("'Member'", "'SecondMember'")
    in_child = member.replace("'Member'", "'InChild'").replace(
        "is disabled in viewports", "is not instanced in the viewport (a collection or instancer on its path is "
        "disabled in viewports)")  # its collection is the disabled one
    if host == "separate children":  # the child collections are the instanced ones
        assert sorted(_instances_by_host(result)["Host"]) == ["Member", "RenderHidden", "SecondUnit", "Unit"]
        assert result.warnings == [second_member.replace("collection 'Source'", "collection 'Second'")]
    else:
        assert set(_instances_by_host(result)["Host"]) == {"Unit", "SecondUnit"}
        assert sorted(result.warnings) == [in_child, member, second_member]


def test_a_collection_info_node_the_output_does_not_use_names_nothing(scene):
    """A Collection Info node left unconnected instances nothing: its collection's members are not
    missing instances, even though the host instances another collection."""
    used, unused = scenes.new_collection("Used", exclude=True), scenes.new_collection("Unused", exclude=True)
    scenes.add_cube("UsedUnit", scale=0.1, collection=used)
    scenes.add_cube("Idle", scale=0.1, collection=unused)
    host = scenes.add_info_node_host("Host", used)
    spare = host.modifiers[0].node_group.nodes.new("GeometryNodeCollectionInfo")
    spare.inputs["Collection"].default_value = unused
    result = extract_scene()
    assert _instances_by_host(result) == {"Host": ["UsedUnit"]}
    assert result.warnings == []


@pytest.mark.parametrize("spare_link", ["none", "muted"])
def test_a_collection_info_node_that_reaches_no_output_does_not_hide_its_members(scene, spare_link):
    """Measured with Cycles (bpy 5.0.1, `benchmarks/cycles_node_references.py`): a host instances a
    render-hidden object through an Object Info node whose object a Switch node computes (which the
    reading cannot resolve, so it is shown as the viewport yields it), and holds a Collection Info
    node naming a collection with that object, unconnected or linked to the output through a muted
    link only. Cycles renders the object; the preview left it out, as if the collection were
    instanced whole, and warned that the collection's other member was missing."""
    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("Shown", scale=0.2, collection=source)
    hidden = scenes.add_cube("Hidden", scale=0.2, collection=source)
    hidden.hide_render = True
    elsewhere = scenes.add_cube("Elsewhere", scale=0.1, location=(0, 0, -50))
    host = scenes.add_mesh("Host", [], [])
    tree = bpy.data.node_groups.new("HostTree", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = tree.nodes, tree.links
    switch = nodes.new("GeometryNodeSwitch")
    switch.input_type = "OBJECT"
    switch.inputs["False"].default_value, switch.inputs["True"].default_value = hidden, elsewhere
    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "RELATIVE"
    info.inputs["As Instance"].default_value = True
    links.new(switch.outputs[0], info.inputs["Object"])
    join = nodes.new("GeometryNodeJoinGeometry")
    links.new(info.outputs["Geometry"], join.inputs[0])
    links.new(join.outputs[0], nodes.new("NodeGroupOutput").inputs[0])
    spare = nodes.new("GeometryNodeCollectionInfo")
    spare.inputs["Collection"].default_value = source
    if spare_link == "muted":
        links.new(spare.outputs[0], join.inputs[0]).is_muted = True
    host.modifiers.new("GN", "NODES").node_group = tree
    result = extract_scene()
    assert _instances_by_host(result) == {"Host": ["Hidden"], None: ["Elsewhere"]}
    assert result.warnings == []


@pytest.mark.parametrize("via_modifier_input", [False, True])
def test_a_collection_fed_to_a_nested_group_follows_the_collection_rule(scene, via_modifier_input):
    """Measured with Cycles (bpy 5.0.1, `benchmarks/cycles_node_references.py`): a reusable group whose
    Collection input feeds a Collection Info node, called with a collection set on the Group node's
    socket or passed down from the modifier's input, instances it like a collection instance: its
    render-hidden member is not rendered. The preview read only the modifier's own tree's inputs and
    drew the hidden member."""
    source = _mixed_collection()
    scenes.add_nested_info_host("Host", source, via_modifier_input=via_modifier_input)
    result = extract_scene()
    assert sorted(_instances_by_host(result)["Host"]) == ["Shown", "VisInVisChild"]
    assert result.warnings == []


@pytest.mark.parametrize("instance_type", ["VERTS", "FACES"])
def test_a_child_of_a_vertex_or_face_instancing_parent_shows_only_as_its_instances(scene, instance_type):
    """Blender hides such a child at its own place in a final render (the viewport shows it there):
    a parent with two faces instances the child twice, and the original is left out (outside QA:
    rendered as an extra object, against Cycles)."""
    parent = scenes.add_mesh("Parent", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (4, 0, 0), (5, 0, 0), (5, 1, 0)],
                             [(0, 1, 2), (3, 4, 5)])
    parent.instance_type = instance_type
    parent.show_instancer_for_render = False
    child = scenes.add_cube("Child", scale=0.2, location=(0, 0, 3))
    child.parent = parent
    source = scenes.new_collection("Source", exclude=True)  # a collection instancer as a child: its own
    scenes.add_cube("Unit", scale=0.1, collection=source)  # instances go with it (outside review)
    scenes.add_collection_instance("Holder", source, location=(0, 0, 9)).parent = parent
    result = extract_scene()
    copies = 6 if instance_type == "VERTS" else 2
    assert sorted(result.object_names) == ["Child"] * copies + ["Unit"] * copies and result.warnings == []
    assert all(i.is_instance and i.instancer == "Parent" for i in result.instances)


def _plate_and_instances_group(source):
    """Geometry nodes joining the input mesh with an instance of object `source` on each of its points."""
    group = bpy.data.node_groups.new("PlateAndInstances", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    given, out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    on_points, info, join = (nodes.new(kind) for kind in ("GeometryNodeInstanceOnPoints", "GeometryNodeObjectInfo",
                                                           "GeometryNodeJoinGeometry"))
    info.inputs["Object"].default_value = source
    links.new(given.outputs[0], on_points.inputs["Points"])
    links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    links.new(on_points.outputs["Instances"], join.inputs[0])
    links.new(given.outputs[0], join.inputs[0])
    links.new(join.outputs[0], out.inputs[0])
    return group


@pytest.mark.parametrize("kind", ["NODES", "FACES"])
@pytest.mark.parametrize("viewport, render", [(True, True), (True, False), (False, True), (False, False)])
def test_show_instancer_for_render_alone_decides_whether_an_instancer_shows_itself(scene, kind, viewport, render):
    """Blender's rule for a final render (BKE_object_visibility, render mode): an object that instances
    things shows itself iff Show Instancer > Render is on; the viewport's flag, which the viewport
    depsgraph applies, changes nothing. Outside review against Cycles: a geometry-nodes carrier
    (is_instancer False) with Render off still showed its own plate, and an instancer with Viewport off
    and Render on was left out with a warning calling it hidden in the viewport."""
    plate = scenes.add_mesh("Plate", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)],
                            location=(0, 0, 2))
    cube = scenes.add_cube("Cube", scale=0.2, location=(0, 0, 2))
    if kind == "NODES":  # a cube on each of the plate's 4 corners; the source itself is not rendered
        cube.location, cube.hide_render = (50, 0, 0), True
        plate.modifiers.new("GN", "NODES").node_group = _plate_and_instances_group(cube)
    else:  # one cube on the plate's one face
        plate.instance_type, cube.parent = "FACES", plate
    plate.show_instancer_for_viewport, plate.show_instancer_for_render = viewport, render
    result = extract_scene()
    copies = 4 if kind == "NODES" else 1
    assert sum(i.is_instance and i.instancer == "Plate" for i in result.instances) == copies
    own = [k for k, i in enumerate(result.instances) if not i.is_instance]
    assert [result.instances[k].name for k in own] == (["Plate"] if render else [])
    assert result.warnings == []
    if render:
        plate_triangles = result.world_triangles()[result.triangle_object_ids() == own[0]]
        assert len(plate_triangles) == 2
        lo, hi = bounds(plate_triangles)
        np.testing.assert_allclose(lo, (0, 0, 2), atol=1e-6)
        np.testing.assert_allclose(hi, (1, 1, 2), atol=1e-6)


@pytest.mark.parametrize("source", ["EMPTY", "LIGHT"])
@pytest.mark.parametrize("viewport, render", [(True, True), (True, False), (False, True), (False, False)])
def test_a_carrier_instancing_only_empties_or_lights_is_an_instancer(scene, source, viewport, render):
    """Geometry nodes whose output holds instances of an empty or a light only: Blender still counts the
    object as an instancer (its geometry has instances), so Show Instancer > Render off hides its own
    mesh, as Cycles does (checked: 142 hit pixels with the flag on, 0 off, for both sources). The walk
    saw only mesh instances and kept the plate."""
    plate = scenes.add_mesh("Plate", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)],
                            location=(0, 0, 2))
    data = None if source == "EMPTY" else bpy.data.lights.new("Bulb", "POINT")
    thing = bpy.data.objects.new("Thing", data)
    scene.collection.objects.link(thing)
    group = _plate_and_instances_group(thing)
    next(n for n in group.nodes if n.bl_idname == "GeometryNodeObjectInfo").inputs["As Instance"].default_value = True
    plate.modifiers.new("GN", "NODES").node_group = group
    plate.show_instancer_for_viewport, plate.show_instancer_for_render = viewport, render
    result = extract_scene()
    assert result.object_names == (["Plate"] if render else [])
    assert result.warnings == []


def test_a_view_layer_not_enabled_for_rendering_is_named(scene):
    """Outside review: the preview renders the window's view layer; a final render writes only the
    layers enabled for rendering, so a disabled one gets a warning (and renders as before)."""
    scenes.add_cube("Box")
    bpy.context.view_layer.use = False
    result = extract_scene()
    assert result.object_names == ["Box"]
    assert result.warnings == [f"view layer '{bpy.context.view_layer.name}' is not enabled for rendering (Use for "
                               "Rendering off): the preview renders it, a final render writes only the enabled layers"]


@pytest.mark.parametrize("instance_type", ["VERTS", "FACES"])
def test_a_child_disabled_in_renders_is_not_instanced_on_vertices_or_faces(scene, instance_type):
    """Outside QA against Cycles: Blender instances the children that the depsgraph holds, and a render's
    leaves out a child disabled in renders (object_dupli.cc, make_child_duplis), so a final render shows
    no copies of it; the viewport's depsgraph the preview reads still made them."""
    parent = scenes.add_mesh("Parent", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (4, 0, 0), (5, 0, 0), (5, 1, 0)],
                             [(0, 1, 2), (3, 4, 5)])
    parent.instance_type = instance_type
    parent.show_instancer_for_render = False
    for name, hidden in (("Shown", False), ("Hidden", True)):
        child = scenes.add_cube(name, scale=0.2, location=(0, 0, 3))
        child.parent, child.hide_render = parent, hidden
    result = extract_scene()
    copies = 6 if instance_type == "VERTS" else 2
    assert sorted(result.object_names) == ["Shown"] * copies and result.warnings == []


@pytest.mark.parametrize("nested_instancer_hidden", [False, True])
def test_collection_info_follows_nested_collection_instances(scene, nested_instancer_hidden):
    """Outside QA against Cycles: a Collection Info node instancing a collection that holds an empty
    instancing a second collection showed the second's members disabled in renders (they were taken
    for objects the node instances directly). A render expands the nesting as a collection instance:
    the inner collection's render-visible members only, and none when the inner instancer is disabled
    in renders."""
    inner = scenes.new_collection("Inner", exclude=True)
    scenes.add_cube("InnerShown", collection=inner)
    scenes.add_cube("InnerHidden", collection=inner).hide_render = True
    outer = scenes.new_collection("Outer", exclude=True)
    scenes.add_cube("OuterShown", collection=outer)
    nested = scenes.add_collection_instance("Nested", inner, location=(3, 0, 0), collection=outer)
    nested.hide_render = nested_instancer_hidden
    scenes.add_info_node_host("Carrier", outer)
    result = extract_scene()
    expected = ["OuterShown"] if nested_instancer_hidden else ["InnerShown", "OuterShown"]
    assert sorted(_instances_by_host(result)["Carrier"]) == expected


def _leaf_centres(result: ExtractedScene, name: str) -> list[tuple[float, ...]]:
    """Centres of the instances of object `name`, sorted (each instance is one whole cube)."""
    return sorted(tuple(np.round(inst.matrix_world[:3, 3], 6)) for inst in result.instances if inst.name == name)


@pytest.mark.parametrize("top", scenes.TWO_PATH_TOPS)
@pytest.mark.parametrize("hidden_path", scenes.TWO_PATH_HIDINGS)
def test_an_object_reached_by_a_visible_and_a_render_hidden_path_is_made_once(scene, top, hidden_path):
    """Outside review against Cycles: 'Mid' holds an empty instancing 'LeafC' (Leaf) at x = -3 and
    another at x = +3 that a render does not make (Disable in Renders, or in a render-hidden child
    collection); Blender makes no instances from a render-hidden object (object_dupli.cc,
    get_dupli_generator) nor from a hidden child collection's members, but the viewport's depsgraph
    makes both, and the verdict kept per (object, top-level instancer) drew Leaf at +3 too (145-579
    extra pixels). Also when the hidden path's object itself is directly in 'Mid' (no nesting at all
    on the visible path)."""
    scenes.add_two_path_scene(top, hidden_path)
    expected = [(0.0, 0.0, 0.0)] if hidden_path == "visible twin of a hidden instancer" else [(-3.0, 0.0, 0.0)]
    result = extract_scene()
    assert _leaf_centres(result, "Leaf") == expected


@pytest.mark.parametrize("hidden", [False, True])
@pytest.mark.parametrize("source_kind", scenes.OBJECT_INFO_SOURCES)
def test_an_object_info_source_hidden_from_renders_brings_its_own_mesh_but_not_its_instances(
        scene, source_kind, hidden):
    """Outside review against Cycles: an Object Info node (As Instance) of a render-hidden object
    still shows that object's own mesh in a render, but not the instances the object makes itself
    (Blender makes none from a render-hidden object, at any depth); the preview drew them (~1,100
    pixels each). With the source visible both show."""
    scenes.add_object_info_of_instancer(source_kind, hidden)
    own, made = {"collection instancer": ([], ["X"]), "vertex-instancing parent": (["Source"], ["X"] * 3),
                 "nodes carrier": ([], ["Source"] * 2)}[source_kind]  # a carrier's instances are its own entries
    result = extract_scene()
    expected = own if hidden else own + made
    assert sorted(_instances_by_host(result).get("Host", [])) == sorted(expected)


@pytest.mark.parametrize("first_layer_renders", [True, False])
def test_background_scenes_are_rendered_through_their_render_view_layer(scene, first_layer_renders):
    """Outside QA against Cycles: a render shows the objects of the scene's Background Scene (and of
    that one's, chained) as the depsgraph holds them; the preview left them out with no warning. A
    background scene contributes its first view layer enabled for rendering (else its first), with
    that layer's exclusions and Disable in Renders; checked against Cycles with either layer enabled.
    (Switching `use` after an evaluation crashed the bpy module's next one, so each case is set up
    before the first.)"""
    scenes.add_cube("Own")
    first = bpy.data.scenes.new("Set")
    scene.background_set = first
    scenes.add_cube("InSet", location=(3, 0, 0), collection=first.collection)
    scenes.add_cube("HiddenInSet", location=(6, 0, 0), collection=first.collection).hide_render = True
    side = bpy.data.collections.new("Side")
    first.collection.children.link(side)
    scenes.add_cube("InSide", location=(9, 0, 0), collection=side)
    second = bpy.data.scenes.new("SetOfSet")
    first.background_set = second
    scenes.add_cube("InSetOfSet", location=(12, 0, 0), collection=second.collection)
    first.view_layers.new("Other").layer_collection.children["Side"].exclude = True
    first.view_layers[0].use = first_layer_renders  # else the second layer renders, which excludes Side
    expected = ["InSet", "InSetOfSet", "InSide", "Own"] if first_layer_renders else ["InSet", "InSetOfSet", "Own"]
    assert sorted(extract_scene().object_names) == expected


def test_background_scene_objects_hidden_in_the_viewport_are_named(scene):
    """As the scene's own: a final render shows a background scene's object disabled in viewports,
    the viewport's depsgraph does not hold it, so the preview names what it leaves out (it said
    nothing); an object in both scenes is named once."""
    scenes.add_cube("Own")
    background = bpy.data.scenes.new("Set")
    scene.background_set = background
    scenes.add_cube("InSet", location=(3, 0, 0), collection=background.collection)
    scenes.add_cube("HiddenInSet", location=(6, 0, 0), collection=background.collection).hide_viewport = True
    both = scenes.add_cube("HiddenInBoth", location=(9, 0, 0))
    background.collection.objects.link(both)
    both.hide_viewport = True
    result = extract_scene()
    assert sorted(result.object_names) == ["InSet", "Own"]
    hidden = sorted(w.split("'")[1] for w in result.warnings if "is hidden in the viewport" in w)
    assert hidden == ["HiddenInBoth", "HiddenInSet"]


def test_geometry_that_is_not_triangles_inside_mesh_objects_is_named(scene):
    """Geometry nodes that turn a mesh into points, and hair particles drawn as strands: Cycles
    renders both, the preview cannot trace them and says so (outside QA: left out in silence)."""
    points = scenes.add_cube("Pointy")
    group = bpy.data.node_groups.new("ToPoints", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    inp, out, to_points = (group.nodes.new(kind) for kind in
                           ("NodeGroupInput", "NodeGroupOutput", "GeometryNodeMeshToPoints"))
    group.links.new(inp.outputs[0], to_points.inputs[0])
    group.links.new(to_points.outputs[0], out.inputs[0])
    points.modifiers.new("GN", "NODES").node_group = group
    hairy = scenes.add_cube("Hairy", location=(4, 0, 0))
    hairy.modifiers.new("Fur", "PARTICLE_SYSTEM")
    hairy.particle_systems[0].settings.type = "HAIR"
    result = extract_scene()
    assert result.object_names == ["Hairy"]
    assert sorted(result.warnings) == [
        "object 'Hairy': hair particles 'Fur' are strands, not triangles: left out of the preview",
        "object 'Pointy' makes a point cloud, not triangles: left out of the preview"]


def test_ray_visibility_flags_are_read_and_anded_with_the_instancer(scene):
    """Each instance carries Ray Visibility > Camera and > Shadow, ANDed with its instancer's as Cycles
    does."""
    scenes.add_cube("Plain")
    scenes.add_cube("NoShadow").visible_shadow = False
    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("Unseen", collection=source).visible_camera = False
    scenes.add_cube("Member", collection=source)
    for k in range(3):
        scenes.add_collection_instance(f"Inst{k}", source, location=(3.0 * k, 5.0, 0.0))
    bpy.data.objects["Inst2"].visible_shadow = False
    result = extract_scene()
    flags = sorted((i.name, i.instancer, i.camera, i.shadow) for i in result.instances)
    assert flags == [("Member", "Inst0", True, True), ("Member", "Inst1", True, True),
                     ("Member", "Inst2", True, False), ("NoShadow", None, True, False), ("Plain", None, True, True),
                     ("Unseen", "Inst0", False, True), ("Unseen", "Inst1", False, True)]  # Inst2's: no rays
    assert result.warnings == []


def test_holdout_and_indirect_only_are_read_from_the_object_or_its_instancer(scene):
    """Holdout and Indirect Only as Cycles reads them (measured with Cycles, see render_visibility.py): an
    object's own flag or its collection's; for an instance only the top-level instancer's, so a
    holdout member of an instanced collection is not one. Indirect Only turns camera rays off,
    except on a holdout; with shadow rays off too the object is left out."""
    scenes.add_cube("Plain")
    scenes.add_cube("Hole").is_holdout = True
    masked = scenes.new_collection("Masked")
    bpy.context.view_layer.layer_collection.children["Masked"].holdout = True
    scenes.add_cube("InMasked", collection=masked)
    indirect = scenes.new_collection("Indirect")
    bpy.context.view_layer.layer_collection.children["Indirect"].indirect_only = True
    scenes.add_cube("Bounce", collection=indirect)
    scenes.add_cube("HeldBounce", collection=indirect).is_holdout = True
    scenes.add_cube("Gone", collection=indirect).visible_shadow = False
    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("Member", collection=source).is_holdout = True
    scenes.add_collection_instance("Shown", source, location=(0.0, 5.0, 0.0))
    scenes.add_collection_instance("Cutout", source, location=(3.0, 5.0, 0.0)).is_holdout = True
    scenes.add_collection_instance("Bounced", source, location=(6.0, 5.0, 0.0), collection=indirect)
    result = extract_scene()
    flags = sorted((i.name, i.instancer, i.holdout, i.camera, i.shadow) for i in result.instances)
    assert flags == [("Bounce", None, False, False, True), ("HeldBounce", None, True, True, True),
                     ("Hole", None, True, True, True), ("InMasked", None, True, True, True),
                     ("Member", "Bounced", False, False, True), ("Member", "Cutout", True, True, True),
                     ("Member", "Shown", False, True, True), ("Plain", None, False, True, True)]
    assert result.warnings == []


def test_non_finite_vertices_left_out_with_warning(scene):
    scenes.add_cube("Good")
    verts = [(0, 0, 0), (1, 0, 0), (float("nan"), 1, 0)]
    scenes.add_mesh("Broken", verts, [(0, 1, 2)])
    result = extract_scene()
    assert result.object_names == ["Good"]
    assert result.warnings == ["object 'Broken' has non-finite vertex coordinates; left out"]


def test_a_shared_non_finite_mesh_warns_once_naming_every_user(scene):
    verts = [(0, 0, 0), (1, 0, 0), (float("inf"), 1, 0)]
    first = scenes.add_mesh("Broken", verts, [(0, 1, 2)])
    for name in ("Twin", "Triplet"):
        scenes.link(bpy.data.objects.new(name, first.data))
    scenes.add_cube("Good")
    result = extract_scene()
    assert result.object_names == ["Good"]
    assert result.warnings == ["objects 'Broken', 'Triplet', 'Twin' (sharing mesh 'Broken') have non-finite "
                               "vertex coordinates; left out"]


# --- record layout and helpers ------------------------------------------------


def test_empty_scene(scene):
    result = extract_scene()
    assert result.object_count == 0 and result.triangle_count == 0
    assert result.world_triangles().shape == (0, 3, 3)
    assert result.triangle_object_ids().shape == (0,)


def test_records_layout_and_world_triangles_match_naive(scene):
    source = scenes.new_collection("S", exclude=True)
    scenes.add_cube("A", scale=0.3, collection=source)
    for i in range(20):  # >16 instances exercises the batched scatter path
        inst = scenes.add_collection_instance(f"I{i}", source, location=(i, i % 3, 0))
        inst.rotation_euler = (0.1 * i, 0, 0.2 * i)
        inst.scale = (1 + 0.05 * i,) * 3
    scenes.add_gn_instancer("G", count=3)
    scenes.add_cube("Solo", location=(0, -4, 0))
    result = extract_scene()
    for geom in result.geometries.values():
        assert geom.vertices.dtype == np.float32 and geom.vertices.flags.c_contiguous
        assert geom.triangles.dtype == np.int32 and geom.triangles.shape[1] == 3
    naive = []
    for inst in result.instances:
        geom = result.geometries[inst.geometry_key]
        assert inst.matrix_world.dtype == np.float64 and inst.matrix_world.shape == (4, 4)
        homo = np.c_[geom.vertices.astype(float), np.ones(len(geom.vertices))]
        naive.append((homo @ inst.matrix_world.T)[:, :3][geom.triangles])
    np.testing.assert_allclose(result.world_triangles(), np.concatenate(naive), atol=1e-5)
    ids = result.triangle_object_ids()
    assert ids.dtype == np.int32
    counts = [result.geometries[i.geometry_key].triangle_count for i in result.instances]
    np.testing.assert_array_equal(np.bincount(ids), counts)


def test_read_mesh_matches_loop_triangle_vertices(scene):
    # Quads, a concave quad and a concave n-gon: Blender's own triangulation.
    verts = [(0, 0, 0), (4, 0, 0), (4, 4, 0), (2, 1, 0), (0, 4, 0), (6, 0, 0), (7, 1, 0), (6, 2, 0), (6.3, 1, 0)]
    obj = scenes.add_mesh("Odd", verts, [(0, 1, 2, 3, 4), (5, 6, 7, 8)])
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    got_verts, got_tris = read_mesh(mesh)
    reference = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", reference)
    np.testing.assert_array_equal(got_tris, reference.reshape(-1, 3))
    np.testing.assert_allclose(got_verts, verts)


def test_fingerprint_tracks_geometry_changes(scene):
    scenes.add_shape_key_plane("Keyed")
    prints = {}
    for frame in (1, 1, 10):
        scene.frame_set(frame)
        (geom,) = extract_scene().geometries.values()
        prints.setdefault(frame, set()).add(geometry_fingerprint(geom))
    assert len(prints[1]) == 1 and prints[1] != prints[10]


def _with_crc32_restored(data: bytes, changed: bytes, at: int) -> bytes:
    """`changed` with the four bytes at `at` chosen so that its CRC-32 is `data`'s. CRC-32 is affine
    over GF(2): flipping bit i changes the CRC by a fixed vector e_i whatever the other bytes, and the
    e_i of 32 consecutive bits are independent, so the wanted difference is the XOR of some of them."""
    def effect(i):
        flipped = bytearray(changed)
        flipped[at + i // 8] ^= 1 << (i % 8)
        return zlib.crc32(bytes(flipped)) ^ zlib.crc32(changed)

    basis = []  # (vector, which bits make it), one per leading bit, largest first
    for i in range(32):
        vector, bits = effect(i), 1 << i
        for b_vector, b_bits in basis:
            if vector ^ b_vector < vector:  # vector has b_vector's leading bit
                vector, bits = vector ^ b_vector, bits ^ b_bits
        basis = sorted(basis + [(vector, bits)], reverse=True)
    target, flips = zlib.crc32(changed) ^ zlib.crc32(data), 0
    for b_vector, b_bits in basis:
        if target ^ b_vector < target:
            target, flips = target ^ b_vector, flips ^ b_bits
    assert target == 0
    out = bytearray(changed)
    out[at:at + 4] = (int.from_bytes(out[at:at + 4], "little") ^ flips).to_bytes(4, "little")
    return bytes(out)


def test_a_change_that_keeps_the_crc_changes_the_fingerprint():
    """A mesh edited so that its vertex bytes keep their CRC-32 (which a CRC-32 fingerprint would call
    unchanged, keeping a stale tree and image) gets another fingerprint."""
    from kd_addon.scene_records import MeshGeometry

    vertices = np.arange(30, dtype=np.float32).reshape(10, 3)
    triangles = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    edited = vertices.copy()
    edited[2] = (5.0, -1.0, 7.5)
    forged = np.frombuffer(_with_crc32_restored(vertices.tobytes(), edited.tobytes(), at=36), np.float32)
    forged = forged.reshape(10, 3).copy()
    assert zlib.crc32(forged) == zlib.crc32(vertices) and not np.array_equal(forged, vertices)
    before = geometry_fingerprint(MeshGeometry(0, "M", vertices, triangles))
    assert geometry_fingerprint(MeshGeometry(0, "M", forged, triangles)) != before
    assert geometry_fingerprint(MeshGeometry(0, "M", vertices.copy(), triangles.copy())) == before


def test_a_group_called_many_times_with_the_same_inputs_is_read_once(scene, monkeypatch):
    """A review found a chain of groups, each calling the next four times, read 4^depth times (23 s at
    depth 7). Each (group, inputs) pair is read once, and the collection is named once."""
    from kd_addon import node_instances

    source = scenes.new_collection("Src", exclude=True)
    scenes.add_cube("Unit", scale=0.1, collection=source)
    host = scenes.add_nested_info_host("Host", source)
    inner = host.modifiers[0].node_group.nodes[0].node_tree  # the Scatter group, called with Src
    for level in range(6):  # each new level calls the one below four times and joins them
        group = bpy.data.node_groups.new(f"Level{level}", "GeometryNodeTree")
        group.interface.new_socket("Coll", in_out="INPUT", socket_type="NodeSocketCollection")
        group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
        join = group.nodes.new("GeometryNodeJoinGeometry")
        feed = group.nodes.new("NodeGroupInput").outputs["Coll"]
        for _ in range(4):
            call = group.nodes.new("GeometryNodeGroup")
            call.node_tree = inner
            group.links.new(feed, call.inputs["Coll"])
            group.links.new(call.outputs[0], join.inputs[0])
        group.links.new(join.outputs[0], group.nodes.new("NodeGroupOutput").inputs[0])
        inner = group
    host.modifiers[0].node_group.nodes[0].node_tree = inner
    host.modifiers[0].node_group.nodes[0].inputs["Coll"].default_value = source
    reads = []
    original = node_instances._nodes_reaching_output
    monkeypatch.setattr(node_instances, "_nodes_reaching_output", lambda tree: reads.append(tree.name) or original(tree))
    collections, objects = node_instances.node_references(host)
    assert [c.name for c in collections] == ["Src"] and objects == []
    assert sorted(reads) == sorted(["HostTree", "HostScatter"] + [f"Level{level}" for level in range(6)])


def _evaluation_warnings(result: ExtractedScene) -> list[str]:
    return [w for w in result.warnings if w.startswith("the preview evaluates geometry as the viewport does")]


def test_settings_a_render_evaluates_differently_are_named_in_one_warning(scene):
    """Outside review against Cycles: each of these changed the image by 230-2,200 pixels of 19,200
    with no word from the preview, which reads the viewport's evaluation."""
    subdivided = scenes.add_cube("Subdivided")
    subdivision = subdivided.modifiers.new("Subdivision", "SUBSURF")
    subdivision.levels, subdivision.render_levels = 0, 3
    render_only = scenes.add_cube("RenderOnly", location=(3, 0, 0))
    render_only.modifiers.new("Bevel", "BEVEL").show_viewport = False
    tube = scenes.add_bevel_curve("Tube", location=(6, 0, 0))
    tube.data.resolution_u, tube.data.render_resolution_u = 2, 24
    blob = scenes.add_metaball("Blob", location=(9, 0, 0), resolution=0.4)
    blob.data.render_resolution = 0.1
    switch = scenes.add_cube("Switched", location=(12, 0, 0))
    tree = bpy.data.node_groups.new("Switch", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    tree.nodes.new("GeometryNodeIsViewport")
    tree.links.new(tree.nodes.new("NodeGroupInput").outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
    switch.modifiers.new("Nodes", "NODES").node_group = tree
    pebble = scenes.add_cube("Pebble", scale=0.1, location=(50, 0, 0))
    pebble.hide_render = True
    emitter = scenes.add_particle_emitter("Emitter", count=10, obj=pebble, location=(0, 9, 0))
    emitter.particle_systems[0].settings.display_percentage = 30  # the viewport shows 3 of 10
    simulated = scenes.add_particle_emitter("Simulated", count=10, obj=pebble, location=(0, -9, 0))
    simulated.particle_systems[0].settings.physics_type = "NEWTON"  # renders 30% too: not named
    simulated.particle_systems[0].settings.display_percentage = 30
    switched_off = scenes.add_particle_emitter("SwitchedOff", count=10, obj=pebble, location=(0, -18, 0))
    switched_off.particle_systems[0].settings.display_percentage = 30
    switched_off.modifiers[0].show_viewport = switched_off.modifiers[0].show_render = False  # off in both
    plain = scenes.add_cube("Plain", location=(15, 0, 0))
    same = plain.modifiers.new("Same", "SUBSURF")
    same.levels = same.render_levels = 2  # equal: not named
    scene.render.use_simplify = True
    scene.render.simplify_subdivision, scene.render.simplify_subdivision_render = 2, 4  # Plain: 2 both
    assert _evaluation_warnings(extract_scene()) == [
        "the preview evaluates geometry as the viewport does, a final render with its own settings, which differ "
        "for 'Subdivided' (modifier 'Subdivision' 0 levels in the viewport, 3 in renders), 'RenderOnly' "
        "(modifier 'Bevel' enabled only in renders), 'Tube' (resolution U 2 in the viewport, 24 in renders), "
        "'Blob' (metaball resolution 0.4 in the viewport, 0.1 in renders), 'Switched' (modifier 'Nodes' reads "
        "Is Viewport), 'Emitter' (particles 'Particles': 30% shown in the viewport, all in renders), and "
        "Simplify (max subdivision 2 in the viewport, 4 in renders)"]
    scene.render.use_simplify = False
    for name in ("Subdivided", "RenderOnly", "Tube", "Blob", "Switched", "Emitter", "Simulated"):
        bpy.data.objects.remove(bpy.data.objects[name])
    assert _evaluation_warnings(extract_scene()) == []


def test_the_evaluation_warning_names_a_few_objects_and_counts_the_rest(scene):
    """Instanced members are checked too (their modifiers evaluate as in the viewport as well)."""
    source = scenes.new_collection("Source", exclude=True)
    for i in range(9):
        cube = scenes.add_cube(f"C{i}", location=(3 * i, 0, 0), collection=source)
        cube.modifiers.new("Subdivision", "SUBSURF")  # levels 1, render_levels 2: Blender's defaults
    scenes.add_collection_instance("Instancer", source)
    (warning,) = _evaluation_warnings(extract_scene())
    assert warning.count("(modifier 'Subdivision' 1 levels in the viewport, 2 in renders)") == 6
    assert warning.endswith(" and 3 more object(s)")


def _culling_warnings(result: ExtractedScene) -> list[str]:
    return [w for w in result.warnings if "Culling is on" in w]


def test_objects_cycles_may_cull_are_named(scene):
    """Outside review: with Simplify's Camera Culling on, Cycles left out a cube just outside the view
    whose shadow the preview drew over 13% of the floor, with no word."""
    camera = scenes.add_camera()
    scene.camera = camera
    culled = scenes.add_cube("Culled")
    scenes.add_cube("Kept", location=(3, 0, 0))
    lamp = scenes.add_light()
    for ob in (culled, lamp):  # a light has no geometry to cull: not named
        ob.cycles.use_camera_cull = True
    scene.render.engine = "CYCLES"
    scene.cycles.use_camera_cull = True
    assert _culling_warnings(extract_scene()) == []  # Simplify off: nothing is culled
    scene.render.use_simplify = True
    assert _culling_warnings(extract_scene()) == [
        "Simplify's Camera Culling is on: a Cycles render may leave out 'Culled', which the preview traces "
        "(it does not apply Cycles' culling)"]
    scene.cycles.use_camera_cull = False
    culled.cycles.use_distance_cull = True
    scene.cycles.use_distance_cull = True
    assert "Distance Culling" in _culling_warnings(extract_scene())[0]
    scene.cycles.distance_cull_margin = 0.0  # Cycles culls nothing at distance 0
    assert _culling_warnings(extract_scene()) == []
    scene.cycles.distance_cull_margin = 10.0
    camera.data.type = "PANO"  # Cycles culls nothing for a panoramic camera
    assert _culling_warnings(extract_scene()) == []
    camera.data.type = "PERSP"
    scene.render.engine = "BLENDER_WORKBENCH"
    assert _culling_warnings(extract_scene()) == []


def test_a_view_layer_with_surfaces_filtered_out_renders_no_triangles(scene):
    """Outside review: with View Layer > Filter > Surfaces off Cycles renders no surface (0 hit pixels
    of the 1,069 it renders with it on); the preview drew them all."""
    scenes.add_cube("Box")
    assert extract_scene().triangle_count == 12
    bpy.context.view_layer.use_solid = False
    result = extract_scene()
    assert result.triangle_count == 0 and result.warnings == [
        "view layer 'ViewLayer' has Filter > Surfaces off: a final render shows no surfaces, so the preview "
        "renders none"]


@pytest.mark.parametrize("hidden_path", scenes.TWO_PATH_HIDINGS[:2])
def test_a_hidden_instancer_of_a_collection_does_not_decide_for_a_visible_one(scene, hidden_path):
    """The path walk remembers per instanced collection which members make nothing: a render-hidden
    top-level instancer of the same collection walked first must decide nothing for a visible one
    (outside review, with the hidden child collection: 69 pixels of a copy Cycles does not draw)."""
    scenes.add_two_path_scene("collection instance", hidden_path)
    bpy.data.objects["Top"].hide_render = True
    scenes.add_collection_instance("Later", bpy.data.collections["Mid"], location=(0, 9, 0))
    order = [i.parent.name for i in bpy.context.evaluated_depsgraph_get().object_instances if i.is_instance]
    assert order.index("Top") < order.index("Later")  # the hidden one is walked first
    assert _leaf_centres(extract_scene(), "Leaf") == [(-3.0, 9.0, 0.0)]


@pytest.mark.parametrize("hidden_first", [True, False])
def test_a_hidden_source_does_not_hide_nested_instances_beside_it(scene, hidden_first):
    """Outside review against Cycles (0 against 183 pixels): a geometry-nodes level that holds no
    object yields no entry, so the hidden Object Info source's entry looked like an ancestor of the
    nested copies after it; an ancestor is believed only when the copies' levels continue its own."""
    scenes.add_hidden_source_beside_nested_instances(hidden_first)
    assert sorted(_instances_by_host(extract_scene()).get("Host", [])) == ["X"] * 4


def test_a_hidden_member_named_directly_shows_once(scene):
    """Outside review against Cycles (124 against 36 pixels): render-hidden X named by an Object Info
    node renders, but not where a collection instance on its path skips it."""
    scenes.add_hidden_member_named_and_nested()
    assert _leaf_centres(extract_scene(), "X") == [(-3.0, 0.0, 0.0)]


def test_instances_of_a_hidden_vertex_parent_in_a_collection_are_not_named_as_missing(scene):
    """Outside review: a render-hidden vertex-instancing parent inside an instanced collection makes no
    copies of its child in a render (Cycles: none), yet the child was named as 'not instanced in the
    viewport ... a final render shows them'."""
    source = scenes.new_collection("K", exclude=True)
    parent = scenes.add_mesh("VParent", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)], collection=source)
    parent.instance_type, parent.hide_render = "VERTS", True
    child = scenes.add_cube("VChild", scale=0.2, collection=source)
    child.parent = parent
    scenes.add_cube("Other", scale=0.2, location=(3, 0, 0), collection=source)
    scenes.add_collection_instance("Top", source)
    result = extract_scene()
    assert result.object_names == ["Other"] and result.warnings == []


def test_subdivision_levels_simplify_caps_alike_are_not_named(scene):
    """Outside review: Subdivision 1 against 3 levels under Simplify's 0 and 0 evaluates to 0 levels
    either way (Cycles' mask equals the preview's), yet was named."""
    scenes.add_cube("Capped").modifiers.new("Subdivision", "SUBSURF").render_levels = 3
    scene.render.use_simplify = True
    scene.render.simplify_subdivision = scene.render.simplify_subdivision_render = 0
    assert _evaluation_warnings(extract_scene()) == []
    scene.render.simplify_subdivision_render = 2
    assert _evaluation_warnings(extract_scene()) == [
        "the preview evaluates geometry as the viewport does, a final render with its own settings, which differ "
        "for 'Capped' (modifier 'Subdivision' 0 levels in the viewport, 2 in renders), and Simplify (max "
        "subdivision 0 in the viewport, 2 in renders)"]


def test_separate_children_with_a_hidden_and_a_visible_instancer_of_one_collection(scene):
    """Outside review against Cycles (0 against 61 pixels): geometry nodes number a collection member's
    own instances from its index + 1, so the copies under the visible instancer (in child collection
    'Sub') also continued the levels of the render-hidden one beside 'Sub'; only an entry's parent
    decides now."""
    leaf_collection = scenes.new_collection("LeafC", exclude=True)
    scenes.add_cube("Leaf", scale=0.3, collection=leaf_collection)
    top = scenes.new_collection("TopC", exclude=True)
    scenes.add_collection_instance("HI", leaf_collection, location=(3, 0, 0), collection=top).hide_render = True
    sub = scenes.new_collection("Sub", parent=top)
    scenes.add_collection_instance("VI", leaf_collection, location=(-3, 0, 0), collection=sub)
    scenes.add_info_node_host("Host", top, separate_children=True)
    assert _leaf_centres(extract_scene(), "Leaf") == [(-3.0, 0.0, 0.0)]
