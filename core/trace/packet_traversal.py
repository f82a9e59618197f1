"""Closest hits of coherent rays (camera rays) traced in packets of simd.LANES through a flat KdTree.

Wald et al. 2001 ("Interactive Rendering with Coherent Ray Tracing", §3) trace neighbouring primary rays
together: the packet walks the kd-tree once, each lane keeping its own [t0, t1]; at an inner node it
goes to the first child only, or the second only, when every active lane agrees, and otherwise visits
both, pushing the second with the lanes that enter it and their intervals. A leaf's triangles are
tested against all its active lanes (packet_leaf.py). One sign per axis for the whole packet fixes
which child comes first, so a lane whose direction has another sign on some axis, a zero component, or
a magnitude float32 cannot bound (OUTSIDE_FLOAT32) leaves the packet and is traced by the single-ray
kernel (traversal.trace_rays) afterwards. In an any-hit packet (occlusion_packets.py) the order does
not matter, so lanes of both signs share it: on such an axis each lane takes its parts of the two
children by its own sign (_mixed_node_step), and a lane that finds a hit leaves the packet.

Node steps run in float32 lanes, conservatively (docs/choices.md#float32-node-arithmetic): per lane
o' = fl32(o), i' = fl32(1 / d) and err = c |split| + e with c = 2^-21 |i'|, e = c (|o'| + 2^-126) +
2^-126, so [ts' - err, ts' + err] holds the exact plane distance ts. The lane's part of the first child
is [t0, min(t1, ts' + err)], of the second [max(t0, ts' - err), t1]: each contains the exact part, so a
lane visits every cell the exact traversal visits, in the same front-to-back order (the packet's signs
are the lane's). The interval and the stack stay in float32; the starting interval is rounded outward. The
set-up runs in lanes too (packet_setup.py).
A lane stops only when every stacked cell left to it starts (float32 bound, widened down) after its
best hit: cells behind that start later still. The leaf test is float64, so t, u, v equal the
single-ray test's, and hits equal traversal.trace_ray's except where two different triangles give a
lane exactly the same t in different leaves (the first one visited wins in both, and the packet may
visit a cell the single ray's tighter bounds skip).
A lazy tree is handed to queries.intersect whole (an unbuilt node would stop the packet).
"""
import functools
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from . import simd as S
from .array_views import at, keep_alive, rows, unowned
from ..inputs import as_ray_limits, as_rays, hits_as_float32
from .kdtree import KdTree
from .layout import LEAF
from .queries import Hits, intersect
from ..jit.threads import thread_count
from .packet_leaf import BEST, ROWS, leaf_test
from .packet_boxes import ROWS32, T0, T1, plane_bounds
from .packet_setup import LANE_BITS, MIXED, OUTSIDE_FLOAT32, leave_to_single_rays, setup_packet
from .traversal import STACK_SIZE, block_range, thread_shares, trace_rays, unowned_tree
from .triangle_test import LEAF_CHUNK

L = S.LANES
TILE_SHAPE = (4, 2) if L == 8 else (4, 4)  # a packet: neighbouring pixels (width x height)
PACKETS_PER_TASK = 8  # packets of one block of interleaved_blocks


class PacketRays(NamedTuple):
    """The rays of a trace_packets call: origins, directions (R, 3), tmin, tmax (R,), and `order`, L ray
    indices a packet (packet_order)."""

    origins: np.ndarray
    directions: np.ndarray
    tmin: np.ndarray
    tmax: np.ndarray
    order: np.ndarray


class PacketOutputs(NamedTuple):
    """Per-ray results: t, prim, u, v (R,), and single (R,) uint8, set for rays left to single rays."""

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray
    single: np.ndarray


