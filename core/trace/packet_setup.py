"""A packet's set-up in vector lanes (packet_traversal.py): its rays gathered into LANES-wide rows, the
lanes that can join it, the root box clip, the shear of the leaf test and the node step's float32 rows.

Every quantity repeats the scalar set-up's float64 or float32 arithmetic operation for operation
(traversal.clip_to_box, triangle_test.ray_shear, the node step's constants), only lane-wise, so each
lane gets the same bits (docs/choices.md#camera-ray-packets-set-up-in-lanes). Lanes of a packet share
the shear's axes when they share the dominant axis (their signs are the packet's); otherwise the
scalar ray_shear fills each lane and the leaf test goes lane by lane. Lanes outside the packet (no
ray, another sign, a miss of the root box) hold another lane's values, which no mask lets through.
"""
import numpy as np
from numba import njit

from . import simd as S
from .array_views import at, rows
from .packet_boxes import C32, E32, INV32, O32, SCALE, T0, T1, TINY, rounded_down, rounded_up
from .packet_leaf import BEST, LANE_BY_LANE, O, ONE_ORIGIN, ONE_ORIGIN_BY_LANE, SAME_AXES, SX, SY, SZ, TMIN
from .traversal import WIDEN
from .triangle_test import ray_shear

L = S.LANES
OUTSIDE_FLOAT32 = 2.0 ** 60  # |o|, |d|, |1 / d| or the root box beyond: the lane goes to single rays
MIXED = 8  # signs: bit k + 3 set when an any-hit packet's lanes have both signs on axis k
LANE_BITS = 9  # rows of the scratch `lane_bits`: d > 0 per axis (3), shear axis masks (6: _fill_axis_bits)


@njit(cache=True, inline="always")
def setup_packet(root_box, rays_in, lanes, sc, out, box_fits, any_hit):
    """Fill the scratch for one packet: (bits of the lanes traced, the packet's signs, how they take the
    leaf test: packet_leaf's LANE_BY_LANE, SAME_AXES, ONE_ORIGIN or ONE_ORIGIN_BY_LANE). Lanes that
    cannot join go to single rays (out.single); lanes missing the root box are written as misses, as
    trace_ray returns them. For `any_hit` packets lanes of every sign join (MIXED, below)."""
    valid = 0
    for l in range(L):
        valid |= (1 if lanes[l] >= 0 else 0) << l
    if valid == 0:
        return 0, 0, LANE_BY_LANE
    fill = lanes[S.count_trailing_zeros(valid)]
    o = (_gather(rays_in.origins, lanes, fill, 0), _gather(rays_in.origins, lanes, fill, 1),
         _gather(rays_in.origins, lanes, fill, 2))
    d = (_gather(rays_in.directions, lanes, fill, 0), _gather(rays_in.directions, lanes, fill, 1),
         _gather(rays_in.directions, lanes, fill, 2))
    signs, joins = _signs_and_joins(o, d, valid if box_fits else 0, any_hit)
    leave_to_single_rays(lanes, valid & ~joins, out.single)
    inv = (S.reciprocal(d[0]), S.reciprocal(d[1]), S.reciprocal(d[2]))
    tmin, tmax = _gather_1d(rays_in.tmin, lanes, fill), _gather_1d(rays_in.tmax, lanes, fill)
    t0, t1 = _clip_to_box(root_box, o, inv, tmin, tmax)
    misses = joins & S.mask_bits(S.gt(t0, t1))
    _write_misses(lanes, misses, out)
    bits = joins & ~misses
    if bits == 0:
        return 0, signs, LANE_BY_LANE
    if any_hit:
        signs = _lane_signs(d, bits, sc.lane_bits)
    rays = sc.rays
    for k in range(3):
        S.store(rays, (O + k) * L, o[k])
    S.store(rays, TMIN * L, tmin)
    S.store(rays, BEST * L, tmax)
    _fill_rows32(sc.lanes32, o, inv, t0, t1)
    sc.prims[:] = -1
    one_origin = _one_origin(o, bits)
    if not _fill_shear(rays, sc.axes, d, inv, signs, bits, rays_in.directions, lanes):
        if not one_origin:
            return bits, signs, LANE_BY_LANE
        _fill_axis_bits(sc.axes, bits, sc.lane_bits)
        return bits, signs, ONE_ORIGIN_BY_LANE
    return bits, signs, ONE_ORIGIN if one_origin else SAME_AXES


