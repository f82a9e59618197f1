"""The one kd-tree traversal: front to back with a bounded stack, for closest hit and any hit.

Recursive-descent traversal in iterative form (seed 004 §6, Havran's TA_B^rec; pbrt): each inner node
splits the ray's interval [t0, t1] at the plane, visits the near child and pushes the far one. Any hit
returns at the first hit; closest hit stops once its best hit lies inside the finished leaf's interval.
Robustness without NaN paths:
- The node step runs in float32 (interval, stack and plane distance; docs/choices.md#float32-interval-and-stack):
  the distance to a plane is computed from per-ray float32 constants (ray_constants32) and widened to
  an interval [lo, hi] that surely holds the exact distance. Children are ordered by the direction's
  sign (the side the ray moves into is visited second), which needs no sign test of the distance: the
  near child ends at hi, the far one starts at lo, so a ray grazing a node corner or an edge on a split
  plane visits every cell that might own the hit. The root box clip stays float64, rounded outwards.
- A zero direction component (either sign of zero) never divides: its plane distance is -inf or +inf
  by the origin's side, and a ray lying in the plane (0 times inf, NaN) visits both children over the
  same interval. The closest-hit stop test therefore uses a separate exit bound that such a sibling caps
  at the interval's start.
- Rays that could overflow float32 (origin, box or a direction component or its inverse beyond SAFE32)
  get an infinite widening: they visit every cell their root interval crosses, never a NaN.
"""
import numpy as np
from numba import njit, prange

from .array_views import at, rows, unowned
from .layout import KIND_SHIFT, LEAF, LOW_MASK, UNBUILT_COUNT, TreeArrays, suspended_prim
from .triangle_test import LEAF_CHUNK, intersect_leaf_triangle, leaf_candidates, ray_shear

STACK_SIZE = 64  # > DEPTH_LIMIT + 1: one pushed node per level
RAYS_PER_TASK = 64
WIDEN = 1e-9
# The float32 node step's widening (ray_constants32): 8 float32 unit roundoffs (2**-24 each), twice
# what the bound derived there needs, the rest covering the rounding of the widening itself.
WIDEN32 = 2.0 ** -21
TINY32 = 2.0 ** -126  # float32's smallest normal: absorbs the absolute error of subnormal results
SAFE32 = 2.0 ** 60  # origins, boxes and |direction| components (and their inverses) within this: no overflow
TINY32_STEP = 2.0 ** -149  # float32's smallest subnormal
FLOAT32_MAX = float(np.finfo(np.float32).max)
RAY32 = 12  # float32 per-ray constants: o, 1 / d, the widening's slope and offset, 3 each


@njit(cache=True, inline="always")
def _slack(t):
    return WIDEN * abs(t)


@njit(cache=True, inline="always")
def clip_to_box(box, o, d, inv, tmin, tmax):
    """The ray's parameter interval inside the box, widened; t0 > t1 when it misses."""
    t0, t1 = tmin, tmax
    for k in range(3):
        if d[k] == 0.0:
            if o[k] < box[k] or o[k] > box[k + 3]:
                return 1.0, 0.0
        else:
            ta = (box[k] - o[k]) * inv[k]
            tb = (box[k + 3] - o[k]) * inv[k]
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta - _slack(ta))
            t1 = min(t1, tb + _slack(tb))
    return t0, t1


