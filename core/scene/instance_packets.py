"""Coherent rays in packets through a two-level scene of several instances, one instance at a time.

trace_scene (instance_traversal.py) walks the top level and hands each instance the best hit so far as
tmax, so its closest hit is the closest of the visible instances' closest hits, the instance its walk
meets first winning an exact tie in t. Here each instance the rays see (nearest world box first) takes
the packets that have a lane whose segment meets its world box (the clip of
instance_traversal._misses_box), in its object space with trace_scene's arithmetic
(instance_traversal._to_object), every lane searching up to just past its best hit so far, so that a
tie is seen; a closer hit replaces the best. A lane that ties another instance's hit exactly, and one a
packet leaves to single rays (packet_traversal.py), is traced again whole by trace_scene, whose answer
it then is by construction. Any-hit lanes (occlusion) leave once an instance occludes them.
Each instance costs a pass over the packets, where the top level's walk visits only the instances a ray
meets, so scenes of more than MOST_INSTANCES visible instances stay with single rays
(docs/choices.md#camera-and-shadow-packets-through-several-instances).
"""
import numpy as np
from numba import njit, prange

from ..jit.threads import thread_count
from ..trace.layout import TreeArrays
from ..trace.packet_traversal import L, PacketOutputs, PacketRays, trace_packets
from ..trace.traversal import clip_to_box
from .instance_traversal import _to_object, trace_scene_rays

MOST_INSTANCES = 16  # visible instances traced packet by packet, one at a time; more: single rays
BATCH_PACKETS = 65536  # packets a batch: 524,288 lanes of work buffers (49 MB at most), whatever the frame size
DECIDED = np.uint8(1)  # a lane's state: an any-hit lane that something occludes
RETRACE = np.uint8(2)  # a lane left to trace_scene (a packet left it, or two instances tie)


def visible_instances(arrays, ray_mask):
    """The instances (SceneArrays) that rays of kind `ray_mask` see and that hold something: an empty
    mesh's inverted world box, which the top level leaves out, would clip as the whole line."""
    boxes = arrays.world_boxes
    return np.flatnonzero(((arrays.visibility & ray_mask) != 0) & (boxes[:, 0] <= boxes[:, 3]))


def trace_instances_in_packets(arrays, o, d, lo, hi, order, threads, ray_mask, any_hit):
    """(t, instance, prim, u, v) as trace_valid_rays gives them for coherent rays grouped by `order`
    (L ray indices a packet, -1 for none, read-only) through the instances (SceneArrays) rays of kind
    `ray_mask` see. Closest hits; with `any_hit`, whether there is a hit (prim >= 0) as trace_valid_rays
    says, the hit itself being any one. The packets go in batches of BATCH_PACKETS, each through every
    instance, so the per-lane buffers (new_lane_work) do not grow with the frame."""
    n = len(o)
    hits = (np.full(n, np.inf), np.full(n, -1, np.int32), np.full(n, -1, np.int32), np.zeros(n), np.zeros(n))
    if not len(order):
        return hits
    state = np.zeros(n, np.uint8)
    instances = _nearest_first(arrays, visible_instances(arrays, ray_mask), o, order)
    lanes = min(len(order), BATCH_PACKETS * L)
    work = new_lane_work(lanes)
    with thread_count(threads):
        for start in range(0, len(order), lanes):
            batch = order[start:start + lanes]
            for k in instances:
                _through_instance(arrays, int(k), (o, d, lo, hi, batch), hits, state, work, any_hit)
        retrace(arrays, (o, d, lo, hi), np.flatnonzero(state == RETRACE), any_hit, ray_mask, hits)
    return hits


