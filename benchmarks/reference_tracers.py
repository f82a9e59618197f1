"""Reference ray tracers for benchmark ratios: Embree (via ``embreex``) and
Blender's ``mathutils.bvhtree.BVHTree``.

Both take triangles as an (N, 3, 3) array (world space, like
``benchmarks.scenes.Scene.triangles``) and offer the same two queries:

``closest(origins, dirs) -> (t, prim)``
    ``t`` float64 (R,): the ray parameter of the closest hit, i.e. the hit is
    at ``origin + t * dir`` (dirs need not be unit length), ``inf`` on a miss;
    ``prim`` int64 (R,): index of the hit triangle, ``-1`` on a miss.
``occluded(origins, dirs, tmax) -> hit``
    bool (R,): whether any triangle is hit with ``0 <= t <= tmax``
    (``tmax`` a scalar or an (R,) array, in the same parametric units).

Both hit front and back faces and have no ``tnear``: a ray starting on a
surface may hit it at t ~ 0, so offset shadow/AO ray origins yourself.
Each tracer records its build time in ``build_seconds``.
"""

from __future__ import annotations

import time

import numpy as np


def _as_rays(origins, dirs):
    o = np.asarray(origins)
    d = np.asarray(dirs)
    if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
        raise ValueError(f"origins and dirs must both be (R, 3), got {o.shape} and {d.shape}")
    return o, d


def _as_triangles(triangles, dtype):
    tris = np.ascontiguousarray(triangles, dtype=dtype)
    if tris.ndim != 3 or tris.shape[1:] != (3, 3):
        raise ValueError(f"triangles must be (N, 3, 3), got {tris.shape}")
    return tris


class EmbreeTracer:
    """Embree 4 through ``embreex`` (4.4): float32 BVH, single-ray queries.

    Threading: ``embreex``'s ``EmbreeScene.run`` is a plain serial Cython loop
    calling ``rtcIntersect1`` / ``rtcOccluded1`` one ray at a time, and it does
    not release the GIL, so tracing is SINGLE-THREADED (two Python threads on
    halves of the rays take as long as one thread on all of them).  The BVH
    *build* (scene commit) is Embree's own TBB-parallel builder (CPU/wall
    time of about 1-2 measured on a shared 2-core box).  Ratios against a
    multi-threaded tracer should say so.

    Build timing: ``build_seconds`` = ``mesh_seconds`` + ``commit_seconds``.
    ``embreex.mesh_construction.TriangleMesh`` copies the triangles into
    Embree's buffers with a slow serial loop (about 0.4 s for 250k triangles,
    whichever input layout or dtype), several times longer than Embree's own
    BVH build (``commit_seconds``, about 0.06-0.1 s on 2 cores).  Compare
    builders against ``commit_seconds``; ``build_seconds`` is what a Python
    user of embreex pays.

    ``closest`` uses one ``run(..., output=1)`` pass, which returns distance and
    primID together (plus u, v, Ng that we drop).

    ``occluded`` is a true Embree occlusion query (``query='OCCLUDED'``, i.e.
    ``rtcOccluded1``: any hit, first-hit termination) with ``tfar = tmax``
    passed through ``run``'s ``dists`` argument.  ``tnear`` is hard-wired to 0
    by ``embreex``.

    Precision: origins, directions, tmax and vertices are converted to float32.
    """

    def __init__(self, triangles):
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        tris = _as_triangles(triangles, np.float32)
        self.n_triangles = tris.shape[0]
        t0 = time.perf_counter()
        self._scene = rtcs.EmbreeScene()
        self._mesh = TriangleMesh(self._scene, tris) if self.n_triangles else None
        t1 = time.perf_counter()
        # embreex commits (builds the BVH) lazily on the first run(); force it
        # here with one ray so the build is timed here, not in the first query.
        self._scene.run(
            np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32), query="DISTANCE"
        )
        t2 = time.perf_counter()
        self.mesh_seconds = t1 - t0  # embreex copying the triangles into Embree buffers (serial)
        self.commit_seconds = t2 - t1  # Embree's BVH build proper (rtcCommitScene, TBB-parallel)
        self.build_seconds = t2 - t0

    @staticmethod
    def _rays32(origins, dirs):
        o, d = _as_rays(origins, dirs)
        return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)

    def closest(self, origins, dirs):
        o, d = self._rays32(origins, dirs)
        if o.shape[0] == 0:
            return np.empty(0), np.empty(0, np.int64)
        res = self._scene.run(o, d, output=1)
        prim = res["primID"].astype(np.int64)  # INVALID_GEOMETRY_ID comes back as -1
        t = res["tfar"].astype(np.float64)
        t[prim < 0] = np.inf
        return t, prim

    def occluded(self, origins, dirs, tmax):
        o, d = self._rays32(origins, dirs)
        n = o.shape[0]
        if n == 0:
            return np.empty(0, bool)
        # A fresh float32 array: run() uses (and for DISTANCE queries overwrites) it in place.
        tfar = np.empty(n, np.float32)
        tfar[:] = tmax
        res = self._scene.run(o, d, dists=tfar, query="OCCLUDED")
        return res >= 0  # embreex returns 0 for occluded rays and -1 otherwise