@njit(cache=True, inline="always")
def trace_ray(tree, o, d, tmin, tmax, any_hit, stack_node, stack_t, inv, flags, ray32):
    """(t, prim, u, v) of the closest hit in (tmin, tmax), or of any hit if `any_hit`; prim -1 on a miss.
    On a lazy tree a ray reaching an unbuilt subtree returns prim = suspended_prim(subtree) (<= -2):
    front to back, the eager traversal would enter that subtree, so the caller builds it and retraces
    (lazy.py, seed 003 §3). `stack_node`, `stack_t` (float32), `inv` (3), `flags` (LEAF_CHUNK uint8)
    and `ray32` (RAY32 float32) are the caller's scratch. Leaves are screened LEAF_CHUNK triangles at a
    time (leaf_candidates) before the full test. Inlined into its callers (docs/choices.md#inline-the-traversal)."""
    nodes, node_split, leaf_prims = tree.nodes, tree.node_split, tree.leaf_prims
    root_box, leaf_tris, base = tree.bounds, tree.leaf_triangles, tree.base
    t0, t1, flips = root_interval32(root_box, o, d, inv, tmin, tmax, ray32)
    if t0 > t1 or nodes.shape[0] == 0:
        return np.inf, -1, 0.0, 0.0
    kx, ky, kz, sx, sy, sz = ray_shear(d)
    best_t, best_prim, best_u, best_v = tmax, -1, 0.0, 0.0
    node, sp, t_exit = 0, 0, t1
    while True:
        word = nodes[at(2 * node + 1)]  # one record a step (layout.py): kind and child in this word
        a = word >> KIND_SHIFT
        if a < LEAF:
            node, t1, t_exit, sp = _descend(a, node_split[at(2 * node)], word & LOW_MASK, (ray32, flips), t0, t1,
                                            t_exit, (stack_node, stack_t), sp)
            continue
        first, n = np.int64(nodes[at(2 * node)]), np.int64(word & LOW_MASK)
        if n == UNBUILT_COUNT:  # an unbuilt subtree: the one extra test, made only at leaves
            return np.inf, suspended_prim(first), 0.0, 0.0
        end = first + n
        for lo in range(first, end, LEAF_CHUNK):
            hi = min(end, lo + LEAF_CHUNK)
            if not leaf_candidates(leaf_tris, base + lo, base + hi, o, kx, ky, kz, sx, sy, flags):
                continue
            for j in range(lo, hi):
                if flags[at(j - lo)] == 0:
                    continue
                t, u, v = intersect_leaf_triangle(leaf_tris, base + j, o, kx, ky, kz, sx, sy, sz)
                if tmin < t < best_t:
                    best_t, best_prim, best_u, best_v = t, leaf_prims[at(j)], u, v
                    if any_hit:
                        return best_t, best_prim, best_u, best_v
        if best_prim >= 0 and best_t <= t_exit:  # no slack: stopping late is safe, early is not
            break
        node, t0, t1, t_exit, sp = _pop(stack_node, stack_t, sp, best_t, best_prim >= 0)
        if node < 0:
            break
    if best_prim < 0:
        return np.inf, -1, 0.0, 0.0
    return best_t, best_prim, best_u, best_v


@njit(cache=True, inline="always")
def root_interval32(box, o, d, inv, tmin, tmax, ray32):
    """The ray's interval in the root box as float32 (t0, t1), rounded outwards (t0 > t1 on a miss), and
    its child order bits (bit k set: axis k's near child is the right one), with ray32 filled for the
    node steps (ray_constants32). inv receives 1 / d (0 for a zero component)."""
    for k in range(3):
        inv[k] = 1.0 / d[k] if d[k] != 0.0 else 0.0
    t0, t1 = clip_to_box(box, o, d, inv, tmin, tmax)
    ray_constants32(box, o, d, inv, ray32)
    flips = 0
    for k in range(3):
        if ray32[3 + k] < 0.0:
            flips |= 1 << k
    return _down32(t0), _up32(t1), flips


@njit(cache=True, inline="always")
def _down32(t):
    """A float32 <= t, within 2 float32 ulps of it (no library call): t is first moved down by more than
    the conversion's rounding (half an ulp, relative 2**-24, or 2**-150 for a subnormal), then capped at
    float32's largest finite value so a huge t (or inf, giving NaN) does not round up to inf."""
    r = t - abs(t) * 2.0 ** -23 - TINY32_STEP
    return np.float32(r if r <= FLOAT32_MAX else FLOAT32_MAX)


@njit(cache=True, inline="always")
def _up32(t):
    """A float32 >= t, within 2 float32 ulps of it (inf beyond float32's range); see _down32."""
    r = t + abs(t) * 2.0 ** -23 + TINY32_STEP
    return np.float32(r if r >= -FLOAT32_MAX else -FLOAT32_MAX)


