"""The render engine's cameras, checked against Blender's own projection and against core's rays.

- engine_viewport.camera_from_matrices: the viewport's camera from a region's view and window matrices.
  Blender's projection of a camera (Object.calc_matrix_camera, lens, sensor fit, shift) and of a
  viewport-like orthographic view whose near plane lies behind the viewpoint are the references:
  every pixel's ray, pushed to any depth, must project (bpy_extras.view3d_utils, the region's
  perspective matrix) onto that pixel's centre.
- engine_final.crop_camera: a Render Region's camera gives the whole frame's rays of those pixels.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import bpy
import numpy as np
import pytest
from bpy_extras import view3d_utils
from mathutils import Matrix, Vector

import core
from kd_addon.engine_final import crop_camera
from kd_addon.engine_viewport import camera_from_matrices
from kd_addon.scene_input import camera_input
from tests import bpy_scenes as scenes


def region_and_view(view_matrix, window_matrix, width, height):
    """Stand-ins for a Region and its RegionView3D with the attributes view3d_utils reads."""
    view, window = Matrix(view_matrix), Matrix(window_matrix)
    rv3d = SimpleNamespace(view_matrix=view, window_matrix=window, perspective_matrix=window @ view,
                           is_perspective=window[3][2] != 0.0)
    return SimpleNamespace(width=width, height=height), rv3d


def assert_rays_project_to_pixel_centres(camera_in, view_matrix, window_matrix, width, height):
    camera = core.Camera(**camera_in.keywords())
    origins, directions, tmin, tmax = camera.rays(width, height)
    region, rv3d = region_and_view(view_matrix, window_matrix, width, height)
    rows, columns = np.divmod(np.arange(width * height), width)
    expected = np.stack([columns + 0.5, height - (rows + 0.5)], axis=1)  # region coordinates: from the bottom
    span = np.minimum(tmax, tmin + 50.0)
    for depth in (tmin + 1e-3 * (span - tmin), 0.5 * (tmin + span), span):
        points = origins + directions * depth[:, None]
        projected = np.array([view3d_utils.location_3d_to_region_2d(region, rv3d, Vector(p))[:] for p in points])
        assert np.abs(projected - expected).max() < 1e-3


def scene_camera(kind, *, lens=35.0, shift=(0.0, 0.0), sensor_fit="AUTO", ortho_scale=6.0):
    scenes.reset()
    cam = scenes.add_camera("Cam")
    cam.data.type, cam.data.lens, cam.data.sensor_fit, cam.data.ortho_scale = kind, lens, sensor_fit, ortho_scale
    cam.data.shift_x, cam.data.shift_y = shift
    cam.data.clip_start, cam.data.clip_end = 0.5, 80.0
    cam.location = (3.0, -4.0, 2.5)
    cam.rotation_euler = (math.radians(70), math.radians(5), math.radians(35))
    bpy.context.view_layer.update()
    return cam


@pytest.mark.parametrize("kind,size,shift,fit", [
    ("PERSP", (40, 24), (0.0, 0.0), "AUTO"),
    ("PERSP", (24, 40), (0.15, -0.3), "AUTO"),
    ("PERSP", (40, 24), (-0.2, 0.1), "VERTICAL"),
    ("ORTHO", (36, 20), (0.1, 0.25), "AUTO"),
    ("ORTHO", (20, 36), (0.0, 0.0), "HORIZONTAL"),
])
def test_camera_from_a_cameras_matrices_matches_blenders_projection(kind, size, shift, fit):
    """Camera view: the region's matrices are the camera's (lens, sensor fit, shift); the camera from
    them makes the F12 camera's rays."""
    cam = scene_camera(kind, shift=shift, sensor_fit=fit)
    width, height = size
    depsgraph = bpy.context.evaluated_depsgraph_get()
    window = cam.calc_matrix_camera(depsgraph, x=width, y=height)
    view = cam.matrix_world.normalized().inverted()
    from_matrices = camera_from_matrices(view, window, width, height)
    assert_rays_project_to_pixel_centres(from_matrices, view, window, width, height)
    final, _ = camera_input(cam.data, cam.matrix_world, width, height)
    ours = core.Camera(**from_matrices.keywords()).rays(width, height)
    theirs = core.Camera(**final.keywords()).rays(width, height)
    for a, b in zip(ours, theirs):
        assert np.allclose(a, b, rtol=1e-6, atol=1e-6)


