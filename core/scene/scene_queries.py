"""Closest-hit and any-hit queries over a TwoLevelScene: input checks, then one parallel kernel."""
from typing import NamedTuple

import numpy as np

from ..inputs import as_ray_limits, as_rays, hits_as_float32
from .instance_traversal import trace_scene_rays
from ..build.lazy import resolve_suspended
from .ray_visibility import ALL_RAYS, as_ray_mask
from ..jit.threads import thread_count
from .two_level import as_two_level


class SceneHits(NamedTuple):
    """Per-ray results: `t` (float32, inf on a miss), `instance` and `prim` (int32, the instance and
    its mesh's triangle index, -1 on a miss), `u`, `v` (float32 barycentric weights of vertices 1, 2).
    For a scene from build_scene or a SceneBuilder these are the caller's indices (instances in the
    order given, triangles of the instance's mesh), whatever the layout merged or reordered."""

    t: np.ndarray
    instance: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray


def intersect_scene(scene, origins, directions, tmin=0.0, tmax=np.inf, threads=None, ray_mask=ALL_RAYS):
    """Closest hit of each ray in (tmin, tmax); `scene` a TwoLevelScene (or a KdTree, as one instance).
    ray_mask: the rays' kind (ray_visibility.py): CAMERA_RAYS or SHADOW_RAYS meet only the instances
    visible to that kind; ALL_RAYS every instance visible to any."""
    t, inst, prim, u, v, lo, hi = trace_scene_all(scene, origins, directions, tmin, tmax, False, threads, ray_mask)
    ids = getattr(scene, "caller_ids", None)
    if ids is not None:
        inst, prim = ids.map(inst, prim)
    t32, u32, v32 = hits_as_float32(t, prim, u, v, lo, hi, threads)
    return SceneHits(t32, inst, prim, u32, v32)


def occluded_scene(scene, origins, directions, tmin=0.0, tmax=np.inf, threads=None, ray_mask=ALL_RAYS):
    """(R,) bool: does each ray hit anything in (tmin, tmax)? Stops at the first hit found. ray_mask as
    in intersect_scene."""
    return trace_scene_all(scene, origins, directions, tmin, tmax, True, threads, ray_mask)[2] >= 0


def trace_scene_all(scene, origins, directions, tmin, tmax, any_hit, threads, ray_mask=ALL_RAYS):
    """Checked rays through the scene: float64 (t, u, v) and int32 (instance, prim) arrays, then the
    rays' (R,) limits (lo, hi). A lazy KdTree builds the subtrees its rays reach (lazy.py) and the rays
    that stopped there are retraced."""
    o, d = as_rays(origins, directions, threads)
    lo, hi = as_ray_limits(tmin, tmax, len(o))
    return (*trace_valid_rays(scene, o, d, lo, hi, any_hit, threads, as_ray_mask(ray_mask)), lo, hi)


def trace_valid_rays(scene, o, d, lo, hi, any_hit, threads, ray_mask=ALL_RAYS):
    """trace_scene_all without the input checks, for rays that are valid by construction: C-contiguous
    float64, finite, non-zero directions, 0 <= lo <= hi (a Camera's rays). The checks are several passes
    over the arrays (docs/choices.md#unchecked-camera-rays)."""
    scene = as_two_level(scene)
    n = len(o)
    t, u, v = np.empty(n), np.empty(n), np.empty(n)
    inst, prim = np.empty(n, np.int32), np.empty(n, np.int32)
    with thread_count(threads):
        trace_scene_rays(scene.arrays, o, d, lo, hi, any_hit, ray_mask, t, inst, prim, u, v)

    def retrace(rays):  # rays that stopped at unbuilt subtrees of a lazy tree, now built
        scene.refresh()
        out = [np.empty(len(rays)), np.empty(len(rays), np.int32), np.empty(len(rays), np.int32),
               np.empty(len(rays)), np.empty(len(rays))]
        with thread_count(threads):
            trace_scene_rays(scene.arrays, o[rays], d[rays], lo[rays], hi[rays], any_hit, ray_mask, *out)
        t[rays], inst[rays], prim[rays], u[rays], v[rays] = out

    if scene.lazy_tree is not None:
        resolve_suspended(scene.lazy_tree, prim, retrace, threads)
    return t, inst, prim, u, v
