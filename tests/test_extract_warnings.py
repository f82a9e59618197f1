"""Extraction's warnings: what a final render shows and the preview leaves out or renders
differently is named (bpy module, no UI)."""

from __future__ import annotations

import bpy
import pytest

from kd_addon.extract import extract_scene
from kd_addon.scene_records import ExtractedScene
from tests import bpy_scenes as scenes
from tests.extract_support import instances_by_host, triangles_of

pytestmark = pytest.mark.usefixtures("extraction_path")  # each test on the walk and the bulk path


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


def test_an_eye_hidden_child_of_an_instancing_parent_is_not_named(scene):
    """A vertex parent's child shows only as the parent's instances, in renders as in the viewport, and
    the eye icon keeps those instances in the viewport: nothing differs, so nothing is named. Disabled
    in viewports, its instances go: named."""
    parent = scenes.add_cube("Parent")
    parent.instance_type = "VERTS"
    child = scenes.add_cube("Child", scale=0.2)
    child.parent = parent
    child.hide_set(True)
    result = extract_scene()
    assert len(instances_by_host(result)["Parent"]) == 8 and result.warnings == []
    child.hide_set(False)
    child.hide_viewport = True
    assert [w for w in extract_scene().warnings if "'Child'" in w]


def test_hidden_instancers_and_viewport_disabled_members_are_named(scene):
    """A collection instancer hidden in the viewport takes its instances with it, and a member of an
    instanced collection disabled in viewports is not evaluated for the instances: a final render
    shows both, so the preview names them rather than leave their triangles out in silence."""
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
    """Checked against Cycles (hit masks equal): particles render a collection's objects but do
    not expand the collection instances among them (object_dupli.cc makes no nested instances for
    particles), and no render instances a metaball; the preview leaves both out, as a render does,
    and must not warn that each 'is not instanced in the viewport ... a final render shows them'."""
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
    assert sorted(instances_by_host(result)["Top"]) == ["DeepUnit", "Unit"]
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
        assert sorted(instances_by_host(result)["Host"]) == ["Member", "RenderHidden", "SecondUnit", "Unit"]
        assert result.warnings == [second_member.replace("collection 'Source'", "collection 'Second'")]
    else:
        assert set(instances_by_host(result)["Host"]) == {"Unit", "SecondUnit"}
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
    assert instances_by_host(result) == {"Host": ["UsedUnit"]}
    assert result.warnings == []


def test_a_view_layer_not_enabled_for_rendering_is_named(scene):
    """The preview renders the window's view layer; a final render writes only the
    layers enabled for rendering, so a disabled one gets a warning (and renders as before)."""
    scenes.add_cube("Box")
    bpy.context.view_layer.use = False
    result = extract_scene()
    assert result.object_names == ["Box"]
    assert result.warnings == [f"view layer '{bpy.context.view_layer.name}' is not enabled for rendering (Use for "
                               "Rendering off): the preview renders it, a final render writes only the enabled layers"]


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
    renders both, the preview cannot trace them and says so rather than leave them out in silence."""
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


def test_a_meshs_finite_triangles_stay_and_the_warning_counts_the_others(scene):
    """As Cycles: only the triangles that use a non-finite vertex are left out; every user of the shared
    mesh keeps the others."""
    verts = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (float("inf"), 1, 0)]
    first = scenes.add_mesh("Half", verts, [(0, 1, 2), (1, 3, 2)])
    scenes.link(bpy.data.objects.new("Twin", first.data))
    result = extract_scene()
    assert sorted(result.object_names) == ["Half", "Twin"]
    assert result.triangle_count == 2
    assert result.warnings == ["objects 'Half', 'Twin' (sharing mesh 'Half') have non-finite vertex coordinates; the 1 "
                               "of its 2 triangles that use them left out"]


def test_a_loose_non_finite_vertex_changes_nothing(scene):
    scenes.add_mesh("Loose", [(0, 0, 0), (1, 0, 0), (0, 1, 0), (float("nan"), 1, 0)], [(0, 1, 2)])
    result = extract_scene()
    assert result.object_names == ["Loose"] and result.triangle_count == 1 and result.warnings == []


def _evaluation_warnings(result: ExtractedScene) -> list[str]:
    return [w for w in result.warnings if w.startswith("the preview evaluates geometry as the viewport does")]


def test_settings_a_render_evaluates_differently_are_named_in_one_warning(scene):
    """Checked against Cycles: each of these changes the image by 230-2,200 pixels of 19,200, and the
    preview, which reads the viewport's evaluation, names them (docs/extraction.md#viewport-evaluation-against-render-evaluation)."""
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
    """With Simplify's Camera Culling on, Cycles leaves out a cube just outside the view whose shadow
    the preview draws over 13% of the floor; the preview names such objects (docs/extraction.md#known-gaps)."""
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
    """With View Layer > Filter > Surfaces off Cycles renders no surface (0 hit pixels of the 1,069
    it renders with it on), and neither does the preview."""
    scenes.add_cube("Box")
    assert extract_scene().triangle_count == 12
    bpy.context.view_layer.use_solid = False
    result = extract_scene()
    assert result.triangle_count == 0 and result.warnings == [
        "view layer 'ViewLayer' has Filter > Surfaces off: a final render shows no surfaces, so the preview "
        "renders none"]


def test_instances_of_a_hidden_vertex_parent_in_a_collection_are_not_named_as_missing(scene):
    """A render-hidden vertex-instancing parent inside an instanced collection makes no copies of its
    child in a render (Cycles: none), so the child must not be named as 'not instanced in the
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
    """Subdivision 1 against 3 levels under Simplify's 0 and 0 evaluates to 0 levels either way
    (Cycles' mask equals the preview's), so it is not named."""
    scenes.add_cube("Capped").modifiers.new("Subdivision", "SUBSURF").render_levels = 3
    scene.render.use_simplify = True
    scene.render.simplify_subdivision = scene.render.simplify_subdivision_render = 0
    assert _evaluation_warnings(extract_scene()) == []
    scene.render.simplify_subdivision_render = 2
    assert _evaluation_warnings(extract_scene()) == [
        "the preview evaluates geometry as the viewport does, a final render with its own settings, which differ "
        "for 'Capped' (modifier 'Subdivision' 0 levels in the viewport, 2 in renders), and Simplify (max "
        "subdivision 0 in the viewport, 2 in renders)"]
