"""Camera-ray packets against build settings: which tree the packet traversal traces fastest.

Usage: python benchmarks/bench_packet_tree_options.py [--scene suzanne-251k] [--runs 15] [CONFIG_JSON ...]

Each CONFIG_JSON is a dict of build options (default: the SAH's intersection cost 0.3, the default, against
0.5, 0.8 and 1.2). One tree is built per setting; then, run by run and in alternating order, each tree's
bench_core camera rays are traced in packets (core.trace.packet_traversal.intersect_packets, 2 threads)
and the setting's tree is built again. Printed per setting: nodes and SAH cost, median packet time and
build time, and the medians of the per-run ratios to the first setting (the runs alternate their order,
so drifts of a shared machine fall on every setting alike). Hits are checked against core.intersect.
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from bench_core import CAMERA_WIDTH, camera_workload  # noqa: E402
from core.trace.packet_traversal import intersect_packets  # noqa: E402
from scenes import load_scene  # noqa: E402

DEFAULT_CONFIGS = ['{"intersection_cost": 0.3}', '{"intersection_cost": 0.5}', '{"intersection_cost": 0.8}',
                   '{"intersection_cost": 1.2}']


def timed(fn):
    t = time.perf_counter()
    result = fn()
    return time.perf_counter() - t, result


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--runs", type=int, default=15)
    ap.add_argument("configs", nargs="*", default=DEFAULT_CONFIGS)
    args = ap.parse_args()
    scene = load_scene(args.scene)
    origins, directions = camera_workload(scene)[:2]
    configs = [json.loads(text) for text in args.configs]
    jit, trees = timed(lambda: [core.build_kdtree(scene.triangles, **config) for config in configs])
    for tree in trees:
        reference = core.intersect(tree, origins, directions)
        packets = intersect_packets(tree, origins, directions, CAMERA_WIDTH)
        if not np.array_equal(packets.prim, reference.prim):
            raise SystemExit(f"packet hits differ from core.intersect's on {tree.options}")
    print(f"{args.scene}: {len(origins):,} camera rays; first builds and JIT {jit:.1f} s (excluded)")
    traces, builds = [[] for _ in configs], [[] for _ in configs]
    for run in range(args.runs):
        order = range(len(configs)) if run % 2 == 0 else reversed(range(len(configs)))
        for i in order:
            traces[i].append(timed(lambda: intersect_packets(trees[i], origins, directions, CAMERA_WIDTH))[0])
            builds[i].append(timed(lambda: core.build_kdtree(scene.triangles, **configs[i]))[0])
    trace_base, build_base = np.array(traces[0]), np.array(builds[0])
    for text, tree, trace, build in zip(args.configs, trees, traces, builds):
        stats = tree.stats()
        trace, build = np.array(trace), np.array(build)
        print(f"{text:>36}: {stats['nodes']:>7,} nodes, SAH {stats['sah_cost']:.3f}; packets "
              f"{np.median(trace) * 1e3:6.1f} ms (x{np.median(trace / trace_base):.3f}), build "
              f"{np.median(build) * 1e3:6.1f} ms (x{np.median(build / build_base):.3f})")


if __name__ == "__main__":
    main()
