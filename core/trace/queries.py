"""Closest-hit and any-hit queries over a KdTree: input checks, then one parallel kernel.

A KdTree could also be queried as a one-instance scene (scene_queries.py, as the renderer does); the
library's own queries keep the direct kernel, which skips the instance transform
(docs/choices.md#direct-kernel-for-tree-queries)."""
from typing import NamedTuple

import numpy as np

from ..inputs import as_ray_limits, as_rays, hits_as_float32
from .kdtree import KdTree
from ..build.lazy import resolve_suspended
from ..jit.threads import thread_count
from .traversal import trace_rays


class Hits(NamedTuple):
    """Per-ray results: `t` (float32, inf on a miss), `prim` (int32 triangle index, -1 on a miss),
    `u`, `v` (float32 barycentric weights of the triangle's vertices 1 and 2)."""

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray


def intersect(tree, origins, directions, tmin=0.0, tmax=np.inf, threads=None):
    """Closest hit of each ray in the open interval (tmin, tmax); tmin, tmax scalars or (R,) arrays."""
    t, prim, u, v, lo, hi = _trace(tree, origins, directions, tmin, tmax, False, threads)
    t32, u32, v32 = hits_as_float32(t, prim, u, v, lo, hi, threads)
    return Hits(t32, prim, u32, v32)


def occluded(tree, origins, directions, tmin=0.0, tmax=np.inf, threads=None):
    """(R,) bool: does each ray hit anything in (tmin, tmax)? Stops at the first hit found. Runs of
    consecutive rays with one origin go in packets (occlusion_packets.py) on an eager tree."""
    _check_tree(tree)
    if tree.lazy:
        return _trace(tree, origins, directions, tmin, tmax, True, threads)[1] >= 0
    from .occlusion_packets import occluded_prims  # imported here: packet_traversal imports this module
    o, d = as_rays(origins, directions, threads)
    lo, hi = as_ray_limits(tmin, tmax, len(o))
    with thread_count(threads):
        return occluded_prims(tree.arrays, o, d, lo, hi) >= 0


def _check_tree(tree):
    if not isinstance(tree, KdTree):
        hint = ": use core.intersect_scene / occluded_scene for a TwoLevelScene" if hasattr(tree, "meshes") else ""
        raise ValueError(f"tree must be a core.KdTree, got {type(tree).__name__}{hint}")


def _trace(tree, origins, directions, tmin, tmax, any_hit, threads):
    _check_tree(tree)
    o, d = as_rays(origins, directions, threads)
    lo, hi = as_ray_limits(tmin, tmax, len(o))
    n = len(o)
    t = np.empty(n)
    prim = np.empty(n, np.int32)
    u = np.empty(n)
    v = np.empty(n)
    with thread_count(threads):
        trace_rays(tree.arrays, o, d, lo, hi, any_hit, t, prim, u, v)

        def retrace(rays):  # rays that stopped at unbuilt subtrees, now built (lazy trees only)
            m = len(rays)
            out = [np.empty(m), np.empty(m, np.int32), np.empty(m), np.empty(m)]
            trace_rays(tree.arrays, o[rays], d[rays], lo[rays], hi[rays], any_hit, *out)
            t[rays], prim[rays], u[rays], v[rays] = out

        resolve_suspended(tree, prim, retrace, threads)
    return t, prim, u, v, lo, hi