class BlenderBVHTracer:
    """``mathutils.bvhtree.BVHTree.FromPolygons`` with a Python loop over
    ``ray_cast`` -- what a Blender add-on would use without a custom tracer.

    ``ray_cast`` normalises the direction and returns a Euclidean distance; we
    convert to and from the parametric ``t`` of this module using |dir|.  It
    has no any-hit query, so ``occluded`` is a closest-hit ``ray_cast`` limited
    to ``distance = tmax * |dir|``.  BVHTree stores float32 coordinates.

    Importing ``bpy`` (needed before ``mathutils`` can be imported from the
    PyPI ``bpy`` module) has side effects on the whole process: for example
    Numba's threading layer becomes ``tbb`` (bpy bundles libtbb) instead of
    ``omp``.  Time this tracer in its own process if that matters.
    """

    def __init__(self, triangles, epsilon: float = 0.0):
        import bpy  # noqa: F401  (makes mathutils importable)
        from mathutils.bvhtree import BVHTree

        tris = _as_triangles(triangles, np.float64)
        n = tris.shape[0]
        self.n_triangles = n
        t0 = time.perf_counter()
        verts = tris.reshape(-1, 3).tolist()
        polys = np.arange(3 * n).reshape(n, 3).tolist()
        t1 = time.perf_counter()
        self._tree = BVHTree.FromPolygons(verts, polys, all_triangles=True, epsilon=epsilon)
        t2 = time.perf_counter()
        self.convert_seconds = t1 - t0  # numpy -> Python lists
        self.build_seconds = t2 - t1  # BVHTree.FromPolygons itself

    def closest(self, origins, dirs):
        o, d = _as_rays(origins, dirs)
        n = o.shape[0]
        norms = np.linalg.norm(np.asarray(d, np.float64), axis=1)
        t = np.full(n, np.inf)
        prim = np.full(n, -1, np.int64)
        ray_cast = self._tree.ray_cast
        for k, (ok, dk) in enumerate(zip(o.tolist(), d.tolist())):
            _, _, index, dist = ray_cast(ok, dk)
            if index is not None:
                t[k] = dist
                prim[k] = index
        with np.errstate(divide="ignore", invalid="ignore"):
            t /= norms
        return t, prim

    def occluded(self, origins, dirs, tmax):
        o, d = _as_rays(origins, dirs)
        n = o.shape[0]
        norms = np.linalg.norm(np.asarray(d, np.float64), axis=1)
        limit = (np.broadcast_to(np.asarray(tmax, np.float64), (n,)) * norms).tolist()
        hit = np.zeros(n, bool)
        ray_cast = self._tree.ray_cast
        for k, (ok, dk, lk) in enumerate(zip(o.tolist(), d.tolist(), limit)):
            if ray_cast(ok, dk, lk)[2] is not None:
                hit[k] = True
        return hit
