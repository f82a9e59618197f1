"""A pixel's sample rays traced as any-hit packets inside the sampling kernel (render_kernels.py).

All rays of a pixel start at its ray start: its AO rays, and its shadow rays towards each light with
extent that casts shadows, make one-origin any-hit packets (occlusion_packets.py: lanes of every sign,
each lane's answer the single ray's, so images do not change). A chunk of a pixel's samples is traced use
by use (the AO ray, then each such light's ray), each ray with its own tmax. Sobol's consecutive samples
are spread over the hemisphere on purpose, so a chunk's AO rays are first put in order of where they
fall: quarter of azimuth, then the inner or outer half of Malley's disk (u1 < 1/2), by a counting sort
that keeps sample order inside a cell. A packet's lanes then point roughly one way and walk the same
nodes (docs/choices.md#ao-rays-in-packets-inside-the-sampling-kernel). A light's rays all point at the
light already, so they go in sample order (docs/choices.md#light-samples-in-packets). Lights without
extent repeat sample 0's ray (render_kernels.py) and lights without shadows need none: neither is in packets.
Packets apply to batches of at least render_kernels.PACKED_BATCH samples (a progressive step of one
sample gives each packet one lane) on any scene, lazy trees included: a packet that meets an unbuilt
node leaves its lanes to single rays, which stop there as before. The chunk's rays go through each
instance that shadow rays see and whose world box meets the box of their segments (found down the top
level: scene/box_query.py; where that box meets more than MAX_CHUNK_INSTANCES, each ray walks the top
level alone), each ray only where the single ray's clip lets it into the instance's box, in that
instance's object space (instance_traversal._to_object, as single rays go); a ray that one instance
occludes leaves the packets, and a ray clear of all of them is clear, as an any-hit query through the top
level finds (docs/choices.md#sample-packets-through-the-instances-a-chunks-rays-may-meet).
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

from ..scene.box_query import instances_meeting_box, new_box_query
from ..scene.instance_traversal import _misses_box, _to_object, mesh_tree, unowned_scene
from ..scene.ray_visibility import SHADOW_RAYS
from ..trace import simd as S
from ..trace.array_views import rows, unowned
from ..trace.layout import LEAF
from ..trace.traversal import clip_to_box
from ..trace.packet_traversal import (PacketOutputs, PacketRays, box_fits_float32, new_packet_work, trace_packet,
                                     unowned_outputs, unowned_packet_work, unowned_rays)
from .lights import DELTA, NO_SHADOW
from .ray_memo import TRACE, keep_traced, reused_visibility, unowned_memo
from .sample_rays import USE_AO, ao_direction, ray_of_use, uses_of_mode

L = S.LANES
CHUNK = 8 * L  # samples of a pixel whose rays are traced together, use by use
CELLS = 8  # hemisphere cells of the AO sort: 4 quarters of azimuth x 2 halves of the disk
# most instances a chunk's rays are traced through in packets: where the box of their segments meets more
# (long light rays across a scene of many instances), each ray's own walk of the top level does better
MAX_CHUNK_INSTANCES = 16
ANSWERED, DECIDED = -1, -2  # ChunkWork.cells of a ray answered beforehand (or needing none), of one traced or left
PASSED = -3  # cells <= PASSED: a pending ray outside the instance being traced (_enters)


class ChunkWork(NamedTuple):
    """A thread's buffers for one chunk (CHUNK samples): `rays` (PacketRays: object-space origins and
    directions, tmin, each ray's tmax, the packets' lane order), `out` (PacketOutputs), `world` (CHUNK, 3)
    the world-space directions of the use being traced, `cells` (CHUNK,) int64 each pending ray's cell
    (else ANSWERED, DECIDED, or PASSED - cell while set aside by _enters), `starts` (CELLS + 1,) int64
    the sort's cell offsets, and for every use (row) and sample (column): `answers` (uses, CHUNK) int64
    the ray's any-hit prim or ray_memo.TRACE,
    `weights` (uses, CHUNK) its weight (sample_rays.ray_of_use: 0 when it needs no ray); `inv` (3,) a
    direction's reciprocals for a box clip (_enters); `reach` (6,) the box of the pending rays' segments
    (_extend_reach); `query` box_query.new_box_query's buffers, for the instances that box may meet."""

    rays: PacketRays
    out: PacketOutputs
    world: np.ndarray
    cells: np.ndarray
    starts: np.ndarray
    answers: np.ndarray
    weights: np.ndarray
    inv: np.ndarray
    reach: np.ndarray
    query: tuple


