"""A small animated scene for the command line's default run and for tests.

It exercises every path the preview handles from frame to frame: a deforming mesh (Wave), a keyed
modifier (Simple Deform), rigid keyed motion, collection instances (one instancer spinning), a sun, a
point light and a camera; ~25k triangles, frames 1-24. Built from bpy.data and bmesh only, so it
works in background mode without operator context.
"""

from __future__ import annotations

import math

import bmesh
import bpy
from mathutils import Matrix, Vector

FRAMES = (1, 24)
RESOLUTION = (960, 540)


def _mesh_object(name: str, fill, collection) -> bpy.types.Object:
    """Object whose mesh is made by `fill(bm)`."""
    bm = bmesh.new()
    fill(bm)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


def _key(obj, path: str, frames_values) -> None:
    for frame, value in frames_values:
        setattr(obj, path, value)
        obj.keyframe_insert(path, frame=frame)


def _ground(collection):
    return _mesh_object("Ground", lambda bm: bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=15.0),
                        collection)


def _wave_sheet(collection):
    sheet = _mesh_object("WaveSheet", lambda bm: bmesh.ops.create_grid(bm, x_segments=80, y_segments=80, size=2.0),
                         collection)
    sheet.location = (-3.5, 2.5, 0.6)
    wave = sheet.modifiers.new("Wave", "WAVE")
    wave.height, wave.width, wave.speed, wave.narrowness = 0.35, 1.2, 0.12, 1.0
    return sheet


def _twist_column(collection):
    def fill(bm):
        bmesh.ops.create_cube(bm, size=1.0, matrix=Matrix.Diagonal((0.6, 0.6, 3.0, 1.0)))
        bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=12, use_grid_fill=True)

    column = _mesh_object("TwistColumn", fill, collection)
    column.location = (3.0, 2.5, 1.5)
    twist = column.modifiers.new("Twist", "SIMPLE_DEFORM")
    twist.deform_method, twist.deform_axis = "TWIST", "Z"
    twist.keyframe_insert("angle", frame=FRAMES[0])
    twist.angle = math.radians(180)
    twist.keyframe_insert("angle", frame=FRAMES[1])
    return column


def _movers(collection):
    monkey = _mesh_object("Monkey", lambda bm: bmesh.ops.create_monkey(bm), collection)
    smooth = monkey.modifiers.new("Smooth", "SUBSURF")
    smooth.levels = smooth.render_levels = 1  # as a final render evaluates it: the preview shows the viewport's
    _key(monkey, "location", [(FRAMES[0], (-2.0, -2.0, 1.0)), (FRAMES[1], (2.0, -2.0, 1.6))])
    _key(monkey, "rotation_euler", [(FRAMES[0], (0.0, 0.0, -0.6)), (FRAMES[1], (0.0, 0.0, 0.6))])
    cube = _mesh_object("Cube", lambda bm: bmesh.ops.create_cube(bm, size=1.0), collection)
    _key(cube, "location", [(FRAMES[0], (0.0, 4.0, 0.5)), (FRAMES[1], (0.0, 0.0, 0.5))])
    _key(cube, "rotation_euler", [(FRAMES[0], (0.0, 0.0, 0.0)), (FRAMES[1], (0.0, 0.0, math.pi))])
    return monkey, cube


def _pillar_ring(scene):
    """One 'Pillar' collection (excluded from the view layer) instanced by six empties."""
    pillars = bpy.data.collections.new("Pillars")
    scene.collection.children.link(pillars)
    for layer in scene.view_layers:
        layer.layer_collection.children[pillars.name].exclude = True

    def shaft(bm):
        bmesh.ops.create_cone(bm, cap_ends=True, segments=24, radius1=0.25, radius2=0.25, depth=2.0,
                              matrix=Matrix.Translation((0.0, 0.0, 1.0)))

    _mesh_object("PillarShaft", shaft, pillars)
    ball = _mesh_object("PillarBall", lambda bm: bmesh.ops.create_uvsphere(
        bm, u_segments=24, v_segments=12, radius=0.4), pillars)
    ball.location = (0.0, 0.0, 2.3)
    ring = []
    for i in range(6):
        angle = 2.0 * math.pi * i / 6.0
        empty = bpy.data.objects.new(f"Pillar.{i}", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", pillars
        empty.location = (6.5 * math.cos(angle), 6.5 * math.sin(angle), 0.0)
        scene.collection.objects.link(empty)
        ring.append(empty)
    _key(ring[0], "rotation_euler", [(FRAMES[0], (0.0, 0.0, 0.0)), (FRAMES[1], (0.6, 0.0, 0.0))])
    return ring


def _lights(collection):
    sun_data = bpy.data.lights.new("Sun", "SUN")
    sun_data.energy, sun_data.angle = 3.0, math.radians(3.0)
    sun = bpy.data.objects.new("Sun", sun_data)
    sun.rotation_euler = (math.radians(40), math.radians(15), math.radians(30))
    point_data = bpy.data.lights.new("Lamp", "POINT")
    point_data.energy, point_data.shadow_soft_size = 800.0, 0.3
    point = bpy.data.objects.new("Lamp", point_data)
    point.location = (-3.0, -4.0, 5.0)
    for obj in (sun, point):
        collection.objects.link(obj)
    return sun, point


def _camera(scene):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (10.0, -11.0, 7.0)
    direction = Vector((0.0, 0.5, 0.8)) - cam.location
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = 32.0
    scene.collection.objects.link(cam)
    scene.camera = cam
    return cam


def build_demo_scene(scene: bpy.types.Scene | None = None) -> bpy.types.Scene:
    """Fill `scene` (default: the current one, expected empty) with the demo; return it."""
    scene = scene or bpy.context.scene
    root = scene.collection
    _ground(root)
    _wave_sheet(root)
    _twist_column(root)
    _movers(root)
    _pillar_ring(scene)
    _lights(root)
    _camera(scene)
    scene.frame_start, scene.frame_end = FRAMES
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    scene.frame_set(FRAMES[0])
    return scene
