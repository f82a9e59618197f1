"""A packet's leaf test: one leaf triangle against every active lane (packet_traversal.py).

The watertight test (Woop, Benthin and Wald 2013, "Watertight Ray/Triangle Intersection") in float64
lanes, with triangle_test._hit's operations in its order (edge values, det, t, the t rounding bound),
so each lane gets the single-ray t, u, v bit for bit; lanes with an exactly zero edge value, where the
tie rule decides, take the single-ray test itself (triangle_test.intersect_leaf_triangle), as do all
lanes of a packet whose lanes shear along different axes. Triangles are taken in leaf order, as
traversal.trace_ray does. When the lanes also share one origin (a perspective camera), the vertices'
differences from it are scalars, the same float64 differences every lane would compute
(docs/choices.md#camera-ray-packets-one-origin-in-the-leaf-test).

Lanes sharing the origin but not the shear axes (an any-hit packet of rays in every direction from
one point) pick each lane's coordinates of those differences with masks, so their t is the single-ray
test's as well.

The vector test reads a triangle's vertices from the triangles by index (triangles[prim]: 36
consecutive bytes, the values the leaf-ordered copy holds), one or two cache lines a triangle where the
copy's nine coordinate rows take nine a leaf, and asks for every triangle of a leaf at its start
(docs/choices.md#packet-leaf-triangles-by-index). The single-ray test of tie lanes keeps the copy.

The per-packet scratch `rays` holds one float64 row per quantity below, lane l of row r at r * L + l.
"""
import numpy as np
from numba import njit

from . import simd as S
from ..build.leaf_triangles import GROUPED_LEAF, LEAF_GROUP
from .array_views import at, rows
from .packet_boxes import lanes_meeting_box
from .traversal import leaf_hit
from .triangle_test import GAMMA, intersect_leaf_triangle

L = S.LANES
G2, G3, G5 = (n * GAMMA / (1.0 - n * GAMMA) for n in (2, 3, 5))  # triangle_test._gamma(n), the same doubles

# rows of the float64 scratch `rays`: origin (3 rows), tmin, the best hit's t, the shear (sx, sy, sz)
O, TMIN, BEST, SX, SY, SZ = 0, 3, 4, 5, 6, 7
ROWS = 8

# how a packet's lanes take the leaf test: lane by lane (shear axes differ), in vectors, in vectors with
# one origin for all lanes (its differences from the vertices computed once, as scalars), and so with
# shear axes that differ by lane (each lane picks its coordinates of the differences)
LANE_BY_LANE, SAME_AXES, ONE_ORIGIN, ONE_ORIGIN_BY_LANE = 0, 1, 2, 3
SCREENED_LANES = 2  # an any-hit leaf with at most this many active lanes is tested lane by lane, screened


