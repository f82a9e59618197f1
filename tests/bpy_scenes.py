"""Small bpy scene builders for tests (no operators where bpy.data will do).

Every builder works on the current scene; call :func:`reset` first to start
from an empty factory scene. Geometry is built from explicit coordinates so
tests can state the expected triangles independently of Blender.
"""

from __future__ import annotations

import math

import bpy
import numpy as np

# A 2x2x2 cube centered on the origin: 8 vertices, 6 quads -> 12 triangles.
CUBE_VERTS = [(x, y, z) for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)]
CUBE_FACES = [
    (0, 1, 3, 2), (4, 6, 7, 5),  # -x, +x
    (0, 4, 5, 1), (2, 3, 7, 6),  # -y, +y
    (0, 2, 6, 4), (1, 5, 7, 3),  # -z, +z
]


def reset() -> bpy.types.Scene:
    """Empty factory scene (no objects), frame 1."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.frame_set(1)
    return scene


def link(obj: bpy.types.Object, collection: bpy.types.Collection | None = None):
    """Link obj into collection (default: the scene's master collection)."""
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def add_mesh(name, verts, faces, *, location=(0, 0, 0), collection=None, edges=()):
    """Mesh object from explicit vertices/faces."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], list(edges), [tuple(f) for f in faces])
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    return link(obj, collection)


def add_cube(name="Cube", *, offset=(0, 0, 0), scale=1.0, location=(0, 0, 0), collection=None):
    """Axis-aligned cube: CUBE_VERTS * scale + offset in object space."""
    verts = [tuple(scale * c + o for c, o in zip(v, offset)) for v in CUBE_VERTS]
    return add_mesh(name, verts, CUBE_FACES, location=location, collection=collection)


def add_empty(name="Empty", *, location=(0, 0, 0), collection=None):
    """Plain empty (no geometry)."""
    obj = bpy.data.objects.new(name, None)
    obj.location = location
    return link(obj, collection)


def new_collection(name, *, parent=None, exclude=False):
    """Collection linked under parent (default scene root); optionally excluded
    from the view layer so only its instances are rendered."""
    coll = bpy.data.collections.new(name)
    (parent or bpy.context.scene.collection).children.link(coll)
    if exclude:
        layer = bpy.context.view_layer.layer_collection.children[coll.name]
        layer.exclude = True
    return coll


def add_collection_instance(name, source, *, location=(0, 0, 0), collection=None):
    """Empty that instances collection `source` at `location`, linked into `collection` (default the
    scene's)."""
    obj = add_empty(name, location=location, collection=collection)
    obj.instance_type = "COLLECTION"
    obj.instance_collection = source
    return obj


def add_armature_rig(name="Rig", *, angle_at_frame=((1, 0.0), (10, math.pi / 2))):
    """Armature with one bone along +Y at the origin, plus a 2x2 quad plane
    at x in [1,2], y in [0,1] fully weighted to it. The bone's Z rotation is
    keyed at the given (frame, angle) pairs, so a vertex p maps to Rz(angle) p.
    Returns (armature object, mesh object)."""
    arm = bpy.data.armatures.new(name)
    rig = link(bpy.data.objects.new(name, arm))
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    bone = arm.edit_bones.new("Bone")
    bone.head, bone.tail, bone.roll = (0, 0, 0), (0, 1, 0), 0.0
    bpy.ops.object.mode_set(mode="OBJECT")
    skin = add_mesh(f"{name}Skin", [(1, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0)], [(0, 1, 2, 3)])
    group = skin.vertex_groups.new(name="Bone")
    group.add([0, 1, 2, 3], 1.0, "REPLACE")
    mod = skin.modifiers.new("Armature", "ARMATURE")
    mod.object = rig
    pose_bone = rig.pose.bones["Bone"]
    pose_bone.rotation_mode = "XYZ"
    for frame, angle in angle_at_frame:
        pose_bone.rotation_euler = (0.0, 0.0, angle)
        pose_bone.keyframe_insert("rotation_euler", frame=frame)
    return rig, skin


def add_shape_key_plane(name="Keyed", *, lift=2.0, value_at_frame=((1, 0.0), (10, 1.0))):
    """Unit quad at z=0 with a shape key that lifts every vertex by `lift`;
    the key's value is keyframed at the given (frame, value) pairs."""
    obj = add_mesh(name, [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Lift")
    for point in key.data:
        point.co.z += lift
    for frame, value in value_at_frame:
        key.value = value
        key.keyframe_insert("value", frame=frame)
    return obj


def instances_on_points_group(name, make_points, make_instance, pick_instance=False):
    """Geometry-nodes tree: the output of `make_instance(nodes)` (its "Mesh" output, else its first) on
    every point of the mesh `make_points(nodes)` (a node with a "Mesh" output), picking instance i
    modulo their count on point i when `pick_instance`. The input geometry is dropped."""
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    nodes.new("NodeGroupInput")
    out = nodes.new("NodeGroupOutput")
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    on_points.inputs["Pick Instance"].default_value = pick_instance
    links.new(make_points(nodes).outputs["Mesh"], on_points.inputs["Points"])
    instance = make_instance(nodes)
    links.new(instance.outputs.get("Mesh") or instance.outputs[0], on_points.inputs["Instance"])
    links.new(on_points.outputs["Instances"], out.inputs[0])
    return group


def _node(nodes, kind, **inputs):
    node = nodes.new(kind)
    for key, value in inputs.items():
        node.inputs[key.replace("_", " ")].default_value = value
    return node


def gn_line_instances_group(count, offset, cube_size):
    """Mesh Line(count, offset) -> Instance on Points with a Mesh Cube(cube_size)."""
    return instances_on_points_group(
        "LineInstances", lambda nodes: _node(nodes, "GeometryNodeMeshLine", Count=count, Offset=offset),
        lambda nodes: _node(nodes, "GeometryNodeMeshCube", Size=(cube_size,) * 3))


def tile_instances_group(columns, rows):
    """A columns x rows grid of points 1 apart, a 0.5 x 0.5 quad (2 triangles) on each."""
    return instances_on_points_group(
        "Tiles", lambda nodes: _node(nodes, "GeometryNodeMeshGrid", Vertices_X=columns, Vertices_Y=rows,
                                     Size_X=columns - 1, Size_Y=rows - 1),
        _tile)


def tile_line_group(count):
    """`count` points 1 apart on a line, a 0.5 x 0.5 quad (2 triangles) on each."""
    return instances_on_points_group(
        "Tiles", lambda nodes: _node(nodes, "GeometryNodeMeshLine", Count=count, Offset=(1.0, 0.0, 0.0)), _tile)


def _tile(nodes):
    return _node(nodes, "GeometryNodeMeshGrid", Vertices_X=2, Vertices_Y=2, Size_X=0.5, Size_Y=0.5)


def add_gn_instancer(name="GNHost", *, count=4, offset=(2, 0, 0), cube_size=1.0, location=(0, 0, 0)):
    """Empty-mesh object whose geometry-nodes modifier emits `count` cube
    instances (12 triangles each) at i * offset, i = 0..count-1."""
    obj = add_mesh(name, [], [], location=location)
    mod = obj.modifiers.new("GN", "NODES")
    mod.node_group = gn_line_instances_group(count, offset, cube_size)
    return obj


def add_info_node_host(name, target, *, separate_children=False, via_modifier_input=False, location=(0, 0, 0),
                       realize=False):
    """Empty-mesh object whose geometry-nodes modifier outputs the instances of a Collection Info
    node (`target` a collection) or an Object Info node (`target` an object), unrealized unless
    `realize` (a Realize Instances node). With `via_modifier_input` the target comes from a modifier
    input linked through a Group Input node."""
    is_collection = isinstance(target, bpy.types.Collection)
    group = bpy.data.node_groups.new(f"{name}Info", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    info = nodes.new("GeometryNodeCollectionInfo" if is_collection else "GeometryNodeObjectInfo")
    port = "Collection" if is_collection else "Object"
    if is_collection:
        info.inputs["Separate Children"].default_value = separate_children
    output = info.outputs[0 if is_collection else "Geometry"]
    if realize:
        realized = nodes.new("GeometryNodeRealizeInstances")
        links.new(output, realized.inputs[0])
        output = realized.outputs[0]
    links.new(output, nodes.new("NodeGroupOutput").inputs[0])
    obj = add_mesh(name, [], [], location=location)
    mod = obj.modifiers.new("GN", "NODES")
    if via_modifier_input:
        item = group.interface.new_socket(port, in_out="INPUT",
                                          socket_type="NodeSocketCollection" if is_collection else "NodeSocketObject")
        links.new(nodes.new("NodeGroupInput").outputs[port], info.inputs[port])
        mod.node_group = group
        set_modifier_input(mod, item.identifier, target)
    else:
        info.inputs[port].default_value = target
        mod.node_group = group
    if not is_collection:
        info.inputs["As Instance"].default_value = True
    return obj


def light_nodes_on(data):
    """The light's node tree, on as Cycles renders it: Use Nodes turned on up to Blender 5.0; from 5.1
    every light has a tree, always used, and Use Nodes is deprecated (setting it warns)."""
    prop = data.bl_rna.properties.get("use_nodes")
    if prop is not None and not getattr(prop, "is_deprecated", False):
        data.use_nodes = True
    return data.node_tree


def set_modifier_input(mod, identifier, value):
    """Set a geometry nodes modifier's input: an ID property up to Blender 5.1, an RNA property
    (`mod.properties.inputs.<identifier>.value`) from 5.2 on."""
    inputs = getattr(getattr(mod, "properties", None), "inputs", None)
    if inputs is not None:
        getattr(inputs, identifier).value = value
    else:
        mod[identifier] = value


def add_nested_info_host(name, collection, *, via_modifier_input=False, location=(0, 0, 0)):
    """Empty-mesh object whose geometry nodes call a reusable group ("Scatter": its Collection input
    into a Collection Info node, out unrealized) with `collection`, set on the Group node's socket,
    or with `via_modifier_input`, fed to it from the modifier's own input."""
    scatter = bpy.data.node_groups.new(f"{name}Scatter", "GeometryNodeTree")
    scatter.interface.new_socket("Coll", in_out="INPUT", socket_type="NodeSocketCollection")
    scatter.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    info = scatter.nodes.new("GeometryNodeCollectionInfo")
    scatter.links.new(scatter.nodes.new("NodeGroupInput").outputs["Coll"], info.inputs["Collection"])
    scatter.links.new(info.outputs[0], scatter.nodes.new("NodeGroupOutput").inputs[0])
    group = bpy.data.node_groups.new(f"{name}Tree", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    call = group.nodes.new("GeometryNodeGroup")
    call.node_tree = scatter
    group.links.new(call.outputs[0], group.nodes.new("NodeGroupOutput").inputs[0])
    obj = add_mesh(name, [], [], location=location)
    mod = obj.modifiers.new("GN", "NODES")
    if via_modifier_input:
        item = group.interface.new_socket("Coll", in_out="INPUT", socket_type="NodeSocketCollection")
        group.links.new(group.nodes.new("NodeGroupInput").outputs["Coll"], call.inputs["Coll"])
        mod.node_group = group
        set_modifier_input(mod, item.identifier, collection)
    else:
        call.inputs["Coll"].default_value = collection
        mod.node_group = group
    return obj


def add_bevel_curve(name="Tube", *, length=4.0, radius=0.5, location=(0, 0, 0)):
    """Straight poly curve from x=0 to x=length beveled into an open tube of
    the given radius around the x axis."""
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = radius
    curve.bevel_resolution = 2
    spline = curve.splines.new("POLY")
    spline.points.add(1)
    spline.points[0].co = (0, 0, 0, 1)
    spline.points[1].co = (length, 0, 0, 1)
    obj = bpy.data.objects.new(name, curve)
    obj.location = location
    return link(obj)


def add_text(name="Label", body="Hi", *, extrude=0.1, location=(0, 0, 0)):
    """Extruded text object with the built-in font (size 1)."""
    curve = bpy.data.curves.new(name, "FONT")
    curve.body = body
    curve.extrude = extrude
    obj = bpy.data.objects.new(name, curve)
    obj.location = location
    return link(obj)


def add_metaball(name="Blob", *, radius=1.0, resolution=0.1, location=(0, 0, 0)):
    """Single metaball sphere element (viewport resolution as given: the
    viewport depsgraph tessellates with `resolution`, not render_resolution)."""
    meta = bpy.data.metaballs.new(name)
    meta.resolution = resolution
    element = meta.elements.new()
    element.radius = radius
    obj = bpy.data.objects.new(name, meta)
    obj.location = location
    return link(obj)


def add_light(name="Lamp"):
    """Point light (never triangles)."""
    return link(bpy.data.objects.new(name, bpy.data.lights.new(name, "POINT")))


def add_camera(name="Cam"):
    """Camera (never triangles)."""
    return link(bpy.data.objects.new(name, bpy.data.cameras.new(name)))


def add_wavy_sheet(name, cells, *, location):
    """A cells x cells height field of 2 cells^2 triangles, made with foreach_set (bpy.ops primitives this
    size take minutes in the bpy module)."""
    x, y = np.meshgrid(np.linspace(-1, 1, cells + 1), np.linspace(-1, 1, cells + 1), indexing="ij")
    verts = np.stack([x, y, 0.05 * np.sin(20 * x) * np.cos(20 * y)], -1).reshape(-1, 3).astype(np.float32)
    i = (np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)[None, :]).ravel()
    tris = np.concatenate([np.stack([i, i + cells + 1, i + cells + 2], -1), np.stack([i, i + cells + 2, i + 1], -1)])
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", verts.ravel())
    mesh.loops.add(tris.size)
    mesh.loops.foreach_set("vertex_index", tris.astype(np.int32).ravel())
    mesh.polygons.add(len(tris))
    mesh.polygons.foreach_set("loop_start", np.arange(0, tris.size, 3, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    return link(obj)


def add_particle_emitter(name, *, count, collection=None, obj=None, whole_collection=True, location=(0, 0, 0),
                         size=10.0):
    """A size x size quad at `location` (z up) emitting `count` particles at frame 1, without physics,
    rendered as `obj` or as `collection` (whole, or one member per particle); the emitter itself is
    not rendered."""
    half = size / 2
    emitter = add_mesh(name, [(-half, -half, 0), (half, -half, 0), (half, half, 0), (-half, half, 0)],
                       [(0, 1, 2, 3)], location=location)
    emitter.modifiers.new("Particles", "PARTICLE_SYSTEM")
    settings = emitter.particle_systems[0].settings
    settings.count, settings.frame_start, settings.frame_end = count, 1, 1
    settings.physics_type, settings.particle_size = "NO", 1.0
    if collection is not None:
        settings.render_type, settings.instance_collection = "COLLECTION", collection
        settings.use_whole_collection = whole_collection
    else:
        settings.render_type, settings.instance_object = "OBJECT", obj
    emitter.show_instancer_for_render = False
    return emitter


def add_collection_points_host(name, collection, *, count, separate_children=True, location=(0, 0, 0)):
    """Empty-mesh object whose geometry nodes put the output of a Collection Info node on `count`
    points 3 apart along x (Instance on Points, picking instance i modulo the number of children on
    point i when `separate_children`), unrealized."""
    def info(nodes):
        node = nodes.new("GeometryNodeCollectionInfo")
        node.inputs["Collection"].default_value = collection
        node.inputs["Separate Children"].default_value = separate_children
        return node

    def line(nodes):
        return _node(nodes, "GeometryNodeMeshLine", Count=count, Offset=(3.0, 0.0, 0.0))

    group = instances_on_points_group(f"{name}Points", line, info, pick_instance=separate_children)
    obj = add_mesh(name, [], [], location=location)
    obj.modifiers.new("GN", "NODES").node_group = group
    return obj


TWO_PATH_TOPS = ("collection instance", "collection info")
TWO_PATH_HIDINGS = ("hidden instancer", "instancer in a hidden child collection", "visible twin of a hidden instancer")


def add_two_path_scene(top, hidden_path):
    """Cube 'Leaf' (0.3) in excluded collection 'LeafC', reached two ways through excluded collection
    'Mid': by an empty 'Vis' instancing LeafC at x = -3 (or, for "visible twin of a hidden instancer",
    by Leaf itself linked into Mid, at 0), and by an empty 'Hid' instancing LeafC at x = +3 that a
    render does not make: Disable in Renders, or for "instancer in a hidden child collection" inside a
    render-hidden child collection of Mid. 'Top' instances Mid at the origin: an empty (`top`
    "collection instance") or a Collection Info node host ("collection info"). A final render shows
    Leaf once, from the visible path."""
    leaf_collection = new_collection("LeafC", exclude=True)
    add_cube("Leaf", scale=0.3, collection=leaf_collection)
    mid = new_collection("Mid", exclude=True)
    if hidden_path == "visible twin of a hidden instancer":
        mid.objects.link(bpy.data.objects["Leaf"])
    else:
        add_collection_instance("Vis", leaf_collection, location=(-3, 0, 0), collection=mid)
    holder = mid
    if hidden_path == "instancer in a hidden child collection":
        holder = new_collection("HiddenChild", parent=mid)
        holder.hide_render = True
    hidden = add_collection_instance("Hid", leaf_collection, location=(3, 0, 0), collection=holder)
    hidden.hide_render = hidden_path != "instancer in a hidden child collection"
    if top == "collection instance":
        add_collection_instance("Top", mid)
    else:
        add_info_node_host("Top", mid)


OBJECT_INFO_SOURCES = ("collection instancer", "vertex-instancing parent", "nodes carrier")


def add_object_info_of_instancer(source_kind, hidden):
    """'Host', whose Object Info node (As Instance) instances 'Source', an object at z = -30 that
    instances things itself: an empty instancing collection 'K' (cube 'X'), a triangle (legs 2) instancing
    its child 'X' on its 3 vertices, or a geometry-nodes carrier making 2 cubes of its own (at x = 0, 2). `hidden`:
    Source has Disable in Renders, so a final render shows only its own mesh through Host (Blender
    makes no instances from a render-hidden object)."""
    far = (30, 30, -30)  # out of the way: Object Info instances Source's local geometry at Host
    if source_kind == "collection instancer":
        inner = new_collection("K", exclude=True)
        add_cube("X", scale=0.3, collection=inner)
        source = add_collection_instance("Source", inner, location=far)
    elif source_kind == "vertex-instancing parent":
        source = add_mesh("Source", [(0, 0, 0), (2, 0, 0), (0, 2, 0)], [(0, 1, 2)], location=far)
        source.instance_type = "VERTS"
        child = add_cube("X", scale=0.3)
        child.parent = source  # at the parent's origin: instanced on its vertices
    else:
        source = add_gn_instancer("Source", count=2, cube_size=0.6, location=far)
    source.hide_render = hidden
    add_info_node_host("Host", source)


def _object_info(tree, target):
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = target
    info.inputs["As Instance"].default_value = True
    return info.outputs["Geometry"]


def _on_points(tree, instance, xs):
    """Instance on Points of `instance` on points at (x, 0, 0) for x in xs (a Mesh Line)."""
    line = tree.nodes.new("GeometryNodeMeshLine")
    line.inputs["Count"].default_value = len(xs)
    line.inputs["Start Location"].default_value = (xs[0], 0.0, 0.0)
    line.inputs["Offset"].default_value = (xs[1] - xs[0] if len(xs) > 1 else 0.0, 0.0, 0.0)
    node = tree.nodes.new("GeometryNodeInstanceOnPoints")
    tree.links.new(line.outputs[0], node.inputs["Points"])
    tree.links.new(instance, node.inputs["Instance"])
    return node.outputs[0]


def add_joined_nodes_host(name, outputs_of, *, location=(0, 0, 0)):
    """Empty-mesh object whose geometry nodes join the geometries `outputs_of(tree)` returns, in order."""
    tree = bpy.data.node_groups.new(f"{name}Tree", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    join = tree.nodes.new("GeometryNodeJoinGeometry")
    for output in outputs_of(tree):
        tree.links.new(output, join.inputs[0])
    tree.links.new(join.outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
    host = add_mesh(name, [], [], location=location)
    host.modifiers.new("GN", "NODES").node_group = tree
    return host


def add_hidden_source_beside_nested_instances(hidden_first):
    """Cube 'X'; a render-hidden carrier 'H' (no faces) whose nodes instance X; 'Host' joins an Object
    Info instance of H (a render makes nothing of it) and X on 2 x 2 points through two Instance on
    Points levels (4 copies in a render), H's part first or last. The nested copies sit one level
    deeper than H's entry, with a geometry level between that yields no entry."""
    x = add_cube("X", scale=0.2, location=(0, 0, -30))
    hidden = add_joined_nodes_host("H", lambda tree: [_on_points(tree, _object_info(tree, x), [0.0])],
                                   location=(0, 0, -40))
    hidden.hide_render = True

    def parts(tree):
        of_hidden = _on_points(tree, _object_info(tree, hidden), [-4.0])
        nested = _on_points(tree, _on_points(tree, _object_info(tree, x), [0.0, 1.0]), [0.0, 2.0])
        return [of_hidden, nested] if hidden_first else [nested, of_hidden]

    add_joined_nodes_host("Host", parts)


def add_hidden_member_named_and_nested():
    """Render-hidden cube 'X' in excluded collection 'LeafC'; excluded 'Mid' holds an empty 'F'
    instancing LeafC; 'Host' joins an Object Info instance of X (rendered: named directly) and a
    Collection Info instance of Mid (a render skips X there, it is hidden in LeafC)."""
    leaf_collection = new_collection("LeafC", exclude=True)
    x = add_cube("X", scale=0.3, collection=leaf_collection)
    x.hide_render = True
    mid = new_collection("Mid", exclude=True)
    add_collection_instance("F", leaf_collection, location=(3, 0, 0), collection=mid)

    def parts(tree):
        info = tree.nodes.new("GeometryNodeCollectionInfo")
        info.inputs["Collection"].default_value = mid
        return [_on_points(tree, _object_info(tree, x), [-3.0]), _on_points(tree, info.outputs[0], [0.0])]

    add_joined_nodes_host("Host", parts)
