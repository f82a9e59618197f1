"""Cycles' Simplify > Culling, which the preview does not apply, named.

With Simplify on, Cycles leaves out objects marked for Camera Culling outside the widened view, or
for Distance Culling beyond the distance (Cycles' BlenderObjectCulling). The preview traces every
object, so a culled object's shadow shows where a render has none; rather than redo Cycles' tests,
the objects marked for culling are named, in one warning a frame.

This module imports bpy only.
"""
from __future__ import annotations

import bpy

from .viewport_evaluation import first_few

GEOMETRY_TYPES = frozenset(("MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES", "POINTCLOUD", "VOLUME"))
LABELS = {"use_camera_cull": "Camera Culling", "use_distance_cull": "Distance Culling"}  # flag: setting


def culling_warning(objects, scene: bpy.types.Scene) -> list[str]:
    """[] or one warning naming the objects among `objects` (the original objects the preview shows)
    that a Cycles render of `scene` may leave out by Simplify's Camera or Distance Culling."""
    kinds = _scene_culling(scene)
    if not kinds:
        return []
    marked = sorted({ob.name for ob in objects if _marked(ob, kinds)})
    if not marked:
        return []
    names = first_few([f"'{name}'" for name in marked])
    return [f"Simplify's {' and '.join(LABELS[k] for k in kinds)} is on: a Cycles render may leave out {names}, "
            f"which the preview traces (it does not apply Cycles' culling)"]


def _scene_culling(scene: bpy.types.Scene) -> list[str]:
    """The culling kinds a Cycles render of the scene applies (object flag names)."""
    render, settings = scene.render, getattr(scene, "cycles", None)
    if render.engine != "CYCLES" or not render.use_simplify or settings is None or render.use_multiview:
        return []
    camera = scene.camera
    if camera is None or camera.type != "CAMERA" or camera.data.type == "PANO":
        return []
    kinds = []
    if settings.use_camera_cull:
        kinds.append("use_camera_cull")
    if settings.use_distance_cull and settings.distance_cull_margin > 0.0:  # Cycles: a distance of 0 culls nothing
        kinds.append("use_distance_cull")
    return kinds


def _marked(ob: bpy.types.Object, kinds: list[str]) -> bool:
    """Whether the object has geometry for a render to cull (lights, cameras and empties have none) and
    any of the flags set."""
    if ob.type not in GEOMETRY_TYPES:
        return False
    flags = getattr(ob, "cycles", None)
    return flags is not None and any(getattr(flags, kind, False) for kind in kinds)
