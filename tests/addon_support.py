"""Shared helpers for the add-on tests (tests/test_addon_*.py); the `addon` and `scene` fixtures and
Numba's cache folder are set in tests/conftest.py."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import bpy
import numpy as np

from tests import bpy_scenes as scenes

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable


EVENT_PROPERTIES = {p.identifier for p in bpy.types.Event.bl_rna.properties}


def event(kind):
    """A stand-in for the bpy.types.Event Blender passes to an operator's modal(): the real Event's
    properties and no other (reading another raises AttributeError, as on the real one)."""
    return SimpleNamespace(**({name: None for name in EVENT_PROPERTIES} | {"type": kind, "value": "PRESS"}))


def exr_channels(path):
    """{channel: (H, W) float32, row 0 = top} of an EXR, read with OpenImageIO (or the benchmark's own
    numpy reader), not with Blender, whose loading could hide a colour transform its saving applied."""
    from benchmarks.cycles_ao import read_exr
    return read_exr(path)[0]


def add_quad(name, half_x, half_y, *, location=(0, 0, 0)):
    """Axis-aligned rectangle in the XY plane, centred on `location`."""
    verts = [(-half_x, -half_y, 0), (half_x, -half_y, 0), (half_x, half_y, 0), (-half_x, half_y, 0)]
    return scenes.add_mesh(name, verts, [(0, 1, 2, 3)], location=location)


def add_top_camera(*, location=(0, 0, 10), ortho_scale=None, lens=50.0, name="Cam"):
    """Camera looking straight down -Z (Blender's default orientation), made the scene camera."""
    cam = scenes.add_camera(name)
    cam.location = location
    if ortho_scale is not None:
        cam.data.type, cam.data.ortho_scale = "ORTHO", ortho_scale
    cam.data.lens = lens
    bpy.context.scene.camera = cam
    return cam


def floor_scene(width, height, *, camera=True):
    """A fresh scene: a 10 x 10 floor, the top camera above it (unless camera=False), at width x height."""
    scenes.reset()
    add_quad("Floor", 5, 5)
    if camera:
        add_top_camera()
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = width, height
    return scene


def add_sun(name="Sun", rotation=(0.0, 0.0, 0.0), energy=3.0):
    sun = scenes.link(bpy.data.objects.new(name, bpy.data.lights.new(name, "SUN")))
    sun.rotation_euler = rotation
    sun.data.energy = energy
    return sun


def half_plane_scene(*, offset=(0.0, 0.0, 0.0), size=(64, 32)):
    """Orthographic camera 10 above a plane covering exactly the left half of its view, a cube
    standing on the plane, and a sun. Returns the scene. The view is 8 x 4 units (ortho_scale 8
    along the larger, horizontal side); the plane spans x in [-4, 0], y in [-2, 2] (+ offset)."""
    scene = bpy.context.scene
    ox, oy, oz = offset
    add_quad("Ground", 2.0, 2.0, location=(ox - 2.0, oy, oz))
    scenes.add_cube("Box", scale=0.5, location=(ox - 2.0, oy, oz + 0.5))
    add_top_camera(location=(ox, oy, oz + 10.0), ortho_scale=8.0)
    add_sun(rotation=(math.radians(30), 0.0, 0.0))
    scene.render.resolution_x, scene.render.resolution_y = size
    settings = getattr(scene, "kd_preview", None)
    if settings is not None:
        settings.resolution_percentage, settings.samples, settings.ao_distance = 100, 8, 1.0
        settings.mode = "ao"  # the checks below are AO's (the default, "auto", would add the sun's shadows)
    return scene


def column_of(x, width=64):
    """Pixel column whose centre is at world x (view x in [-4, 4])."""
    return int((x + 4.0) / 8.0 * width)


def check_half_plane_image(img):
    """Alpha exactly on the left half; AO in [0, 1]; 1 on open ground and on the cube's top."""
    assert img.shape == (32, 64, 4) and img.dtype == np.float32
    assert (img[:, :32, 3] == 1.0).all() and (img[:, 32:, 3] == 0.0).all()
    assert (img[:, 32:, :3] == 0.0).all()
    ao = img[:, :32, 0]
    assert (ao >= 0.0).all() and (ao <= 1.0).all()
    assert (img[..., 0] == img[..., 1]).all() and (img[..., 1] == img[..., 2]).all()  # grey AO
    assert ao[16, column_of(-3.9)] == 1.0  # ground 1.4 from the cube: nothing within ao_distance 1
    assert ao[16, column_of(-2.0)] == 1.0  # centre of the cube's top face
    assert ao[16, column_of(-2.6)] < 0.9  # ground right beside the cube's wall


def preview_pixels(name="KD Preview") -> np.ndarray:
    """The preview image as (H, W, 4), row 0 at the top (as the renderer returns it)."""
    image = bpy.data.images[name]
    width, height = image.size
    flat = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(flat)
    return flat.reshape(height, width, 4)[::-1]


def run_python(code_or_args, *, env=None, timeout=600, cwd=REPO) -> subprocess.CompletedProcess:
    """Run the venv's Python (a -c snippet or argument list) from the repo root.
    `env` adds to this process's environment; a value of None removes that variable."""
    args = ["-c", code_or_args] if isinstance(code_or_args, str) else list(code_or_args)
    full_env = dict(os.environ, **(env or {}))
    full_env = {k: v for k, v in full_env.items() if v is not None}
    return subprocess.run([PYTHON, *args], cwd=cwd, env=full_env, capture_output=True, text=True, timeout=timeout)
