"""The packet kernel alone against Embree, in one process, for comparing revisions of core run by turns.

Usage: python benchmarks/bench_packet_kernel.py [ROOT] [--runs 7]

ROOT is a folder holding a `core/` package (default: this checkout), e.g. another revision exported with
`git archive REV | tar -x -C ROOT` (copy benchmarks/data/suzanne-251k.* there too). Traces suzanne-251k's
640 x 480 camera rays with `trace_packets` on one thread and with embreex (one thread), alternating,
after an untimed call each, and prints the median CPU time per million rays of both and their ratio:
run it for two ROOTs in turn, several times, and compare the ratios (Embree is the same-run reference
that absorbs the host's load).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", nargs="?", default=str(Path(__file__).resolve().parent.parent))
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()
    sys.path[:0] = [str(Path(__file__).resolve().parent), args.root]  # the ROOT's core, imported below
    import core
    from core.jit.threads import thread_count
    from core.trace.packet_traversal import PacketOutputs, PacketRays, packet_order, trace_packets
    from reference_tracers import EmbreeTracer
    from scenes import load_scene
    from workload import camera_workload

    scene = load_scene("suzanne-251k")
    o, d = camera_workload(scene, 640, 480)
    n = len(o)
    tree = core.build_kdtree(scene.triangles)
    embree = EmbreeTracer(scene.triangles)
    rays = PacketRays(o, d, np.zeros(n), np.full(n, np.inf), packet_order(640, 480))

    def packets():
        out = PacketOutputs(np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n), np.zeros(n, np.uint8))
        with thread_count(1):
            trace_packets(tree.arrays, rays, out)

    packets()
    embree.closest(o, d)
    ours, theirs = [], []
    for _ in range(args.runs):
        for fn, times in ((packets, ours), (lambda: embree.closest(o, d), theirs)):
            cpu = time.process_time()
            fn()
            times.append(time.process_time() - cpu)
    a, b = float(np.median(ours)), float(np.median(theirs))
    print(f"{args.root}: packet kernel {a / n * 1e9:.1f} ms CPU per Mray, Embree {b / n * 1e9:.1f}; "
          f"ours / Embree speed {b / a:.3f}")


if __name__ == "__main__":
    main()
