"""Closest hits of coherent rays (camera rays) traced in packets of simd.LANES through a flat KdTree.

Wald et al. 2001 ("Interactive Rendering with Coherent Ray Tracing", §3) trace neighbouring primary rays
together: the packet walks the kd-tree once, each lane keeping its own [t0, t1]; at an inner node it
goes to the near child only, or the far child only, when every active lane agrees, and otherwise visits
both, pushing the far child with the lanes that enter it and their intervals. A leaf's triangles are
tested against all its active lanes. That needs one sign per axis for the whole packet (it fixes which
child is near), so a lane whose direction has another sign on some axis, or a zero component, leaves
the packet and is traced by the single-ray kernel (traversal.trace_rays) afterwards.

Results equal traversal.trace_ray's, hit for hit, because each lane makes the single-ray traversal's
decisions with its arithmetic:
- node steps are float64 lanes computing (split - o) / d and the 1e-9 relative widening exactly as
  traversal._descend does (no contraction into FMAs), with the same near-only / far-only / both cases;
  with strict direction signs no lane lies in a plane, so a lane's exit bound is its t1;
- a lane finishes once its best hit lies within the leaf interval it just left, and stacked entries it
  cannot improve on are dropped, as traversal._pop does;
- leaves: each triangle is tested against the active lanes with the watertight test (Woop, Benthin and
  Wald 2013, "Watertight Ray/Triangle Intersection") in float64 lanes, with triangle_test._hit's
  operations in its order (edge values, det, t, the t rounding bound), so each lane gets the
  single-ray t bit for bit; lanes with an exactly zero edge value, where the tie rule decides, take the
  single-ray test itself (triangle_test.intersect_leaf_triangle), as do all lanes of a packet whose
  lanes shear along different axes. Triangles are taken in leaf order, as trace_ray does.
A lazy tree is handed to queries.intersect whole (an unbuilt node would stop the packet).
"""
import functools
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from . import simd as S
from .array_views import at, rows, unowned
from ..inputs import as_ray_limits, as_rays, hit_distances_as_float32
from .kdtree import KdTree
from .layout import LEAF, UNBUILT_COUNT
from .queries import Hits, intersect
from ..jit.threads import thread_count
from .traversal import (STACK_SIZE, WIDEN, block_range, clip_to_box, interleaved_blocks, node_word, trace_rays,
                        unowned_tree)
from .triangle_test import GAMMA, intersect_leaf_triangle, ray_shear

L = S.LANES
G2, G3, G5 = (n * GAMMA / (1.0 - n * GAMMA) for n in (2, 3, 5))  # triangle_test._gamma(n), the same doubles
TILE_SHAPE = (4, 2)  # a packet: 4 x 2 neighbouring pixels (width x height)
PACKETS_PER_TASK = 8  # packets a parallel task traces with one stack

# rows of the per-packet scratch `rays` (row r holds lane l at r * L + l)
O, INV, T0, T1, TMIN, BEST, SX, SY, SZ = 0, 3, 6, 7, 8, 9, 10, 11, 12
ROWS = 13


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
    """One packet's working set: `rays` (ROWS * L, the rows named above), lane origins `lane_o` (L, 3),
    shear axes `axes` (L, 3), and the best hit's prim, u, v per lane."""

    rays: np.ndarray
    lane_o: np.ndarray
    axes: np.ndarray
    prims: np.ndarray
    us: np.ndarray
    vs: np.ndarray


