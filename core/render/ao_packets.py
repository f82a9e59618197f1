"""A pixel's AO rays traced as any-hit packets inside the sampling kernel (render_kernels.py).

All AO rays of a pixel start at its ray start, so they make one-origin any-hit packets
(occlusion_packets.py: lanes of every sign, each lane's answer the single ray's, so images do not change).
Sobol's consecutive samples are spread over the hemisphere on purpose, so the samples of a chunk are
first put in order of where they fall: quarter of azimuth, then the inner or outer half of Malley's disk
(u1 < 1/2), by a counting sort that keeps sample order inside a cell. A packet's lanes then point
roughly one way and walk the same nodes (docs/choices.md#ao-rays-in-packets-inside-the-sampling-kernel).
Packets apply to batches of at least render_kernels.PACKED_BATCH samples (a progressive step of one
sample gives each packet one lane) on a scene of at most MAX_PACKET_INSTANCES instances, lazy trees
included: a packet that meets an unbuilt node leaves its lanes to single rays, which stop there as
before. The chunk's rays go through each instance that shadow rays see and whose world box reaches
within ao_distance of the origin, in that instance's object space (instance_traversal._to_object, as
single rays go); a ray that one instance occludes leaves the packets, and a ray clear of all of them is
clear, as an any-hit query through the top level finds (docs/choices.md#ao-packets-through-several-instances).
Rays the memo answers (ray_memo.py) are not traced, and rays a packet leaves are traced one by one by
the sampling kernel, through the whole scene. The sampling kernel takes
`packed`: for None it is compiled without any of this code (the helpers below are overloads that are
nothing for None), so a renderer that steps one sample at a time (the add-on's first step, and its steps
until the packed version is cached) compiles what it did before packets (docs/choices.md#ao-packets-compiled-only-for-batches).
"""
from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.extending import overload

from ..scene.instance_traversal import _to_object, mesh_tree, unowned_scene
from ..scene.ray_visibility import SHADOW_RAYS
from ..trace import simd as S
from ..trace.array_views import rows, unowned
from ..trace.layout import LEAF
from ..trace.packet_traversal import (PacketOutputs, PacketRays, box_fits_float32, new_packet_work, trace_packet,
                                     unowned_outputs, unowned_packet_work, unowned_rays)
from .ray_memo import TRACE, keep_traced, reused_visibility, unowned_memo
from .sampling import seeded_sample_2d
from .shading import cosine_direction

L = S.LANES
CHUNK = 8 * L  # AO samples of a pixel sorted and traced together
CELLS = 8  # hemisphere cells of the sort: 4 quarters of azimuth x 2 halves of the disk
MAX_PACKET_INSTANCES = 16  # most instances a scene's AO packets take: every chunk tests each one's box
MEMO_ANSWERED, DECIDED = -1, -2  # AoWork.cells of a ray the memo answered, and of one traced or left


class AoWork(NamedTuple):
    """A thread's buffers for one chunk (CHUNK rays): `rays` (PacketRays: object-space origins and
    directions, tmin, tmax, the packets' lane order), `out` (PacketOutputs), `world` (CHUNK, 3) the
    world-space directions, `cells` (CHUNK,) int64 each pending ray's cell (else MEMO_ANSWERED, DECIDED),
    `starts` (CELLS + 1,) int64 the sort's cell offsets, `prims` (CHUNK,) int64 each ray's any-hit prim."""

    rays: PacketRays
    out: PacketOutputs
    world: np.ndarray
    cells: np.ndarray
    starts: np.ndarray
    prims: np.ndarray


def ao_work_for(scene, ao_distance, packed):
    """(packets, prims, owners): new_ao_work's packets, their chunk's answers (AoWork.prims) and the
    arrays to keep alive when `packed` is not None; else (None, an empty array, None). Jitted code only.
    These helpers are overloads that Numba compiles as small functions of their own: inlined, with a None
    argument, they gave wrong indices (docs/choices.md#ao-packets-compiled-only-for-batches)."""
    raise NotImplementedError("called from jitted code only")


@overload(ao_work_for)
def _ao_work_for(scene, ao_distance, packed):
    if isinstance(packed, types.NoneType):
        return lambda scene, ao_distance, packed: (None, np.empty(0, np.int64), None)

    def work(scene, ao_distance, packed):
        packets, owners = new_ao_work(scene, ao_distance)
        return packets, packets[0].prims, owners
    return work


def in_packets(packets):
    """Whether the AO rays go in packets: `packets` from ao_work_for, not None, the scene one they take."""
    raise NotImplementedError("called from jitted code only")


@overload(in_packets)
def _in_packets(packets):
    if isinstance(packets, types.NoneType):
        return lambda packets: False
    return lambda packets: packets[2]


