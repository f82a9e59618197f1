"""A light's shader nodes, read where the preview can apply them exactly.

A light with *Use Nodes* on emits what its node tree's Light Output receives. Blender's default tree,
and what most artists make of it, is one Emission node with a constant Color and Strength feeding the
output: Cycles then emits the light's Color times that Color, and its power times that Strength. The
preview applies such a tree (the colour multiplies in, a Strength of 0 or below leaves the light out as
emitting nothing; a positive Strength is a power, which the preview does not weight, see the README's
shadow formula). Anything else (a texture or Blackbody node feeding the Emission node, another shader,
a group, nothing connected) is named as not applied, so the user knows the preview's light differs.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Emission:
    """What a plain Emission node adds to a light: its colour (RGB) and its Strength."""

    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    strength: float = 1.0


NO_NODES = Emission()


def plain_emission(light) -> Emission | None:
    """The light's emission when its nodes are off (NO_NODES) or are a plain Emission node with
    unconnected Color and Strength feeding the active Light Output; None for any other tree."""
    tree = getattr(light, "node_tree", None)
    if not getattr(light, "use_nodes", False) or tree is None:
        return NO_NODES
    output = tree.get_output_node("CYCLES")  # the Light Output Cycles renders (active, Cycles or All)
    if output is None or output.mute:
        return None
    links = list(output.inputs[0].links)  # the Surface socket
    if len(links) != 1 or links[0].is_muted or not links[0].is_valid:
        return None
    node = links[0].from_node
    if node.type != "EMISSION" or node.mute:
        return None
    color, strength = node.inputs["Color"], node.inputs["Strength"]
    if color.is_linked or strength.is_linked:
        return None
    return Emission(tuple(float(c) for c in color.default_value[:3]), float(strength.default_value))
