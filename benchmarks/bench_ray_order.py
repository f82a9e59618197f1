"""Does reordering incoherent rays make single-ray tracing faster? bench_core's AO rays (8 a camera hit,
length 1, any hit) traced as given and reordered by direction octant and origin Morton code (Garanzha and
Loop 2010 sort rays so; here without their packets), each order paired in the same run.

Usage: python benchmarks/bench_ray_order.py [--scene suzanne-251k] [--runs 7] [--threads N]

Prints per order the median trace time, the median of the per-run ratios to the given order, and the
NumPy cost of computing the order (key and argsort), which a kept reordering would pay on every call.
Checks that every order gives the same answer per ray.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from scenes import load_scene  # noqa: E402
from workload import ao_workload, camera_workload  # noqa: E402

BITS = 10  # Morton bits per axis


def _spread(q):
    """The low 10 bits of q moved to every third bit (Morton interleave)."""
    q = q.astype(np.uint64) & np.uint64(0x3FF)
    for shift, mask in ((16, 0x30000FF), (8, 0x300F00F), (4, 0x30C30C3), (2, 0x9249249)):
        q = (q | (q << np.uint64(shift))) & np.uint64(mask)
    return q


def order_keys(origins, directions):
    """(Morton code of the origin in the origins' box, direction octant) per ray."""
    lo, hi = origins.min(0), origins.max(0)
    q = ((origins - lo) / np.maximum(hi - lo, 1e-30) * (2 ** BITS - 1)).astype(np.uint64)
    code = _spread(q[:, 0]) | (_spread(q[:, 1]) << np.uint64(1)) | (_spread(q[:, 2]) << np.uint64(2))
    octant = ((directions[:, 0] < 0) * 1 + (directions[:, 1] < 0) * 2 + (directions[:, 2] < 0) * 4).astype(np.uint64)
    return code, octant


ORDERS = {
    "as given": None,
    "octant": lambda code, octant: octant,
    "morton": lambda code, octant: code,
    "octant, then morton": lambda code, octant: (octant << np.uint64(3 * BITS)) | code,
    "morton, then octant": lambda code, octant: (code << np.uint64(3)) | octant,
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    if args.threads:
        import numba  # noqa: PLC0415
        numba.set_num_threads(args.threads)
    scene = load_scene(args.scene)
    cam = camera_workload(scene)
    tree = core.build_kdtree(scene.triangles)
    probe = core.intersect(tree, *cam)
    o, d = ao_workload(scene.triangles, *cam, probe.t.astype(np.float64), probe.prim)
    t = time.perf_counter()
    code, octant = order_keys(o, d)
    orders = {name: np.arange(len(o)) if key is None else np.argsort(key(code, octant), kind="stable")
              for name, key in ORDERS.items()}
    cost = (time.perf_counter() - t) / (len(ORDERS) - 1)
    reference = core.occluded(tree, o, d, tmax=1.0)
    rays = {name: (o[order].copy(), d[order].copy()) for name, order in orders.items()}
    for name, (oo, dd) in rays.items():
        assert np.array_equal(core.occluded(tree, oo, dd, tmax=1.0), reference[orders[name]]), name
    times = {name: [] for name in rays}
    for run in range(args.runs):
        items = list(rays.items())
        for name, (oo, dd) in items if run % 2 == 0 else items[::-1]:
            t = time.perf_counter()
            core.occluded(tree, oo, dd, tmax=1.0)
            times[name].append(time.perf_counter() - t)
    given = np.array(times["as given"])
    print(f"{args.scene}: {len(o):,} AO rays, {args.runs} runs; computing one order in NumPy: {cost * 1e3:.0f} ms")
    for name, t in times.items():
        print(f"{name:>20}: {np.median(t) * 1e3:7.1f} ms  {len(o) / np.median(t) / 1e6:5.2f} Mrays/s  "
              f"ratio to the given order {np.median(np.array(t) / given):.3f}")


if __name__ == "__main__":
    main()
