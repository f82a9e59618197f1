"""Pinhole camera rays in Blender's convention (numpy): a test oracle for the
benchmark harness, not a fast path.

Convention (matches Blender's camera with sensor fit AUTO, no lens shift,
square pixels):
  * the camera looks down its local -Z axis, local +Y is up, +X is right;
  * ``fov`` is the full field of view along the *larger* image dimension
    (``camera.data.angle`` for sensor fit AUTO);
  * rays go through pixel centres;
  * ray ``k`` belongs to pixel (row ``k // width``, column ``k % width``) and
    row 0 is the TOP row of the image (the usual image order, not Blender's
    bottom-up pixel buffers).
"""

from __future__ import annotations

import math

import numpy as np


def camera_rays(camera_matrix, fov: float, width: int, height: int):
    """Return ``(origins, directions)``, both float64 (width*height, 3).

    ``camera_matrix`` is the 4x4 camera-to-world matrix (``cam.matrix_world``).
    Directions are unit length in world space (so a hit distance ``t`` is a
    Euclidean distance); origins are all the camera position.
    """
    m = np.asarray(camera_matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"camera_matrix must be 4x4, got {m.shape}")
    width, height = int(width), int(height)
    if width <= 0 or height <= 0:
        raise ValueError("width and height must be positive")

    half = math.tan(0.5 * float(fov))  # half-extent of the image plane at z = -1
    if width >= height:
        half_x, half_y = half, half * height / width
    else:
        half_x, half_y = half * width / height, half

    x = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * half_x
    y = (1.0 - (np.arange(height) + 0.5) / height * 2.0) * half_y  # row 0 = top
    xx, yy = np.meshgrid(x, y)  # (height, width), row-major like the image

    d_cam = np.empty((height * width, 3))
    d_cam[:, 0] = xx.ravel()
    d_cam[:, 1] = yy.ravel()
    d_cam[:, 2] = -1.0
    dirs = d_cam @ m[:3, :3].T  # (also correct if the matrix carries a uniform scale)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.broadcast_to(m[:3, 3], dirs.shape).copy()
    return origins, dirs