def answer_ao_chunk(scene, packets, pixel, samples, batch, memo, rays):
    """trace_ao_chunk with packets from ao_work_for; nothing for None."""
    raise NotImplementedError("called from jitted code only")


@overload(answer_ao_chunk)
def _answer_ao_chunk(scene, packets, pixel, samples, batch, memo, rays):
    if isinstance(packets, types.NoneType):
        return lambda scene, packets, pixel, samples, batch, memo, rays: None

    def answer(scene, packets, pixel, samples, batch, memo, rays):
        # A function of its own: its arrays become unowned views again, as packet_traversal.trace_packet's.
        i, origin, normal, ao_seeds, uses = pixel
        trace_ao_chunk(unowned_scene(scene), _unowned_packets(packets),
                       (i, unowned(origin), unowned(normal), ao_seeds, uses), samples, batch, unowned_memo(memo),
                       unowned(rays))
    return answer


@njit(cache=True, inline="always")
def _unowned_packets(packets):
    """new_ao_work's packets as unowned views (array_views.py)."""
    work, packet_work, apply = packets
    work = AoWork(unowned_rays(work.rays), unowned_outputs(work.out), unowned(work.world), unowned(work.cells),
                  unowned(work.starts), unowned(work.prims))
    return work, unowned_packet_work(packet_work), apply


@njit(cache=True, inline="always")
def packets_take(scene):
    """Whether the AO rays of a scene (SceneArrays) go in packets: it has at most MAX_PACKET_INSTANCES
    instances, each of which a chunk tests (render_kernels' rule, and PreviewRender's through py_func)."""
    return scene.mesh_of.shape[0] <= MAX_PACKET_INSTANCES


@njit(cache=True, inline="always")
def new_ao_work(scene, ao_distance):
    """((AoWork, packet work, whether packets apply: packets_take), owners): a thread's AO packet buffers
    as unowned views and the arrays owning them, which the caller keeps alive."""
    owned = (np.zeros((CHUNK, 3)), np.zeros((CHUNK, 3)), np.zeros(CHUNK), np.full(CHUNK, ao_distance),
             np.full(CHUNK, -1, np.int64), np.empty(CHUNK), np.empty(CHUNK, np.int32), np.empty(CHUNK),
             np.empty(CHUNK), np.zeros(CHUNK, np.uint8), np.empty((CHUNK, 3)), np.empty(CHUNK, np.int64),
             np.empty(CELLS + 1, np.int64), np.empty(CHUNK, np.int64))
    rays = PacketRays(unowned(owned[0]), unowned(owned[1]), unowned(owned[2]), unowned(owned[3]),
                      unowned(owned[4]))
    out = PacketOutputs(unowned(owned[5]), unowned(owned[6]), unowned(owned[7]), unowned(owned[8]),
                        unowned(owned[9]))
    work = AoWork(rays, out, unowned(owned[10]), unowned(owned[11]), unowned(owned[12]), unowned(owned[13]))
    sc, stack, packet_owned = new_packet_work()
    return (work, (sc, stack), packets_take(scene)), (owned, packet_owned)


@njit(cache=True, inline="always")
def trace_ao_chunk(scene, packets, pixel, samples, batch, memo, rays):
    """The AO rays of samples[0]..samples[1]-1 of pixel = (i, origin, normal, ao seeds, uses): each one's
    any-hit prim (>= 0 occluded, -1 clear) into packets[0].prims[s - samples[0]], from the memo or the
    packets, kept in the memo; ray_memo.TRACE for a ray a packet left (or all, once fewer than two are
    pending), which the caller traces alone through the scene. Every ray is counted in rays[i], as
    render_kernels' single rays are. The packets go through packet_traversal.trace_packet, one compiled
    function shared with the packet kernel (docs/choices.md#ao-rays-in-packets-inside-the-sampling-kernel),
    instance by instance (_through_instance)."""
    work, packet_work, _ = packets
    i, origin, first, end, uses = pixel[0], pixel[1], samples[0], samples[1], pixel[4]
    n = end - first
    pending = _directions(work, pixel, samples, batch, memo, rays)
    reach = batch.ao_distance
    inst, instances = 0, scene.mesh_of.shape[0]
    while pending > 1 and inst < instances:
        if _reached(scene, inst, origin, reach):
            pending = _through_instance(scene, inst, work, packet_work, origin, n, pending)
        inst += 1
    unfinished = inst < instances  # a ray left pending has not met every instance: the caller traces it
    for k in range(n):
        if work.cells[k] == MEMO_ANSWERED:
            continue
        if work.cells[k] >= 0:
            work.prims[k] = TRACE if unfinished else -1
        if work.prims[k] != TRACE:
            keep_traced(memo, i, (first + k) * uses, work.prims[k])


