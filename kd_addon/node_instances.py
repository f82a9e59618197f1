"""Which collections an object instances whole, through a Collection Info node or particles.

Why this matters: a final render expands such a collection like a collection instance, so a member
with ``hide_render`` (or in a render-hidden child collection) is not rendered, while the viewport
depsgraph the preview reads yields it. Measured with Cycles (bpy 5.0.1, a cube and a hide_render
sphere in an excluded collection): Collection Info with *Separate Children* off instances only the
cube; with it on, or behind *Realize Instances*, Cycles renders the sphere too, and so does an
*Object Info* node pointing at a hidden object.

So only Collection Info nodes that are not muted and whose *Separate Children* input is not linked
count. With it off, the node's collection is instanced whole. With it on, the node makes one instance
per child: a child *object* is an object reference, rendered even when render-hidden (the sphere
above), while a child *collection* is a collection reference, which a render expands like a
collection instance (measured with Cycles: a hide_render child collection, and a hide_render object
in a visible child collection, were not rendered, with the node's output used directly or picked by
Instance on Points). The depsgraph's entries do not say which reference made them, but the node tree
does, as reliably as in the whole case: the child collections count as instanced whole and the child
objects as instanced directly. Instance on Points picks among the unfiltered children, in the
viewport and in a render alike, so leaving those members out reproduces the render exactly.

The collection is read from the socket's value, or, in the modifier's own node tree, from the
modifier input a Group Input link (through reroutes) feeds it. Object Info objects are collected
too: an object instanced directly keeps being rendered even if it is also a hidden member of such a
collection. Anything the reading cannot resolve (a collection computed by other nodes, or fed through
a nested group's inputs, a linked *Separate Children*) is left out, which keeps the preview's earlier
behaviour: the instance is shown.

Particle systems that render a collection (*Render As: Collection*) expand it the same way in a
render, whole or picking one member per particle (measured with Cycles: a hide_render member, a member
in a hide_render child collection and a hide_render member of a visible child collection were not
rendered); particles rendering one object render it even when it is render-hidden. So
:func:`particle_references` returns those collections and objects alike. With *Whole Collection* off
the viewport also picks among a different set of members than a render (the render-visible ones
only), which extract.py warns about: the preview cannot reproduce a render's pick.

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
    for mod in ob.modifiers:
        if mod.type == "NODES" and mod.node_group is not None:
            _walk(mod.node_group, mod, {mod.node_group.as_pointer()}, collections, objects)
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


def _walk(tree, mod, seen: set[int], collections: list, objects: list) -> None:
    """Collect from `tree` and the groups it uses; `mod` resolves Group Input links (None below the
    modifier's own tree, whose group inputs are not the modifier's)."""
    for node in tree.nodes:
        if node.mute:
            continue
        kind = node.bl_idname
        if kind == "GeometryNodeCollectionInfo":
            separate = node.inputs.get("Separate Children")
            if separate is not None and separate.is_linked:
                continue  # unknown which way the node instances: keep the instances shown
            found = _socket_value(node.inputs.get("Collection"), mod)
            if not isinstance(found, bpy.types.Collection):
                continue
            if separate is not None and separate.default_value:  # one reference per child
                collections.extend(found.children)
                objects.extend(found.objects)
            else:
                collections.append(found)
        elif kind == "GeometryNodeObjectInfo":
            found = _socket_value(node.inputs.get("Object"), mod)
            if isinstance(found, bpy.types.Object):
                objects.append(found)
        elif kind == "GeometryNodeGroup" and node.node_tree is not None:
            ptr = node.node_tree.as_pointer()
            if ptr not in seen:
                seen.add(ptr)
                _walk(node.node_tree, None, seen, collections, objects)


def _socket_value(socket, mod):
    """The ID an input socket holds: its own value when unlinked, else the modifier input that a
    Group Input link feeds it (only where `mod` is given); None when it cannot be read."""
    if socket is None:
        return None
    if not socket.is_linked:
        return getattr(socket, "default_value", None)
    link = socket.links[0]
    while link.from_node.bl_idname == "NodeReroute":
        upstream = link.from_node.inputs[0]
        if not upstream.is_linked:
            return None
        link = upstream.links[0]
    if mod is None or link.from_node.bl_idname != "NodeGroupInput":
        return None
    try:
        return mod[link.from_socket.identifier]
    except KeyError:
        return None
