"""Coherent rays through a TwoLevelScene in packets (packet_traversal.py) where the scene allows it:
camera rays (closest hits) and the shadow rays of a light without extent (occlusion).

A scene of one instance in a one-leaf top level (a flat KdTree, or a scene whose objects all went to
one soup) is traced as trace_scene traces it: every ray is carried into the instance's object space by
its world-to-object matrix (instance_traversal._to_object, the same float64 arithmetic) and traced
through the mesh tree in (tmin, tmax), here in packets. Rays the packets leave to single rays (mixed
signs, zero components) are traced by trace_scene_rays itself, and so is every ray of any other scene
or of a lazy tree, so results are trace_valid_rays' (see packet_traversal.py for exact ties in t).
Packets find closest hits; occlusion takes whether there is one in (tmin, tmax), which is whether an
any-hit query finds one.
"""
import numpy as np
from numba import njit, prange

from ..jit.threads import thread_count
from ..trace.layout import LEAF, TreeArrays
from ..trace.packet_traversal import PacketOutputs, PacketRays, trace_packets
from .instance_traversal import _to_object, trace_scene_rays
from .scene_queries import trace_valid_rays
from .two_level import as_two_level


def trace_camera_packets(scene, o, d, lo, hi, order, threads, ray_mask):
    """trace_valid_rays(scene, o, d, lo, hi, False, threads, ray_mask) for coherent rays; `order` groups
    the rays into packets (L ray indices a packet, -1 for none: packet_traversal.packet_order)."""
    scene = as_two_level(scene)
    if not packets_apply(scene, ray_mask):
        return trace_valid_rays(scene, o, d, lo, hi, False, threads, ray_mask)
    return _trace_in_packets(scene, o, d, lo, hi, order, threads, ray_mask, False)


def occluded_in_packets(scene, o, d, lo, hi, order, threads, ray_mask):
    """(R,) bool: whether each ray meets something in (lo, hi), as trace_valid_rays' any-hit query
    tells it, for coherent rays grouped by `order` as in trace_camera_packets."""
    scene = as_two_level(scene)
    if not packets_apply(scene, ray_mask):
        return trace_valid_rays(scene, o, d, lo, hi, True, threads, ray_mask)[2] >= 0
    return _trace_in_packets(scene, o, d, lo, hi, order, threads, ray_mask, True)[2] >= 0


def packets_apply(scene, ray_mask):
    """Whether rays of kind `ray_mask` through the TwoLevelScene are traced in packets: one eager mesh
    instance visible to them in a one-leaf top level (flat_instance, run as Python here)."""
    return scene.lazy_tree is None and flat_instance.py_func(scene.arrays, ray_mask) >= 0


@njit(cache=True, inline="always")
def flat_instance(arrays, ray_mask):
    """The instance of a scene (SceneArrays) of one instance in a one-leaf top level, when rays of kind
    `ray_mask` see it; else -1. The camera and hard-shadow packets' rule for taking a scene (packets_apply;
    the sampling kernel's packets take any scene: render/sample_packets.py)."""
    items = arrays.top_items
    if items.shape[0] != 1 or arrays.top_axis[0] != LEAF or arrays.visibility[items[0]] & ray_mask == 0:
        return -1
    return items[0]


def _trace_in_packets(scene, o, d, lo, hi, order, threads, ray_mask, any_hit):
    """Packets through the one instance (packets_apply), the rays they leave traced singly, all of them
    as any-hit queries when `any_hit` (a lane stops at its first hit): (t, instance, prim, u, v) as
    trace_valid_rays gives them."""
    s = scene.arrays
    n, inst = len(o), int(s.top_items[0])
    t, u, v, prim = np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.int32)
    single = np.zeros(n, np.uint8)
    with thread_count(threads):
        o_obj, d_obj = _in_object_space(s.world_to_object[inst], o, d)
        trace_packets(_mesh_tree(s, int(s.mesh_of[inst])), PacketRays(o_obj, d_obj, lo, hi, order),
                      PacketOutputs(t, prim, u, v, single), any_hit)
        instance = np.where(prim >= 0, np.int32(inst), np.int32(-1))
        rest = np.flatnonzero(single.view(np.bool_))
        if len(rest):
            out = [np.empty(len(rest)), np.empty(len(rest), np.int32), np.empty(len(rest), np.int32),
                   np.empty(len(rest)), np.empty(len(rest))]
            trace_scene_rays(s, o[rest], d[rest], lo[rest], hi[rest], any_hit, ray_mask, *out)
            t[rest], instance[rest], prim[rest], u[rest], v[rest] = out
    return t, instance, prim, u, v


IDENTITY = np.eye(3, 4)


def _in_object_space(w2o, o, d):
    """The rays in the instance's object space. A flat KdTree's instance has the identity matrix, whose
    product leaves every finite coordinate as it is (but -0.0, which becomes +0.0: zero components go to
    single rays, which take the world rays), so its rays are used as they are: no pass, no copies."""
    if np.array_equal(w2o, IDENTITY):
        return o, d
    o_obj, d_obj = np.empty_like(o), np.empty_like(d)
    _rays_to_object(w2o, o, d, o_obj, d_obj)
    return o_obj, d_obj


def _mesh_tree(s, m):
    """Mesh m's tree in the packed arrays (instance_traversal.mesh_tree, as slices)."""
    n0, n1 = s.node_start[m], s.node_start[m + 1]
    r0, r1 = s.ref_start[m], s.ref_start[m + 1]
    return TreeArrays(s.axis[n0:n1], s.split[n0:n1], s.child[n0:n1], s.count[n0:n1], s.leaf_prims[r0:r1],
                      s.triangles[s.tri_start[m]:s.tri_start[m + 1]], s.mesh_bounds[m], s.leaf_triangles, int(r0))


@njit(cache=True, parallel=True)
def _rays_to_object(w2o, o, d, o_obj, d_obj):
    for r in prange(o.shape[0]):
        _to_object(w2o, o[r], d[r], o_obj[r], d_obj[r])