class PacketScratch(NamedTuple):
    """One packet's working set: `rays` (ROWS * L float64, packet_leaf's rows), lane origins `lane_o`
    (L, 3, filled where a lane takes the single-ray test), shear axes `axes` (L, 3), the best hit's prim,
    u, v per lane, `lanes32` (ROWS32 * L float32, the node step's rows: packet_setup.py) and `lane_bits`
    (LANE_BITS int64 lane masks: packet_setup.py), `flags` (LEAF_CHUNK uint8, the leaf screen's)."""

    rays: np.ndarray
    lane_o: np.ndarray
    axes: np.ndarray
    prims: np.ndarray
    us: np.ndarray
    vs: np.ndarray
    lanes32: np.ndarray
    lane_bits: np.ndarray
    flags: np.ndarray


class PacketStack(NamedTuple):
    """The traversal stack: node, lane bits and per-lane [t0, t1] (2 L float32) of each entry."""

    node: np.ndarray
    bits: np.ndarray
    t: np.ndarray


@functools.lru_cache(maxsize=8)
def packet_order(width, height, tile_shape=TILE_SHAPE):
    """Ray indices (image order, row-major, `width` columns) grouped in tiles of tile_shape pixels, one
    packet of L lanes per tile, tiles in image order; -1 fills lanes of tiles cut by the image edge.
    Read-only and kept for the next frame of the same size (building it costs ~ms per 100k rays)."""
    tw, th = tuple(tile_shape)
    if tw * th != L:
        raise ValueError(f"tile_shape must cover {L} pixels, got {tile_shape}")
    tiles_x, tiles_y = -(-width // tw), -(-height // th)
    ty, tx, ly, lx = np.meshgrid(np.arange(tiles_y), np.arange(tiles_x), np.arange(th), np.arange(tw),
                                 indexing="ij")
    x, y = tx * tw + lx, ty * th + ly
    order = np.where((x < width) & (y < height), y * width + x, -1).astype(np.int64).ravel()
    order.flags.writeable = False
    return order


def intersect_packets(tree, origins, directions, width, tmin=0.0, tmax=np.inf, tile_shape=TILE_SHAPE,
                      threads=None, stats=None):
    """Closest hits as queries.intersect gives them (Hits), for rays in image order: ray k is pixel
    (k // width, k % width). Neighbouring pixels are traced as packets; `stats`, a dict if given, gets
    the number of packets and of rays traced singly."""
    if not isinstance(tree, KdTree):
        raise ValueError(f"tree must be a core.KdTree, got {type(tree).__name__}")
    o, d = as_rays(origins, directions, threads)
    n = len(o)
    if n % width:
        raise ValueError(f"{n} rays do not fill rows of width {width}")
    if tree.lazy:
        return intersect(tree, o, d, tmin, tmax, threads)
    lo, hi = as_ray_limits(tmin, tmax, n)
    order = packet_order(int(width), n // width, tuple(tile_shape))
    t, prim, u, v = np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n)
    single = np.zeros(n, np.uint8)
    with thread_count(threads):
        # any_hit passed, not left to its default: an omitted argument would be another specialisation
        trace_packets(tree.arrays, PacketRays(o, d, lo, hi, order), PacketOutputs(t, prim, u, v, single), False)
        rest = np.flatnonzero(single.view(np.bool_))
        if len(rest):
            out = [np.empty(len(rest)), np.empty(len(rest), np.int32), np.empty(len(rest)), np.empty(len(rest))]
            trace_rays(tree.arrays, o[rest], d[rest], lo[rest], hi[rest], False, *out)
            t[rest], prim[rest], u[rest], v[rest] = out
    if stats is not None:
        stats.update(packets=len(order) // L, single_rays=len(rest))
    t32, u32, v32 = hits_as_float32(t, prim, u, v, lo, hi, threads)
    return Hits(t32, prim, u32, v32)


@njit(cache=True, parallel=True)
def trace_packets(tree, rays_in, out, any_hit=False):
    """Trace the packets of rays_in.order (PacketRays) in parallel into `out` (PacketOutputs); rays that
    cannot join their packet are left for the single-ray kernel with out.single[ray] = 1. With `any_hit`
    a lane stops at the first hit it finds (prim >= 0, t its distance), as trace_ray's any hit does.
    One prange iteration a thread, taking the iterations a static schedule of interleaved_blocks' prange
    would give that thread, so the scratch arrays are made once a thread
    (docs/choices.md#packet-scratch-once-a-thread)."""
    n = rays_in.order.shape[0] // L
    threads, share, per_band, run = thread_shares(n, PACKETS_PER_TASK)
    for k in prange(threads):
        _trace_packet_blocks(tree, rays_in, out, (k * share, k * share + share, per_band, run, n), any_hit)


@njit(cache=True)
def _trace_packet_blocks(tree, rays_in, out, blocks, any_hit):
    """The packets of iterations blocks[0]..blocks[1]-1 (blocks: first, end, per_band, run, packets;
    traversal.block_range) with one set of scratch arrays and the tree as unowned views (see
    traversal._trace_block)."""
    first, end, per_band, run, n = blocks
    views, rays_in, out = _unowned_arguments(tree, rays_in, out)
    sc, stack, owned = new_packet_work()
    box_fits = box_fits_float32(views.bounds)
    for i in range(first, end):
        start, stop = block_range(i, per_band, run, n, PACKETS_PER_TASK)
        for p in range(start, stop):
            _trace_packet(views, rays_in, rows(rays_in.order, p * L, p * L + L), (sc, stack), out, box_fits, any_hit)
    keep_alive(owned)  # the owners of sc and stack


@njit(cache=True, inline="always")
def _unowned_arguments(tree, rays_in, out):
    """The tree, rays and outputs as unowned views (array_views.py)."""
    return unowned_tree(tree), unowned_rays(rays_in), unowned_outputs(out)


@njit(cache=True, inline="always")
def unowned_rays(rays_in):
    """PacketRays as unowned views (array_views.py)."""
    return PacketRays(unowned(rays_in.origins), unowned(rays_in.directions), unowned(rays_in.tmin),
                      unowned(rays_in.tmax), unowned(rays_in.order))


@njit(cache=True, inline="always")
def unowned_outputs(out):
    """PacketOutputs as unowned views (array_views.py)."""
    return PacketOutputs(unowned(out.t), unowned(out.prim), unowned(out.u), unowned(out.v), unowned(out.single))


@njit(cache=True, inline="always")
def new_packet_work():
    """(PacketScratch, PacketStack, owners): one packet's working set as unowned views, whose reference
    counts are no-ops (array_views.py), and the arrays that own them, which the caller keeps alive
    (array_views.keep_alive) while it traces."""
    owned = (np.zeros(ROWS * L), np.zeros((L, 3)), np.zeros((L, 3), np.int64), np.empty(L, np.int32), np.empty(L),
             np.empty(L), np.zeros(ROWS32 * L, np.float32), np.empty(STACK_SIZE, np.int32),
             np.empty(STACK_SIZE, np.int64), np.empty(STACK_SIZE * 2 * L, np.float32), np.zeros(LANE_BITS, np.int64),
             np.zeros(LEAF_CHUNK, np.uint8))
    sc = PacketScratch(unowned(owned[0]), unowned(owned[1]), unowned(owned[2]), unowned(owned[3]),
                       unowned(owned[4]), unowned(owned[5]), unowned(owned[6]), unowned(owned[10]), unowned(owned[11]))
    stack = PacketStack(unowned(owned[7]), unowned(owned[8]), unowned(owned[9]))
    return sc, stack, owned


@njit(cache=True)
def trace_packet(tree, rays_in, lanes, work, out, box_fits, any_hit):
    """_trace_packet compiled as a function of its own, for the sampling kernel's sample packets
    (sample_packets.py), so that kernel does not carry a second inlined copy of the packet traversal. The
    arrays are taken as unowned views again at entry: the caller's views are not known to be unowned
    in here, and every view made inside would count references, at twice the packet's time
    (docs/choices.md#ao-packets-compiled-only-for-batches). any_hit must be a bool value, never a literal,
    or this compiles twice."""
    tree, rays_in, out = _unowned_arguments(tree, rays_in, out)
    _trace_packet(tree, rays_in, unowned(lanes), unowned_packet_work(work), out, box_fits, any_hit)


@njit(cache=True, inline="always")
def unowned_packet_work(work):
    """new_packet_work's (PacketScratch, PacketStack) as unowned views (array_views.py)."""
    sc, stack = work
    sc = PacketScratch(unowned(sc.rays), unowned(sc.lane_o), unowned(sc.axes), unowned(sc.prims), unowned(sc.us),
                       unowned(sc.vs), unowned(sc.lanes32), unowned(sc.lane_bits), unowned(sc.flags))
    return sc, PacketStack(unowned(stack.node), unowned(stack.bits), unowned(stack.t))


@njit(cache=True, inline="always")
def _trace_packet(tree, rays_in, lanes, work, out, box_fits, any_hit):
    """One packet: the rays `lanes` (L indices into rays_in, -1 for none) through the tree with `work`
    = (PacketScratch, PacketStack) of new_packet_work, their hits written to `out`; rays that cannot
    join, and every ray of a packet that meets an unbuilt node, get out.single[ray] = 1. box_fits:
    box_fits_float32 of the tree's root box."""
    sc, stack = work
    bits, signs, mode = setup_packet(tree.bounds, rays_in, lanes, sc, out, box_fits, any_hit)
    if bits == 0:
        return
    if _traverse(tree, sc, mode, signs, bits, stack, any_hit):
        leave_to_single_rays(lanes, bits, out.single)
    else:
        _write(lanes, bits, sc, out)


@njit(cache=True, inline="always")
def box_fits_float32(box):
    """Whether the root box lies inside the range float32 lanes bound (packet_setup.OUTSIDE_FLOAT32). It
    starts from a comparison: a literal True could type the result Literal[bool] and compile trace_packet
    twice."""
    fits = abs(box[0]) < OUTSIDE_FLOAT32
    for k in range(1, 6):
        fits &= abs(box[k]) < OUTSIDE_FLOAT32
    return fits


@njit(cache=True, inline="always")
def _traverse(tree, sc, mode, signs, bits, stack, any_hit):
    """Walk the tree with the packet (module docstring); True if it met an unbuilt node (lazy tree).
    With `any_hit` a lane that found a hit leaves the active lanes and every stacked entry (`done`)."""
    axis, split, child, count, leaf_prims = tree.axis, tree.split, tree.child, tree.count, tree.leaf_prims
    leaf_tris, base = tree.leaf_triangles, tree.base
    lanes32, stack_node, stack_bits, stack_t = sc.lanes32, stack.node, stack.bits, stack.t
    t0, t1 = S.load(lanes32, T0 * L), S.load(lanes32, T1 * L)
    node, m, sp, done = 0, bits, 0, 0
    while True:
        a = axis[at(node)]
        if a < LEAF:
            if (signs >> a) & MIXED:
                node, m, t0, t1, sp = _mixed_node_step(lanes32, a, split[at(node)], child[at(node)],
                                                       sc.lane_bits[at(a)], m, t0, t1, stack, sp)
                continue
            node, m, t0, t1, sp = _node_step(lanes32, a, split[at(node)], child[at(node)], signs, m, t0, t1,
                                             stack, sp)
            continue
        if a != LEAF:
            return True
        first = child[at(node)]
        found = leaf_test((leaf_tris, tree.leaf_boxes, tree.triangles), leaf_prims, base + first,
                          base + first + count[at(node)], first, m, sc, mode, any_hit)
        if any_hit:
            done |= found
        node, m, t0, t1, sp = _pop(sc.rays, stack_node, stack_bits, stack_t, sp, done)
        if node < 0:
            return False


@njit(cache=True, inline="always")
def _node_step(lanes32, a, pos, left, signs, m, t0, t1, stack, sp):
    """One inner node for the active lanes m: (next node, its lanes, their t0 and t1, stack size).
    A lane's part of the first child is [t0, min(t1, hi)], of the second [max(t0, lo), t1], with
    [lo, hi] the widened plane distance (module docstring); lanes entering both push the second."""
    lo, hi = plane_bounds(lanes32, a, pos)
    in_first = m & S.mask_bits(S.le(t0, hi))
    in_second = m & S.mask_bits(S.le(lo, t1))
    first, second = (left, left + 1) if (signs >> a) & 1 else (left + 1, left)
    if in_first == 0:
        return second, in_second, S.vmax(t0, lo), t1, sp
    if in_second != 0:
        _push(stack, sp, second, in_second, S.vmax(t0, lo), t1)
        sp += 1
    return first, in_first, t0, S.vmin(t1, hi), sp


@njit(cache=True, inline="always")
def _mixed_node_step(lanes32, a, pos, left, up, m, t0, t1, stack, sp):
    """_node_step for an any-hit packet whose lanes have both signs on axis a (`up`: lanes with d[a] > 0):
    each lane's parts of the two children follow its own sign (the near part [t0, min(t1, hi)] is the
    left child's where d[a] > 0, the right child's otherwise). The children are taken in the order of
    the lowest lane entering both (with one origin, all such lanes start on its side of the plane); the
    order only decides which hit an any-hit lane meets first, never whether it meets one."""
    lo, hi = plane_bounds(lanes32, a, pos)
    near = m & S.mask_bits(S.le(t0, hi))
    far = m & S.mask_bits(S.le(lo, t1))
    in_left, in_right = (near & up) | (far & ~up), (far & up) | (near & ~up)
    up_mask = S.mask_from_bits(up)
    near_t1, far_t0 = S.vmin(t1, hi), S.vmax(t0, lo)
    left_t0, left_t1 = S.select(up_mask, t0, far_t0), S.select(up_mask, near_t1, t1)
    right_t0, right_t1 = S.select(up_mask, far_t0, t0), S.select(up_mask, t1, near_t1)
    if in_left == 0:
        return left + 1, in_right, right_t0, right_t1, sp
    if in_right == 0:
        return left, in_left, left_t0, left_t1, sp
    both = in_left & in_right
    if (up >> S.count_trailing_zeros(both if both != 0 else in_left)) & 1:
        _push(stack, sp, left + 1, in_right, right_t0, right_t1)
        return left, in_left, left_t0, left_t1, sp + 1
    _push(stack, sp, left, in_left, left_t0, left_t1)
    return left + 1, in_right, right_t0, right_t1, sp + 1


@njit(cache=True, inline="always")
def _push(stack, sp, node, bits, t0, t1):
    stack.node[at(sp)], stack.bits[at(sp)] = node, bits
    S.store(stack.t, sp * 2 * L, t0)
    S.store(stack.t, sp * 2 * L + L, t1)


@njit(cache=True, inline="always")
def _pop(rays, stack_node, stack_bits, stack_t, sp, done):
    """The next stacked node with lanes that may still find a closer hit there: (node, lanes, t0, t1,
    sp), node -1 when none. A lane skips an entry whose start (a lower bound) lies after its best hit,
    and every entry once it is `done`."""
    best = S.load(rays, BEST * L)
    while sp > 0:
        sp -= 1
        t0 = S.load(stack_t, sp * 2 * L)
        m = stack_bits[at(sp)] & ~done & ~S.mask_bits(S.lt(best, S.to_f64(t0)))
        if m != 0:
            return stack_node[at(sp)], m, t0, S.load(stack_t, sp * 2 * L + L), sp
    return -1, 0, S.splat_f32(0.0), S.splat_f32(0.0), 0


@njit(cache=True, inline="always")
def _write(lanes, bits, sc, out):
    for l in range(L):
        if (bits >> l) & 1:
            r = lanes[l]
            if sc.prims[l] >= 0:
                out.t[r], out.prim[r], out.u[r], out.v[r] = sc.rays[BEST * L + l], sc.prims[l], sc.us[l], sc.vs[l]
            else:
                out.t[r], out.prim[r], out.u[r], out.v[r] = np.inf, -1, 0.0, 0.0