def chunk_work_for(scene, uses, packed):
    """(packets, answers, weights, owners): new_chunk_work's packets, their chunk's answers and weights
    (ChunkWork.answers, .weights) and the arrays to keep alive when `packed` is not None; else (None, two
    empty arrays, None). Jitted code only. These helpers are overloads that Numba compiles as small
    functions of their own: inlined, with a None argument, they gave wrong indices
    (docs/choices.md#ao-packets-compiled-only-for-batches)."""
    raise NotImplementedError("called from jitted code only")


@overload(chunk_work_for)
def _chunk_work_for(scene, uses, packed):
    if isinstance(packed, types.NoneType):
        return lambda scene, uses, packed: (None, np.empty((0, 0), np.int64), np.empty((0, 0)), None)

    def work(scene, uses, packed):
        packets, owners = new_chunk_work(scene, uses)
        return packets, packets[0].answers, packets[0].weights, owners
    return work


def in_packets(packets):
    """Whether the sample rays go in packets: `packets` from chunk_work_for is not None."""
    raise NotImplementedError("called from jitted code only")


@overload(in_packets)
def _in_packets(packets):
    if isinstance(packets, types.NoneType):
        return lambda packets: False
    return lambda packets: True


@njit(cache=True, inline="always")
def in_chunk(lights, use):
    """Whether the rays of `use` go in packets: the AO rays, and those of a light with extent that casts
    shadows (a light without extent repeats sample 0's ray; one without shadows needs none)."""
    return use == USE_AO or (lights[use - 1, DELTA] == 0.0 and lights[use - 1, NO_SHADOW] == 0.0)


def answer_chunk(scene, packets, pixel, samples, batch, lights, memo, rays):
    """trace_chunk with packets from chunk_work_for; nothing for None."""
    raise NotImplementedError("called from jitted code only")


@overload(answer_chunk)
def _answer_chunk(scene, packets, pixel, samples, batch, lights, memo, rays):
    if isinstance(packets, types.NoneType):
        return lambda scene, packets, pixel, samples, batch, lights, memo, rays: None

    def answer(scene, packets, pixel, samples, batch, lights, memo, rays):
        # A function of its own: its arrays become unowned views again, as packet_traversal.trace_packet's.
        i, point, origin, normal, ps, ao_seeds, uses = pixel
        trace_chunk(unowned_scene(scene), _unowned_packets(packets),
                    (i, unowned(point), unowned(origin), unowned(normal), ps, ao_seeds, uses), samples, batch,
                    unowned(lights), unowned_memo(memo), unowned(rays))
    return answer


@njit(cache=True, inline="always")
def _unowned_packets(packets):
    """new_chunk_work's packets as unowned views (array_views.py)."""
    work, packet_work = packets
    query = (unowned(work.query[0]), unowned(work.query[1]))
    work = ChunkWork(unowned_rays(work.rays), unowned_outputs(work.out), unowned(work.world), unowned(work.cells),
                     unowned(work.starts), unowned(work.answers), unowned(work.weights), unowned(work.inv),
                     unowned(work.reach), query)
    return work, unowned_packet_work(packet_work)


