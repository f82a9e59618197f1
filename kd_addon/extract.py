"""Scene extraction: an evaluated depsgraph -> per-mesh triangles, their placements, and warnings.

Everything Cycles renders as triangles is read from ``depsgraph.object_instances``: meshes after
modifiers, armatures, shape keys and geometry nodes, and the tessellated meshes of curves, text,
surfaces and metaballs. The panel, command line and Live Update read the viewport's depsgraph, so they
see the viewport's evaluation (Subdivision "Levels Viewport", geometry nodes' "Is Viewport") and miss
objects hidden in the viewport; the render's visibility rules are applied on top and what is missing is
named. A final render through the render engine (engine_final.py) hands over the render's own depsgraph
(``depsgraph.mode == "RENDER"``): it has evaluated and chosen everything as the render does, so its
entries are taken as they are, only ray visibility applied, and nothing viewport-related is warned about.

The work is split by job: scene_records.py (the records, no bpy), mesh_reading.py (a mesh into
numpy), render_visibility.py (what a final render shows), scene_walk.py (entries into records) and
extraction_warnings.py (what the preview leaves out). This module imports bpy, never ``core``.
"""

from __future__ import annotations

import time

import bpy

from . import bulk_instances
from .cycles_culling import culling_warning
from .extraction_warnings import (left_out_warnings, objects_shown, surfaces_off_warnings,
                                  unused_layer_warnings)
from .instance_table import as_table, concatenated
from .render_visibility import RenderVisibility
from .scene_records import ExtractedScene, non_finite_warnings
from .scene_walk import EntryReader, SelfEntry, hidden_by_viewport_flag_only
from .viewport_evaluation import viewport_evaluation_warning


def extract_scene(depsgraph: bpy.types.Depsgraph | None = None) -> ExtractedScene:
    """Extract every render-visible triangle mesh of an evaluated depsgraph.

    With no argument, uses ``bpy.context.evaluated_depsgraph_get()``. Call
    ``scene.frame_set(f)`` first to extract another frame.
    """
    t0 = time.perf_counter()
    if depsgraph is None:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    vis = RenderVisibility(depsgraph)
    render_mode = depsgraph.mode == "RENDER"
    walker = EntryReader(vis, render_mode)
    instances = bulk_instances.read_in_bulk(depsgraph, walker) if bulk_instances.usable(depsgraph) else None
    path = "bulk" if instances is not None else "walk"
    if instances is None:
        walker = EntryReader(vis, render_mode)  # a bulk reading given up leaves its notes behind
        instances = [r for r in map(walker.read, depsgraph.object_instances) if r is not None]
        instances = walker.without_hidden_carriers(instances)
    surfaces_off = surfaces_off_warnings(depsgraph.view_layer)
    evaluated = {ob.original.as_pointer() for ob in depsgraph.objects}
    flag_hidden = [] if render_mode else hidden_by_viewport_flag_only(depsgraph, evaluated, walker.instanced_by)
    shown = [ob for ob in flag_hidden if ob.type == "MESH" and ob.show_instancer_for_render and vis.scene_object(ob)]
    extra = [r for r in map(walker.read, (SelfEntry(ob.evaluated_get(depsgraph)) for ob in shown)) if r is not None]
    if extra:
        instances = concatenated([as_table(instances), as_table(extra)]) if path == "bulk" else instances + extra
    viewport_shown = evaluated | {ob.as_pointer() for ob in flag_hidden}
    shown_objects = objects_shown(depsgraph, vis, instances.distinct_kinds() if path == "bulk" else instances)
    if surfaces_off:
        instances = []
    return ExtractedScene(
        geometries=walker.geometries.geometries,
        instances=instances,
        warnings=(surfaces_off + unused_layer_warnings(depsgraph) + walker.geometries.warnings
                  + non_finite_warnings(walker.non_finite_placements) + list(walker.not_triangles.values())
                  + left_out_warnings(depsgraph, vis, walker.instanced_by, viewport_shown, walker.paths.blocked,
                                    walker.meshed, render_mode)
                  + ([] if render_mode else viewport_evaluation_warning(shown_objects, depsgraph.scene))
                  + culling_warning(shown_objects, depsgraph.scene)),
        extract_ms=(time.perf_counter() - t0) * 1e3,
        frame=depsgraph.scene.frame_current,
        path=path,
    )
