"""Instancing paths checked against a final render's own depsgraph (tests/render_depsgraph.py).

The preview reads the viewport's depsgraph and decides which of its entries a render makes; a render
engine gets the render-mode depsgraph, which has decided already. Each scene here nests instancers in a
way where the two can disagree (Cycles agreed with the render depsgraph each time). The rules are in
docs/extraction.md#instances; what stays open is in docs/extraction.md#known-gaps.
"""
from __future__ import annotations

import bpy
import pytest

from kd_addon.extract import extract_scene
from kd_addon.node_instances import node_references
from tests import bpy_scenes as scenes
from tests.render_depsgraph import differences, render_entries

pytestmark = pytest.mark.usefixtures("extraction_path")  # each test on the walk and the bulk path


def assert_extraction_matches_render():
    result = extract_scene()
    entries = render_entries()
    assert entries, "the render made nothing: the scene does not test anything"
    assert differences(result, entries) == []
    return result


def _object_info_host(name, target, *, as_instance, location=(0, 0, 0)):
    host = scenes.add_info_node_host(name, target, location=location)
    info = next(n for n in host.modifiers["GN"].node_group.nodes if n.bl_idname == "GeometryNodeObjectInfo")
    info.inputs["As Instance"].default_value = as_instance
    return host


def _collection_with_hidden_member(name="Rocks"):
    """A collection excluded from the view layer with a visible cube and a render-hidden one."""
    rocks = scenes.new_collection(name, exclude=True)
    scenes.add_cube(f"{name}Shown", scale=0.3, collection=rocks)
    scenes.add_cube(f"{name}Hidden", scale=0.3, offset=(1, 0, 0), collection=rocks).hide_render = True
    return rocks


@pytest.mark.parametrize("source", ["collection info", "object info", "object info as instance"])
def test_a_carrier_inside_a_collection_instance_brings_what_it_instances(scene, source):
    """A geometry-nodes carrier that is a member of an instanced collection, instancing an object or a
    collection that is not a member: the render shows its instances under the outer instancer (the
    preview dropped them all, without a word)."""
    inner = scenes.new_collection("Inner", exclude=True)
    if source == "collection info":
        rocks = scenes.new_collection("Rocks", exclude=True)
        scenes.add_cube("Rock", scale=0.3, collection=rocks)
        carrier = scenes.add_info_node_host("Carrier", rocks)
    else:
        rock = scenes.add_cube("Rock", scale=0.3, location=(0, 0, -30))
        carrier = _object_info_host("Carrier", rock, as_instance=source.endswith("as instance"))
    bpy.context.scene.collection.objects.unlink(carrier)
    inner.objects.link(carrier)
    scenes.add_collection_instance("Outer", inner, location=(5, 0, 0))
    result = assert_extraction_matches_render()
    made = "Carrier" if source == "object info" else "Rock"  # As Instance off: realized into the carrier
    assert any(i.name == made and i.instancer == "Outer" for i in result.instances)


@pytest.mark.parametrize("as_instance", [False, True])
def test_object_info_of_a_collection_instancer_leaves_render_hidden_members_out(scene, as_instance):
    """Object Info of an empty that instances a collection with a render-hidden member: a render
    leaves the member out, as any instance of the collection does (the preview showed it)."""
    rocks = _collection_with_hidden_member()
    empty = scenes.add_collection_instance("RocksEmpty", rocks, location=(0, 0, -30))
    _object_info_host("Carrier", empty, as_instance=as_instance)
    result = assert_extraction_matches_render()
    assert {i.name for i in result.instances} >= {"RocksShown"}
    assert "RocksHidden" not in {i.name for i in result.instances}


