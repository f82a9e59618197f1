"""Cameras in Blender's convention: camera-to-world matrix, looking down local -Z with +Y up."""
import numpy as np


class Camera:
    """A perspective (`fov`) or orthographic (`ortho_scale`) camera.

    matrix_world: 4x4 camera-to-world matrix (Blender's `camera.matrix_world`).
    fov: full field of view in radians along the larger image dimension (Blender's sensor fit AUTO).
    ortho_scale: width of the view along the larger image dimension (Blender's `ortho_scale`).
    clip_start, clip_end: distances along the view axis; geometry outside is not seen.
    """

    def __init__(self, matrix_world, fov=None, *, ortho_scale=None, clip_start=0.0, clip_end=np.inf):
        m = np.asarray(matrix_world, np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all():
            raise ValueError(f"camera matrix_world must be a finite 4x4 matrix, got shape {m.shape}")
        if (fov is None) == (ortho_scale is None):
            raise ValueError("camera needs exactly one of fov (perspective) or ortho_scale (orthographic)")
        if fov is not None and not 0.0 < fov < np.pi:
            raise ValueError(f"camera fov must be in (0, pi) radians, got {fov}")
        if ortho_scale is not None and not ortho_scale > 0.0:
            raise ValueError(f"camera ortho_scale must be > 0, got {ortho_scale}")
        if not 0.0 <= clip_start < clip_end:
            raise ValueError(f"camera clip range must satisfy 0 <= clip_start < clip_end, got {clip_start}, {clip_end}")
        if abs(np.linalg.det(m[:3, :3])) < 1e-12:
            raise ValueError("camera matrix_world is singular (zero scale)")
        self.matrix_world = m
        self.fov, self.ortho_scale = fov, ortho_scale
        self.clip_start, self.clip_end = float(clip_start), float(clip_end)

    @property
    def position(self):
        return self.matrix_world[:3, 3].copy()

    def translated(self, offset):
        """The same camera in a frame whose origin is at `offset` (positions minus offset)."""
        m = self.matrix_world.copy()
        m[:3, 3] -= np.asarray(offset, np.float64)
        return Camera(m, self.fov, ortho_scale=self.ortho_scale, clip_start=self.clip_start,
                      clip_end=self.clip_end)

    def rays(self, width, height):
        """Rays through pixel centres, row 0 at the top: (origins, directions, tmin, tmax), (H*W, 3).

        Directions have unit length along the view axis, so tmin/tmax are the clip distances.
        """
        half_w, half_h = self._half_extent(width, height)
        x = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * half_w
        y = (1.0 - (np.arange(height) + 0.5) / height * 2.0) * half_h
        xx, yy = np.meshgrid(x, y)
        rot = self.matrix_world[:3, :3] / np.linalg.norm(self.matrix_world[:3, :3], axis=0)
        n = width * height
        if self.fov is not None:
            local = np.stack([xx.ravel(), yy.ravel(), -np.ones(n)], axis=1)
            directions = local @ rot.T
            origins = np.broadcast_to(self.matrix_world[:3, 3], (n, 3)).copy()
        else:
            local = np.stack([xx.ravel(), yy.ravel(), np.zeros(n)], axis=1)
            origins = local @ rot.T + self.matrix_world[:3, 3]
            directions = np.broadcast_to(-rot[:, 2], (n, 3)).copy()
        return origins, directions, np.full(n, self.clip_start), np.full(n, self.clip_end)

    def _half_extent(self, width, height):
        """Half the image plane's size at distance 1 (perspective) or in world units (ortho)."""
        half = np.tan(self.fov / 2.0) if self.fov is not None else self.ortho_scale / 2.0
        if width >= height:
            return half, half * height / width
        return half * width / height, half

    def __repr__(self):
        kind = f"fov={self.fov:.4f}" if self.fov is not None else f"ortho_scale={self.ortho_scale}"
        return f"Camera(position={self.position.round(4).tolist()}, {kind})"
