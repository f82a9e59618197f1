"""Watertight ray/triangle intersection (Woop, Benthin and Wald 2013, JCGT 2(1)), with an exact tie rule.

The ray is sheared to run along +z; edge functions are 2D cross products of the transformed vertices,
so a shared edge gives exact negatives in its two triangles: no ray slips between neighbours. A zero
edge value counts only when the edge direction (inside on its left) points "up, or right if
horizontal": a symbolic perturbation, so exactly one triangle of a closed fan owns each edge and
vertex (Woop et al. accept every zero). Float64 on float32 vertices; zero-area triangles never hit.
`leaf_candidates` screens a run of a leaf's triangles at once (most fail there: edge values straddle
zero) from the leaf-ordered copy in a loop LLVM vectorises, with the same operations (no fast-math).
"""
import numpy as np
from numba import njit

from .array_views import at


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
    """(t, u, v) of the hit on the (3, 3) triangle `tri`, u and v weighting vertices 1 and 2; t is inf on
    a miss."""
    ox, oy, oz = o[kx], o[ky], o[kz]
    ax, ay, az = _sheared(tri[0, kx], tri[0, ky], tri[0, kz], ox, oy, oz, sx, sy)
    bx, by, bz = _sheared(tri[1, kx], tri[1, ky], tri[1, kz], ox, oy, oz, sx, sy)
    cx, cy, cz = _sheared(tri[2, kx], tri[2, ky], tri[2, kz], ox, oy, oz, sx, sy)
    return _hit(ax, ay, az, bx, by, bz, cx, cy, cz, sx, sy, sz)


@njit(cache=True, inline="always")
def intersect_leaf_triangle(leaf_tris, j, o, kx, ky, kz, sx, sy, sz):
    """intersect_triangle on column j of the leaf-ordered copy (leaf_triangles.py): the same float32
    vertices, so the same result, read from the cache lines the screen has just loaded
    (docs/choices.md#leaf-ordered-triangle-copy)."""
    ox, oy, oz = o[at(kx)], o[at(ky)], o[at(kz)]
    j = at(j)  # unsigned indices: no wraparound code (array_views.at)
    ax, ay, az = _sheared(leaf_tris[at(kx), j], leaf_tris[at(ky), j], leaf_tris[at(kz), j], ox, oy, oz, sx, sy)
    bx, by, bz = _sheared(leaf_tris[at(3 + kx), j], leaf_tris[at(3 + ky), j], leaf_tris[at(3 + kz), j], ox, oy, oz,
                          sx, sy)
    cx, cy, cz = _sheared(leaf_tris[at(6 + kx), j], leaf_tris[at(6 + ky), j], leaf_tris[at(6 + kz), j], ox, oy, oz,
                          sx, sy)
    return _hit(ax, ay, az, bx, by, bz, cx, cy, cz, sx, sy, sz)


@njit(cache=True, inline="always")
def _hit(ax, ay, az, bx, by, bz, cx, cy, cz, sx, sy, sz):
    """(t, u, v) from the three sheared vertices (see the module docstring); t is inf on a miss."""
    u, v, w = _edge_values(ax, ay, bx, by, cx, cy)
    if _straddles(u, v, w):
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
    if t <= _t_rounding((ax, ay, az), (bx, by, bz), (cx, cy, cz), (sx, sy, sz), (u, v, w), det):
        return np.inf, 0.0, 0.0  # not surely in front of the origin: a ray leaving a surface misses it
    return t, v / det, w / det


@njit(cache=True, inline="always")
def _sheared(x, y, z, ox, oy, oz, sx, sy):
    """A float32 vertex (in the ray's kx, ky, kz order) relative to the origin, sheared along the ray."""
    z = np.float64(z) - oz
    return (np.float64(x) - ox) - sx * z, (np.float64(y) - oy) - sy * z, z


@njit(cache=True, inline="always")
def _edge_values(ax, ay, bx, by, cx, cy):
    return cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax


@njit(cache=True, inline="always")
def _straddles(u, v, w):
    """Edge values of both signs: the ray passes outside the triangle. Bitwise, not short-circuit, so
    the vectorised loop has no branch."""
    return ((u < 0.0) | (v < 0.0) | (w < 0.0)) & ((u > 0.0) | (v > 0.0) | (w > 0.0))


LEAF_CHUNK = 32  # triangles leaf_candidates screens at once (one flags buffer)


@njit(cache=True, inline="always")
def leaf_candidates(leaf_tris, lo, hi, o, kx, ky, kz, sx, sy, flags):
    """flags[j - lo] = 1 for the leaf-ordered triangles lo..hi-1 (hi - lo <= LEAF_CHUNK) whose edge
    values do not straddle zero, the only ones intersect_triangle may hit; returns whether any does.

    leaf_tris is (9, R) float32, row 3 v + k holding coordinate k of vertex v (leaf_triangles.py).
    The index is unsigned: with a signed one Numba wraps negative indices, and LLVM then gathers the
    loads instead of reading them as vectors (slower than the scalar loop)."""
    ox, oy, oz = o[kx], o[ky], o[kz]
    found = 0
    for i in range(lo, hi):
        j = np.uint64(i)
        ax, ay, az = _sheared(leaf_tris[kx, j], leaf_tris[ky, j], leaf_tris[kz, j], ox, oy, oz, sx, sy)
        bx, by, bz = _sheared(leaf_tris[3 + kx, j], leaf_tris[3 + ky, j], leaf_tris[3 + kz, j], ox, oy, oz, sx, sy)
        cx, cy, cz = _sheared(leaf_tris[6 + kx, j], leaf_tris[6 + ky, j], leaf_tris[6 + kz, j], ox, oy, oz, sx, sy)
        u, v, w = _edge_values(ax, ay, bx, by, cx, cy)
        keep = np.uint8(not _straddles(u, v, w))
        flags[i - lo] = keep
        found |= keep
    return found != 0


GAMMA = 2.0 ** -53  # float64's unit roundoff; gamma(n) below is Higham's n u / (1 - n u)


@njit(cache=True, inline="always")
def _gamma(n):
    return n * GAMMA / (1.0 - n * GAMMA)


@njit(cache=True, inline="always")
def _t_rounding(a, b, c, shear, edges, det):
    """A bound on the rounding error of t (sheared vertices a, b, c, the shear (sx, sy, sz), the edge
    values (u, v, w) and their sum det), from pbrt-v3's watertight test (Pharr, Jakob and Humphreys,
    §3.9.6): a t below it may be 0 or negative. pbrt bounds the shear term sx * z by the scaled z;
    here it applies to the unscaled z (sz only scales t), bounded by |sx| |z|, which stays tight for
    tiny directions (pbrt's form lost a real hit at t = 1.4e15 for a ray along 2e-16 * (0, -1, 0)).
    Without it a ray starting exactly on a triangle (tmin 0) reported that triangle at t ~ 1e-17,
    sometimes instead of its true closest hit (the renderer's offset ray starts stay far above it)."""
    (ax, ay, az), (bx, by, bz), (cx, cy, cz) = a, b, c
    sx, sy, sz = shear
    u, v, w = edges
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