@njit(cache=True, inline="always")
def ray_constants32(box, o, d, inv, ray32):
    """Fill ray32 with the float32 node step's per-ray constants: for each axis k, the origin o'_k and
    1 / d_k rounded to float32 (i'_k), the widening's slope c_k = WIDEN32 |i'_k| and offset
    e_k = c_k (|o'_k| + TINY32) + TINY32, so that err = c_k |p| + e_k bounds the error of
    ts' = fl32(fl32(p - o'_k) * i'_k) against the exact (p - o_k) / d_k for a float32 split p.

    The bound (Higham, "Accuracy and Stability of Numerical Algorithms", §2.2: fl(x) = x (1 + d) + h,
    |d| <= u = 2**-24, |h| <= 2**-150 for a subnormal result; Ize, "Robust BVH Ray Traversal", JCGT
    2(2), 2013 makes the same per-operation count for a box test): with S = |p| + |o|,
    o' = o (1 + d1) + h1; i' = (1 / d)(1 + d0)(1 + d3), |d0| <= 2**-53 (the float64 division);
    fl(p - o') = (p - o')(1 + d2); ts' = fl(p - o') i' (1 + d4) + h4. So |ts' - ts| <= 4 u |1 / d| S
    + |1 / d| 2**-149 + 2**-150 + O(u^2) S |1 / d|. WIDEN32 = 8 u gives twice the first term; the rest
    of the margin covers the float32 rounding of c |p| + e, of e, of ts' -+ err and the (1 + 2u)
    between |1 / d| and |i'|; TINY32 covers the absolute terms.
    A zero component gets i' = -inf, err 0: the plane distance is -inf or +inf by the origin's side,
    which the monotone rounding of o' keeps (o < p gives o' <= p; o' == p visits both children), and NaN
    in the plane. Where the origin, the box or a direction component lies outside SAFE32 (or its
    inverse does), float32 could overflow: the ray gets err = inf with o' = i' = 0 (every plane is
    straddled; never NaN)."""
    safe = True
    for k in range(6):
        safe &= abs(box[k]) <= SAFE32
    for k in range(3):
        safe &= abs(o[k]) <= SAFE32 and (d[k] == 0.0 or 1.0 / SAFE32 <= abs(d[k]) <= SAFE32)
    for k in range(3):
        if d[k] == 0.0:
            ray32[k], ray32[3 + k], ray32[6 + k], ray32[9 + k] = np.float32(o[k]), -np.inf, 0.0, 0.0
        elif safe:
            o32, inv32 = np.float32(o[k]), np.float32(inv[k])
            c = WIDEN32 * abs(np.float64(inv32))  # exact: a power of two times a normal float32
            ray32[k], ray32[3 + k], ray32[6 + k] = o32, inv32, c
            ray32[9 + k] = c * (abs(np.float64(o32)) + TINY32) + TINY32
        else:
            ray32[k], ray32[3 + k], ray32[6 + k], ray32[9 + k] = 0.0, np.copysign(0.0, d[k]), 0.0, np.inf


@njit(cache=True, inline="always")
def _descend(a, pos, left, ray, t0, t1, t_exit, stack, sp):
    """Step into an inner node, all in float32: (next node, its t1, its exit bound, stack size), pushing
    the far child onto stack = (stack_node, stack_t); ray = (ray32, flips) from root_interval32. The near
    child is the one the ray leaves (the left
    for a positive direction component), the far one the one it moves into, whatever the plane's
    distance: below t0 only the far child is crossed, beyond t1 only the near one. t_exit bounds where a
    closest hit lets the search stop (everything on the stack starts at or after it); a ray lying in the
    plane pushes a sibling over the same interval, so below it it drops to t0. Comparisons are written
    so that a NaN distance (a ray in the plane) takes both children over [t0, t1]."""
    stack_node, stack_t = stack
    ray32, flips = ray
    ts = (pos - ray32[at(a)]) * ray32[at(3 + a)]
    err = ray32[at(6 + a)] * abs(pos) + ray32[at(9 + a)]
    lo, hi = ts - err, ts + err
    flip = (flips >> a) & 1  # from a register: the next node's address waits for no float load
    near, far = left + flip, left + 1 - flip
    if lo > t1:
        return near, t1, t_exit, sp
    if hi < t0:
        return far, t1, t_exit, sp
    lo = lo if lo > t0 else t0
    hi = hi if hi < t1 else t1
    sp = _push(stack_node, stack_t, sp, far, lo, t1, t_exit)
    return near, hi, min(t_exit, lo), sp


