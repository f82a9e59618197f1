"""Coherent rays through a TwoLevelScene in packets (packet_traversal.py) where the scene allows it:
camera rays (closest hits) and the shadow rays of a light without extent (occlusion).

A scene of one instance in a one-leaf top level (a flat KdTree, or a scene whose objects all went to
one soup) is traced as trace_scene traces it: every ray is carried into the instance's object space by
its world-to-object matrix (instance_traversal._to_object, the same float64 arithmetic) and traced
through the mesh tree in (tmin, tmax), here in packets. A scene of up to
instance_packets.MOST_INSTANCES instances the rays see takes them one at a time (instance_packets.py).
Rays the packets leave to single rays (mixed signs, zero components) are traced by trace_scene_rays
itself, and so is every ray of any other scene or of a lazy tree, so results are trace_valid_rays'
(see packet_traversal.py for exact ties in t). Packets find closest hits; occlusion takes whether there
is one in (tmin, tmax), which is whether an any-hit query finds one.
"""
import numpy as np
from numba import njit, prange

from .. import buffer_pool
from ..jit.kernel_cache import holds_version
from ..jit.threads import thread_count
from ..trace.layout import LEAF
from ..trace.packet_traversal import PacketOutputs, PacketRays, trace_packets
from . import instance_packets
from .instance_packets import MOST_INSTANCES, packed_mesh_tree, retrace, trace_instances_in_packets, visible_instances
from .instance_traversal import _to_object
from .scene_queries import trace_valid_rays
from .two_level import as_two_level


def trace_camera_packets(scene, o, d, lo, hi, order, threads, ray_mask):
    """trace_valid_rays(scene, o, d, lo, hi, False, threads, ray_mask) for coherent rays; `order` groups
    the rays into packets (L ray indices a packet, -1 for none: packet_traversal.packet_order)."""
    return _traced(as_two_level(scene), (o, d, lo, hi, order), threads, ray_mask, False)


def occluded_in_packets(scene, o, d, lo, hi, order, threads, ray_mask):
    """(R,) bool: whether each ray meets something in (lo, hi), as trace_valid_rays' any-hit query
    tells it, for coherent rays grouped by `order` as in trace_camera_packets."""
    return _traced(as_two_level(scene), (o, d, lo, hi, order), threads, ray_mask, True)[2] >= 0


def packets_apply(scene, ray_mask):
    """Whether rays of kind `ray_mask` through the TwoLevelScene are traced in packets: an eager scene
    with one to MOST_INSTANCES instances visible to them."""
    return scene.lazy_tree is None and 0 < len(visible_instances(scene.arrays, ray_mask)) <= MOST_INSTANCES


def packet_kernels_ready():
    """Whether the packets of trace_camera_packets and occluded_in_packets run without a compile: each
    kernel they call from Python holds a version, loaded or cached (kernel_cache.holds_version). A
    renderer's packets call each with one set of argument types (tests/test_packets_once_cached.py), so a
    version held is theirs. Their first compile takes about half a minute, which a caller that must not
    wait skips with single rays (docs/choices.md#the-first-frames-compile-without-the-packet-kernels)."""
    return all(holds_version(kernel) for kernel in (trace_packets, _rays_to_object, *instance_packets.KERNELS))


def _traced(scene, rays, threads, ray_mask, any_hit):
    """(t, instance, prim, u, v) of rays = (o, d, lo, hi, order): in packets through one instance of a
    flat top level, through several one at a time, or singly where the packets do not apply."""
    o, d, lo, hi, order = rays
    order = np.asarray(order).view()
    order.setflags(write=False)  # as the renderer's orders: one compiled version of each packet kernel
    if not packets_apply(scene, ray_mask):
        return trace_valid_rays(scene, o, d, lo, hi, any_hit, threads, ray_mask)
    if flat_instance.py_func(scene.arrays, ray_mask) >= 0:
        return _trace_in_packets(scene, o, d, lo, hi, order, threads, ray_mask, any_hit)
    return trace_instances_in_packets(scene.arrays, o, d, lo, hi, order, threads, ray_mask, any_hit)


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
    t, u, v, prim = buffer_pool.empty(n), buffer_pool.empty(n), buffer_pool.empty(n), buffer_pool.empty(n, np.int32)
    single = buffer_pool.zeros(n, np.uint8)
    with thread_count(threads):
        o_obj, d_obj = _in_object_space(s.world_to_object[inst], o, d)
        trace_packets(packed_mesh_tree(s, int(s.mesh_of[inst])), PacketRays(o_obj, d_obj, lo, hi, order),
                      PacketOutputs(t, prim, u, v, single), any_hit)
        instance = buffer_pool.empty(n, np.int32)
        np.right_shift(prim, 31, out=instance)  # -1 where prim < 0 (a miss), else 0: two passes, no mask
        np.bitwise_or(instance, inst, out=instance)
        retrace(s, (o, d, lo, hi), np.flatnonzero(single.view(np.bool_)), any_hit, ray_mask, (t, instance, prim, u, v))
    return t, instance, prim, u, v


IDENTITY = np.eye(3, 4)


def _in_object_space(w2o, o, d):
    """The rays in the instance's object space. A flat KdTree's instance has the identity matrix, whose
    product leaves every finite coordinate as it is (but -0.0, which becomes +0.0: zero components go to
    single rays, which take the world rays), so its rays are used as they are: no pass, no copies."""
    if np.array_equal(w2o, IDENTITY):
        return o, d
    o_obj, d_obj = buffer_pool.empty(o.shape), buffer_pool.empty(d.shape)
    _rays_to_object(w2o, o, d, o_obj, d_obj)
    return o_obj, d_obj


@njit(cache=True, parallel=True)
def _rays_to_object(w2o, o, d, o_obj, d_obj):
    for r in prange(o.shape[0]):
        _to_object(w2o, o[r], d[r], o_obj[r], d_obj[r])