@pytest.mark.parametrize("route", ["object info", "object info as instance", "collection info", "vertices"])
def test_a_nested_collection_info_carrier_leaves_render_hidden_members_out(scene, route):
    """A carrier scattering a collection with a render-hidden member, reached through another
    instancer: Object Info of the carrier, Collection Info of a collection holding it, or a parent
    instancing it on its vertices. A render leaves the member out on every route."""
    rocks = _collection_with_hidden_member()
    inner_host = scenes.add_info_node_host("Scatter", rocks, location=(0, 0, -30))
    if route.startswith("object info"):
        _object_info_host("Top", inner_host, as_instance=route.endswith("as instance"))
    elif route == "collection info":
        holder = scenes.new_collection("Holder", exclude=True)
        bpy.context.scene.collection.objects.unlink(inner_host)
        holder.objects.link(inner_host)
        scenes.add_info_node_host("Top", holder)
    else:
        parent = scenes.add_mesh("Top", [(0, 0, 0), (3, 0, 0)], [], edges=[(0, 1)])
        parent.instance_type = "VERTS"
        inner_host.parent = parent
    result = assert_extraction_matches_render()
    assert "RocksShown" in {i.name for i in result.instances}
    assert "RocksHidden" not in {i.name for i in result.instances}


@pytest.mark.parametrize("kind", ["emitter particles", "hair particles", "vertices"])
def test_an_instanced_instancer_hides_itself_and_makes_its_instances(scene, kind):
    """An emitter or a vertex-instancing parent inside an instanced collection, with Show Instancer
    (Show Emitter) for renders off: a render hides its own mesh there as it does at the top level, and
    makes its instances under the outer instancer (the preview showed the mesh, and dropped the
    particles' instances of an object that is not a member)."""
    inner = scenes.new_collection("Inner", exclude=True)
    if kind.endswith("particles"):
        dot = scenes.add_cube("Dot", scale=0.1, location=(0, 0, -30))
        host = scenes.add_particle_emitter("Host", count=5, obj=dot)
        settings = host.particle_systems[0].settings
        settings.type = kind.split()[0].upper()
        settings.physics_type = "NEWTON"  # hair without physics grows no strands
    else:
        host = scenes.add_mesh("Host", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
        host.instance_type = "VERTS"
        dot = scenes.add_cube("Dot", scale=0.1)
        dot.parent = host
        bpy.context.scene.collection.objects.unlink(dot)
        inner.objects.link(dot)
    host.show_instancer_for_render = False
    bpy.context.scene.collection.objects.unlink(host)
    inner.objects.link(host)
    scenes.add_collection_instance("Outer", inner, location=(20, 0, 0))
    result = assert_extraction_matches_render()
    assert not any(i.name == "Host" for i in result.instances)
    assert sum(i.name == "Dot" and i.instancer == "Outer" for i in result.instances) == (4 if kind == "vertices" else 5)


@pytest.mark.parametrize("kind, method", [("EMITTER", "DOT"), ("EMITTER", "NONE"), ("HAIR", "PATH"), ("HAIR", "RENDER")])
def test_particles_not_displayed_as_rendered_are_named(scene, kind, method):
    """Blender makes particles' object instances in the viewport only when they display as Rendered;
    a render always does. The preview cannot show them, so it names them rather than leave them out in
    silence."""
    pebble = scenes.add_cube("Pebble", scale=0.1, location=(0, 0, -30))
    emitter = scenes.add_particle_emitter("Emitter", count=10, obj=pebble)
    settings = emitter.particle_systems[0].settings
    settings.type, settings.physics_type, settings.display_method = kind, "NEWTON", method
    result = extract_scene()
    missing = differences(result, render_entries())
    named = [w for w in result.warnings if "display as" in w]
    if method == "RENDER":
        assert missing == [] and named == []
    else:
        assert [m.split(":")[0] for m in missing] == ["('Pebble', 'Emitter')"]
        shown_as = {"DOT": "Point", "NONE": "None", "PATH": "Path"}[method]
        assert named and f"'Emitter' (particles 'Particles' display as '{shown_as}' in the viewport" in named[0]


@pytest.mark.parametrize("update", ["UPDATE_ALWAYS", "NEVER"])
def test_a_metaball_never_updated_in_the_viewport_is_named(scene, update):
    """Update on Edit: Never leaves a metaball unmeshed in the viewport (a render meshes it)."""
    blob = scenes.add_metaball("Blob")
    blob.data.update_method = update
    blob.data.render_resolution = blob.data.resolution
    result = extract_scene()
    assert (result.triangle_count == 0) == (update == "NEVER")
    assert any("'Blob' (metaball Update on Edit 'Never'" in w for w in result.warnings) == (update == "NEVER")
    assert render_entries()  # a render meshes it either way


@pytest.mark.parametrize("keep_curve", [False, True])
def test_a_curves_object_whose_nodes_make_a_mesh_is_named_only_for_what_is_left(scene, keep_curve):
    """A hair curves object whose geometry nodes turn a curve into a tube: the tube is triangles, which
    the preview shows, so no "is hair curves, not triangles: left out" warning is due. With the
    curve kept beside the tube, that curve is named."""
    hair = scenes.link(bpy.data.objects.new("Hair", bpy.data.hair_curves.new("Hair")))
    tree = bpy.data.node_groups.new("Tube", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    line = tree.nodes.new("GeometryNodeCurvePrimitiveLine")
    profile = tree.nodes.new("GeometryNodeCurvePrimitiveCircle")
    tube = tree.nodes.new("GeometryNodeCurveToMesh")
    tree.links.new(line.outputs[0], tube.inputs["Curve"])
    tree.links.new(profile.outputs[0], tube.inputs["Profile Curve"])
    out = tube.outputs[0]
    if keep_curve:
        join = tree.nodes.new("GeometryNodeJoinGeometry")
        tree.links.new(line.outputs[0], join.inputs[0])
        tree.links.new(tube.outputs[0], join.inputs[0])
        out = join.outputs[0]
    tree.links.new(out, tree.nodes.new("NodeGroupOutput").inputs[0])
    hair.modifiers.new("GN", "NODES").node_group = tree
    result = assert_extraction_matches_render()
    assert [i.name for i in result.instances] == ["Hair"]
    named = [w for w in result.warnings if "'Hair'" in w]
    assert named == (["object 'Hair' is hair curves: the preview shows the triangles its geometry nodes make and "
                      "leaves the rest out"] if keep_curve else [])


def test_a_member_showing_itself_only_in_renders_is_named_for_its_own_mesh(scene):
    """A vertex-instancing member of an instanced collection with Show Instancer off for the viewport
    and on for renders: the viewport makes its instances but not its own mesh, which a render shows.
    The warning names that mesh, not a collection disabled in viewports or its instances."""
    inner = scenes.new_collection("Inner", exclude=True)
    parent = scenes.add_mesh("Parent", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], collection=inner)
    parent.instance_type = "VERTS"
    parent.show_instancer_for_viewport, parent.show_instancer_for_render = False, True
    scenes.add_cube("Dot", scale=0.1, collection=inner).parent = parent
    scenes.add_collection_instance("Outer", inner, location=(0, 8, 0))
    result = extract_scene()
    missing = differences(result, render_entries())
    assert [m.split(":")[0] for m in missing] == ["('Parent', 'Outer')"]
    assert result.warnings == ["object 'Parent' in collection 'Inner' (instanced by 'Outer') has Show Instancer > "
                               "Viewport off: the preview leaves its own mesh out there, a final render shows it"]


EARLIER_SCENES = (
    [(f"two paths: {top}, {hiding}", lambda top=top, hiding=hiding: scenes.add_two_path_scene(top, hiding))
     for top in scenes.TWO_PATH_TOPS for hiding in scenes.TWO_PATH_HIDINGS]
    + [(f"object info of a {kind}, hidden {hidden}",
        lambda kind=kind, hidden=hidden: scenes.add_object_info_of_instancer(kind, hidden))
       for kind in scenes.OBJECT_INFO_SOURCES for hidden in (False, True)]
    + [(f"hidden source beside nested instances, first {first}",
        lambda first=first: scenes.add_hidden_source_beside_nested_instances(first)) for first in (True, False)]
    + [("hidden member named and nested", scenes.add_hidden_member_named_and_nested)])


@pytest.mark.parametrize("build", [b for _, b in EARLIER_SCENES], ids=[n for n, _ in EARLIER_SCENES])
def test_earlier_reviews_scenes_match_a_render_depsgraph(scene, build):
    """The nested-instancer scenes of test_extract_visibility.py (each checked against Cycles by pixel
    counts, and by that file's expected instances) against a render's own depsgraph, object by object."""
    build()
    assert differences(extract_scene(), render_entries()) == []  # two of them render nothing, as the preview


@pytest.mark.parametrize("below", [False, True])
@pytest.mark.parametrize("route", ["collection instance", "object info"])
def test_a_vertex_parents_child_in_a_render_disabled_collection_is_not_copied(scene, route, below):
    """A render's depsgraph holds no object of a render-disabled collection, or of one below it, so a
    vertex parent has no such child to copy (a copy of it is 159 pixels where Cycles draws none)."""
    hidden = bpy.data.collections.new("Hidden")
    hidden.hide_render = True
    holder = hidden
    if below:  # the child's own collection is not disabled, one above it is
        holder = bpy.data.collections.new("Sub")
        hidden.children.link(holder)
    if route == "collection instance":
        inner = scenes.new_collection("Inner", exclude=True)
        inner.children.link(hidden)
        parent = scenes.add_mesh("Parent", [(0, 0, 0), (2, 0, 0), (0, 2, 0)], [(0, 1, 2)], collection=inner)
        scenes.add_collection_instance("Outer", inner)
    else:
        bpy.context.scene.collection.children.link(hidden)
        parent = scenes.add_mesh("Parent", [(0, 0, 0), (2, 0, 0), (0, 2, 0)], [(0, 1, 2)], location=(0, 0, -30))
        _object_info_host("Outer", parent, as_instance=True)
    parent.instance_type = "VERTS"
    parent.show_instancer_for_render = parent.show_instancer_for_viewport = False
    scenes.add_cube("Kid", scale=0.3, collection=holder).parent = parent
    scenes.add_cube("Ground", scale=3.0, location=(0, 0, -5))
    result = assert_extraction_matches_render()
    assert not any(i.name == "Kid" for i in result.instances)


@pytest.mark.parametrize("kind", ["text", "curve"])
def test_object_info_of_a_render_hidden_curve_or_text_shows_nothing(scene, kind):
    """Object Info (As Instance) shows a render-hidden mesh, but not a render-hidden text or curve
    (a copy of it is 187 pixels where Cycles draws none)."""
    source = (scenes.add_text("Source", "Ab", location=(0, 0, -30)) if kind == "text"
              else scenes.add_bevel_curve("Source", location=(0, 0, -30)))
    source.hide_render = True
    scenes.add_info_node_host("Host", source)
    scenes.add_cube("Ground", scale=3.0, location=(0, 0, -5))
    result = assert_extraction_matches_render()
    assert not any(i.name == "Source" for i in result.instances)


@pytest.mark.parametrize("separate", [False, True])
def test_separate_children_set_by_the_modifiers_input_is_read(scene, separate):
    """Collection Info's Separate Children fed from the modifier's own input: off, the collection is
    instanced whole and a render leaves its render-hidden member out; on, each child object is a
    reference and renders. The preview must follow the input, not keep the member either way."""
    rocks = _collection_with_hidden_member()
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    item = tree.interface.new_socket("Separate", in_out="INPUT", socket_type="NodeSocketBool")
    info = tree.nodes.new("GeometryNodeCollectionInfo")
    info.inputs["Collection"].default_value = rocks
    tree.links.new(tree.nodes.new("NodeGroupInput").outputs["Separate"], info.inputs["Separate Children"])
    tree.links.new(info.outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
    host = scenes.add_mesh("Host", [], [])
    modifier = host.modifiers.new("GN", "NODES")
    modifier.node_group = tree
    scenes.set_modifier_input(modifier, item.identifier, separate)
    result = assert_extraction_matches_render()
    assert ("RocksHidden" in {i.name for i in result.instances}) == separate


def test_members_hidden_in_renders_too_are_not_named_as_shown_by_one(scene):
    """A member with Show Instancer off for the viewport and for renders shows its own mesh in neither:
    it must not be named as 'a final render shows it'."""
    inner = scenes.new_collection("Inner", exclude=True)
    parent = scenes.add_mesh("Parent", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], collection=inner)
    parent.instance_type = "VERTS"
    parent.show_instancer_for_viewport = parent.show_instancer_for_render = False
    scenes.add_cube("Dot", scale=0.1, collection=inner).parent = parent
    scenes.add_collection_instance("Outer", inner, location=(0, 8, 0))
    result = assert_extraction_matches_render()
    assert result.warnings == []


def test_an_emitter_picking_members_inside_an_instanced_collection_is_named(scene):
    """Particles giving each particle one member of a collection with a render-hidden member pick
    differently in a render (among the render-visible members): named at the top level, and inside
    an instanced collection too."""
    rocks = _collection_with_hidden_member()
    inner = scenes.new_collection("Inner", exclude=True)
    emitter = scenes.add_particle_emitter("Emitter", count=4, collection=rocks, whole_collection=False, size=2.0)
    bpy.context.scene.collection.objects.unlink(emitter)
    inner.objects.link(emitter)
    scenes.add_collection_instance("Outer", inner)
    named = [w for w in extract_scene().warnings if "particle-to-object assignment differs" in w]
    assert len(named) == 1 and named[0].startswith("object 'Emitter': particle system 'Particles' gives each")


@pytest.mark.parametrize("viewport_hidden_first", [False, True])
def test_members_are_numbered_with_the_viewport_hidden_ones(scene, viewport_hidden_first):
    """Two instancers of one collection inside an instanced one, the first render-hidden, neither with
    an entry of its own (Show Instancer off in the viewport): their copies are told apart by the member
    index, which counts every member, viewport-hidden ones too (counting only the shown ones, a
    viewport-hidden member ahead of them lets the hidden instancer's copy through)."""
    rocks = scenes.new_collection("Rocks", exclude=True)
    scenes.add_cube("Rock", scale=0.3, collection=rocks)
    inner = scenes.new_collection("Inner", exclude=True)
    if viewport_hidden_first:
        scenes.add_cube("Away", scale=0.1, location=(0, 0, 9), collection=inner).hide_viewport = True
    hidden = scenes.add_collection_instance("Hidden", rocks, location=(3, 0, 0), collection=inner)
    shown = scenes.add_collection_instance("Shown", rocks, location=(-3, 0, 0), collection=inner)
    hidden.hide_render = True
    hidden.show_instancer_for_viewport = shown.show_instancer_for_viewport = False
    scenes.add_collection_instance("Outer", inner)
    result = extract_scene()
    assert sum(i.name == "Rock" for i in result.instances) == 1
    missing = [d for d in differences(result, render_entries()) if not d.startswith("('Away'")]
    assert missing == []


@pytest.mark.parametrize("order", [(True, False), (False, True)])
def test_a_group_called_twice_with_other_switches_is_read_twice(scene, order):
    """A node group feeding its Collection and Separate Children inputs to a Collection Info node,
    called with the same collection, once separated and once whole: each call is read with its own
    switches, in either order (a walk that read the group once would lose the second call's). (Which
    copy of the render-hidden member a render keeps, the separated call's, the preview cannot tell from
    the other's: docs/extraction.md#known-gaps.)"""
    rocks = _collection_with_hidden_member()
    group = bpy.data.node_groups.new("Pick", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Collection", in_out="INPUT", socket_type="NodeSocketCollection")
    group.interface.new_socket("Separate", in_out="INPUT", socket_type="NodeSocketBool")
    inputs, info = group.nodes.new("NodeGroupInput"), group.nodes.new("GeometryNodeCollectionInfo")
    group.links.new(inputs.outputs["Collection"], info.inputs["Collection"])
    group.links.new(inputs.outputs["Separate"], info.inputs["Separate Children"])
    group.links.new(info.outputs[0], group.nodes.new("NodeGroupOutput").inputs[0])
    tree = bpy.data.node_groups.new("Host", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    join = tree.nodes.new("GeometryNodeJoinGeometry")
    for separate in order:
        call = tree.nodes.new("GeometryNodeGroup")
        call.node_tree = group
        call.inputs["Collection"].default_value, call.inputs["Separate"].default_value = rocks, separate
        tree.links.new(call.outputs[0], join.inputs[0])
    tree.links.new(join.outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
    host = scenes.add_mesh("Host", [], [])
    host.modifiers.new("GN", "NODES").node_group = tree
    collections, objects = node_references(host)
    assert [c.name for c in collections] == ["Rocks"]  # the whole call
    assert sorted(o.name for o in objects) == ["RocksHidden", "RocksShown"]  # the separated call's children


def test_a_point_cloud_whose_nodes_make_instances_is_not_named(scene):
    """A point cloud whose nodes put an instance of a mesh on new points: everything renders as
    triangles, so no "is a point cloud, not triangles: left out" warning is due."""
    rock = scenes.add_cube("Rock", scale=0.2, location=(0, 0, -30))
    cloud = scenes.link(bpy.data.objects.new("Cloud", bpy.data.pointclouds.new("Cloud")))
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    points = tree.nodes.new("GeometryNodePoints")
    points.inputs["Count"].default_value = 3
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value, info.inputs["As Instance"].default_value = rock, True
    on_points = tree.nodes.new("GeometryNodeInstanceOnPoints")
    tree.links.new(points.outputs[0], on_points.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
    cloud.modifiers.new("GN", "NODES").node_group = tree
    result = assert_extraction_matches_render()
    assert sum(i.name == "Rock" and i.instancer == "Cloud" for i in result.instances) == 3
    assert result.warnings == []


@pytest.mark.parametrize("sibling", [False, True])
def test_a_nested_instancer_disabled_in_viewports_is_named_once(scene, sibling):
    """A collection instancer inside an instanced collection, disabled in viewports: its copies are
    missing from the preview (with a visible sibling instancing the same collection: 1 copy against a
    render's 2). The instancer is named, once, and not again through its members."""
    leaf = scenes.new_collection("Leaf", exclude=True)
    scenes.add_cube("LeafCube", scale=0.3, collection=leaf)
    branch = scenes.new_collection("Branch", exclude=True)
    scenes.add_collection_instance("LeafInst", leaf, location=(1, 0, 0), collection=branch).hide_viewport = True
    if sibling:
        scenes.add_collection_instance("LeafInst2", leaf, location=(-1, 0, 0), collection=branch)
    scenes.add_cube("BranchBox", scale=0.25, collection=branch)
    scenes.add_collection_instance("Tree", branch)
    result = extract_scene()
    missing = differences(result, render_entries())
    assert [m.split(":")[0] for m in missing] == ["('LeafCube', 'Tree')"]
    assert result.warnings == ["object 'LeafInst' in collection 'Branch' (instanced by 'Tree') is disabled in "
                               "viewports: the preview leaves its instances out, a final render shows them"]
