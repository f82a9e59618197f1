"""Render visibility in extraction: what a final render shows of objects, collections, instancers,
ray visibility and holdout, checked against the rules Cycles follows (bpy module, no UI)."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from kd_addon.extract import extract_scene
from kd_addon.scene_records import ExtractedScene
from tests import bpy_scenes as scenes
from tests.extract_support import bounds, instances_by_host

pytestmark = pytest.mark.usefixtures("extraction_path")  # each test on the walk and the bulk path


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
    """Measured with Cycles (docs/choices.md#collections-instanced-by-nodes-or-particles-follow-the-collection-instance-rule): a collection that a Collection Info node instances whole is
    expanded like a collection instance in a render, so its render-hidden members (own flag or a
    hidden child collection) are not rendered; with Separate Children on a child object is an object
    reference and is rendered, a child collection is expanded like a collection instance and its
    render-hidden members are not (the preview must not draw them), and a hidden object that an Object
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
    """Measured with Cycles (docs/choices.md#collections-instanced-by-nodes-or-particles-follow-the-collection-instance-rule):
    particles rendering a collection whole expand it like a collection instance, leaving out its
    render-hidden members (own flag, a hidden child collection, a hidden member of a visible child
    collection), and so does the preview. Particles rendering one render-hidden object still show it."""
    source = _mixed_collection()
    pebble = scenes.add_cube("Pebble", scale=0.1, location=(50, 0, 0))
    pebble.hide_render = True
    scenes.add_particle_emitter("Whole", count=3, collection=source)
    scenes.add_particle_emitter("Single", count=2, obj=pebble, location=(20, 0, 0))
    result = extract_scene()
    by_host = instances_by_host(result)
    assert sorted(by_host) == ["Single", "Whole"]
    assert sorted(by_host["Whole"]) == ["Shown"] * 3 + ["VisInVisChild"] * 3
    assert by_host["Single"] == ["Pebble"] * 2
    assert result.warnings == []


def test_particles_picking_collection_members_leave_render_hidden_ones_out_and_warn(scene):
    """With Whole Collection off each particle gets one member: the viewport picks among all the
    members it shows, a final render among the render-visible ones only (Cycles draws cubes on
    particles where the viewport's pick puts render-hidden spheres). The preview
    cannot reproduce the render's pick: it leaves the render-hidden members out and says so. A pick
    among members that are all render-visible is the render's and stays quiet."""
    source = _mixed_collection()
    scenes.add_particle_emitter("Picker", count=40, collection=source, whole_collection=False)
    plain = scenes.new_collection("Plain", exclude=True)
    scenes.add_cube("Left", scale=0.2, collection=plain)
    scenes.add_cube("Right", scale=0.2, offset=(1, 0, 0), collection=plain)
    scenes.add_particle_emitter("Quiet", count=10, collection=plain, whole_collection=False, location=(30, 0, 0))
    result = extract_scene()
    by_host = instances_by_host(result)
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
    render-hidden child collection and a render-hidden member of a visible one (as
    Cycles does), while a render-hidden child object, an object reference, is drawn.
    The pick is over the unfiltered children in both, so the points keep their objects."""
    _mixed_collection()
    scenes.add_collection_points_host("Points", bpy.data.collections["Src"], count=8)
    result = extract_scene()
    assert sorted(result.object_names) == ["Hidden"] * 2 + ["Shown"] * 2 + ["VisInVisChild"] * 2
    assert {i.instancer for i in result.instances} == {"Points"}
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
    assert instances_by_host(result) == {"Host": ["Hidden"], None: ["Elsewhere"]}
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
    assert sorted(instances_by_host(result)["Host"]) == ["Shown", "VisInVisChild"]
    assert result.warnings == []


@pytest.mark.parametrize("instance_type", ["VERTS", "FACES"])
def test_a_child_of_a_vertex_or_face_instancing_parent_shows_only_as_its_instances(scene, instance_type):
    """Blender hides such a child at its own place in a final render (the viewport shows it there):
    a parent with two faces instances the child twice, and the original is left out, as Cycles
    leaves it out (kept, it would be an extra object)."""
    parent = scenes.add_mesh("Parent", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (4, 0, 0), (5, 0, 0), (5, 1, 0)],
                             [(0, 1, 2), (3, 4, 5)])
    parent.instance_type = instance_type
    parent.show_instancer_for_render = False
    child = scenes.add_cube("Child", scale=0.2, location=(0, 0, 3))
    child.parent = parent
    source = scenes.new_collection("Source", exclude=True)  # a collection instancer as a child: its own
    scenes.add_cube("Unit", scale=0.1, collection=source)  # instances go with it
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
    depsgraph applies, changes nothing. Checked against Cycles: a geometry-nodes carrier
    (is_instancer False) with Render off shows its own plate, and an instancer with Viewport off and
    Render on shows itself (no warning calling it hidden in the viewport)."""
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


@pytest.mark.parametrize("instance_type", ["VERTS", "FACES"])
def test_a_child_disabled_in_renders_is_not_instanced_on_vertices_or_faces(scene, instance_type):
    """Checked against Cycles: Blender instances the children that the depsgraph holds, and a render's
    leaves out a child disabled in renders (object_dupli.cc, make_child_duplis), so a final render shows
    no copies of it, though the viewport's depsgraph the preview reads makes them."""
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
    """Checked against Cycles: a Collection Info node instancing a collection that holds an empty
    instancing a second collection must not show the second's members disabled in renders (they are
    not objects the node instances directly). A render expands the nesting as a collection instance:
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
    assert sorted(instances_by_host(result)["Carrier"]) == expected


def _leaf_centres(result: ExtractedScene, name: str) -> list[tuple[float, ...]]:
    """Centres of the instances of object `name`, sorted (each instance is one whole cube)."""
    return sorted(tuple(np.round(inst.matrix_world[:3, 3], 6)) for inst in result.instances if inst.name == name)


@pytest.mark.parametrize("top", scenes.TWO_PATH_TOPS)
@pytest.mark.parametrize("hidden_path", scenes.TWO_PATH_HIDINGS)
def test_an_object_reached_by_a_visible_and_a_render_hidden_path_is_made_once(scene, top, hidden_path):
    """Checked against Cycles: 'Mid' holds an empty instancing 'LeafC' (Leaf) at x = -3 and
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
    """Checked against Cycles: an Object Info node (As Instance) of a render-hidden object
    still shows that object's own mesh in a render, but not the instances the object makes itself
    (Blender makes none from a render-hidden object, at any depth; drawn, they are ~1,100 pixels
    each). With the source visible both show."""
    scenes.add_object_info_of_instancer(source_kind, hidden)
    own, made = {"collection instancer": ([], ["X"]), "vertex-instancing parent": (["Source"], ["X"] * 3),
                 "nodes carrier": ([], ["Source"] * 2)}[source_kind]  # a carrier's instances are its own entries
    result = extract_scene()
    expected = own if hidden else own + made
    assert sorted(instances_by_host(result).get("Host", [])) == sorted(expected)


@pytest.mark.parametrize("first_layer_renders", [True, False])
def test_background_scenes_are_rendered_through_their_render_view_layer(scene, first_layer_renders):
    """Checked against Cycles: a render shows the objects of the scene's Background Scene (and of
    that one's, chained) as the depsgraph holds them, and so does the preview. A
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


@pytest.mark.parametrize("hidden_path", scenes.TWO_PATH_HIDINGS[:2])
def test_a_hidden_instancer_of_a_collection_does_not_decide_for_a_visible_one(scene, hidden_path):
    """The path walk remembers per instanced collection which members make nothing: a render-hidden
    top-level instancer of the same collection walked first must decide nothing for a visible one
    (with the hidden child collection, a wrong decision draws 69 pixels of a copy Cycles does not)."""
    scenes.add_two_path_scene("collection instance", hidden_path)
    bpy.data.objects["Top"].hide_render = True
    scenes.add_collection_instance("Later", bpy.data.collections["Mid"], location=(0, 9, 0))
    order = [i.parent.name for i in bpy.context.evaluated_depsgraph_get().object_instances if i.is_instance]
    assert order.index("Top") < order.index("Later")  # the hidden one is walked first
    assert _leaf_centres(extract_scene(), "Leaf") == [(-3.0, 9.0, 0.0)]


@pytest.mark.parametrize("hidden_first", [True, False])
def test_a_hidden_source_does_not_hide_nested_instances_beside_it(scene, hidden_first):
    """Checked against Cycles by pixel counts: a geometry-nodes level that holds no object
    yields no entry, so the hidden Object Info source's entry can look like an ancestor of the nested
    copies after it; an ancestor is believed only when the copies' levels continue its own."""
    scenes.add_hidden_source_beside_nested_instances(hidden_first)
    assert sorted(instances_by_host(extract_scene()).get("Host", [])) == ["X"] * 4


def test_a_hidden_member_named_directly_shows_once(scene):
    """Checked against Cycles by pixel counts: render-hidden X named by an Object Info
    node renders, but not where a collection instance on its path skips it."""
    scenes.add_hidden_member_named_and_nested()
    assert _leaf_centres(extract_scene(), "X") == [(-3.0, 0.0, 0.0)]


def test_separate_children_with_a_hidden_and_a_visible_instancer_of_one_collection(scene):
    """Checked against Cycles by pixel counts: geometry nodes number a collection member's
    own instances from its index + 1, so the copies under the visible instancer (in child collection
    'Sub') also continue the levels of the render-hidden one beside 'Sub'; only an entry's parent
    decides."""
    leaf_collection = scenes.new_collection("LeafC", exclude=True)
    scenes.add_cube("Leaf", scale=0.3, collection=leaf_collection)
    top = scenes.new_collection("TopC", exclude=True)
    scenes.add_collection_instance("HI", leaf_collection, location=(3, 0, 0), collection=top).hide_render = True
    sub = scenes.new_collection("Sub", parent=top)
    scenes.add_collection_instance("VI", leaf_collection, location=(-3, 0, 0), collection=sub)
    scenes.add_info_node_host("Host", top, separate_children=True)
    assert _leaf_centres(extract_scene(), "Leaf") == [(-3.0, 0.0, 0.0)]