class PacketStack(NamedTuple):
    """The traversal stack: node, lane bits and per-lane [t0, t1] (2 L floats) of each entry."""

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
    o, d = as_rays(origins, directions)
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
        trace_packets(tree.arrays, PacketRays(o, d, lo, hi, order), PacketOutputs(t, prim, u, v, single))
        rest = np.flatnonzero(single)
        if len(rest):
            out = [np.empty(len(rest)), np.empty(len(rest), np.int32), np.empty(len(rest)), np.empty(len(rest))]
            trace_rays(tree.arrays, o[rest], d[rest], lo[rest], hi[rest], False, *out)
            t[rest], prim[rest], u[rest], v[rest] = out
    if stats is not None:
        stats.update(packets=len(order) // L, single_rays=len(rest))
    return Hits(hit_distances_as_float32(t, prim, lo, hi), prim, u.astype(np.float32), v.astype(np.float32))


@njit(cache=True, parallel=True)
def trace_packets(tree, rays_in, out):
    """Trace the packets of rays_in.order (PacketRays) in parallel into `out` (PacketOutputs); rays that
    cannot join their packet are left for the single-ray kernel with out.single[ray] = 1."""
    n = rays_in.order.shape[0] // L
    iterations, per_band = interleaved_blocks(n, PACKETS_PER_TASK)
    for i in prange(iterations):
        start, stop = block_range(i, per_band, n, PACKETS_PER_TASK)
        _trace_packet_block(tree, rays_in, out, start, stop)


@njit(cache=True)
def _trace_packet_block(tree, rays_in, out, start, stop):
    """Packets start..stop-1 with one set of scratch arrays and the tree as unowned views (see
    traversal._trace_block)."""
    views = unowned_tree(tree)
    owned = (np.zeros(ROWS * L), np.zeros((L, 3)), np.zeros((L, 3), np.int64), np.empty(L, np.int32), np.empty(L),
             np.empty(L), np.empty(STACK_SIZE, np.int32), np.empty(STACK_SIZE, np.int64), np.empty(STACK_SIZE * 2 * L))
    # unowned views of everything the per-packet code takes: their reference counts are no-ops (array_views)
    sc = PacketScratch(unowned(owned[0]), unowned(owned[1]), unowned(owned[2]), unowned(owned[3]),
                       unowned(owned[4]), unowned(owned[5]))
    stack = PacketStack(unowned(owned[6]), unowned(owned[7]), unowned(owned[8]))
    rays_in = PacketRays(unowned(rays_in.origins), unowned(rays_in.directions), unowned(rays_in.tmin),
                         unowned(rays_in.tmax), unowned(rays_in.order))
    out = PacketOutputs(unowned(out.t), unowned(out.prim), unowned(out.u), unowned(out.v), unowned(out.single))
    for p in range(start, stop):
        lanes = rows(rays_in.order, p * L, p * L + L)
        bits, signs, same_axes = _setup(views.bounds, rays_in, lanes, sc, out)
        if bits == 0:
            continue
        if _traverse(views, sc, same_axes, signs, bits, stack):
            _leave_to_single_rays(lanes, bits, out.single)
        else:
            _write(lanes, bits, sc, out)


@njit(cache=True, inline="always")
def _packet_signs(directions, lanes):
    """Bit k set when most of the lanes' directions are positive on axis k (the packet's signs)."""
    signs = 0
    for k in range(3):
        balance = 0
        for l in range(L):
            r = lanes[l]
            if r >= 0:
                balance += 1 if directions[r, k] > 0.0 else (-1 if directions[r, k] < 0.0 else 0)
        signs |= (1 if balance >= 0 else 0) << k
    return signs


@njit(cache=True, inline="always")
def _agrees(d, signs):
    """Whether direction d is strictly positive on the packet's positive axes, negative on the others."""
    ok = True
    for k in range(3):
        ok &= d[k] > 0.0 if (signs >> k) & 1 else d[k] < 0.0
    return ok


@njit(cache=True, inline="always")
def _setup(root_box, rays_in, lanes, sc, out):
    """Fill the scratch for one packet: (bits of the lanes traced, the packet's signs, whether all of
    them shear along the same axes). Lanes that disagree go to single rays; lanes missing the root box
    are written as misses here, as trace_ray returns them."""
    origins, directions, tmin, tmax = rays_in.origins, rays_in.directions, rays_in.tmin, rays_in.tmax
    rays, lane_o, axes, prims = sc.rays, sc.lane_o, sc.axes, sc.prims
    signs = _packet_signs(directions, lanes)
    rays[:] = 0.0
    bits = 0
    for l in range(L):
        r = lanes[l]
        if r < 0:
            continue
        o, d = rows(origins, r, r + 1)[0], rows(directions, r, r + 1)[0]
        if not _agrees(d, signs):
            out.single[r] = 1
            continue
        inv = (1.0 / d[0], 1.0 / d[1], 1.0 / d[2])  # non-zero: the packet's lanes have strict signs
        t0, t1 = clip_to_box(root_box, o, d, inv, tmin[r], tmax[r])
        if t0 > t1:
            out.t[r], out.prim[r], out.u[r], out.v[r] = np.inf, -1, 0.0, 0.0
            continue
        _fill_lane(rays, lane_o, axes, l, o, d, inv, t0, t1, tmin[r], tmax[r])
        prims[l] = -1
        bits |= 1 << l
    return bits, signs, _same_axes(axes, bits)


@njit(cache=True, inline="always")
def _fill_lane(rays, lane_o, axes, l, o, d, inv, t0, t1, tmin, tmax):
    for k in range(3):
        rays[(O + k) * L + l] = o[k]
        rays[(INV + k) * L + l] = inv[k]
        lane_o[l, k] = o[k]
    kx, ky, kz, sx, sy, sz = ray_shear(d)
    axes[l, 0], axes[l, 1], axes[l, 2] = kx, ky, kz
    rays[T0 * L + l], rays[T1 * L + l], rays[TMIN * L + l], rays[BEST * L + l] = t0, t1, tmin, tmax
    rays[SX * L + l], rays[SY * L + l], rays[SZ * L + l] = sx, sy, sz


@njit(cache=True, inline="always")
def _same_axes(axes, bits):
    if bits == 0:
        return True
    first = S.count_trailing_zeros(bits)
    same = True
    for l in range(L):
        if (bits >> l) & 1:
            same &= axes[l, 0] == axes[first, 0] and axes[l, 2] == axes[first, 2]
    return same


@njit(cache=True, inline="always")
def _traverse(tree, sc, same_axes, signs, bits, stack):
    """Walk the tree with the packet (module docstring); True if it met an unbuilt node (lazy tree)."""
    nodes, node_split, leaf_prims = tree.nodes, tree.node_split, tree.leaf_prims
    leaf_tris, base = tree.leaf_triangles, tree.base
    rays, stack_node, stack_bits, stack_t = sc.rays, stack.node, stack.bits, stack.t
    t0, t1 = S.load(rays, T0 * L), S.load(rays, T1 * L)
    node, m, sp, done, found = 0, bits, 0, 0, 0
    while True:
        a, low = node_word(nodes, node)
        if a < LEAF:
            node, m, t0, t1, sp = _node_step(rays, a, node_split[at(node), 0], low, signs, m, t0, t1,
                                             stack_node, stack_bits, stack_t, sp)
            continue
        if low == UNBUILT_COUNT:
            return True
        first = np.int64(nodes[at(node), 0])
        found |= _leaf(leaf_tris, leaf_prims, base + first, base + first + low, first, m, sc, same_axes)
        done |= S.mask_bits(S.le(S.load(rays, BEST * L), t1)) & found & m  # as trace_ray: best_t <= t_exit
        node, m, t0, t1, sp, done = _pop(rays, found, done, stack_node, stack_bits, stack_t, sp)
        if node < 0:
            return False


@njit(cache=True, inline="always")
def _node_step(rays, a, pos, left, signs, m, t0, t1, stack_node, stack_bits, stack_t, sp):
    """traversal._descend for every active lane: (next node, its lanes, their t0 and t1, stack size).
    The packet's sign on the axis fixes the first child; lanes entering both push the second."""
    oa, inv_a, p = S.load(rays, (O + a) * L), S.load(rays, (INV + a) * L), S.splat_f64(pos)
    ts = S.mul(S.sub(p, oa), inv_a)
    slack = S.mul(S.splat_f64(WIDEN), S.vabs(ts))
    near_only = S.mask_or(S.le(ts, S.splat_f64(0.0)), S.gt(ts, S.add(t1, slack)))
    far_only = S.mask_andnot(S.lt(ts, S.sub(t0, slack)), near_only)
    both = S.mask_not(S.mask_or(near_only, far_only))
    positive = (signs >> a) & 1
    near_first = S.mask_bits(S.lt(oa, p) if positive else S.gt(oa, p))
    near_or_both, far_or_both = S.mask_bits(S.mask_or(near_only, both)), S.mask_bits(S.mask_or(far_only, both))
    in_first = m & ((near_first & near_or_both) | (~near_first & far_or_both))
    in_second = m & ((near_first & far_or_both) | (~near_first & near_or_both))
    first, second = (left, left + 1) if positive else (left + 1, left)
    ts = S.vmin(S.vmax(ts, t0), t1)  # where both: the split, clamped into [t0, t1] as _descend does
    if in_first == 0:
        return second, in_second, S.select(both, ts, t0), t1, sp
    if in_second != 0:
        stack_node[at(sp)], stack_bits[at(sp)] = second, in_second
        S.store(stack_t, sp * 2 * L, S.select(both, ts, t0))
        S.store(stack_t, sp * 2 * L + L, t1)
        sp += 1
    return first, in_first, t0, S.select(both, ts, t1), sp


@njit(cache=True, inline="always")
def _pop(rays, found, done, stack_node, stack_bits, stack_t, sp):
    """The next stacked node with lanes still searching: (node, lanes, t0, t1, sp, done), node -1 when
    none. As traversal._pop, a lane whose hit lies before an entry's start (less the slack) skips it;
    without in-plane lanes that means it is done."""
    best = S.load(rays, BEST * L)
    while sp > 0:
        sp -= 1
        m = stack_bits[at(sp)] & ~done
        if m == 0:
            continue
        t0, t1 = S.load(stack_t, sp * 2 * L), S.load(stack_t, sp * 2 * L + L)
        skip = found & m & S.mask_bits(S.lt(best, S.sub(t0, S.mul(S.splat_f64(WIDEN), S.vabs(t0)))))
        done |= skip
        m &= ~skip
        if m != 0:
            return stack_node[at(sp)], m, t0, t1, sp, done
    return -1, 0, best, best, 0, done


@njit(cache=True, inline="always")
def _leaf(leaf_tris, leaf_prims, column, end, first, m, sc, same_axes):
    """Test the leaf's triangles (columns column..end-1 of the leaf-ordered copy, prims from
    leaf_prims[first]) against the active lanes m, in leaf order; bits of lanes whose best hit changed.
    Lanes sharing shear axes are tested in vectors (_lanes_test); otherwise lane by lane."""
    found = 0
    for k in range(end - column):
        j, prim = column + k, leaf_prims[at(first + k)]
        if same_axes:
            found |= _lanes_test(leaf_tris, j, prim, m, sc)
            continue
        candidates = m
        while candidates != 0:
            l = S.count_trailing_zeros(candidates)
            candidates &= candidates - 1
            if _test_lane(leaf_tris, j, prim, l, sc):
                found |= 1 << l
    return found


@njit(cache=True, inline="always")
def _lanes_test(leaf_tris, column, prim, m, sc):
    """triangle_test._hit for the lanes m against one triangle, in float64 lanes with its operations in
    its order (the sign flip by det's sign is exact and left out where it cannot change a bit), so each
    lane gets the single-ray test's t. Lanes with an exactly zero edge value, where the tie rule
    decides, take the single-ray test itself. Returns the bits of lanes whose best hit changed."""
    rays, axes, prims, us, vs = sc.rays, sc.axes, sc.prims, sc.us, sc.vs
    l0 = S.count_trailing_zeros(m)
    kx, ky, kz = axes[at(l0), 0], axes[at(l0), 1], axes[at(l0), 2]
    ax, ay, az, bx, by, bz, cx, cy, cz = _sheared_triangle(leaf_tris, column, rays, kx, ky, kz)
    u = S.sub(S.mul(cx, by), S.mul(cy, bx))
    v = S.sub(S.mul(ax, cy), S.mul(ay, cx))
    w = S.sub(S.mul(bx, ay), S.mul(by, ax))
    zero = S.splat_f64(0.0)
    negative = S.mask_or(S.mask_or(S.lt(u, zero), S.lt(v, zero)), S.lt(w, zero))
    positive = S.mask_or(S.mask_or(S.gt(u, zero), S.gt(v, zero)), S.gt(w, zero))
    candidates = m & ~S.mask_bits(S.mask_and(negative, positive))
    if candidates == 0:
        return 0
    ties = candidates & S.mask_bits(S.mask_or(S.mask_or(S.eq(u, zero), S.eq(v, zero)), S.eq(w, zero)))
    found = 0
    while ties != 0:
        l = S.count_trailing_zeros(ties)
        ties &= ties - 1
        if _test_lane(leaf_tris, column, prim, l, sc):
            found |= 1 << l
    candidates &= ~S.mask_bits(S.mask_or(S.mask_or(S.eq(u, zero), S.eq(v, zero)), S.eq(w, zero)))
    if candidates == 0:
        return found
    det = S.add(S.add(u, v), w)
    flip = S.select(S.gt(det, zero), S.splat_f64(1.0), S.splat_f64(-1.0))
    u, v, w, det = S.mul(flip, u), S.mul(flip, v), S.mul(flip, w), S.mul(flip, det)
    sz = S.load(rays, SZ * L)
    t = S.div(S.mul(S.add(S.add(S.mul(u, az), S.mul(v, bz)), S.mul(w, cz)), sz), det)
    best = S.load(rays, BEST * L)
    inside = S.mask_and(S.lt(S.load(rays, TMIN * L), t), S.lt(t, best))
    hits = candidates & S.mask_bits(S.mask_and(inside, S.gt(det, zero)))
    if hits == 0:
        return found
    bound = _t_rounding((ax, ay, az), (bx, by, bz), (cx, cy, cz), (S.load(rays, SX * L), S.load(rays, SY * L), sz),
                        (u, v, w), det)
    hits &= S.mask_bits(S.gt(t, bound))
    if hits == 0:
        return found
    S.store(rays, BEST * L, S.select(S.mask_from_bits(hits), t, best))
    hu, hv = S.div(v, det), S.div(w, det)
    found |= hits
    while hits != 0:
        l = S.count_trailing_zeros(hits)
        hits &= hits - 1
        prims[at(l)], us[at(l)], vs[at(l)] = prim, S.lane(hu, l), S.lane(hv, l)
    return found


@njit(cache=True, inline="always")
def _sheared_triangle(leaf_tris, j, rays, kx, ky, kz):
    """The three vertices of column j sheared along each lane's ray (triangle_test._sheared in lanes)."""
    ox, oy, oz = S.load(rays, (O + kx) * L), S.load(rays, (O + ky) * L), S.load(rays, (O + kz) * L)
    sx, sy = S.load(rays, SX * L), S.load(rays, SY * L)
    a = _sheared(leaf_tris[at(kx), at(j)], leaf_tris[at(ky), at(j)], leaf_tris[at(kz), at(j)], ox, oy, oz, sx, sy)
    b = _sheared(leaf_tris[at(3 + kx), at(j)], leaf_tris[at(3 + ky), at(j)], leaf_tris[at(3 + kz), at(j)], ox, oy,
                 oz, sx, sy)
    c = _sheared(leaf_tris[at(6 + kx), at(j)], leaf_tris[at(6 + ky), at(j)], leaf_tris[at(6 + kz), at(j)], ox, oy,
                 oz, sx, sy)
    return a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]