@njit(cache=True, inline="always")
def _pop(stack_node, stack_t, sp, best_t, found):
    """The next stacked node that may hold a hit closer than best_t: (node, t0, t1, t_exit, sp), node -1
    when none can. A node starting after best_t is skipped (its t0 is a lower bound already: _descend),
    but the search ends only once best_t is within the entry's exit bound: below an in-plane sibling,
    which starts where its twin did, the entries do not start in order."""
    while sp > 0:
        sp -= 1
        node, t0, t1, t_exit = stack_node[at(sp)], stack_t[at(sp), 0], stack_t[at(sp), 1], stack_t[at(sp), 2]
        if not found or best_t >= t0:
            return node, t0, t1, t_exit, sp
        if best_t <= t_exit:
            break
    zero = np.float32(0.0)
    return -1, zero, zero, zero, 0


@njit(cache=True, inline="always")
def _push(stack_node, stack_t, sp, node, t0, t1, t_exit):
    stack_node[at(sp)] = node
    stack_t[at(sp), 0] = t0
    stack_t[at(sp), 1] = t1
    stack_t[at(sp), 2] = t_exit
    return sp + 1


BANDS = 16  # interleaved_blocks: the bands of the image every thread gets a share of
RUN = 8  # ... in runs of this many consecutive blocks, which keep the tree's cache lines warm


@njit(cache=True, inline="always")
def interleaved_blocks(n, block_size):
    """(iterations, per_band) of a prange over the blocks of block_size items among n, in which
    iteration i runs items block_range(i, per_band, n, block_size): the iterations visit BANDS bands
    of the blocks in turn, RUN consecutive blocks of a band at a time.
    Numba's prange gives each thread one contiguous range (a static schedule) and ray costs differ by
    image region; dealt band by band, any contiguous range takes the same share of every band whatever
    the thread count (docs/choices.md#interleaved-ray-blocks). Results do not depend on the order."""
    n_blocks = (n + block_size - 1) // block_size
    per_band = (n_blocks + BANDS - 1) // BANDS
    per_band = (per_band + RUN - 1) // RUN * RUN
    return per_band * BANDS, per_band


@njit(cache=True, inline="always")
def block_range(i, per_band, n, block_size):
    """(start, stop) of the items iteration i runs (blocks are a permutation of the iterations;
    iterations past the last block get an empty range)."""
    b = (i // RUN) % BANDS * per_band + i // (RUN * BANDS) * RUN + i % RUN
    start = min(n, b * block_size)
    return start, min(n, start + block_size)


@njit(cache=True, parallel=True)
def trace_rays(tree, origins, directions, tmin, tmax, any_hit, out_t, out_prim, out_u, out_v):
    """Trace all rays in parallel, in blocks of RAYS_PER_TASK that share one traversal stack."""
    n = origins.shape[0]
    iterations, per_band = interleaved_blocks(n, RAYS_PER_TASK)
    for i in prange(iterations):
        start, stop = block_range(i, per_band, n, RAYS_PER_TASK)
        _trace_block(tree, origins, directions, tmin, tmax, any_hit, start, stop, out_t, out_prim, out_u, out_v)


@njit(cache=True, inline="always")
def unowned_tree(tree):
    """The TreeArrays as unowned views, made once per block of rays (array_views.py)."""
    return TreeArrays(unowned(tree.axis), unowned(tree.split), unowned(tree.child), unowned(tree.count),
                      unowned(tree.nodes), unowned(tree.node_split), unowned(tree.leaf_prims),
                      unowned(tree.triangles), unowned(tree.bounds), unowned(tree.leaf_triangles), tree.base)


@njit(cache=True)
def _trace_block(tree, origins, directions, tmin, tmax, any_hit, start, stop, out_t, out_prim, out_u, out_v):
    """Rays start..stop-1 with one stack, the tree's arrays and each ray's origin and direction as
    unowned views (array_views.py; docs/choices.md#unowned-array-views)."""
    stack_node, stack_t, inv = np.empty(STACK_SIZE, np.int32), np.empty((STACK_SIZE, 3), np.float32), np.empty(3)
    flags, ray32 = np.empty(LEAF_CHUNK, np.uint8), np.empty(RAY32, np.float32)
    views = unowned_tree(tree)
    scratch = (unowned(stack_node), unowned(stack_t), unowned(inv), unowned(flags), unowned(ray32))
    for r in range(start, stop):
        t, prim, u, v = trace_ray(views, rows(origins, r, r + 1)[0], rows(directions, r, r + 1)[0], tmin[r],
                                  tmax[r], any_hit, scratch[0], scratch[1], scratch[2], scratch[3], scratch[4])
        out_t[r] = t
        out_prim[r] = prim
        out_u[r] = u
        out_v[r] = v
