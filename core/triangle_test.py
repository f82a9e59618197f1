"""Watertight ray/triangle intersection (Woop, Benthin and Wald 2013, JCGT 2(1)), with an exact tie rule.

The ray is sheared so it runs along +z from the origin; each vertex is transformed once, and the three
edge functions are 2D cross products of transformed vertices. A shared edge is computed from the same
two transformed vertices in both triangles, so the two values are exact negatives: no ray slips between
neighbours. Woop et al. accept zero edge values, so a ray through an edge or vertex hits every triangle
sharing it; here a zero is accepted only when the edge direction (oriented so the inside is on its left)
points "up, or right if horizontal". That is a symbolic perturbation of the ray by a fixed infinitesimal
offset, so exactly one triangle of a closed fan owns each edge and vertex: no ray hits twice.
Everything is in float64 on float32 vertices; zero-area triangles (det == 0) never hit.
"""
import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def ray_shear(d):
    """Per-ray constants: the dominant axis kz, the other two (kx, ky keep winding), and the shear."""
    ax, ay, az = abs(d[0]), abs(d[1]), abs(d[2])
    kz = 0 if (ax >= ay and ax >= az) else (1 if ay >= az else 2)
    kx = kz + 1 if kz < 2 else 0
    ky = kx + 1 if kx < 2 else 0
    if d[kz] < 0.0:
        kx, ky = ky, kx
    return kx, ky, kz, d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]


@njit(cache=True, inline="always")
def _owns_zero_edge(ex, ey):
    """Tie rule for an edge function that is exactly zero (see module docstring)."""
    return ey > 0.0 or (ey == 0.0 and ex > 0.0)


@njit(cache=True, inline="always")
def intersect_triangle(tri, o, kx, ky, kz, sx, sy, sz):
    """(t, u, v) of the hit, u and v weighting vertices 1 and 2; t is inf on a miss."""
    az = tri[0, kz] - o[kz]
    bz = tri[1, kz] - o[kz]
    cz = tri[2, kz] - o[kz]
    ax = (tri[0, kx] - o[kx]) - sx * az
    ay = (tri[0, ky] - o[ky]) - sy * az
    bx = (tri[1, kx] - o[kx]) - sx * bz
    by = (tri[1, ky] - o[ky]) - sy * bz
    cx = (tri[2, kx] - o[kx]) - sx * cz
    cy = (tri[2, ky] - o[ky]) - sy * cz
    u = cx * by - cy * bx
    v = ax * cy - ay * cx
    w = bx * ay - by * ax
    if (u < 0.0 or v < 0.0 or w < 0.0) and (u > 0.0 or v > 0.0 or w > 0.0):
        return np.inf, 0.0, 0.0
    det = u + v + w
    if det == 0.0:
        return np.inf, 0.0, 0.0
    s = 1.0 if det > 0.0 else -1.0
    u, v, w, det = s * u, s * v, s * w, s * det
    if ((u == 0.0 and not _owns_zero_edge(s * (bx - cx), s * (by - cy)))
            or (v == 0.0 and not _owns_zero_edge(s * (cx - ax), s * (cy - ay)))
            or (w == 0.0 and not _owns_zero_edge(s * (ax - bx), s * (ay - by)))):
        return np.inf, 0.0, 0.0
    t = (u * az + v * bz + w * cz) * sz / det
    if t <= _t_rounding(ax, ay, bx, by, cx, cy, az, bz, cz, sx, sy, sz, u, v, w, det):
        return np.inf, 0.0, 0.0  # not surely in front of the origin: a ray leaving a surface misses it
    return t, v / det, w / det


GAMMA = 2.0 ** -53  # float64's unit roundoff; gamma(n) below is Higham's n u / (1 - n u)


@njit(cache=True, inline="always")
def _gamma(n):
    return n * GAMMA / (1.0 - n * GAMMA)


@njit(cache=True, inline="always")
def _t_rounding(ax, ay, bx, by, cx, cy, az, bz, cz, sx, sy, sz, u, v, w, det):
    """A bound on the rounding error of t, from pbrt-v3's watertight test (Pharr, Jakob and Humphreys,
    §3.9.6): a t below it may be 0 or negative. pbrt bounds the shear term sx * z by the scaled z
    (|sx| <= 1); ours is applied to the unscaled z (sz only scales t) and bounded by |sx| |z|, which
    keeps the bound tight for tiny directions: with pbrt's form a ray along 2e-16 * (0, -1, 0) lost a
    real hit at t = 1.4e15, and one 1e30 away along 1e-15 * (0, 0, -1) its hit at t = 1e45. Without
    it a ray starting exactly on a triangle (tmin 0) reported that triangle at t ~ 1e-17, and, in the
    tree, sometimes instead of its true closest hit (outside QA; the renderer's offset ray starts stay
    far above it)."""
    shear_z = max(abs(az), abs(bz), abs(cz))  # the shear adds sx * z: unscaled z, times |sx| <= 1
    max_z = shear_z * abs(sz)  # t's z values are scaled by sz (huge for a tiny direction)
    max_x = max(abs(ax), abs(bx), abs(cx))
    max_y = max(abs(ay), abs(by), abs(cy))
    delta_z = _gamma(3) * max_z
    delta_x = _gamma(5) * (max_x + abs(sx) * shear_z)
    delta_y = _gamma(5) * (max_y + abs(sy) * shear_z)
    delta_e = 2.0 * (_gamma(2) * max_x * max_y + delta_y * max_x + delta_x * max_y)
    max_e = max(u, v, w)
    return 3.0 * (_gamma(3) * max_e * max_z + delta_e * max_z + delta_z * max_e) / det
