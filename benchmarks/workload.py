"""The rays the core benchmark traces: 512x512 camera rays and 8 cosine-weighted AO rays per hit.

AO rays start at the camera hit point, offset along the geometric normal (turned to face the camera) by
a small multiple of the hit point's magnitude, with tmax = 1.0, as the issue specifies.
"""
import numpy as np

from camera import camera_rays


CAMERA_WIDTH = 512


def camera_workload(scene, width=CAMERA_WIDTH, height=512):
    """Origins and directions of the scene's camera rays."""
    return camera_rays(scene.camera_matrix, scene.camera_fov, width, height)


def ao_workload(triangles, origins, directions, t, prim, per_hit=8, seed=0):
    """Origins and directions of `per_hit` cosine-weighted AO rays at every camera hit."""
    hit = prim >= 0
    p = origins[hit] + t[hit, None] * directions[hit]
    tri = triangles[prim[hit]].astype(np.float64)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n *= -np.sign((n * directions[hit]).sum(axis=1))[:, None]
    p = p + n * (1e-4 * (1.0 + np.abs(p).max(axis=1)))[:, None]
    rng = np.random.default_rng(seed)
    m = len(p) * per_hit
    n_rep = np.repeat(n, per_hit, axis=0)
    local = _cosine_directions(rng.random(m), rng.random(m))
    return np.repeat(p, per_hit, axis=0), _to_world(local, n_rep)


def _cosine_directions(u1, u2):
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u1))], axis=1)


def _to_world(local, n):
    """Rotate local (x, y, z) directions so z maps onto the normals n (Duff et al. 2017 basis)."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    s = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return local[:, :1] * t + local[:, 1:2] * s + local[:, 2:3] * n