@njit(cache=True, inline="always")
def new_chunk_work(scene, uses):
    """((ChunkWork, packet work), owners): a thread's packet buffers for `uses` uses a sample as unowned
    views, and the arrays owning them, which the caller keeps alive."""
    owned = (np.zeros((CHUNK, 3)), np.zeros((CHUNK, 3)), np.zeros(CHUNK), np.zeros(CHUNK),
             np.full(CHUNK, -1, np.int64), np.empty(CHUNK), np.empty(CHUNK, np.int32), np.empty(CHUNK),
             np.empty(CHUNK), np.zeros(CHUNK, np.uint8), np.empty((CHUNK, 3)), np.empty(CHUNK, np.int64),
             np.empty(CELLS + 1, np.int64), np.empty((uses, CHUNK), np.int64), np.empty((uses, CHUNK)), np.empty(3),
             np.empty(6), new_box_query(MAX_CHUNK_INSTANCES))
    rays = PacketRays(unowned(owned[0]), unowned(owned[1]), unowned(owned[2]), unowned(owned[3]),
                      unowned(owned[4]))
    out = PacketOutputs(unowned(owned[5]), unowned(owned[6]), unowned(owned[7]), unowned(owned[8]),
                        unowned(owned[9]))
    query = (unowned(owned[17][0]), unowned(owned[17][1]))
    work = ChunkWork(rays, out, unowned(owned[10]), unowned(owned[11]), unowned(owned[12]), unowned(owned[13]),
                     unowned(owned[14]), unowned(owned[15]), unowned(owned[16]), query)
    sc, stack, packet_owned = new_packet_work()
    return (work, (sc, stack)), (owned, packet_owned)


@njit(cache=True, inline="always")
def trace_chunk(scene, packets, pixel, samples, batch, lights, memo, rays):
    """The rays of samples[0]..samples[1]-1 of pixel = (i, point, origin, normal, pixel seed, AO seeds,
    uses) for every use of the batch's mode that goes in packets (in_chunk), use by use (trace_use)."""
    uses = pixel[6]
    first_use, last_use = uses_of_mode(batch.mode, uses)
    for use in range(first_use, last_use):
        if in_chunk(lights, use):
            trace_use(scene, packets, pixel, samples, batch, lights, use, memo, rays)


@njit(cache=True, inline="always")
def trace_use(scene, packets, pixel, samples, batch, lights, use, memo, rays):
    """The rays of one use of the chunk's samples: each one's weight into packets[0].weights[use] and
    its any-hit prim (>= 0 occluded, -1 clear) into packets[0].answers[use, s - samples[0]], from the
    memo or the packets, kept in the memo; ray_memo.TRACE for a ray a packet left (or all, once fewer
    than two are pending, or all when their segments may meet more than MAX_CHUNK_INSTANCES instances),
    which the caller traces alone through the scene (counted in memo.alone[i]).
    Every ray is counted in rays[i], as render_kernels' single rays are. The packets go through
    packet_traversal.trace_packet, one compiled function shared with the packet kernel
    (docs/choices.md#ao-rays-in-packets-inside-the-sampling-kernel), through each instance the rays'
    segments may meet (_instances_reached, then _through_instance)."""
    work, packet_work = packets
    i, origin, first, end, uses = pixel[0], pixel[2], samples[0], samples[1], pixel[6]
    answers = rows(work.answers, use, use + 1)[0]
    n = end - first
    pending = _rays_of_use(scene, work, pixel, samples, batch, lights, use, memo, rays)
    unfinished = pending > 0  # a ray left pending has not met every instance it may: the caller traces it
    if pending > 1:
        near = _instances_reached(scene, work)
        k = 0
        while pending > 1 and k < near <= MAX_CHUNK_INSTANCES:
            pending = _through_instance(scene, work.query[0][k], work, packet_work, (origin, answers), n, pending)
            k += 1
        unfinished = k < near
    for k in range(n):
        if work.cells[k] == ANSWERED:
            continue
        if work.cells[k] >= 0:
            answers[k] = TRACE if unfinished else -1
        if answers[k] != TRACE:
            keep_traced(memo, i, (first + k) * uses + use, answers[k])
        else:
            memo.alone[i] += 1


