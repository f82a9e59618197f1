"""The one kd-tree traversal: front to back with a bounded stack, for closest hit and any hit.

Recursive-descent traversal in iterative form (seed 004 §6, Havran's TA_B^rec; pbrt): each inner node
splits the ray's interval [t0, t1] at the plane, visits the near child and pushes the far one. Any hit
returns at the first hit; closest hit stops once its best hit lies inside the finished leaf's interval.
Robustness without NaN paths:
- A zero direction component (either sign of zero) never divides: the ray stays on its origin's side,
  and a ray lying in the plane visits both children. Both then cover the same interval, so the
  closest-hit stop test uses a separate exit bound that such a sibling caps at the interval's start.
- A ray starting on a plane goes to the side its direction points to.
- Interval tests are widened by a relative 1e-9 (float64 errors are ~1e-16), so a ray grazing a node
  corner or an edge on a split plane visits every cell that might own the hit.
"""
import numpy as np
from numba import njit, prange

from .array_views import at, keep_alive, rows, unowned
from ..jit.threads import kernel_threads
from .layout import LEAF, TreeArrays, suspended_prim
from .triangle_test import LEAF_CHUNK, intersect_leaf_triangle, leaf_candidates, ray_shear

STACK_SIZE = 64  # > DEPTH_LIMIT + 1: one pushed node per level
RAYS_PER_TASK = 64
WIDEN = 1e-9


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
def trace_ray(tree, o, d, tmin, tmax, any_hit, stack_node, stack_t, inv, flags):
    """(t, prim, u, v) of the closest hit in (tmin, tmax), or of any hit if `any_hit`; prim -1 on a miss.
    On a lazy tree a ray reaching an unbuilt subtree returns prim = suspended_prim(subtree) (<= -2):
    front to back, the eager traversal would enter that subtree, so the caller builds it and retraces
    (lazy.py, seed 003 §3). `stack_node`, `stack_t`, `inv` (3) and `flags` (LEAF_CHUNK uint8) are the
    caller's scratch. Leaves are screened LEAF_CHUNK triangles at a time (leaf_candidates) before the
    full test. Inlined into its callers (docs/choices.md#inline-the-traversal)."""
    axis, split, child, count, leaf_prims = tree.axis, tree.split, tree.child, tree.count, tree.leaf_prims
    root_box, leaf_tris, base = tree.bounds, tree.leaf_triangles, tree.base
    for k in range(3):
        inv[k] = 1.0 / d[k] if d[k] != 0.0 else 0.0
    t0, t1 = clip_to_box(root_box, o, d, inv, tmin, tmax)
    if t0 > t1 or axis.shape[0] == 0:
        return np.inf, -1, 0.0, 0.0
    kx, ky, kz, sx, sy, sz = ray_shear(d)
    best_t, best_prim, best_u, best_v = tmax, -1, 0.0, 0.0
    node, sp, t_exit = 0, 0, t1
    while True:
        a = axis[at(node)]
        if a < LEAF:
            node, t1, t_exit, sp = _descend(node, a, split[at(node)], child[at(node)], o[at(a)], d[at(a)], inv[at(a)],
                                            t0, t1, t_exit, (stack_node, stack_t), sp)
            continue
        first = child[at(node)]
        if a != LEAF:  # UNBUILT: the one extra test, made only at leaves
            return np.inf, suspended_prim(first), 0.0, 0.0
        t, prim, u, v = leaf_hit(leaf_tris, leaf_prims, base, first, first + count[at(node)],
                                 (o, kx, ky, kz, sx, sy, sz), tmin, best_t, any_hit, flags)
        if prim >= 0:
            best_t, best_prim, best_u, best_v = t, prim, u, v
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
def leaf_hit(leaf_tris, leaf_prims, base, first, end, ray, tmin, best, any_hit, flags):
    """(t, prim, u, v) of the closest hit in (tmin, best) among the leaf's triangles first..end-1 (the
    first one found if `any_hit`), prim -1 when none; `ray` is (o, kx, ky, kz, sx, sy, sz) (ray_shear).
    Screened LEAF_CHUNK triangles at a time (leaf_candidates) before the full test, in leaf order."""
    o, kx, ky, kz, sx, sy, sz = ray
    best_prim, best_u, best_v = -1, 0.0, 0.0
    for lo in range(first, end, LEAF_CHUNK):
        hi = min(end, lo + LEAF_CHUNK)
        if not leaf_candidates(leaf_tris, base + lo, base + hi, o, kx, ky, kz, sx, sy, flags):
            continue
        for j in range(lo, hi):
            if flags[at(j - lo)] == 0:
                continue
            t, u, v = intersect_leaf_triangle(leaf_tris, base + j, o, kx, ky, kz, sx, sy, sz)
            if tmin < t < best:
                best, best_prim, best_u, best_v = t, leaf_prims[at(j)], u, v
                if any_hit:
                    return best, best_prim, best_u, best_v
    return best, best_prim, best_u, best_v


