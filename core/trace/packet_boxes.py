"""A packet's lanes against axis planes and boxes in float32, conservatively: the node step's plane
distances (packet_traversal.py) and the test of a group of leaf triangles' box (packet_leaf.py).

Each lane keeps float32 rows (the scratch `lanes32`, filled by packet_setup._fill_rows32): o' = fl32(o),
i' = fl32(1 / d), c = SCALE |i'| and e = c (|o'| + TINY) + TINY per axis, and its starting interval
rounded outward. For any float32 plane position p, [(p - o') i' - err, (p - o') i' + err] with
err = c |p| + e holds the exact distance (p - o) / d (docs/choices.md#float32-node-arithmetic), so a
box's slab entry and exit bound the exact ones, and a lane whose widened entry lies after its widened
exit has a line that misses the box.
"""
import numpy as np
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
def rounded_down(t):
    """float64 lanes t >= 0 as float32 lanes no larger (0 below a tiny t), as rounded_up mirrored."""
    return S.select(S.gt(t, S.splat_f64(2.0 * TINY)), S.to_f32(S.mul(t, S.splat_f64(1.0 - 2.0 ** -22))),
                    S.splat_f32(0.0))


@njit(cache=True, inline="always")
def plane_bounds(lanes32, a, pos):
    """Each lane's widened distance [lo, hi] to the plane at pos on axis a (module docstring)."""
    ts = S.mul(S.sub(S.splat_f32(pos), S.load(lanes32, (O32 + a) * L)), S.load(lanes32, (INV32 + a) * L))
    err = S.fma(S.load(lanes32, (C32 + a) * L), S.splat_f32(abs(pos)), S.load(lanes32, (E32 + a) * L))
    return S.sub(ts, err), S.add(ts, err)


@njit(cache=True, inline="always")
def lanes_meeting_box(lanes32, boxes, g, m, kz, limits):
    """The lanes of m whose triangles' test may accept a triangle inside box g of `boxes` (G, 6) float32;
    kz: the lanes' shared depth axis (triangle_test.ray_shear), or -1 when it differs by lane; limits:
    (tmin, best) float64 lanes, the range a hit's computed t must fall in.
    Two conditions, each kept by every such lane:
    - the ray's line meets the box: a hit's exact point lies in the box, at its exact t, within each
      slab's widened interval (module docstring);
    - with kz given, the kz slab's widened interval meets [tmin, best]: the test's computed t is a convex
      combination of the vertices' kz depths over d[kz] (Woop et al.), so it lies in that slab up to a
      few float64 roundings. The exact t may differ from it by far more on a sliver seen edge on, so the
      range is not tested against the other slabs."""
    entry, leave = S.splat_f32(-np.inf), S.splat_f32(np.inf)
    depth_entry, depth_leave = entry, leave
    for k in range(3):
        lo_a, hi_a = plane_bounds(lanes32, k, boxes[at(g), at(k)])
        lo_b, hi_b = plane_bounds(lanes32, k, boxes[at(g), at(k + 3)])
        slab_entry, slab_leave = S.vmin(lo_a, lo_b), S.vmax(hi_a, hi_b)
        entry, leave = S.vmax(entry, slab_entry), S.vmin(leave, slab_leave)
        if k == kz:
            depth_entry, depth_leave = slab_entry, slab_leave
    tmin, best = limits
    inside = S.mask_and(S.le(entry, leave), S.mask_and(S.le(depth_entry, rounded_up(best)),
                                                       S.le(rounded_down(tmin), depth_leave)))
    return m & S.mask_bits(inside)
