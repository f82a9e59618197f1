"""Any-hit queries in packets for runs of consecutive rays that share one origin (ambient-occlusion
rays from one surface point), the rest as single rays.

A run's rays point in every direction, so the packet's lanes differ in sign (packet_traversal's
_mixed_node_step: in an any-hit traversal the visiting order decides which hit is met first, never
whether one is) and in shear axes (packet_leaf's ONE_ORIGIN_BY_LANE test, each lane's t equal to the
single-ray test's). Both traversals visit every cell the ray's segment crosses, and a lane reports a
hit only where triangle_test gives the single ray one in (tmin, tmax), so `occluded` gives the single-ray
kernel's answer for every ray (docs/choices.md#any-hit-packets-for-rays-sharing-an-origin).
"""
import numpy as np
from numba import njit

from . import simd as S
from .packet_traversal import PacketOutputs, PacketRays, trace_packets
from .traversal import trace_rays

L = S.LANES


def occluded_prims(tree_arrays, o, d, lo, hi):
    """(R,) int32: a hit triangle in (lo, hi) for each ray, or -1; packets for runs of rays with one
    origin, single rays for the rest. The caller checks the rays and sets the thread count; the tree
    is eager (every node built)."""
    n = len(o)
    single = np.zeros(n, np.uint8)
    order = origin_runs(o, single)
    order.setflags(write=False)  # as every caller's order: one compiled trace_packets (packet_traversal.py)
    t, prim, u, v = np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n)
    if len(order) == 0:
        trace_rays(tree_arrays, o, d, lo, hi, True, t, prim, u, v)
        return prim
    trace_packets(tree_arrays, PacketRays(o, d, lo, hi, order), PacketOutputs(t, prim, u, v, single), True)
    rest = np.flatnonzero(single.view(np.bool_))
    if len(rest):
        m = len(rest)
        out = [np.empty(m), np.empty(m, np.int32), np.empty(m), np.empty(m)]
        trace_rays(tree_arrays, o[rest], d[rest], lo[rest], hi[rest], True, *out)
        prim[rest] = out[1]
    return prim


@njit(cache=True)
def origin_runs(origins, single):
    """Packets (L ray indices each, -1 filling) of the runs of consecutive rays whose origins are equal,
    a run cut into packets of up to L rays; rays left alone (a run or a run's remainder of one) get
    single[ray] = 1. An empty order when there is no packet."""
    n = origins.shape[0]
    packets = 0
    i = 0
    while i < n:
        j = _run_end(origins, i, n)
        if j - i > 1:
            packets += 1
        else:
            single[i] = 1
        i = j
    order = np.full(packets * L, -1, np.int64)
    if packets == 0:
        return order
    p, i = 0, 0
    while i < n:
        j = _run_end(origins, i, n)
        if j - i > 1:
            for k in range(i, j):
                order[p * L + k - i] = k
            p += 1
        i = j
    return order


@njit(cache=True, inline="always")
def _run_end(origins, i, n):
    """The end of the packet starting at ray i: up to L rays with ray i's origin."""
    j = i + 1
    while j < n and j - i < L and (origins[j, 0] == origins[i, 0] and origins[j, 1] == origins[i, 1]
                                   and origins[j, 2] == origins[i, 2]):
        j += 1
    return j