@njit(cache=True, inline="always")
def _descend(node, a, pos, left, oa, da, inv_a, t0, t1, t_exit, stack, sp):
    """Step into an inner node: (next node, its t1, its exit bound, stack size), pushing the far child
    onto stack = (stack_node, stack_t). t_exit bounds where a closest hit lets the search stop
    (everything on the stack starts at or after it); a ray lying in the plane pushes a sibling over the
    same interval, so below it it drops to t0."""
    stack_node, stack_t = stack
    if da == 0.0:
        if oa < pos:
            return left, t1, t_exit, sp
        if oa > pos:
            return left + 1, t1, t_exit, sp
        sp = _push(stack_node, stack_t, sp, left + 1, t0, t1, t_exit)
        return left, t1, min(t_exit, t0), sp
    near, far = (left, left + 1) if (oa < pos or (oa == pos and da < 0.0)) else (left + 1, left)
    ts = (pos - oa) * inv_a
    if ts <= 0.0 or ts > t1 + _slack(ts):
        return near, t1, t_exit, sp
    if ts < t0 - _slack(ts):
        return far, t1, t_exit, sp
    ts = min(max(ts, t0), t1)
    sp = _push(stack_node, stack_t, sp, far, ts, t1, t_exit)
    return near, ts, min(t_exit, ts), sp


@njit(cache=True, inline="always")
def _pop(stack_node, stack_t, sp, best_t, found):
    """The next stacked node that may hold a hit closer than best_t: (node, t0, t1, t_exit, sp), node -1
    when none can. A node starting after best_t is skipped, but the search ends only once best_t is
    within the entry's exit bound: below an in-plane sibling, which starts where its twin did, the
    entries do not start in order."""
    while sp > 0:
        sp -= 1
        node, t0, t1, t_exit = stack_node[at(sp)], stack_t[at(sp), 0], stack_t[at(sp), 1], stack_t[at(sp), 2]
        if not found or best_t >= t0 - _slack(t0):
            return node, t0, t1, t_exit, sp
        if best_t <= t_exit:
            break
    return -1, 0.0, 0.0, 0.0, 0


@njit(cache=True, inline="always")
def _push(stack_node, stack_t, sp, node, t0, t1, t_exit):
    stack_node[at(sp)] = node
    stack_t[at(sp), 0] = t0
    stack_t[at(sp), 1] = t1
    stack_t[at(sp), 2] = t_exit
    return sp + 1


BANDS = 16  # interleaved_blocks: the bands of the image every thread gets a share of


