"""A packet's lanes against axis planes and boxes in float32, conservatively: the node step's plane
distances (packet_traversal.py) and the test of a group of leaf triangles' box (packet_leaf.py).

Each lane keeps float32 rows (the scratch `lanes32`, filled by packet_setup._fill_rows32): o' = fl32(o),
i' = fl32(1 / d), c = SCALE |i'| and e = c (|o'| + TINY) + TINY per axis, and its starting interval
rounded outward. For any float32 plane position p, [(p - o') i' - err, (p - o') i' + err] with
err = c |p| + e holds the exact distance (p - o) / d (docs/choices.md#float32-node-arithmetic), so a
box's slab entry and exit bound the exact ones, and a lane whose widened entry lies after its widened
exit cannot meet anything inside the box.
"""
from numba import njit

from . import simd as S
from .array_views import at

L = S.LANES
SCALE = 2.0 ** -21  # c = SCALE |i'|
TINY = 2.0 ** -126

# rows of the float32 scratch `lanes32`: o' (3 rows), i' (3), c (3), e (3), and the root interval
O32, INV32, C32, E32, T0, T1 = 0, 3, 6, 9, 12, 13
ROWS32 = 14


@njit(cache=True, inline="always")
def rounded_up(t):
    """float64 lanes t >= 0 as float32 lanes no smaller: rounding to nearest errs by 2^-24 relative, which
    the widening by 2^-22 and a tiny step cover."""
    return S.to_f32(S.add(S.mul(t, S.splat_f64(1.0 + 2.0 ** -22)), S.splat_f64(2.0 * TINY)))


@njit(cache=True, inline="always")
def plane_bounds(lanes32, a, pos):
    """Each lane's widened distance [lo, hi] to the plane at pos on axis a (module docstring)."""
    ts = S.mul(S.sub(S.splat_f32(pos), S.load(lanes32, (O32 + a) * L)), S.load(lanes32, (INV32 + a) * L))
    err = S.fma(S.load(lanes32, (C32 + a) * L), S.splat_f32(abs(pos)), S.load(lanes32, (E32 + a) * L))
    return S.sub(ts, err), S.add(ts, err)


@njit(cache=True, inline="always")
def lanes_meeting_box(lanes32, boxes, g, m, best):
    """The lanes of m whose ray may meet box g of `boxes` (G, 6) float32 between its starting interval's
    start and `best` (float64 lanes: the best hit's t so far), all bounds widened: a lane left out meets
    no point of the box in that range. Lanes' directions have no zero component (packet_setup)."""
    near = S.load(lanes32, T0 * L)
    far = rounded_up(best)
    for k in range(3):
        lo_a, hi_a = plane_bounds(lanes32, k, boxes[at(g), at(k)])
        lo_b, hi_b = plane_bounds(lanes32, k, boxes[at(g), at(k + 3)])
        near = S.vmax(near, S.vmin(lo_a, lo_b))
        far = S.vmin(far, S.vmax(hi_a, hi_b))
    return m & S.mask_bits(S.le(near, far))
