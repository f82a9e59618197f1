"""Packet traversal benchmark: camera rays in packets (core.packet_traversal, tiles of simd.LANES pixels)
against core.intersect and Embree, on suzanne-251k.

Usage: python benchmarks/bench_packets.py [--scene suzanne-251k] [--width 640 --height 480] [--runs 7]
                                          [--no-compile] [--json benchmarks/out/bench_packets.json]

In one process and one run: packets on 1 and 2 threads, core.intersect on 2 threads, embreex on 1 thread
(its only mode: reference_tracers.py), each called once untimed, then --runs rounds taking the four in
turn (so load from other processes falls on all of them alike); medians of wall time, with the
process's CPU time beside them. The *_kernel rows time the kernels alone (packet kernel plus the
single-ray kernel for its leftovers; core's single-ray kernel), without the queries' input checks,
which cost the same for both queries. Compile time is measured apart, in a child process with an empty Numba
cache (the packet kernel's first call, and core.intersect's for scale). Agreement: hit triangles of
the packets against core.intersect (expected identical) and against Embree (float32, its own ties).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import core  # noqa: E402
from core.trace.packet_traversal import (TILE_SHAPE, PacketOutputs, PacketRays, intersect_packets, packet_order,  # noqa: E402
                                        trace_packets)
from core.jit.threads import thread_count  # noqa: E402
from core.trace.traversal import trace_rays  # noqa: E402
from scenes import load_scene  # noqa: E402
from workload import camera_workload  # noqa: E402

COMPILE_CHILD = """
import sys, time, json, numpy as np
sys.path[:0] = [%r]
import core
from core.trace.packet_traversal import intersect_packets
tree = core.build_kdtree(np.eye(3, dtype=np.float32)[None])
o, d = np.zeros((8, 3)), np.ones((8, 3))
t = time.perf_counter(); intersect_packets(tree, o, d, 4); packets = time.perf_counter() - t
t = time.perf_counter(); intersect_packets(tree, o, d, 4); again = time.perf_counter() - t
t = time.perf_counter(); core.intersect(tree, o, d); single = time.perf_counter() - t
print(json.dumps({"packets_compile_s": packets, "packets_second_call_s": again, "intersect_compile_s": single}))
"""


def compile_seconds():
    """First-call times with an empty Numba cache, in a child process (the build's kernels are compiled
    before the clock starts, by the tiny build)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, "-c", COMPILE_CHILD % str(HERE.parent)], env=env, capture_output=True,
                             text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def timed(fn):
    wall, cpu = time.perf_counter(), time.process_time()
    result = fn()
    return time.perf_counter() - wall, time.process_time() - cpu, result


def agreement(prim_a, t_a, prim_b, t_b):
    same = prim_a == prim_b
    both = (prim_a >= 0) & (prim_b >= 0)
    rel = np.abs(t_a[both].astype(np.float64) - t_b[both]) / np.maximum(np.abs(t_b[both]), 1e-30)
    return {"prim_agree": float(same.mean()), "hit_miss_agree": float(((prim_a >= 0) == (prim_b >= 0)).mean()),
            "t_max_rel_diff": float(rel.max()) if rel.size else 0.0,
            "t_max_rel_diff_same_prim": float(rel[same[both]].max()) if same[both].any() else 0.0}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--no-compile", action="store_true", help="skip the cold-compile child process")
    ap.add_argument("--json", default=str(HERE / "out" / "bench_packets.json"))
    args = ap.parse_args()

    compile_info = {} if args.no_compile else compile_seconds()
    scene = load_scene(args.scene)
    o, d = camera_workload(scene, args.width, args.height)
    n = len(o)
    tree = core.build_kdtree(scene.triangles)
    from reference_tracers import EmbreeTracer
    embree = EmbreeTracer(scene.triangles)
    stats = {}
    tracers = {
        "packets_1t": lambda: intersect_packets(tree, o, d, args.width, threads=1, stats=stats),
        "packets_2t": lambda: intersect_packets(tree, o, d, args.width, threads=2),
        "intersect_2t": lambda: core.intersect(tree, o, d, threads=2),
        "embree_1t": lambda: embree.closest(o, d),
        "packets_kernel_1t": kernel_packets(tree, o, d, args.width, args.height, 1),
        "packets_kernel_2t": kernel_packets(tree, o, d, args.width, args.height, 2),
        "trace_rays_kernel_2t": kernel_single(tree, o, d, 2),
    }
    t = time.perf_counter()
    results = {name: fn() for name, fn in tracers.items()}  # untimed first calls (cache loads, warm-up)
    warm_s = time.perf_counter() - t
    walls = {name: [] for name in tracers}
    cpus = {name: [] for name in tracers}
    for _ in range(args.runs):
        for name, fn in tracers.items():
            wall, cpu, _ = timed(fn)
            walls[name].append(wall)
            cpus[name].append(cpu)

    mrays = {name: n / float(np.median(w)) / 1e6 for name, w in walls.items()}
    packets, single, (embree_t, embree_prim) = results["packets_1t"], results["intersect_2t"], results["embree_1t"]
    report = {
        "scene": args.scene, "triangles": int(len(scene.triangles)), "rays": n,
        "image": [args.width, args.height], "runs": args.runs, "tile": list(TILE_SHAPE),
        "Mrays_per_s_median": mrays,
        "wall_s_runs": walls, "cpu_s_runs": cpus,
        "cpu_ms_per_Mray_median": {k: float(np.median(v)) / n * 1e9 for k, v in cpus.items()},
        "ratios": {
            "packets_1t / embree_1t": mrays["packets_1t"] / mrays["embree_1t"],
            "packets_2t / embree_1t": mrays["packets_2t"] / mrays["embree_1t"],
            "packets_2t / intersect_2t": mrays["packets_2t"] / mrays["intersect_2t"],
            "packets_1t / intersect_2t": mrays["packets_1t"] / mrays["intersect_2t"],
            "intersect_2t / embree_1t": mrays["intersect_2t"] / mrays["embree_1t"],
            "packets_kernel_1t / trace_rays_kernel_2t": mrays["packets_kernel_1t"] / mrays["trace_rays_kernel_2t"],
            "packets_kernel_2t / trace_rays_kernel_2t": mrays["packets_kernel_2t"] / mrays["trace_rays_kernel_2t"],
            "packets_kernel_1t / embree_1t": mrays["packets_kernel_1t"] / mrays["embree_1t"],
        },
        "single_ray_fraction": stats["single_rays"] / n, "packets": stats["packets"],
        "agreement_vs_intersect": agreement(packets.prim, packets.t, single.prim, single.t),
        "agreement_vs_embree": agreement(packets.prim, packets.t, embree_prim, embree_t),
        "compile": compile_info, "warm_up_s": warm_s,
        "threads_available": core_threads(), "load_average": os.getloadavg(),
    }
    print_report(report)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(report, indent=1))
    print(f"written {args.json}")


