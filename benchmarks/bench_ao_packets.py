"""AO occlusion rays in any-hit packets against the single-ray kernel and embreex, in one process.

Usage: python benchmarks/bench_ao_packets.py [--scene suzanne-251k] [--rounds 7] [--told]

bench_core's AO rays (workload.ao_workload: 8 cosine-weighted rays a camera hit, tmax 1, consecutive,
one origin each) traced by `core.occluded` (packets for runs of one origin: occlusion_packets.py), by
the single-ray any-hit kernel on every ray (what core.occluded did before), and by embreex on one
thread, by turns in each round. Printed: Mrays/s medians and the per-round ratios; `--told` builds the
tree told the frame's rays (as bench_against_revision does: fewer, bigger leaves). Answers must match.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from core.jit.threads import thread_count  # noqa: E402
from core.trace.traversal import trace_rays  # noqa: E402
from reference_tracers import EmbreeTracer  # noqa: E402
from scenes import load_scene  # noqa: E402
from workload import ao_workload, camera_workload  # noqa: E402


def single_rays(tree, o, d, tmax):
    n = len(o)
    out = [np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n)]
    with thread_count(None):
        trace_rays(tree.arrays, o, d, np.zeros(n), np.full(n, tmax), True, *out)
    return out[1] >= 0


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--told", action="store_true", help="build the tree told the frame's rays")
    args = ap.parse_args()
    scene = load_scene(args.scene)
    cam = camera_workload(scene)
    rays = core.frame_ray_count(640, 480, "shadow", 1, [core.Light.point((2.0, -3.0, 4.0))]) if args.told else None
    tree = core.build_kdtree(scene.triangles, rays=rays)
    probe = core.intersect(tree, *cam)
    o, d = ao_workload(scene.triangles, *cam, probe.t.astype(np.float64), probe.prim)
    embree = EmbreeTracer(scene.triangles)
    runs = {"packets": lambda: core.occluded(tree, o, d, tmax=1.0), "single rays": lambda: single_rays(tree, o, d, 1.0),
            "embreex 1 thread": lambda: embree.occluded(o, d, 1.0)}
    answers = [f() for f in runs.values()]  # also the compile / warm-up, untimed
    print(f"{args.scene}: {len(o):,} AO rays, {tree}; packets equal single rays: "
          f"{np.array_equal(answers[0], answers[1])}, occluded {answers[0].mean():.3f}")
    times = {name: [] for name in runs}
    for _ in range(args.rounds):
        for name, f in runs.items():
            t = time.perf_counter()
            f()
            times[name].append(time.perf_counter() - t)
    for name, t in times.items():
        print(f"{name:>17}: {len(o) / np.median(t) / 1e6:6.2f} Mrays/s")
    ref = np.array(times["embreex 1 thread"])
    for name in ("packets", "single rays"):
        print(f"{name:>17} / embreex: {np.median(ref / np.array(times[name])):.3f} (per-round median)")
    print(f"packets / single rays: {np.median(np.array(times['single rays']) / np.array(times['packets'])):.3f}x")


if __name__ == "__main__":
    main()