@njit(cache=True, inline="always")
def _max3_abs(a, b, c):
    return S.vmax(S.vmax(S.vabs(a), S.vabs(b)), S.vabs(c))


@njit(cache=True, inline="always")
def _t_rounding(a, b, c, shear, edges, det):
    """triangle_test._t_rounding in lanes, the same operations in the same order."""
    (ax, ay, az), (bx, by, bz), (cx, cy, cz) = a, b, c
    sx, sy, sz = shear
    u, v, w = edges
    shear_z = _max3_abs(az, bz, cz)
    max_z = S.mul(shear_z, S.vabs(sz))
    max_x, max_y = _max3_abs(ax, bx, cx), _max3_abs(ay, by, cy)
    delta_z = S.mul(S.splat_f64(G3), max_z)
    delta_x = S.mul(S.splat_f64(G5), S.add(max_x, S.mul(S.vabs(sx), shear_z)))
    delta_y = S.mul(S.splat_f64(G5), S.add(max_y, S.mul(S.vabs(sy), shear_z)))
    delta_e = S.mul(S.splat_f64(2.0), S.add(S.add(S.mul(S.mul(S.splat_f64(G2), max_x), max_y),
                                                  S.mul(delta_y, max_x)), S.mul(delta_x, max_y)))
    max_e = S.vmax(S.vmax(u, v), w)
    total = S.add(S.add(S.mul(S.mul(S.splat_f64(G3), max_e), max_z), S.mul(delta_e, max_z)), S.mul(delta_z, max_e))
    return S.div(S.mul(S.splat_f64(3.0), total), det)