def new_lane_work(lanes):
    """Buffers of a batch's lanes, indexed by lane: the object-space origins and directions, tmin, the
    lane's limit (tmax of its search) and the packet outputs (PacketOutputs); and by packet: the
    world-space inverse direction of the lane being clipped and whether the instance takes the packet,
    so that no instance pass allocates."""
    packets = -(-lanes // L)
    return (np.empty((lanes, 3)), np.empty((lanes, 3)), np.empty(lanes), np.empty(lanes),
            PacketOutputs(np.empty(lanes), np.empty(lanes, np.int32), np.empty(lanes), np.empty(lanes),
                          np.zeros(lanes, np.uint8)), np.empty((packets, 3)), np.empty(packets, np.bool_))


def _through_instance(arrays, k, rays, hits, state, work, any_hit):
    """Instance k's packets of the batch rays[4] (those _enter_instance marks) traced lane by lane in the
    work buffers (new_lane_work) and folded into `hits` (_take_hits)."""
    batch = rays[4]
    t, _, prim, _, _ = hits
    o_obj, d_obj, lo_lane, limit, found, inv, keep = work
    keep = keep[:len(batch) // L]
    _enter_instance(arrays.world_boxes[k], arrays.world_to_object[k], rays, (t, prim, state),
                    (o_obj, d_obj, lo_lane, limit, found.single), inv, keep)
    if keep.any():
        packets = _open_lanes(batch, keep, state)
        tree = packed_mesh_tree(arrays, int(arrays.mesh_of[k]))
        trace_packets(tree, PacketRays(o_obj, d_obj, lo_lane, limit, packets), found, any_hit)
        _take_hits(found, k, (packets, batch), hits, state, any_hit)


def retrace(arrays, rays, rest, any_hit, ray_mask, hits):
    """Trace rays `rest` of rays = (o, d, lo, hi) singly through the scene (trace_scene) into their rows
    of hits = (t, instance, prim, u, v)."""
    if not len(rest):
        return
    o, d, lo, hi = rays
    out = [np.empty(len(rest)), np.empty(len(rest), np.int32), np.empty(len(rest), np.int32), np.empty(len(rest)),
           np.empty(len(rest))]
    trace_scene_rays(arrays, o[rest], d[rest], lo[rest], hi[rest], any_hit, ray_mask, *out)
    for column, values in zip(hits, out):
        column[rest] = values


def packed_mesh_tree(arrays, m):
    """Mesh m's tree in the packed arrays (instance_traversal.mesh_tree, as slices)."""
    n0, n1 = arrays.node_start[m], arrays.node_start[m + 1]
    r0, r1 = arrays.ref_start[m], arrays.ref_start[m + 1]
    return TreeArrays(arrays.axis[n0:n1], arrays.split[n0:n1], arrays.child[n0:n1], arrays.count[n0:n1],
                      arrays.leaf_prims[r0:r1], arrays.triangles[arrays.tri_start[m]:arrays.tri_start[m + 1]],
                      arrays.mesh_bounds[m], arrays.leaf_triangles,
                      arrays.leaf_boxes[arrays.box_start[m]:arrays.box_start[m + 1]], int(r0))


def _open_lanes(batch, keep, state):
    """The lanes (indices into `batch`) of the packets marked in `keep`, their closed lanes (state not 0)
    as -1: read-only, as the renderer's order is (one compiled packet kernel)."""
    packets = np.arange(len(batch), dtype=np.int64).reshape(-1, L)[keep].ravel()
    rays = batch[packets]
    closed = rays < 0
    closed[~closed] = state[rays[~closed]] != 0
    packets[closed] = -1
    packets.setflags(write=False)
    return packets


def _nearest_first(arrays, instances, o, order):
    """`instances` by the distance from the first listed ray's origin to their world boxes: for camera
    rays, which share one origin, near instances shorten the later ones' searches."""
    listed = order[order >= 0]
    if not len(listed) or not len(instances):
        return instances
    boxes = arrays.world_boxes[instances]
    origin = o[listed[0]]
    gap = np.maximum(np.maximum(boxes[:, :3] - origin, origin - boxes[:, 3:]), 0.0)
    return instances[np.argsort((gap * gap).sum(axis=1), kind="stable")]


@njit(cache=True, parallel=True)
def _enter_instance(box, w2o, rays, best, lanes, inv, keep):
    """Mark in `keep` the packets of the batch with an open lane (state 0: neither RETRACE nor DECIDED)
    whose segment (lo, limit) meets the world box; every open lane gets its limit (its best hit's t moved
    up one float, so that a tie is found; else its tmax; lo where its segment misses the box, as
    trace_scene then skips the instance), and those of marked packets their tmin, the instance's
    object-space ray and a clear `single` flag. rays: (o, d, lo, hi, batch); best: (t, prim,
    state), by ray; lanes: (o_obj, d_obj, lo_lane, limit, single), by lane of the batch; inv: a row a
    packet of scratch for the inverse direction."""
    o, d, lo, hi, batch = rays
    t, prim, state = best
    o_obj, d_obj, lo_lane, limit, single = lanes
    for p in prange(batch.shape[0] // L):
        met = False
        for j in range(p * L, p * L + L):
            r = batch[j]
            if r < 0 or state[r] != 0:
                continue
            limit[j] = np.nextafter(t[r], np.inf) if prim[r] >= 0 else hi[r]
            for a in range(3):
                inv[p, a] = 1.0 / d[r, a] if d[r, a] != 0.0 else 0.0
            t0, t1 = clip_to_box(box, o[r], d[r], inv[p], lo[r], limit[j])
            if t0 <= t1:
                met = True
            else:  # trace_scene does not enter the instance: an empty interval, no hit accepted
                limit[j] = lo[r]
        keep[p] = met
        if met:
            for j in range(p * L, p * L + L):
                r = batch[j]
                if r >= 0 and state[r] == 0:
                    _to_object(w2o, o[r], d[r], o_obj[j], d_obj[j])
                    lo_lane[j] = lo[r]
                    single[j] = 0


@njit(cache=True, parallel=True)
def _take_hits(found, k, lanes, best, state, any_hit):
    """Fold instance k's packet hits (`found`, by lane) into the best ones (by ray): a closer hit
    replaces the best, an exact tie with another instance's hit, or a lane the packet left, is marked
    RETRACE; with `any_hit`, a hit closes its lane (DECIDED). lanes: (the packets' lanes, the batch)."""
    packets, batch = lanes
    t, inst, prim, u, v = best
    for i in prange(packets.shape[0]):
        j = packets[i]
        if j < 0:
            continue
        r = batch[j]
        if found.single[j]:
            state[r] = RETRACE
        elif found.prim[j] >= 0:
            if prim[r] >= 0 and found.t[j] == t[r]:
                state[r] = RETRACE
            else:  # below the limit: closer than the best
                t[r], inst[r], prim[r], u[r], v[r] = found.t[j], k, found.prim[j], found.u[j], found.v[j]
                if any_hit:
                    state[r] = DECIDED


KERNELS = (_enter_instance, _take_hits)  # called from Python for each instance, beside trace_packets
