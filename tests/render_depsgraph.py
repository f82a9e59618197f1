"""What a final render's own depsgraph holds: the reference the preview's extraction is checked against.

bpy gives a render-mode depsgraph only to a render engine, so this registers a tiny Python engine whose
render() reads `depsgraph.object_instances` (Blender evaluates it as for a final render: render-only
modifiers, render visibility, instancing paths, particles) and renders the scene with it once. Only
the camera and shadow ray flags are applied here (ANDed with the top-level instancer, as Cycles
does): everything else a render leaves out, the render depsgraph has already left out. Independent of
kd_addon/extract.py, which reconstructs the same from the viewport's depsgraph.
"""
from __future__ import annotations

import bpy
import numpy as np

_captured: list = []
_extracted: list = []  # kd_addon.extract.extract_scene of the render's depsgraph, when asked for
_extract = [False]


class CaptureEngine(bpy.types.RenderEngine):
    bl_idname = "KDPREVIEW_TEST_CAPTURE"
    bl_label = "KD Preview test capture"

    def render(self, depsgraph):
        _captured[:] = list(_mesh_entries(depsgraph))
        if _extract[0]:
            from kd_addon.extract import extract_scene
            _extracted[:] = [extract_scene(depsgraph)]
        render = depsgraph.scene.render
        scale = render.resolution_percentage / 100
        result = self.begin_result(0, 0, int(render.resolution_x * scale), int(render.resolution_y * scale))
        self.end_result(result)


def _mesh_entries(depsgraph):
    """(object name, top-level instancer name or None, world-space (T, 3, 3) triangles) per mesh entry
    that camera or shadow rays can see."""
    for inst in depsgraph.object_instances:
        ob = inst.object
        if not isinstance(ob.data, bpy.types.Mesh) or not inst.show_self:
            continue
        orig = ob.original
        parent = inst.parent.original if inst.is_instance and inst.parent else None
        owners = (orig,) if parent is None else (orig, parent)
        if not (all(o.visible_camera for o in owners) or all(o.visible_shadow for o in owners)):
            continue
        mesh = ob.data
        mesh.calc_loop_triangles()
        if len(mesh.loop_triangles) == 0:
            continue
        co = np.array([v.co[:] for v in mesh.vertices], np.float64)
        corners = np.array([t.vertices[:] for t in mesh.loop_triangles], np.int64)
        matrix = np.array(inst.matrix_world, np.float64)
        yield orig.name, parent.name if parent else None, co[corners] @ matrix[:3, :3].T + matrix[:3, 3]


def extraction_in_render(scene: bpy.types.Scene | None = None):
    """(kd_addon.extract.extract_scene of a final render's own depsgraph, as the render engine reads it,
    the render's mesh entries)."""
    _extract[0] = True
    try:
        entries = render_entries(scene)
    finally:
        _extract[0] = False
    extracted = _extracted.pop()
    return extracted, entries


def render_entries(scene: bpy.types.Scene | None = None) -> list:
    """Renders `scene` (default: the context's) once with the capture engine at a few pixels and
    returns its mesh entries; the scene's engine and resolution are put back. Adds a camera when
    the scene has none (a render needs one)."""
    scene = scene or bpy.context.scene
    if scene.camera is None:
        camera = bpy.data.objects.new("CaptureCamera", bpy.data.cameras.new("CaptureCamera"))
        scene.collection.objects.link(camera)
        scene.camera = camera
    kept = scene.render.engine, scene.render.resolution_x, scene.render.resolution_y
    bpy.utils.register_class(CaptureEngine)  # and unregistered: bpy 4.2 crashed at exit with it left in
    try:
        scene.render.engine = CaptureEngine.bl_idname
        scene.render.resolution_x, scene.render.resolution_y = 8, 6
        bpy.ops.render.render(write_still=False, scene=scene.name)
    finally:
        scene.render.engine, scene.render.resolution_x, scene.render.resolution_y = kept
        bpy.utils.unregister_class(CaptureEngine)
    entries = list(_captured)
    _captured.clear()
    return entries


def differences(result, entries, placement: bool = True) -> list[str]:
    """How an ExtractedScene (kd_addon.extract) differs from a render's entries, per (object,
    top-level instancer): missing or extra objects, or other triangle counts, areas or (with
    `placement`) bounds."""
    ids = result.triangle_object_ids()
    world = result.world_triangles().astype(np.float64)
    ours: dict = {}
    for i, inst in enumerate(result.instances):
        ours.setdefault((inst.name, inst.instancer), []).append(world[ids == i])
    theirs: dict = {}
    for name, instancer, tris in entries:
        theirs.setdefault((name, instancer), []).append(tris)
    out = []
    for key in sorted(set(ours) | set(theirs), key=str):
        a = _measure(np.concatenate(ours[key])) if key in ours else None
        b = _measure(np.concatenate(theirs[key])) if key in theirs else None
        compared = slice(1, None if placement else 2)
        if a is None or b is None or a[0] != b[0] or not np.allclose(a[compared], b[compared], rtol=1e-5, atol=1e-4):
            out.append(f"{key}: preview {a}, render {b}")
    return out


def _measure(tris: np.ndarray) -> tuple:
    """(triangles, total area, bounding box min xyz, max xyz)."""
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()
    points = tris.reshape(-1, 3)
    return (len(tris), float(area), *points.min(0).tolist(), *points.max(0).tolist())
