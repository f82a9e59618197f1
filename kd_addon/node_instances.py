"""Which collections an object instances whole, through a Collection Info node or particles.

A final render expands such a collection like a collection instance, so its render-hidden members
are not rendered, while the viewport depsgraph the preview reads yields them; an object named
directly (Object Info, a separated child object, particles rendering one object) is rendered even
when render-hidden (docs/choices.md#collections-instanced-by-nodes-or-particles-follow-the-collection-instance-rule).

Only Collection Info nodes that are not muted, whose *Separate Children* input is not linked and whose
output reaches the active Group Output (through unmuted links, or a muted node's pass-through links)
count. With *Separate Children* off the collection is instanced whole; with it on, child collections
count as instanced whole and child objects as instanced directly. The collection is read from the
socket's value or, through Group Input links, from the modifier's input or the calling Group node's
socket, as far up as it goes. What cannot be resolved (a collection computed by other nodes) is left
out, so the instance is shown. Particles with *Whole Collection* off pick among other members in the
viewport than in a render, which extraction_warnings.py names.

This module imports bpy only.
"""

from __future__ import annotations

import bpy


def node_references(ob: bpy.types.Object) -> tuple[list[bpy.types.Collection], list[bpy.types.Object]]:
    """(collections instanced whole by Collection Info, the child collections of those it separates;
    objects named by Object Info, the child objects of the collections it separates) in the
    geometry-nodes modifiers of `ob` (an original object)."""
    collections: list[bpy.types.Collection] = []
    objects: list[bpy.types.Object] = []
    walked: set = set()
    for mod in ob.modifiers:
        if mod.type == "NODES" and mod.node_group is not None:
            _walk(mod.node_group, _modifier_inputs(mod), set(), walked, collections, objects)
    return _unique(collections), _unique(objects)


def objects_read_as_geometry(ob: bpy.types.Object) -> list[bpy.types.Object]:
    """The objects `ob`'s Object Info nodes read as geometry (As Instance off, or not known to be on):
    their evaluated geometry, instances included, comes through whatever their render visibility,
    where an object instanced as an object makes no instances when it is render-hidden."""
    geometry: list[bpy.types.Object] = []
    walked: set = set()
    for mod in ob.modifiers:
        if mod.type == "NODES" and mod.node_group is not None:
            _walk(mod.node_group, _modifier_inputs(mod), set(), walked, [], [], geometry)
    return _unique(geometry)


def _unique(ids: list) -> list:
    """The IDs in first-seen order, each once."""
    return list({id_.as_pointer(): id_ for id_ in ids}.values())


def has_node_modifier(ob: bpy.types.Object) -> bool:
    return any(m.type == "NODES" for m in ob.modifiers)


def instancing_references(ob: bpy.types.Object) -> tuple[list[bpy.types.Collection], list[bpy.types.Object]]:
    """node_references and particle_references of `ob` together: what its nodes and particles instance."""
    collections, objects = node_references(ob)
    if len(ob.particle_systems):
        particle_collections, particle_objects = particle_references(ob)
        collections, objects = collections + particle_collections, objects + particle_objects
    return collections, objects


def particle_references(ob: bpy.types.Object) -> tuple[list[bpy.types.Collection], list[bpy.types.Object]]:
    """(collections rendered by `ob`'s particle systems, whole or one member per particle; objects
    rendered by them) for an original object."""
    collections: list[bpy.types.Collection] = []
    objects: list[bpy.types.Object] = []
    for system in ob.particle_systems:
        settings = system.settings
        if settings.render_type == "COLLECTION" and settings.instance_collection is not None:
            collections.append(settings.instance_collection)
        elif settings.render_type == "OBJECT" and settings.instance_object is not None:
            objects.append(settings.instance_object)
    return collections, objects