@njit(cache=True, inline="always")
def _reached(scene, inst, origin, reach):
    """Whether AO rays from origin, at most `reach` long, may meet instance inst, as trace_scene decides:
    shadow rays see it, its mesh has nodes, the top level holds it (two_level.build_top_level leaves out
    a box with box[0] <= box[3] false), and, unless the top level is flat (trace_scene then tests no box),
    its world box (rounded outward) comes within `reach` of the origin on every axis, widened by 2^-20 of
    the reach (a unit direction's length rounds to 1 within far less) and 2^-50 of the coordinate (the
    sum's rounding)."""
    if scene.visibility[inst] & SHADOW_RAYS == 0:
        return False
    m = scene.mesh_of[inst]
    if scene.node_start[m + 1] == scene.node_start[m] or not scene.world_boxes[inst, 0] <= scene.world_boxes[inst, 3]:
        return False
    if scene.top_items.shape[0] == 1 and scene.top_axis[0] == LEAF:
        return True
    for k in range(3):
        slack = reach * (1.0 + 2.0 ** -20) + (abs(origin[k]) + reach) * 2.0 ** -50
        if scene.world_boxes[inst, k] > origin[k] + slack or scene.world_boxes[inst, k + 3] < origin[k] - slack:
            return False
    return True


@njit(cache=True, inline="always")
def _through_instance(scene, inst, work, packet_work, origin, n, pending):
    """The pending rays (work.cells >= 0) through instance inst in packets, in its object space (the
    single rays' arithmetic); a ray it occludes, or one a packet leaves (work.out.single), is decided:
    its prim, or TRACE. Returns how many stay pending (clear of every instance so far)."""
    tree = mesh_tree(scene, scene.mesh_of[inst])
    w2o = rows(scene.world_to_object, inst, inst + 1)[0]
    for k in range(n):
        if work.cells[k] >= 0:
            _to_object(w2o, origin, rows(work.world, k, k + 1)[0], rows(work.rays.origins, k, k + 1)[0],
                       rows(work.rays.directions, k, k + 1)[0])
            work.out.single[k] = 0
    _sort_into_packets(work, n, pending)
    any_hit = pending > 1  # True, as a bool value: a literal True would compile trace_packet again
    box_fits = box_fits_float32(tree.bounds)
    for p in range((pending + L - 1) // L):
        trace_packet(tree, work.rays, rows(work.rays.order, p * L, p * L + L), packet_work, work.out, box_fits,
                     any_hit)
    pending = 0
    for k in range(n):
        if work.cells[k] < 0:
            continue
        if work.out.single[k] != 0 or work.out.prim[k] >= 0:
            work.prims[k] = TRACE if work.out.single[k] != 0 else work.out.prim[k]
            work.cells[k] = DECIDED
        else:
            pending += 1
    return pending


@njit(cache=True, inline="always")
def _directions(work, pixel, samples, batch, memo, rays):
    """Each sample's AO direction (render_kernels._ray_of_use's) into work.world; rays the memo answers
    get their prim and cell MEMO_ANSWERED, the others their hemisphere cell. Returns how many rays are
    left to trace."""
    i, origin, normal, ao_seeds, uses = pixel
    first, end = samples
    pending = 0
    for k in range(end - first):
        s = first + k
        d = rows(work.world, k, k + 1)[0]
        u1, u2 = ao_direction(batch.sampler, ao_seeds, s, batch.dim1, normal, d)
        rays[i] += 1
        work.prims[k] = reused_visibility(memo, i, s * uses, origin, d, batch.ao_distance)
        if work.prims[k] != TRACE:
            work.cells[k] = MEMO_ANSWERED
            continue
        work.cells[k] = 2 * min(int(4.0 * u2), 3) + (1 if u1 >= 0.5 else 0)
        pending += 1
    return pending


@njit(cache=True, inline="always")
def ao_direction(sampler, ao_seeds, s, dim1, normal, out):
    """Sample s's AO direction about `normal` into out, cosine-weighted (shading.cosine_direction) from
    the AO use's 2D sample (sampling.seeded_sample_2d), which it returns."""
    u1, u2 = seeded_sample_2d(sampler, ao_seeds, s, dim1)
    cosine_direction(normal, u1, u2, out)
    return u1, u2


@njit(cache=True, inline="always")
def _sort_into_packets(work, n, pending):
    """work.rays.order: the n rays' indices to trace, by cell then sample (a counting sort), -1 up to
    a whole packet."""
    cells, starts, order = work.cells, work.starts, work.rays.order
    starts[:] = 0
    for k in range(n):
        if cells[k] >= 0:
            starts[cells[k] + 1] += 1
    for c in range(CELLS):
        starts[c + 1] += starts[c]
    for k in range(n):
        if cells[k] >= 0:
            order[starts[cells[k]]] = k
            starts[cells[k]] += 1
    for k in range(pending, (pending + L - 1) // L * L):
        order[k] = -1