@njit(cache=True, inline="always")
def _instances_reached(scene, work):
    """How many instances the pending rays, whose segments lie in the box work.reach (_extend_reach),
    may meet, as trace_scene decides, listed in work.query[0]; MAX_CHUNK_INSTANCES + 1 when more. Only
    instances shadow rays see: a flat top level's one instance (trace_scene tests no box there; its box
    holds triangles, so its mesh has nodes); else those of the top level (build_top_level leaves out
    empty boxes) whose world box (rounded outward) overlaps work.reach widened (_widen_reach), found down
    the top level (box_query.py). A test for the whole chunk; _enters then tests each ray."""
    if _flat_top(scene):
        work.query[0][0] = scene.top_items[0]
        return 1 if scene.visibility[scene.top_items[0]] & SHADOW_RAYS != 0 else 0
    _widen_reach(work.reach)
    return instances_meeting_box(scene, work.reach, work.query, MAX_CHUNK_INSTANCES, SHADOW_RAYS)


@njit(cache=True, inline="always")
def _widen_reach(reach):
    """Widen the box of the pending rays' segments by 2^-20 of its size (more than the single ray's clips
    widen a segment, traversal._slack, and than the triangle test's t carries) and 2^-50 of its
    coordinates (the end points' rounding): the box the instances are tested against (_instances_reached)."""
    for k in range(3):
        slack = (reach[k + 3] - reach[k]) * 2.0 ** -20 + (abs(reach[k]) + abs(reach[k + 3])) * 2.0 ** -50
        reach[k], reach[k + 3] = reach[k] - slack, reach[k + 3] + slack


@njit(cache=True, inline="always")
def _flat_top(scene):
    """A one-leaf top level of one instance, where trace_scene tests no instance box."""
    return scene.top_items.shape[0] == 1 and scene.top_axis[0] == LEAF


@njit(cache=True, inline="always")
def _extend_reach(scene, work, origin, d, tmax):
    """Grow work.reach by the segment from origin along d to tmax, or, for an endless ray (a sun's), to
    where the single ray's clip of the scene's top-level box ends it (no instance lies beyond)."""
    end = tmax
    if end == np.inf:
        inv = work.inv
        for a in range(3):
            inv[a] = 1.0 / d[a] if d[a] != 0.0 else 0.0
        t0, t1 = clip_to_box(scene.top_bounds, origin, d, inv, 0.0, tmax)
        end = t1 if t0 <= t1 else 0.0
    box = work.reach
    for a in range(3):
        far = origin[a] + d[a] * end
        box[a] = min(box[a], origin[a], far)
        box[a + 3] = max(box[a + 3], origin[a], far)


