"""Settings whose viewport value the preview's geometry follows where a final render takes another.

The preview reads the viewport's depsgraph (`bpy` offers no render-mode depsgraph outside a render
engine), so modifiers' viewport switches and levels, geometry nodes' Is Viewport, curve, text,
surface and metaball resolution, particles' viewport amounts and display method, and Simplify
evaluate as in the viewport. Each can change the image, so this names them, in one warning a frame.

This module imports bpy only.
"""
from __future__ import annotations

import bpy

CURVE_TYPES = frozenset(("CURVE", "FONT", "SURFACE"))
SUBDIVIDING = frozenset(("SUBSURF", "MULTIRES"))
NAMED_AT_MOST = 6  # objects a warning names before "and N more"


def viewport_evaluation_warning(objects, scene: bpy.types.Scene) -> list[str]:
    """[] or one warning naming what in `objects` (the original objects the preview shows or a render
    would) and in the scene's Simplify settings a final render evaluates differently."""
    found = [f"'{ob.name}' ({'; '.join(diffs)})" for ob in objects if (diffs := _differences(ob, scene.render))]
    simplify = _simplify_differences(scene.render)
    if not found and not simplify:
        return []
    parts = []
    if found:
        parts.append(first_few(found, " object(s)"))
    if simplify:
        parts.append(f"Simplify ({'; '.join(simplify)})")
    return [f"the preview evaluates geometry as the viewport does, a final render with its own settings, which "
            f"differ for {', and '.join(parts)}"]


def first_few(items: list[str], unit: str = "") -> str:
    """The first NAMED_AT_MOST items joined, then "and N more" (+ unit) for the rest."""
    more = len(items) - NAMED_AT_MOST
    return ", ".join(items[:NAMED_AT_MOST]) + (f" and {more} more{unit}" if more > 0 else "")


def _differences(ob: bpy.types.Object, render) -> list[str]:
    out = [text for m in ob.modifiers if (text := _modifier_difference(m, render))]
    data = ob.data
    if ob.type in CURVE_TYPES:
        out += _resolution_difference("resolution U", data.resolution_u, data.render_resolution_u)
        if ob.type == "SURFACE":
            out += _resolution_difference("resolution V", data.resolution_v, data.render_resolution_v)
    elif ob.type == "META":
        if data.update_method == "NEVER":  # checked with the bpy module: no triangles in the viewport
            out.append("metaball Update on Edit 'Never': the viewport meshes none of it")
        elif data.render_resolution != data.resolution:
            out.append(f"metaball resolution {data.resolution:g} in the viewport, {data.render_resolution:g} in renders")
    rendered = {m.particle_system.as_pointer() for m in ob.modifiers
                if m.type == "PARTICLE_SYSTEM" and m.show_render and m.show_viewport}
    for system in ob.particle_systems:
        settings = system.settings
        if system.as_pointer() not in rendered:
            continue  # off in renders or in the viewport: the modifier's own difference names it
        if settings.render_type in ("OBJECT", "COLLECTION") and settings.display_method != "RENDER":
            # Blender makes the instances in the viewport only when they display as rendered
            # (object_dupli.cc: for_render || draw_as == PART_DRAW_REND)
            items = settings.bl_rna.properties["display_method"].enum_items  # hair's items are not listed
            method = settings.display_method
            shown_as = items[method].name if method in items.keys() else method.title()
            out.append(f"particles '{system.name}' display as '{shown_as}' in the viewport, which makes none of "
                       "their instances (Viewport Display > Display As: Rendered does)")
            continue
        if settings.child_type != "NONE":  # the display amount applies to the children then
            if settings.child_percent != settings.rendered_child_count or settings.display_percentage < 100:
                out.append(f"particles '{system.name}': {settings.child_percent} children each at "
                           f"{settings.display_percentage}% in the viewport, {settings.rendered_child_count} in renders")
        elif (settings.display_percentage < 100 and settings.render_type in ("OBJECT", "COLLECTION")
              and not _dynamic(system)):
            out.append(f"particles '{system.name}': {settings.display_percentage}% shown in the viewport, all in renders")
    return out


def _modifier_difference(m, render) -> str | None:
    if m.show_viewport != m.show_render:
        return f"modifier '{m.name}' enabled only {'in renders' if m.show_render else 'in the viewport'}"
    if not m.show_render:
        return None
    if m.type in SUBDIVIDING:
        viewport, final = m.levels, m.render_levels
        if render.use_simplify:  # Simplify caps both (its own difference is named apart)
            viewport, final = min(viewport, render.simplify_subdivision), min(final, render.simplify_subdivision_render)
        if viewport != final:
            return f"modifier '{m.name}' {viewport} levels in the viewport, {final} in renders"
        return None
    if m.type == "SCREW" and m.steps != m.render_steps:
        return f"modifier '{m.name}' {m.steps} steps in the viewport, {m.render_steps} in renders"
    if m.type == "OCEAN" and m.viewport_resolution != m.resolution:
        return f"modifier '{m.name}' resolution {m.viewport_resolution} in the viewport, {m.resolution} in renders"
    if m.type == "NODES" and m.node_group is not None and _uses_is_viewport(m.node_group, set()):
        return f"modifier '{m.name}' reads Is Viewport"
    return None


def _dynamic(system) -> bool:
    """Particles whose display amount renders too (particle.cc, psys_get_current_display_percentage: a
    render takes all of them only when they are not simulated: no physics, keyed, or a baked cache;
    hair without hair dynamics). With children the amount applies to the children instead."""
    settings = system.settings
    if settings.type == "HAIR":
        return system.use_hair_dynamics
    return not system.point_cache.is_baked and settings.physics_type in ("NEWTON", "BOIDS", "FLUID")


def _resolution_difference(label, viewport, render) -> list[str]:
    """A curve's render resolution 0 means the viewport's."""
    return [] if render in (0, viewport) else [f"{label} {viewport} in the viewport, {render} in renders"]


def _uses_is_viewport(tree, seen: set) -> bool:
    """Whether a node tree or a group it calls holds an Is Viewport node (used or not: checking
    whether its value reaches the output is not worth a wrong silence)."""
    if tree.as_pointer() in seen:
        return False
    seen.add(tree.as_pointer())
    for node in tree.nodes:
        if node.bl_idname == "GeometryNodeIsViewport":
            return True
        inner = getattr(node, "node_tree", None)
        if inner is not None and _uses_is_viewport(inner, seen):
            return True
    return False


def _simplify_differences(render) -> list[str]:
    if not render.use_simplify:
        return []
    out = []
    if render.simplify_subdivision != render.simplify_subdivision_render:
        out.append(f"max subdivision {render.simplify_subdivision} in the viewport, "
                   f"{render.simplify_subdivision_render} in renders")
    if render.simplify_child_particles != render.simplify_child_particles_render:
        out.append(f"child particles {render.simplify_child_particles:g} in the viewport, "
                   f"{render.simplify_child_particles_render:g} in renders")
    return out