@njit(cache=True, inline="always")
def _test_lane(leaf_tris, column, prim, l, sc):
    """The single-ray test of lane l against one leaf triangle; keeps the hit if closer (as trace_ray)."""
    rays, lane_o, axes, prims, us, vs = sc.rays, sc.lane_o, sc.axes, sc.prims, sc.us, sc.vs
    t, u, v = intersect_leaf_triangle(leaf_tris, column, rows(lane_o, l, l + 1)[0], axes[at(l), 0],
                                      axes[at(l), 1], axes[at(l), 2], rays[at(SX * L + l)], rays[at(SY * L + l)],
                                      rays[at(SZ * L + l)])
    if rays[at(TMIN * L + l)] < t < rays[at(BEST * L + l)]:
        rays[at(BEST * L + l)], prims[at(l)], us[at(l)], vs[at(l)] = t, prim, u, v
        return True
    return False


@njit(cache=True, inline="always")
def _sheared(x, y, z, ox, oy, oz, sx, sy):
    """triangle_test._sheared in lanes: (x - ox) - sx (z - oz), (y - oy) - sy (z - oz), z - oz."""
    z = S.sub(S.splat_f64(z), oz)
    return S.sub(S.sub(S.splat_f64(x), ox), S.mul(sx, z)), S.sub(S.sub(S.splat_f64(y), oy), S.mul(sy, z)), z


@njit(cache=True, inline="always")
def _leave_to_single_rays(lanes, bits, single):
    for l in range(L):
        if (bits >> l) & 1:
            single[lanes[l]] = 1


@njit(cache=True, inline="always")
def _write(lanes, bits, sc, out):
    for l in range(L):
        if (bits >> l) & 1:
            r = lanes[l]
            if sc.prims[l] >= 0:
                out.t[r], out.prim[r], out.u[r], out.v[r] = sc.rays[BEST * L + l], sc.prims[l], sc.us[l], sc.vs[l]
            else:
                out.t[r], out.prim[r], out.u[r], out.v[r] = np.inf, -1, 0.0, 0.0