@njit(cache=True, inline="always")
def _through_instance(scene, inst, work, packet_work, ray_answers, n, pending):
    """The pending rays (work.cells >= 0) from ray_answers[0] that enter instance inst's world box
    (_enters) through it in packets, in its object space (the single rays' arithmetic); a ray it
    occludes, or one a packet leaves (work.out.single), is decided: its prim, or TRACE, into
    ray_answers[1]. Returns how many stay pending (clear of every instance so far)."""
    origin, answers = ray_answers
    tree = mesh_tree(scene, scene.mesh_of[inst])
    w2o = rows(scene.world_to_object, inst, inst + 1)[0]
    entering = _enters(scene, inst, work, origin, n) if not _flat_top(scene) else pending
    if entering == 0:
        _restore_passed(work, n)
        return pending
    for k in range(n):
        if work.cells[k] >= 0:
            _to_object(w2o, origin, rows(work.world, k, k + 1)[0], rows(work.rays.origins, k, k + 1)[0],
                       rows(work.rays.directions, k, k + 1)[0])
            work.out.single[k] = 0
    _sort_into_packets(work, n, entering)
    any_hit = entering > 0  # True, as a bool value: a literal True would compile trace_packet again
    box_fits = box_fits_float32(tree.bounds)
    for p in range((entering + L - 1) // L):
        trace_packet(tree, work.rays, rows(work.rays.order, p * L, p * L + L), packet_work, work.out, box_fits,
                     any_hit)
    pending = 0
    for k in range(n):
        if work.cells[k] < 0:
            continue
        if work.out.single[k] != 0 or work.out.prim[k] >= 0:
            answers[k] = TRACE if work.out.single[k] != 0 else work.out.prim[k]
            work.cells[k] = DECIDED
        else:
            pending += 1
    return pending + _restore_passed(work, n)


@njit(cache=True, inline="always")
def _restore_passed(work, n):
    """Put the rays _enters set aside (cells <= PASSED) back in their cells; returns how many there were."""
    passed = 0
    for k in range(n):
        if work.cells[k] <= PASSED:
            work.cells[k] = PASSED - work.cells[k]
            passed += 1
    return passed


@njit(cache=True, inline="always")
def _enters(scene, inst, work, origin, n):
    """How many pending rays may meet instance inst, in a top level that is not flat (a flat one tests no
    box: all enter): those whose segment (0, tmax) the single ray's clip of the instance's world box keeps
    (instance_traversal._misses_box, the same float64 arithmetic, so a ray left out here is one
    trace_scene would not enter either). The others' cells become PASSED - cell until the instance is done:
    long rays (a light's) pass most instances' boxes."""
    inv, inside = work.inv, 0
    for k in range(n):
        if work.cells[k] < 0:
            continue
        d = rows(work.world, k, k + 1)[0]
        for a in range(3):
            inv[a] = 1.0 / d[a] if d[a] != 0.0 else 0.0
        if _misses_box(scene.world_boxes, inst, origin, d, inv, 0.0, work.rays.tmax[k]):
            work.cells[k] = PASSED - work.cells[k]
        else:
            inside += 1
    return inside


@njit(cache=True, inline="always")
def _rays_of_use(scene, work, pixel, samples, batch, lights, use, memo, rays):
    """Each sample's ray of `use` (sample_rays.ray_of_use's) into work.world, work.rays.tmax and
    work.weights[use]; rays the memo answers, and light rays that need none (weight 0), get their prim
    and cell ANSWERED, the others their cell (AO rays their hemisphere cell, light rays cell 0) and
    their segment in work.reach. Returns how many rays are left to trace."""
    i, point, origin, normal, ps, ao_seeds, uses = pixel
    first, end = samples
    answers, weights = rows(work.answers, use, use + 1)[0], rows(work.weights, use, use + 1)[0]
    pending = 0
    work.reach[:3], work.reach[3:] = np.inf, -np.inf
    for k in range(end - first):
        s = first + k
        d = rows(work.world, k, k + 1)[0]
        cell = 0
        if use == USE_AO:
            u1, u2 = ao_direction(batch.sampler, ao_seeds, s, batch.dim1, normal, d)
            tmax, weights[k] = batch.ao_distance, 1.0
            cell = 2 * min(int(4.0 * u2), 3) + (1 if u1 >= 0.5 else 0)
        else:
            tmax, weights[k] = ray_of_use(use, lights, point, normal, batch.ao_distance, batch.sampler, ps, ao_seeds,
                                          s, batch.dim1, d)
        answers[k], work.cells[k] = -1, ANSWERED
        if weights[k] <= 0.0:
            continue  # behind the surface or outside the light: no ray, as in the sampling loop
        rays[i] += 1
        answers[k] = reused_visibility(memo, i, s * uses + use, origin, d, tmax)
        if answers[k] != TRACE:
            continue
        work.cells[k], work.rays.tmax[k] = cell, tmax
        _extend_reach(scene, work, origin, d, tmax)
        pending += 1
    return pending


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
