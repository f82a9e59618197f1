"""Independent references for the core's queries.

- `moller_trumbore`: closest hits by brute force over all triangles with the Moller-Trumbore test in
  float64 numpy: independent of the core's code (different test, no tree).
- `brute_watertight`: every triangle tested with the core's own watertight test, no tree: isolates the
  tree and traversal, so results must match exactly (same arithmetic), and it counts hits per ray.
"""
from pathlib import Path

import numpy as np
from numba import njit, prange

from core.jit import kernel_cache
from core.geometry import has_area
from core.trace.triangle_test import intersect_triangle, ray_shear

kernel_cache.register(Path(__file__).parent)  # before the kernels below, which inline core's test


def moller_trumbore(tris, origins, directions, tmin=0.0, tmax=np.inf, chunk=256):
    """(t, prim) of the closest hit in (tmin, tmax) per ray; zero-area triangles never hit.

    Triangles are rounded to float32 first, as the core stores them, then tested in float64.
    """
    tris = np.asarray(tris, np.float32).astype(np.float64)
    v0 = tris[:, 0]
    e1 = tris[:, 1] - v0
    e2 = tris[:, 2] - v0
    area = np.linalg.norm(np.cross(e1, e2), axis=1) > 0
    n = len(origins)
    best_t = np.full(n, np.inf)
    best_p = np.full(n, -1)
    tmin = np.broadcast_to(tmin, (n,))
    tmax = np.broadcast_to(tmax, (n,))
    for s in range(0, n, chunk):
        o = origins[s:s + chunk, None, :]
        d = directions[s:s + chunk, None, :]
        p = np.cross(d, e2[None])
        det = (e1[None] * p).sum(-1)
        with np.errstate(all="ignore"):
            inv = 1.0 / det
            sv = o - v0[None]
            u = (sv * p).sum(-1) * inv
            q = np.cross(sv, e1[None])
            v = (q * d).sum(-1) * inv
            t = (e2[None] * q).sum(-1) * inv
        ok = (det != 0) & area[None] & (u >= 0) & (v >= 0) & (u + v <= 1)
        ok &= (t > tmin[s:s + chunk, None]) & (t < tmax[s:s + chunk, None])
        t = np.where(ok, t, np.inf)
        i = np.argmin(t, axis=1)
        best_t[s:s + chunk] = t[np.arange(len(i)), i]
        best_p[s:s + chunk] = np.where(np.isfinite(best_t[s:s + chunk]), i, -1)
    return best_t, best_p


@njit(parallel=True, cache=True)
def _brute(tris, origins, directions, tmin, tmax, out_t, out_p, out_count):
    for r in prange(origins.shape[0]):
        o = origins[r]
        d = directions[r]
        kx, ky, kz, sx, sy, sz = ray_shear(d)
        best, best_p, count = tmax[r], -1, 0
        for i in range(tris.shape[0]):
            if not has_area(tris[i]):
                continue
            t, u, v = intersect_triangle(tris[i], o, kx, ky, kz, sx, sy, sz)
            if tmin[r] < t < tmax[r]:
                count += 1
                if t < best:
                    best, best_p = t, i
        out_t[r] = best if best_p >= 0 else np.inf
        out_p[r] = best_p
        out_count[r] = count


def brute_watertight(tris, origins, directions, tmin=0.0, tmax=np.inf):
    """(t, prim, hits per ray) with the core's triangle test applied to every triangle."""
    n = len(origins)
    t = np.empty(n)
    p = np.empty(n, np.int64)
    c = np.empty(n, np.int64)
    _brute(np.ascontiguousarray(tris, np.float32), np.ascontiguousarray(origins, np.float64),
           np.ascontiguousarray(directions, np.float64),
           np.ascontiguousarray(np.broadcast_to(tmin, (n,)), np.float64),
           np.ascontiguousarray(np.broadcast_to(tmax, (n,)), np.float64), t, p, c)
    return t, p, c
