"""A pixel's AO rays traced as any-hit packets inside the sampling kernel (render_kernels.py).

All AO rays of a pixel start at its ray start, so they make one-origin any-hit packets
(occlusion_packets.py: lanes of every sign, each lane's answer the single ray's, so images do not change).
Sobol's consecutive samples are spread over the hemisphere on purpose, so the samples of a chunk are
first put in order of where they fall: quarter of azimuth, then the inner or outer half of Malley's disk
(u1 < 1/2), by a counting sort that keeps sample order inside a cell. A packet's lanes then point
roughly one way and walk the same nodes (docs/choices.md#ao-rays-in-packets-inside-the-sampling-kernel).
Packets apply to batches of at least render_kernels.PACKED_BATCH samples (a progressive step of one
sample gives each packet one lane) on a scene of one instance in a one-leaf top level that shadow rays
see (scene_packets.flat_instance), lazy trees included: a packet that meets an unbuilt node leaves its
lanes to single rays, which stop there as before. Rays the memo answers (ray_memo.py) are not traced,
and rays a packet leaves are traced one by one by the sampling kernel. The sampling kernel takes
`packed`: for None it is compiled without any of this code (the helpers below are overloads that are
nothing for None), so a renderer that steps one sample at a time, as the add-on does, compiles what it
did before packets (docs/choices.md#ao-packets-compiled-only-for-batches).
"""
from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.extending import overload

from ..scene.instance_traversal import _to_object, mesh_tree, unowned_scene
from ..scene.ray_visibility import SHADOW_RAYS
from ..scene.scene_packets import flat_instance
from ..trace import simd as S
from ..trace.array_views import rows, unowned
from ..trace.layout import TreeArrays
from ..trace.packet_traversal import (PacketOutputs, PacketRays, box_fits_float32, new_packet_work, trace_packet,
                                     unowned_outputs, unowned_packet_work, unowned_rays, unowned_tree)
from .ray_memo import TRACE, keep_traced, reused_visibility, unowned_memo
from .sampling import seeded_sample_2d
from .shading import cosine_direction

L = S.LANES
CHUNK = 8 * L  # AO samples of a pixel sorted and traced together
CELLS = 8  # hemisphere cells of the sort: 4 quarters of azimuth x 2 halves of the disk


class AoWork(NamedTuple):
    """A thread's buffers for one chunk (CHUNK rays): `rays` (PacketRays: object-space origins and
    directions, tmin, tmax, the packets' lane order), `out` (PacketOutputs), `world` (CHUNK, 3) the
    world-space directions, `cells` (CHUNK,) int64 each ray's cell (-1: answered by the memo),
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
    """Whether the AO rays go in packets: `packets` from ao_work_for, not None, its instance >= 0."""
    raise NotImplementedError("called from jitted code only")


@overload(in_packets)
def _in_packets(packets):
    if isinstance(packets, types.NoneType):
        return lambda packets: False
    return lambda packets: packets[4] >= 0


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
    work, packet_work, tree, box_fits, inst = packets
    work = AoWork(unowned_rays(work.rays), unowned_outputs(work.out), unowned(work.world), unowned(work.cells),
                  unowned(work.starts), unowned(work.prims))
    return work, unowned_packet_work(packet_work), unowned_tree(tree), box_fits, inst


@njit(cache=True, inline="always")
def new_ao_work(scene, ao_distance):
    """((AoWork, packet work, flat tree, box fits, instance or -1), owners): a thread's AO packet buffers
    as unowned views, the flat scene's mesh tree (instance -1 when packets do not apply, the tree then an
    empty one never traced) and the arrays owning the views, which the caller keeps alive."""
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
    inst = flat_instance(scene, SHADOW_RAYS)
    tree = mesh_tree(scene, scene.mesh_of[inst]) if inst >= 0 else _no_tree(scene)
    return (work, (sc, stack), tree, box_fits_float32(tree.bounds), inst), (owned, packet_owned)


@njit(cache=True, inline="always")
def _no_tree(scene):
    """A tree of no nodes, of mesh_tree's type: the packet tree of a scene packets do not apply to (which
    may have no mesh, so mesh_tree(scene, 0) could read past its offsets)."""
    return TreeArrays(rows(scene.axis, 0, 0), rows(scene.split, 0, 0), rows(scene.child, 0, 0),
                      rows(scene.count, 0, 0), rows(scene.leaf_prims, 0, 0), rows(scene.triangles, 0, 0),
                      unowned(scene.top_bounds), scene.leaf_triangles, scene.ref_start[0])


@njit(cache=True, inline="always")
def trace_ao_chunk(scene, packets, pixel, samples, batch, memo, rays):
    """The AO rays of samples[0]..samples[1]-1 of pixel = (i, origin, normal, ao seeds, uses): each one's
    any-hit prim (>= 0 occluded, -1 clear) into packets[0].prims[s - samples[0]], from the memo or its
    packet, kept in the memo; ray_memo.TRACE for a ray its packet left, which the caller traces alone.
    Every ray is counted in rays[i], as render_kernels' single rays are. `packets` comes from
    new_ao_work (its instance >= 0). The packets go through packet_traversal.trace_packet, one compiled
    function shared with the packet kernel (docs/choices.md#ao-rays-in-packets-inside-the-sampling-kernel)."""
    work, packet_work, tree, box_fits, inst = packets
    i, first, end, uses = pixel[0], samples[0], samples[1], pixel[4]
    pending = _directions(work, scene.world_to_object[inst], pixel, samples, batch, memo, rays)
    if pending > 1:
        _sort_into_packets(work, end - first, pending)
        any_hit = pending > 1  # True, as a bool value: a literal True would compile trace_packet again
        for p in range((pending + L - 1) // L):
            trace_packet(tree, work.rays, rows(work.rays.order, p * L, p * L + L), packet_work, work.out, box_fits,
                         any_hit)
    for k in range(end - first):
        if work.cells[k] < 0:
            continue  # answered by the memo
        if pending <= 1 or work.out.single[k] != 0:
            work.prims[k] = TRACE
            continue
        work.prims[k] = work.out.prim[k]
        keep_traced(memo, i, (first + k) * uses, work.prims[k])


@njit(cache=True, inline="always")
def _directions(work, w2o, pixel, samples, batch, memo, rays):
    """Each sample's AO direction (render_kernels._ray_of_use's) into work.world, in object space into
    work.rays; rays the memo answers get their prim and cell -1, the others their cell. Returns how many
    rays are left to trace."""
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
            work.cells[k] = -1
            continue
        work.cells[k] = 2 * min(int(4.0 * u2), 3) + (1 if u1 >= 0.5 else 0)
        _to_object(w2o, origin, d, rows(work.rays.origins, k, k + 1)[0], rows(work.rays.directions, k, k + 1)[0])
        work.out.single[k] = 0
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