@njit(cache=True, inline="always")
def leaf_test(copy, leaf_prims, column, end, first, m, sc, mode, any_hit):
    """Test the leaf's triangles (columns column..end-1 of the leaf-ordered copy, prims from
    leaf_prims[first], vertices triangles[prim]; copy = (leaf_triangles, leaf_boxes, triangles)) against
    the active lanes m, in leaf order; bits of lanes whose best hit changed. `first` is also the leaf's
    first column within its tree, whose column groups leaf_boxes holds.
    A leaf of more than GROUPED_LEAF triangles is taken a column group at a time (leaf_triangles.leaf_boxes):
    only the lanes that may meet the group's box (packet_boxes.lanes_meeting_box) test its triangles,
    which changes no lane's result: a left-out lane could not hit them before its best hit.
    `mode` (above): lanes sharing shear axes or an origin are tested in vectors (_lanes_test); otherwise
    lane by lane. With `any_hit` a lane stops at its first hit, and a leaf with at most SCREENED_LANES
    active lanes takes the single-ray leaf test lane by lane (its screen runs over eight triangles at
    once, where the lanes' vector would run mostly empty)."""
    leaf_tris, boxes, triangles = copy
    if any_hit and S.count_set_bits(m) <= SCREENED_LANES:
        return _screened_lanes(leaf_tris, leaf_prims, column - first, first, end - column + first, m, sc)
    axes = sc.axes
    l0 = S.count_trailing_zeros(m)
    kx, ky, kz = axes[at(l0), 0], axes[at(l0), 1], axes[at(l0), 2]
    grouped = end - column > GROUPED_LEAF
    shift = column - first  # a column of the copy less the same column within the tree
    last = first + end - column - 1
    g0, g1 = (first // LEAF_GROUP, last // LEAF_GROUP + 1) if grouped else (0, 1)
    depth_axis = kz if mode == SAME_AXES or mode == ONE_ORIGIN else -1  # lanes sharing their shear axes
    found = 0
    for g in range(g0, g1):
        if any_hit:
            m &= ~found
            if m == 0:
                break
        lanes = m
        if grouped:  # the limits are loaded only here (docs/choices.md#boxes-over-groups-of-a-large-leafs-triangles)
            limits = (S.load(sc.rays, TMIN * L), S.load(sc.rays, BEST * L))
            lanes = lanes_meeting_box(sc.lanes32, boxes, g, m, depth_axis, limits)
        if lanes == 0:
            continue
        j0, j1 = (max(column, shift + g * LEAF_GROUP), min(end, shift + g * LEAF_GROUP + LEAF_GROUP)) if grouped \
            else (column, end)
        for j in range(j0, j1):  # the lines of every triangle asked for at once, not one after another
            row = leaf_prims[at(first + j - column)] * 9  # triangles[prim]'s first and last float
            S.prefetch(triangles, row)
            S.prefetch(triangles, row + 8)
        for j in range(j0, j1):
            prim = leaf_prims[at(first + j - column)]
            if any_hit:
                lanes &= ~found
                if lanes == 0:
                    break
            if mode != LANE_BY_LANE:
                found |= _lanes_test((leaf_tris, triangles), j, prim, lanes, sc, (kx, ky, kz), mode)
                continue
            candidates = lanes
            while candidates != 0:
                l = S.count_trailing_zeros(candidates)
                candidates &= candidates - 1
                if _test_lane(leaf_tris, j, prim, l, sc):
                    found |= 1 << l
    return found


@njit(cache=True, inline="always")
def _screened_lanes(leaf_tris, leaf_prims, base, first, end, m, sc):
    """traversal.leaf_hit (any hit) for each lane of m on the leaf's triangles first..end-1 (columns
    base + first...); bits of lanes that found a hit."""
    rays = sc.rays
    found = 0
    while m != 0:
        l = S.count_trailing_zeros(m)
        m &= m - 1
        t, prim, u, v = leaf_hit(leaf_tris, leaf_prims, base, first, end, _lane_ray(sc, l), rays[at(TMIN * L + l)],
                                 rays[at(BEST * L + l)], True, sc.flags)
        if prim >= 0:
            rays[at(BEST * L + l)], sc.prims[at(l)], sc.us[at(l)], sc.vs[at(l)] = t, prim, u, v
            found |= 1 << l
    return found


@njit(cache=True, inline="always")
def _lanes_test(tris, column, prim, m, sc, axes, mode):
    """triangle_test._hit for the lanes m against one triangle, in float64 lanes with its operations in
    its order (the sign flip by det's sign is exact and left out where it cannot change a bit), so each
    lane gets the single-ray test's t. Lanes with an exactly zero edge value, where the tie rule
    decides, take the single-ray test itself. Returns the bits of lanes whose best hit changed. `tris`:
    (the leaf-ordered copy, whose column the tie lanes read, the triangles by prim); `axes`: the lanes'
    shear axes (kx, ky, kz) unless `mode` is ONE_ORIGIN_BY_LANE."""
    rays, prims, us, vs = sc.rays, sc.prims, sc.us, sc.vs
    leaf_tris, triangles = tris
    if mode == ONE_ORIGIN:
        ax, ay, az, bx, by, bz, cx, cy, cz = _sheared_from_one_origin(triangles, prim, rays, axes,
                                                                       S.count_trailing_zeros(m))
    elif mode == ONE_ORIGIN_BY_LANE:
        ax, ay, az, bx, by, bz, cx, cy, cz = _sheared_by_lane_axes(triangles, prim, rays, sc.lane_bits,
                                                                    S.count_trailing_zeros(m))
    else:
        ax, ay, az, bx, by, bz, cx, cy, cz = _sheared_triangle(triangles, prim, rays, axes)
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
    closer = S.mask_from_bits(hits)
    S.store(rays, BEST * L, S.select(closer, t, best))
    S.store(us, 0, S.select(closer, S.div(v, det), S.load(us, 0)))
    S.store(vs, 0, S.select(closer, S.div(w, det), S.load(vs, 0)))
    found |= hits
    while hits != 0:
        l = S.count_trailing_zeros(hits)
        hits &= hits - 1
        prims[at(l)] = prim
    return found


@njit(cache=True, inline="always")
def _sheared_triangle(triangles, prim, rays, axes):
    """The vertices of triangles[prim] sheared along each lane's ray (triangle_test._sheared in lanes)."""
    kx, ky, kz = axes
    ox, oy, oz = S.load(rays, (O + kx) * L), S.load(rays, (O + ky) * L), S.load(rays, (O + kz) * L)
    sx, sy = S.load(rays, SX * L), S.load(rays, SY * L)
    t = triangles[at(prim)]
    a = _sheared(t[0, at(kx)], t[0, at(ky)], t[0, at(kz)], ox, oy, oz, sx, sy)
    b = _sheared(t[1, at(kx)], t[1, at(ky)], t[1, at(kz)], ox, oy, oz, sx, sy)
    c = _sheared(t[2, at(kx)], t[2, at(ky)], t[2, at(kz)], ox, oy, oz, sx, sy)
    return a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]


