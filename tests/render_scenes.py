"""Small analytic scenes for renderer tests: planes, boxes and cameras looking at them."""
import numpy as np

import core


def render(tris, camera, size=32, **settings):
    """A size x size preview of triangles `tris` (one kd-tree) with core's render settings."""
    tree = core.build_kdtree(tris)
    return core.render_preview(tree, camera, size, size, **settings)


def quad(center, u, v):
    """Two triangles spanning center +- u +- v."""
    c, u, v = (np.asarray(x, np.float64) for x in (center, u, v))
    p = [c - u - v, c + u - v, c + u + v, c - u + v]
    return np.array([[p[0], p[1], p[2]], [p[0], p[2], p[3]]])


def floor(z=0.0, half=1000.0, center=(0.0, 0.0)):
    return quad((center[0], center[1], z), (half, 0, 0), (0, half, 0))


def look_down(position, fov=0.5):
    """A camera at `position` looking straight down -Z (Blender's default camera orientation)."""
    m = np.eye(4)
    m[:3, 3] = position
    return core.Camera(m, fov)


def look_at(position, target, fov=0.8):
    """A perspective camera at `position` looking at `target` with +Z up."""
    p, t = np.asarray(position, float), np.asarray(target, float)
    back = (p - t) / np.linalg.norm(p - t)
    right = np.cross([0.0, 0.0, 1.0], back)
    if np.linalg.norm(right) < 1e-9:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, back, p
    return core.Camera(m, fov)


def hit_mask(image):
    return image[..., 3] > 0.5


def box(center, half):
    """The 12 outward-facing triangles of an axis-aligned box center +- half."""
    c, h = np.asarray(center, np.float64), np.asarray(half, np.float64)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float64) * h + c
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return corners[faces]
