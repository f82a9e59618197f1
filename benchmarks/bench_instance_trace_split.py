"""Where a ray's time goes in a scene of many instances (issue 50, item 4): top-level steps, instance
transforms, bottom-level traversal.

bench_top_level.py's scatter (noisy 480-triangle spheres on a grid 1 apart) seen from its camera:
480x270 camera rays (closest hit) and, from their hits, one AO-like ray each (length 1, random
directions on the camera's side; closest hit). Three kernels per kind of ray, alternating, medians:
  full       the scene's own kernel (instance_traversal.trace_scene_rays);
  transform  copies of its top-level walk that, in each top leaf, transform the ray to each instance
             and clip it to the mesh's object-space box, but do not walk the mesh tree;
  walk       the same walk doing nothing in top leaves.
The two copies are given each ray's own closest hit as tmax, so they walk the top level as far as
the full trace does. top = walk; transforms = transform - walk; bottom level = full - transform.
A counting copy (one thread) gives the per-ray steps: top inner steps and leaves, instances entered
(transforms), of those whose object box the ray meets, and the mesh trees' steps and triangle tests.

    python benchmarks/bench_instance_trace_split.py [--count 1000000] [--runs 5]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit, prange

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
import core  # noqa: E402
from bench_top_level import camera, scatter  # noqa: E402
from bench_two_level import sphere  # noqa: E402
from camera import camera_rays  # noqa: E402
from core.scene import two_level  # noqa: E402
from core.scene.instance_traversal import _to_object, mesh_tree, new_scratch, unowned_scene  # noqa: E402
from core.trace.array_views import keep_alive, rows  # noqa: E402
from core.trace.layout import LEAF  # noqa: E402
from core.trace.traversal import _descend, _pop, clip_to_box  # noqa: E402
from core.trace.triangle_test import intersect_leaf_triangle, ray_shear  # noqa: E402

WALK, TRANSFORM = 0, 1


@njit(cache=True, inline="always")
def _walk(scene, o, d, tmax, mode, scratch, counts):
    """The top-level walk of trace_scene up to tmax, with no mesh traversal: in each top leaf nothing
    (WALK) or each instance's transform and object-box clip (TRANSFORM). counts (7,) are added to:
    inner steps, leaves, instances entered, object boxes met."""
    axis, split, child, count, items = scene.top_axis, scene.top_split, scene.top_child, scene.top_count, scene.top_items
    stack_node, stack_t, inv = scratch[0], scratch[1], scratch[2]
    inv_obj, o_obj, d_obj = scratch[5], scratch[6], scratch[7]
    for k in range(3):
        inv[k] = 1.0 / d[k] if d[k] != 0.0 else 0.0
    t0, t1 = clip_to_box(scene.top_bounds, o, d, inv, 0.0, tmax)
    if t0 > t1:
        return 0.0
    node, sp, t_exit, met = 0, 0, t1, 0.0
    while True:
        a = axis[node]
        if a != LEAF:
            counts[0] += 1
            node, t1, t_exit, sp = _descend(node, a, split[node], child[node], o[a], d[a], inv[a], t0, t1, t_exit,
                                            (stack_node, stack_t), sp)
            continue
        counts[1] += 1
        if mode == TRANSFORM:
            for j in range(child[node], child[node] + count[node]):
                inst = items[j]
                counts[2] += 1
                _to_object(rows(scene.world_to_object, inst, inst + 1)[0], o, d, o_obj, d_obj)
                for k in range(3):
                    inv_obj[k] = 1.0 / d_obj[k] if d_obj[k] != 0.0 else 0.0
                b0, b1 = clip_to_box(rows(scene.mesh_bounds, scene.mesh_of[inst], scene.mesh_of[inst] + 1)[0],
                                     o_obj, d_obj, inv_obj, 0.0, tmax)
                if b0 <= b1:
                    counts[3] += 1
                    met += b0
        node, t0, t1, t_exit, sp = _pop(stack_node, stack_t, sp, tmax, False)
        if node < 0:
            break
    return met


@njit(cache=True, parallel=True)
def walk_rays(scene, origins, directions, tmax, mode, counts):
    """_walk for every ray (counts: (rays, 7), each ray's row), in blocks of 256 rays."""
    n = origins.shape[0]
    met = np.zeros((n + 255) // 256)
    for block in prange((n + 255) // 256):
        met[block] = _walk_block(scene, origins, directions, tmax, mode, counts, block * 256, min(n, block * 256 + 256))
    return met.sum()


@njit(cache=True)
def _walk_block(scene, origins, directions, tmax, mode, counts, start, stop):
    """Rays start..stop-1 with one scratch: a call of its own, as instance_traversal._trace_block, so each
    thread allocates its own scratch."""
    views = unowned_scene(scene)
    scratch, owners = new_scratch()
    met = 0.0
    for r in range(start, stop):
        met += _walk(views, origins[r], directions[r], tmax[r], mode, scratch, counts[r])
    keep_alive(owners)
    return met


@njit(cache=True)
def count_mesh_steps(scene, origins, directions, tmax, inst_of, counts):
    """The mesh tree's inner steps and triangle tests of each ray in the instance it hit (a counting
    copy of traversal.trace_ray without the leaf screen): counts[:, 4] and counts[:, 5]."""
    scratch, owners = new_scratch()
    stack_node, stack_t, inv, o_obj, d_obj = scratch[3], scratch[4], scratch[5], scratch[6], scratch[7]
    for r in range(origins.shape[0]):
        inst = inst_of[r]
        if inst < 0:
            continue
        _to_object(rows(scene.world_to_object, inst, inst + 1)[0], origins[r], directions[r], o_obj, d_obj)
        tree = mesh_tree(scene, scene.mesh_of[inst])
        for k in range(3):
            inv[k] = 1.0 / d_obj[k] if d_obj[k] != 0.0 else 0.0
        t0, t1 = clip_to_box(tree.bounds, o_obj, d_obj, inv, 0.0, tmax[r] * 1.0000001)
        kx, ky, kz, sx, sy, sz = ray_shear(d_obj)
        node, sp, t_exit, best = 0, 0, t1, tmax[r] * 1.0000001
        while t0 <= t1:
            a = tree.axis[node]
            if a < LEAF:
                counts[r, 4] += 1
                node, t1, t_exit, sp = _descend(node, a, tree.split[node], tree.child[node], o_obj[a], d_obj[a],
                                                inv[a], t0, t1, t_exit, (stack_node, stack_t), sp)
                continue
            for j in range(tree.child[node], tree.child[node] + tree.count[node]):
                counts[r, 5] += 1
                intersect_leaf_triangle(tree.leaf_triangles, tree.base + j, o_obj, kx, ky, kz, sx, sy, sz)
            node, t0, t1, t_exit, sp = _pop(stack_node, stack_t, sp, best, True)
            if node < 0:
                break
    keep_alive(owners)


def ao_rays(origins, directions, t, rng):
    """One ray a camera hit: from just before the hit, a random direction on the camera's side, length 1."""
    hit = np.isfinite(t)
    p = origins[hit] + (t[hit] * (1 - 1e-6))[:, None] * directions[hit]
    d = rng.normal(size=p.shape)
    d *= np.sign((d * -directions[hit]).sum(axis=1))[:, None]
    return np.ascontiguousarray(p), np.ascontiguousarray(d / np.linalg.norm(d, axis=1, keepdims=True))


def split_of(scene, origins, directions, limit, runs):
    """Median ms of full / transform / walk over `runs` alternating runs of rays (0, limit), and the mean
    counts a ray."""
    full = core.intersect_scene(scene, origins, directions, 0.0, limit)
    tmax = np.where(np.isfinite(full.t), full.t.astype(np.float64) * (1 + 1e-6), limit)
    arrays = scene.arrays
    times = {"full": [], "transform": [], "walk": []}
    for _ in range(runs):
        for name in times:
            counts = np.zeros((len(origins), 7), np.int64)
            t0 = time.perf_counter()
            if name == "full":
                core.intersect_scene(scene, origins, directions, 0.0, limit)
            else:
                walk_rays(arrays, origins, directions, tmax, TRANSFORM if name == "transform" else WALK, counts)
            times[name].append((time.perf_counter() - t0) * 1e3)
    counts = np.zeros((len(origins), 7), np.int64)
    walk_rays(arrays, origins, directions, tmax, TRANSFORM, counts)
    count_mesh_steps(arrays, origins, directions, tmax, full.instance, counts)
    return {k: float(np.median(v)) for k, v in times.items()}, counts.mean(axis=0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000000)
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    vertices, triangles = sphere(16, 16, rng, noise=0.2)
    tree = core.build_kdtree(vertices[triangles].astype(np.float32))
    t = time.perf_counter()
    mats, side = scatter(1000, rng)
    small = two_level.build_two_level([tree], np.zeros(len(mats), np.int64), mats)
    o, d = camera_rays(camera(side).matrix_world, 0.7, 32, 18)
    split_of(small, o, d, 1e30, 1)
    print(f"JIT compile / cache load: {time.perf_counter() - t:.1f} s")
    mats, side = scatter(args.count, rng)
    scene = two_level.build_two_level([tree], np.zeros(len(mats), np.int64), mats)
    cam = camera(side)
    o, d = camera_rays(cam.matrix_world, 0.7, 480, 270)
    first = core.intersect_scene(scene, o, d)
    ao_o, ao_d = ao_rays(o, d, first.t, rng)
    print(f"{args.count:,} instances; per ray: top inner steps, top leaves, instances entered, object boxes met, "
          "mesh steps, triangle tests (in the hit instance)")
    for kind, ro, rd, limit in (("camera", o, d, 1e30), ("ao", ao_o, ao_d, 1.0)):
        ms, per_ray = split_of(scene, ro, rd, limit, args.runs)
        top, transforms, bottom = ms["walk"], ms["transform"] - ms["walk"], ms["full"] - ms["transform"]
        print(f"{kind:>6}: {len(ro):,} rays, full {ms['full']:.0f} ms = top walk {top:.0f} "
              f"({100 * top / ms['full']:.0f}%) + transforms and object-box clips {transforms:.0f} "
              f"({100 * transforms / ms['full']:.0f}%) + mesh trees {bottom:.0f} ({100 * bottom / ms['full']:.0f}%)")
        print("        per ray: " + ", ".join(f"{x:.1f}" for x in per_ray[:6]))


if __name__ == "__main__":
    main()