@njit(cache=True, inline="always")
def interleaved_blocks(n, block_size):
    """(iterations, per_band, run) of a prange over the blocks of block_size items among n, in which
    iteration i runs items block_range(i, per_band, run, n, block_size): BANDS bands of per_band
    blocks, each cut into one run of consecutive blocks per thread, and the iterations visit the
    bands' first runs in turn, then their second runs, and so on.
    Numba's prange gives each thread one contiguous range (a static schedule) and ray costs differ by
    image region; dealt so, thread k's range is the k-th run of every band: an equal share of each
    region, and as few jumps between regions as that allows, since a jump leaves the tree nodes in
    cache behind (docs/choices.md#interleaved-ray-blocks, #one-run-a-band-per-thread). Results do
    not depend on the order."""
    return dealt_blocks((n + block_size - 1) // block_size, max(kernel_threads(), 1))


@njit(cache=True, inline="always")
def thread_shares(n, block_size):
    """interleaved_blocks with one prange iteration a thread, so a kernel makes its scratch once a thread:
    (threads, share, per_band, run), thread k running iterations k * share .. k * share + share - 1, the
    ones a static schedule of interleaved_blocks' prange gives it (its run of every band)
    (docs/choices.md#packet-scratch-once-a-thread)."""
    iterations, per_band, run = interleaved_blocks(n, block_size)
    share = run * BANDS
    return iterations // share, share, per_band, run


@njit(cache=True, inline="always")
def dealt_blocks(n_blocks, threads):
    """interleaved_blocks' (iterations, per_band, run) for n_blocks blocks and `threads` threads."""
    run = max(((n_blocks + BANDS - 1) // BANDS + threads - 1) // threads, 1)
    per_band = run * threads
    return per_band * BANDS, per_band, run


@njit(cache=True, inline="always")
def block_range(i, per_band, run, n, block_size):
    """(start, stop) of the items iteration i runs (blocks are a permutation of the iterations;
    iterations past the last block get an empty range)."""
    b = (i // run) % BANDS * per_band + i // (run * BANDS) * run + i % run
    start = min(n, b * block_size)
    return start, min(n, start + block_size)


@njit(cache=True, parallel=True)
def trace_rays(tree, origins, directions, tmin, tmax, any_hit, out_t, out_prim, out_u, out_v):
    """Trace all rays in parallel, in blocks of RAYS_PER_TASK that share one traversal stack."""
    n = origins.shape[0]
    iterations, per_band, run = interleaved_blocks(n, RAYS_PER_TASK)
    for i in prange(iterations):
        start, stop = block_range(i, per_band, run, n, RAYS_PER_TASK)
        _trace_block(tree, origins, directions, tmin, tmax, any_hit, start, stop, out_t, out_prim, out_u, out_v)


@njit(cache=True)
def _trace_block(tree, origins, directions, tmin, tmax, any_hit, start, stop, out_t, out_prim, out_u, out_v):
    """Rays start..stop-1 with one stack, the tree's arrays and each ray's origin and direction as
    unowned views (array_views.py; docs/choices.md#unowned-array-views)."""
    stack_node, stack_t, inv = np.empty(STACK_SIZE, np.int32), np.empty((STACK_SIZE, 3)), np.empty(3)
    flags = np.empty(LEAF_CHUNK, np.uint8)
    views = unowned_tree(tree)
    scratch = (unowned(stack_node), unowned(stack_t), unowned(inv), unowned(flags))
    for r in range(start, stop):
        t, prim, u, v = trace_ray(views, rows(origins, r, r + 1)[0], rows(directions, r, r + 1)[0], tmin[r],
                                  tmax[r], any_hit, scratch[0], scratch[1], scratch[2], scratch[3])
        out_t[r] = t
        out_prim[r] = prim
        out_u[r] = u
        out_v[r] = v
    keep_alive((stack_node, stack_t, inv, flags))  # the owners of `scratch`


@njit(cache=True, inline="always")
def unowned_tree(tree):
    """TreeArrays as unowned views (array_views.py)."""
    return TreeArrays(unowned(tree.axis), unowned(tree.split), unowned(tree.child), unowned(tree.count),
                      unowned(tree.leaf_prims), unowned(tree.triangles), unowned(tree.bounds),
                      unowned(tree.leaf_triangles), unowned(tree.leaf_boxes), tree.base)