@njit(cache=True, inline="always")
def _lane_signs(d, bits, lane_bits):
    """An any-hit packet's signs: bit k as traversal wants it where the lanes `bits` agree on axis k,
    and MIXED << k where they do not, with lane_bits[k] the lanes whose d[k] > 0 (the node step takes
    each lane's children in its own order: packet_traversal.py)."""
    signs = 0
    for k in range(3):
        up = S.mask_bits(S.gt(d[k], S.splat_f64(0.0))) & bits
        lane_bits[k] = up
        if up == bits:
            signs |= 1 << k
        elif up != 0:
            signs |= (1 | MIXED) << k
    return signs


@njit(cache=True, inline="always")
def _fill_axis_bits(axes, bits, lane_bits):
    """lane_bits[3 + 2 i + c] = the lanes `bits` whose shear axis i (kx, ky, kz) is c (0 or 1; the
    others have 2), for packet_leaf's ONE_ORIGIN_BY_LANE test."""
    for i in range(6):
        lane_bits[3 + i] = 0
    for l in range(L):
        if (bits >> l) & 1:
            for i in range(3):
                c = axes[l, i]
                if c < 2:
                    lane_bits[3 + 2 * i + c] |= 1 << l


@njit(cache=True, inline="always")
def _one_origin(o, bits):
    """Whether the lanes `bits` share their origin (equal coordinates; +0 and -0 count as equal, which
    changes no edge value's sign or t: packet_leaf.py)."""
    l0 = S.count_trailing_zeros(bits)
    same = bits
    for k in range(3):
        same &= S.mask_bits(S.eq(o[k], S.splat_f64(S.lane(o[k], l0))))
    return same == bits


@njit(cache=True, inline="always")
def _gather(values, lanes, fill, k):
    """values[lanes[l], k] in lane l as a float64 vector (row `fill` where lanes[l] < 0)."""
    v = S.splat_f64(0.0)
    for l in range(L):
        r = lanes[l]
        v = S.with_lane(v, l, values[at(r if r >= 0 else fill), at(k)])
    return v


@njit(cache=True, inline="always")
def _gather_1d(values, lanes, fill):
    v = S.splat_f64(0.0)
    for l in range(L):
        r = lanes[l]
        v = S.with_lane(v, l, values[at(r if r >= 0 else fill)])
    return v


@njit(cache=True, inline="always")
def _signs_and_joins(o, d, valid, any_hit):
    """(the packet's signs: bit k set when at least as many of the valid lanes' directions are positive
    as negative on axis k, the lanes that can join: d strictly of the packet's sign on every axis (of
    either sign for `any_hit`), and o, d, 1 / d within OUTSIDE_FLOAT32, the float32 bound's range)."""
    zero, big, small = S.splat_f64(0.0), S.splat_f64(OUTSIDE_FLOAT32), S.splat_f64(1.0 / OUTSIDE_FLOAT32)
    signs, joins = 0, valid
    for k in range(3):
        positive = S.mask_bits(S.gt(d[k], zero)) & valid
        negative = S.mask_bits(S.lt(d[k], zero)) & valid
        up = S.count_set_bits(positive) >= S.count_set_bits(negative)
        signs |= (1 if up else 0) << k
        joins &= (positive | negative) if any_hit else (positive if up else negative)
        size = S.vabs(d[k])
        joins &= S.mask_bits(S.mask_and(S.lt(S.vabs(o[k]), big), S.mask_and(S.lt(small, size), S.lt(size, big))))
    return signs, joins


@njit(cache=True, inline="always")
def _clip_to_box(box, o, inv, tmin, tmax):
    """traversal.clip_to_box in lanes, for directions without zero components."""
    t0, t1 = tmin, tmax
    widen = S.splat_f64(WIDEN)
    for k in range(3):
        ta = S.mul(S.sub(S.splat_f64(box[k]), o[k]), inv[k])
        tb = S.mul(S.sub(S.splat_f64(box[k + 3]), o[k]), inv[k])
        swap = S.gt(ta, tb)
        near, far = S.select(swap, tb, ta), S.select(swap, ta, tb)
        t0 = S.vmax(S.sub(near, S.mul(widen, S.vabs(near))), t0)
        t1 = S.vmin(S.add(far, S.mul(widen, S.vabs(far))), t1)
    return t0, t1