def _walk(tree, group_inputs, path: set[int], walked: set, collections: list, objects: list,
          geometry: list | None = None) -> None:
    """Collect from the nodes of `tree` that reach its output, and from the groups they call.
    `group_inputs(identifier)`: the value the caller feeds the tree's group input `identifier`, None
    when unknown. `path`: the groups being walked (Blender forbids recursion; this guards anyway).
    `walked`: the (tree, input values) already walked: a group called many times with the same inputs
    is read once (else a chain of groups each called k ways is read k^depth times). `geometry`:
    where given, collects the Object Info objects not known to be read As Instance."""
    key = (tree.as_pointer(), _input_values(tree, group_inputs))
    if key in walked:
        return
    walked.add(key)
    path = path | {tree.as_pointer()}
    for node in _nodes_reaching_output(tree):
        if node.mute:
            continue
        kind = node.bl_idname
        if kind == "GeometryNodeCollectionInfo":
            separate = node.inputs.get("Separate Children")
            separated = _socket_value(separate, group_inputs) if separate is not None else False
            if not isinstance(separated, (bool, int)):  # an ID property may hold the modifier's bool as an int
                continue  # computed by other nodes: unknown which way the node instances, keep them shown
            found = _socket_value(node.inputs.get("Collection"), group_inputs)
            if not isinstance(found, bpy.types.Collection):
                continue
            if separated:  # one reference per child (a modifier's input may set it)
                collections.extend(found.children)
                objects.extend(found.objects)
            else:
                collections.append(found)
        elif kind == "GeometryNodeObjectInfo":
            found = _socket_value(node.inputs.get("Object"), group_inputs)
            if isinstance(found, bpy.types.Object):
                objects.append(found)
                if geometry is not None and _socket_value(node.inputs.get("As Instance"), group_inputs) is not True:
                    geometry.append(found)
        elif kind == "GeometryNodeGroup" and node.node_tree is not None and node.node_tree.as_pointer() not in path:
            _walk(node.node_tree, _group_node_inputs(node, group_inputs), path, walked, collections, objects,
                  geometry)


def _input_values(tree, group_inputs) -> tuple:
    """What the caller feeds the tree's ID inputs (collections, objects), as pointers, and its boolean
    inputs (Separate Children, As Instance may come from them): the part of the inputs the walk's
    result depends on."""
    values = []
    for item in tree.interface.items_tree:
        if getattr(item, "in_out", None) == "INPUT" and item.socket_type in ("NodeSocketCollection",
                                                                             "NodeSocketObject"):
            value = group_inputs(item.identifier)
            values.append((item.identifier, value.as_pointer() if value is not None else 0))
        elif getattr(item, "in_out", None) == "INPUT" and item.socket_type == "NodeSocketBool":
            value = group_inputs(item.identifier)  # Separate Children, As Instance
            values.append((item.identifier, bool(value) if isinstance(value, (bool, int)) else None))
    return tuple(values)


def _nodes_reaching_output(tree) -> list:
    """The nodes of `tree` whose output reaches its active Group Output, following links that are not
    muted, and across a muted node only its internal (pass-through) links."""
    found: dict[int, object] = {}
    stack = [node for node in tree.nodes if node.bl_idname == "NodeGroupOutput" and node.is_active_output]
    while stack:
        node = stack.pop()
        if node.as_pointer() in found:
            continue
        found[node.as_pointer()] = node
        inputs = [link.from_socket for link in node.internal_links] if node.mute else node.inputs
        stack.extend(link.from_node for socket in inputs for link in socket.links if not link.is_muted)
    return list(found.values())


def _modifier_inputs(mod):
    """group_inputs for the modifier's own node tree: the modifier's input values. Up to Blender 5.1
    they are ID properties of the modifier named by the socket identifier; 5.2 keeps them as RNA
    properties, `mod.properties.inputs.<identifier>.value`, and `mod[identifier]` raises TypeError."""
    inputs = getattr(getattr(mod, "properties", None), "inputs", None)

    def value(identifier):
        if inputs is not None:
            return getattr(getattr(inputs, identifier, None), "value", None)
        try:
            return mod[identifier]
        except (KeyError, TypeError):
            return None
    return value


def _group_node_inputs(node, group_inputs):
    """group_inputs for the tree a Group node calls: the value of the node's own input socket."""
    def value(identifier):
        socket = next((s for s in node.inputs if s.identifier == identifier), None)
        return _socket_value(socket, group_inputs)
    return value


def _upstream(socket):
    """The output socket feeding `socket` through reroutes and links that are not muted (a reroute's
    own when the chain ends there, unfed), or None when nothing does: then the socket's value counts."""
    links = [link for link in socket.links if not link.is_muted]
    source = None
    while links:
        source = links[0].from_socket
        if source.node.bl_idname != "NodeReroute":
            break
        links = [link for link in source.node.inputs[0].links if not link.is_muted]
    return source


def _socket_value(socket, group_inputs):
    """The ID an input socket holds: its own value when nothing feeds it, what the caller feeds the
    group input that does (`group_inputs`), else None: it cannot be read."""
    if socket is None:
        return None
    source = _upstream(socket)
    if source is None:
        return getattr(socket, "default_value", None)
    if source.node.bl_idname != "NodeGroupInput":
        return None  # computed by other nodes, or an unfed reroute
    return group_inputs(source.identifier)