def kernel_packets(tree, o, d, width, height, threads):
    """The packet kernel and the single-ray kernel for its leftovers, without the input checks and
    conversions of the query functions (what a renderer's kernel would run)."""
    n, order = len(o), packet_order(width, height)
    lo, hi = np.zeros(n), np.full(n, np.inf)

    def run():
        out = (np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n))
        single = np.zeros(n, np.uint8)
        with thread_count(threads):
            trace_packets(tree.arrays, PacketRays(o, d, lo, hi, order), PacketOutputs(*out, single))
            rest = np.flatnonzero(single)
            if len(rest):
                trace_rays(tree.arrays, o[rest], d[rest], lo[rest], hi[rest], False,
                           *(a[rest].copy() for a in out))
        return out

    return run


def kernel_single(tree, o, d, threads):
    """core's single-ray kernel (traversal.trace_rays) without the query's checks and conversions."""
    n = len(o)
    lo, hi = np.zeros(n), np.full(n, np.inf)

    def run():
        out = (np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n))
        with thread_count(threads):
            trace_rays(tree.arrays, o, d, lo, hi, False, *out)
        return out

    return run


def print_report(r):
    print(f"== {r['scene']}: {r['triangles']:,} triangles, {r['rays']:,} camera rays "
          f"({r['image'][0]}x{r['image'][1]}), {r['tile'][0]}x{r['tile'][1]} packets, medians of {r['runs']} runs; "
          f"load average {r['load_average'][0]:.1f}")
    for name, m in r["Mrays_per_s_median"].items():
        print(f"  {name:>14}: {m:7.2f} Mrays/s   (CPU {r['cpu_ms_per_Mray_median'][name]:6.1f} ms per Mray)")
    for name, ratio in r["ratios"].items():
        print(f"  {name:>28}: {ratio:.2f}x")
    print(f"  rays traced singly (mixed signs or zero components): {r['single_ray_fraction']:.4%}")
    for ref in ("intersect", "embree"):
        a = r[f"agreement_vs_{ref}"]
        print(f"  vs {ref}: prim agree {a['prim_agree']:.6%}, hit/miss agree {a['hit_miss_agree']:.6%}, "
              f"t max rel diff {a['t_max_rel_diff']:.3g} (same prim {a['t_max_rel_diff_same_prim']:.3g})")
    if r["compile"]:
        c = r["compile"]
        print(f"  cold compile (empty cache): packets {c['packets_compile_s']:.1f} s, core.intersect "
              f"{c['intersect_compile_s']:.1f} s; warm first calls here {r['warm_up_s']:.2f} s")


def core_threads():
    import numba
    return numba.get_num_threads()


if __name__ == "__main__":
    main()