@njit(cache=True, inline="always")
def _fill_rows32(lanes32, o, inv, t0, t1):
    """The node step's float32 rows (packet_traversal's docstring): o', i', c, e, and [t0, t1] rounded
    outward (t0 >= 0: as_ray_limits)."""
    tiny = S.splat_f32(TINY)
    for k in range(3):
        o32, inv32 = S.to_f32(o[k]), S.to_f32(inv[k])
        c = S.mul(S.splat_f32(SCALE), S.vabs(inv32))
        S.store(lanes32, (O32 + k) * L, o32)
        S.store(lanes32, (INV32 + k) * L, inv32)
        S.store(lanes32, (C32 + k) * L, c)
        S.store(lanes32, (E32 + k) * L, S.add(S.mul(c, S.add(S.vabs(o32), tiny)), tiny))
    S.store(lanes32, T0 * L, rounded_down(t0))
    S.store(lanes32, T1 * L, rounded_up(t1))


@njit(cache=True, inline="always")
def _fill_shear(rays, axes, d, inv, signs, bits, directions, lanes):
    """The shear rows (sx, sy, sz) and axes of the lanes `bits`; whether they all share the axes.
    triangle_test.ray_shear: kz the dominant axis (x on ties, then y), kx, ky the next two, swapped
    when d[kz] < 0; sx = d[kx] / d[kz], sy = d[ky] / d[kz], sz = 1 / d[kz]."""
    ax, ay, az = S.vabs(d[0]), S.vabs(d[1]), S.vabs(d[2])
    x_major = S.mask_bits(S.mask_and(S.ge(ax, ay), S.ge(ax, az)))
    y_major = S.mask_bits(S.ge(ay, az)) & ~x_major
    kz = 0 if x_major & bits == bits else (1 if y_major & bits == bits else (2 if (x_major | y_major) & bits == 0
                                                                             else -1))
    if kz < 0 or (signs >> kz) & MIXED:  # the lanes' kz differ, or d[kz]'s sign (which orders kx, ky)
        for l in range(L):
            if (bits >> l) & 1:
                r = lanes[l]
                kx, ky, kz, sx, sy, sz = ray_shear(rows(directions, r, r + 1)[0])
                axes[l, 0], axes[l, 1], axes[l, 2] = kx, ky, kz
                rays[SX * L + l], rays[SY * L + l], rays[SZ * L + l] = sx, sy, sz
        return False
    kx = kz + 1 if kz < 2 else 0
    ky = kx + 1 if kx < 2 else 0
    if not (signs >> kz) & 1:  # d[kz] < 0 in every lane: the packet's sign
        kx, ky = ky, kx
    dz = _pick(kz, d)
    S.store(rays, SX * L, S.div(_pick(kx, d), dz))
    S.store(rays, SY * L, S.div(_pick(ky, d), dz))
    S.store(rays, SZ * L, _pick(kz, inv))
    for l in range(L):
        axes[l, 0], axes[l, 1], axes[l, 2] = kx, ky, kz
    return True


@njit(cache=True, inline="always")
def _pick(k, v):
    return v[0] if k == 0 else (v[1] if k == 1 else v[2])


@njit(cache=True, inline="always")
def leave_to_single_rays(lanes, bits, single):
    """Mark the rays of lanes `bits` for the single-ray kernel (single[ray] = 1)."""
    while bits != 0:
        l = S.count_trailing_zeros(bits)
        bits &= bits - 1
        single[lanes[l]] = 1


@njit(cache=True, inline="always")
def _write_misses(lanes, bits, out):
    while bits != 0:
        l = S.count_trailing_zeros(bits)
        bits &= bits - 1
        r = lanes[l]
        out.t[r], out.prim[r], out.u[r], out.v[r] = np.inf, -1, 0.0, 0.0
