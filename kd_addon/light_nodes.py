"""A light's shader nodes, read where the preview can apply them exactly.

A light with *Use Nodes* on emits what its tree's Light Output receives. The usual tree, one Emission
node with a constant Color and Strength (through reroutes too), is applied: its Color multiplies the
light's, and a positive Strength is a power, which the preview does not weight. A tree from which
Cycles emits nothing (Strength 0 or below, nothing connected, a muted link or Emission node) leaves
the light out by name; anything else (textures, Blackbody, other shaders, groups) is named as not
applied.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Emission:
    """What a light's nodes make of its emission: a colour (RGB) multiplying the light's Color, or
    `nothing`, the reason Cycles emits no light from them ("" when it does)."""

    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    nothing: str = ""


NO_NODES = Emission()


def plain_emission(light) -> Emission | None:
    """The light's emission when its nodes are off (NO_NODES), are a plain Emission node with
    unconnected Color and Strength feeding the Light Output Cycles renders, or certainly emit nothing
    (`nothing` says why); None for any other tree."""
    tree = getattr(light, "node_tree", None)
    if tree is None or not _uses_nodes(light):
        return NO_NODES
    output = tree.get_output_node("CYCLES")  # the Light Output Cycles renders (active, Cycles or All)
    if output is None:
        return Emission(nothing="its nodes have no Light Output that Cycles renders")
    if output.mute:
        return None
    node = _source_node(output.inputs[0])  # the Surface socket
    if isinstance(node, str):
        return Emission(nothing=node)
    if node is None or node.type != "EMISSION":
        return None
    if node.mute:
        return Emission(nothing=f"its Emission node '{node.name}' is muted")
    color, strength = node.inputs["Color"], node.inputs["Strength"]
    if color.is_linked or strength.is_linked:
        return None
    if not strength.default_value > 0.0:
        return Emission(nothing=f"its Emission node's Strength is {strength.default_value:g}")
    return Emission(tuple(float(c) for c in color.default_value[:3]))


def _uses_nodes(light) -> bool:
    """Whether Cycles renders the light's node tree. Up to Blender 5.0 only with Use Nodes on; 5.1
    deprecated Use Nodes (every light has a tree, always used; the property reads True and warns) and
    6.0 removes it, so a deprecated or missing property means the tree is used."""
    prop = light.bl_rna.properties.get("use_nodes")
    if prop is None or getattr(prop, "is_deprecated", False):
        return True
    return bool(light.use_nodes)


def _source_node(socket):
    """The node feeding `socket` through unmuted reroutes; a str saying why nothing reaches it (no
    link, a muted one); None when the link is not one Blender evaluates (invalid)."""
    for _ in range(256):  # reroute chains are short; a loop would be an invalid tree
        links = list(socket.links)
        if not links:
            return "nothing is connected to its Light Output"
        link = links[0]
        if link.is_muted:
            return "a link feeding its Light Output is muted"
        if not link.is_valid:
            return None
        if link.from_node.type != "REROUTE" or link.from_node.mute:
            return link.from_node
        socket = link.from_node.inputs[0]
    return None
