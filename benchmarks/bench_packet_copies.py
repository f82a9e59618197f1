"""The packet kernel of several copies of core in ONE process, by turns, against Embree: paired
comparisons of revisions or of variants (a part done twice, a part left out) for profiling.

Usage: python benchmarks/bench_packet_copies.py DIR/NAME [DIR/NAME ...] [--runs 41] [--threads 1] [--rays N]

Each DIR/NAME is a copy of `core/` under another package name, e.g.
`mkdir -p /tmp/pv/base && git archive REV core | tar -x -C /tmp/pv/base --strip-components=1`
(core imports itself only relatively, so the copies load side by side, each with its own Numba
cache). Traces suzanne-251k's 640 x 480 camera rays with each copy's `trace_packets` on --threads
threads and with embreex (one thread), through the default tree or, with --rays, a tree told that many
rays (seed 000's setting is 614400), after an untimed call each (which compiles), checks each copy's
hits against core.intersect, then takes --runs rounds of all of them in turn and prints medians of the
time per million rays (CPU time on one thread, wall time on more), the speed against Embree and the
time against the first copy.
"""
import argparse
import importlib
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def copy_arrays(tree_arrays, arrays):
    """This tree's arrays as a copy's TreeArrays, field by field: a copy from before a field was added
    (leaf_boxes) takes the fields it knows."""
    return tree_arrays(*[getattr(arrays, name) for name in tree_arrays._fields])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("copies", nargs="+")
    ap.add_argument("--runs", type=int, default=41)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--rays", type=int, default=None, help="build the tree told this many rays")
    args = ap.parse_args()
    sys.path[:0] = [str(HERE), str(HERE.parent)] + [str(Path(c).resolve().parent) for c in args.copies]
    import core
    from core.jit.threads import thread_count
    from reference_tracers import EmbreeTracer
    from scenes import load_scene
    from workload import camera_workload

    scene = load_scene("suzanne-251k")
    o, d = camera_workload(scene, 640, 480)
    n = len(o)
    tree = core.build_kdtree(scene.triangles, **({} if args.rays is None else {"rays": args.rays}))
    embree = EmbreeTracer(scene.triangles)
    reference = core.intersect(tree, o, d)
    tracers = {}
    for copy in args.copies:
        name = Path(copy).name
        packets = importlib.import_module(name + ".trace.packet_traversal")
        arrays = copy_arrays(importlib.import_module(name + ".trace.layout").TreeArrays, tree.arrays)
        rays = packets.PacketRays(o, d, np.zeros(n), np.full(n, np.inf), packets.packet_order(640, 480))

        def run(packets=packets, arrays=arrays, rays=rays):
            out = packets.PacketOutputs(np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n),
                                        np.zeros(n, np.uint8))
            with thread_count(args.threads):
                packets.trace_packets(arrays, rays, out)
            return out

        start = time.perf_counter()
        out = run()
        kept = out.single == 0
        same = (np.array_equal(out.prim[kept], reference.prim[kept])
                and np.array_equal(out.t[kept].astype(np.float32), reference.t[kept]))
        print(f"{name}: first call {time.perf_counter() - start:.1f} s, {(~kept).sum()} rays left to single rays, "
              f"hits equal to core.intersect: {same}", flush=True)
        tracers[name] = run
    tracers["embree"] = lambda: embree.closest(o, d)
    tracers["embree"]()
    cpu = {name: [] for name in tracers}
    clock, kind = (time.process_time, "CPU") if args.threads == 1 else (time.perf_counter, "wall")
    for _ in range(args.runs):
        for name, fn in tracers.items():
            start = clock()
            fn()
            cpu[name].append(clock() - start)
    median = {name: float(np.median(times)) for name, times in cpu.items()}
    first = Path(args.copies[0]).name
    for name in tracers:
        print(f"{name:>16}: {median[name] / n * 1e9:7.1f} ms {kind} per Mray, ours / Embree speed "
              f"{median['embree'] / median[name]:.3f}, time / {first} {median[name] / median[first]:.3f}")


if __name__ == "__main__":
    main()