@njit(cache=True, inline="always")
def _sheared_from_one_origin(triangles, prim, rays, axes, l0):
    """_sheared_triangle for lanes whose origins are all lane l0's: the vertex's differences from the
    origin are one float64 scalar each, the value every lane's subtraction gives."""
    kx, ky, kz = axes
    ox, oy, oz = rays[at((O + kx) * L + l0)], rays[at((O + ky) * L + l0)], rays[at((O + kz) * L + l0)]
    sx, sy = S.load(rays, SX * L), S.load(rays, SY * L)
    t = triangles[at(prim)]
    kx, ky, kz = at(kx), at(ky), at(kz)
    a = _sheared_differences(t[0, kx] - ox, t[0, ky] - oy, t[0, kz] - oz, sx, sy)
    b = _sheared_differences(t[1, kx] - ox, t[1, ky] - oy, t[1, kz] - oz, sx, sy)
    c = _sheared_differences(t[2, kx] - ox, t[2, ky] - oy, t[2, kz] - oz, sx, sy)
    return a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]


@njit(cache=True, inline="always")
def _sheared_by_lane_axes(triangles, prim, rays, lane_bits, l0):
    """_sheared_from_one_origin for lanes whose shear axes differ: the nine differences of the vertices
    from the one origin (lane l0's) as scalars, each lane taking its kx, ky, kz coordinates of them by
    masks (lane_bits[3 + 2 i + c]: lanes whose axis i is c; packet_setup._fill_axis_bits)."""
    ox, oy, oz = rays[at(O * L + l0)], rays[at((O + 1) * L + l0)], rays[at((O + 2) * L + l0)]
    sx, sy = S.load(rays, SX * L), S.load(rays, SY * L)
    picks = (S.mask_from_bits(lane_bits[3]), S.mask_from_bits(lane_bits[4]), S.mask_from_bits(lane_bits[5]),
             S.mask_from_bits(lane_bits[6]), S.mask_from_bits(lane_bits[7]), S.mask_from_bits(lane_bits[8]))
    t = triangles[at(prim)]
    a = _picked_differences(t[0, 0] - ox, t[0, 1] - oy, t[0, 2] - oz, picks, sx, sy)
    b = _picked_differences(t[1, 0] - ox, t[1, 1] - oy, t[1, 2] - oz, picks, sx, sy)
    c = _picked_differences(t[2, 0] - ox, t[2, 1] - oy, t[2, 2] - oz, picks, sx, sy)
    return a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]


@njit(cache=True, inline="always")
def _picked_differences(d0, d1, d2, picks, sx, sy):
    """_sheared_differences with each lane's (kx, ky, kz) coordinates of the differences (d0, d1, d2)."""
    v0, v1, v2 = S.splat_f64(d0), S.splat_f64(d1), S.splat_f64(d2)
    dx = S.select(picks[0], v0, S.select(picks[1], v1, v2))
    dy = S.select(picks[2], v0, S.select(picks[3], v1, v2))
    dz = S.select(picks[4], v0, S.select(picks[5], v1, v2))
    return S.sub(dx, S.mul(sx, dz)), S.sub(dy, S.mul(sy, dz)), dz


@njit(cache=True, inline="always")
def _sheared_differences(dx, dy, dz, sx, sy):
    """_sheared from the scalar differences (x - ox, y - oy, z - oz): dx - sx dz, dy - sy dz, dz."""
    z = S.splat_f64(dz)
    return S.sub(S.splat_f64(dx), S.mul(sx, z)), S.sub(S.splat_f64(dy), S.mul(sy, z)), z


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
def _lane_ray(sc, l):
    """Lane l as the single-ray test takes a ray: (origin, kx, ky, kz, sx, sy, sz) (triangle_test.ray_shear),
    its origin copied into the scratch row lane_o[l]."""
    rays, lane_o, axes = sc.rays, sc.lane_o, sc.axes
    for k in range(3):
        lane_o[at(l), k] = rays[at((O + k) * L + l)]
    return (rows(lane_o, l, l + 1)[0], axes[at(l), 0], axes[at(l), 1], axes[at(l), 2], rays[at(SX * L + l)],
            rays[at(SY * L + l)], rays[at(SZ * L + l)])


@njit(cache=True, inline="always")
def _test_lane(leaf_tris, column, prim, l, sc):
    """The single-ray test of lane l against one leaf triangle; keeps the hit if closer (as trace_ray)."""
    rays, prims, us, vs = sc.rays, sc.prims, sc.us, sc.vs
    o, kx, ky, kz, sx, sy, sz = _lane_ray(sc, l)
    t, u, v = intersect_leaf_triangle(leaf_tris, column, o, kx, ky, kz, sx, sy, sz)
    if rays[at(TMIN * L + l)] < t < rays[at(BEST * L + l)]:
        rays[at(BEST * L + l)], prims[at(l)], us[at(l)], vs[at(l)] = t, prim, u, v
        return True
    return False


@njit(cache=True, inline="always")
def _sheared(x, y, z, ox, oy, oz, sx, sy):
    """triangle_test._sheared in lanes: (x - ox) - sx (z - oz), (y - oy) - sy (z - oz), z - oz."""
    z = S.sub(S.splat_f64(z), oz)
    return S.sub(S.sub(S.splat_f64(x), ox), S.mul(sx, z)), S.sub(S.sub(S.splat_f64(y), oy), S.mul(sy, z)), z