def perspective_window(left, right, bottom, top, near, far):
    """OpenGL's frustum matrix, as Blender's viewport builds it (perspective_m4)."""
    return [[2 * near / (right - left), 0, (right + left) / (right - left), 0],
            [0, 2 * near / (top - bottom), (top + bottom) / (top - bottom), 0],
            [0, 0, -(far + near) / (far - near), -2 * far * near / (far - near)],
            [0, 0, -1, 0]]


def orthographic_window(left, right, bottom, top, near, far):
    """OpenGL's orthographic matrix (orthographic_m4)."""
    return [[2 / (right - left), 0, 0, -(right + left) / (right - left)],
            [0, 2 / (top - bottom), 0, -(top + bottom) / (top - bottom)],
            [0, 0, -2 / (far - near), -(far + near) / (far - near)],
            [0, 0, 0, 1]]


def viewport_view_matrix():
    to_world = Matrix.Translation((1.0, -2.0, 3.0)) @ Matrix.Rotation(0.7, 4, "X") @ Matrix.Rotation(-0.4, 4, "Z")
    return to_world.inverted()


def test_a_perspective_viewport_with_an_offset_frame():
    """A free perspective view zoomed and panned in camera view: an off-centre frustum."""
    view = viewport_view_matrix()
    window = perspective_window(-0.3, 0.5, -0.2, 0.28, 0.01, 1000.0)
    camera = camera_from_matrices(view, window, 50, 30)
    assert camera.fov is not None and math.isclose(camera.clip_start, 0.01) and math.isclose(camera.clip_end, 1000.0)
    assert_rays_project_to_pixel_centres(camera, view, window, 50, 30)


def test_an_orthographic_viewport_whose_near_plane_is_behind_the_view():
    """Blender's orthographic viewport clips from -clip_end/2: the camera moves back to that plane."""
    view = viewport_view_matrix()
    window = orthographic_window(-4.0, 4.0, -2.5, 2.5, -500.0, 500.0)
    camera = camera_from_matrices(view, window, 48, 30)
    assert camera.ortho_scale == pytest.approx(8.0) and camera.clip_start == 0.0
    assert camera.clip_end == pytest.approx(1000.0)
    behind = np.array(view.inverted().translation) - camera.position
    assert np.linalg.norm(behind) == pytest.approx(500.0)
    assert_rays_project_to_pixel_centres(camera, view, window, 48, 30)


@pytest.mark.parametrize("camera_kw,size", [
    (dict(fov=0.9), (40, 24)),
    (dict(fov=0.7, shift=(0.1, -0.05)), (24, 40)),
    (dict(fov=0.8, pixel_aspect=1.5), (30, 20)),
    (dict(ortho_scale=5.0, shift=(0.02, 0.1)), (36, 20)),
])
@pytest.mark.parametrize("region", [(0, 0, 10, 7), (5, 3, 17, 11), (0, 6, 20, 14)])
def test_a_render_regions_camera_makes_the_whole_frames_rays_there(camera_kw, size, region):
    width, height = size
    full = camera_input(SimpleNamespace(type="ORTHO" if "ortho_scale" in camera_kw else "PERSP", clip_start=0.1,
                                        clip_end=100.0, sensor_fit="AUTO", shift_x=0.0, shift_y=0.0, lens=50.0,
                                        sensor_width=36.0, sensor_height=24.0, ortho_scale=1.0),
                        np.eye(4), width, height)[0]
    from dataclasses import replace
    full = replace(full, fov=camera_kw.get("fov"), ortho_scale=camera_kw.get("ortho_scale"),
                   shift=camera_kw.get("shift", (0.0, 0.0)), pixel_aspect=camera_kw.get("pixel_aspect", 1.0))
    x, y, w, h = region
    cropped = crop_camera(full, width, height, region)
    whole = core.Camera(**full.keywords()).rays(width, height)
    part = core.Camera(**cropped.keywords()).rays(w, h)
    index = ((np.arange(h)[:, None] + y) * width + np.arange(w)[None, :] + x).reshape(-1)
    for a, b in zip(part, whole):
        assert np.allclose(a, b[index], rtol=1e-9, atol=1e-9)
