"""Core benchmark: build time, tree statistics and ray throughput per builder, against Embree and BVHTree.

Usage: python benchmarks/bench_core.py [--scenes suzanne-251k,...] [--runs 5] [--sweep] [--no-refs] [--quick]

Prints one table per scene. Build times are medians of --runs builds after a warm-up build by each
builder that absorbs the JIT compile (reported on its own line); throughputs are medians of --runs
traces, camera rays also in packets (core.trace.packet_traversal, "packets"). Embree (embreex,
single-threaded: see reference_tracers.py; --runs traces after an untimed first call, as ours) and
Blender's BVHTree (Python loop over ray_cast, measured on a subset) trace the same rays in the same run;
ratios are ours divided by theirs. Peak build memory is measured in a child process per builder
(ru_maxrss growth over the loaded scene).

Writes benchmarks/out/bench_core.json (benchmarks/results.py: every run of each figure, its median, Embree's
runs of the same rays, the JIT time and the host); benchmarks/report.py renders the docs' tables from it.
--quick (suzanne-251k only, 3 runs, no memory or BVHTree children) checks that the benchmark works.
"""
import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import core  # noqa: E402
import results  # noqa: E402
from core.trace.packet_traversal import intersect_packets  # noqa: E402
from scenes import load_scene  # noqa: E402
from workload import CAMERA_WIDTH, ao_workload, camera_workload  # noqa: E402

BUILDERS = {
    "binned": {},
    "exact": {"builder": "exact"},
    "median": {"builder": "median"},
}
SWEEP = {
    "binned clip=False": {"clip": False},
    "binned top=clustering": {"top": "clustering"},
    "binned skip=True": {"skip": True},
    "binned exact_below=32": {"exact_below": 32},
    "binned exact_below=256": {"exact_below": 256},
    "binned leaf_size=8": {"leaf_size": 8},
    "binned empty_bonus=0.2": {"empty_bonus": 0.2},
    "binned cost_ratio=0.9": {"cost_ratio": 0.9},
    "binned max_depth=30": {"max_depth": 30},
    "binned Ci=4": {"intersection_cost": 4.0},
    "binned threads=1": {"threads": 1},
}


def median_time(fn, runs):
    times, result = timed_runs(fn, runs)
    return float(np.median(times)), result


def timed_runs(fn, runs):
    """(seconds of each of `runs` calls, the last call's result)."""
    times = []
    result = None
    for _ in range(runs):
        t = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t)
    return times, result


def peak_build_bytes_per_triangle(scene_name, options):
    """Peak RSS growth of one build, per triangle, measured in a fresh process after a warm-up.

    Linux keeps the peak (VmHWM) since process start, and loading the scene can peak higher than the
    build: writing 5 to /proc/self/clear_refs resets VmHWM to the current RSS just before the build.
    """
    code = (
        "import sys, json, numpy as np; sys.path[:0] = [%r, %r]\n"
        "import core; from scenes import load_scene\n"
        "def status(key):\n"
        "    for line in open('/proc/self/status'):\n"
        "        if line.startswith(key): return int(line.split()[1]) * 1024\n"
        "tris = load_scene(%r).triangles; core.build_kdtree(tris[:30000], **%r)\n"
        "open('/proc/self/clear_refs', 'w').write('5')\n"
        "base = status('VmRSS:')\n"
        "tree = core.build_kdtree(tris, **%r)\n"
        "print(json.dumps((status('VmHWM:') - base) / len(tris)))\n"
        % (str(HERE), str(HERE.parent), scene_name, options, options))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def bench_builder(scene, label, options, cam, ao, runs, memory):
    build_runs, tree = timed_runs(lambda: core.build_kdtree(scene.triangles, **options), runs)
    stats = tree.stats()
    cam_runs, _ = timed_runs(lambda: core.intersect(tree, *cam), runs)
    packet_runs, _ = timed_runs(lambda: intersect_packets(tree, *cam, CAMERA_WIDTH), runs)
    ao_runs, _ = timed_runs(lambda: core.occluded(tree, *ao, tmax=1.0), runs)
    build_s, cam_s, ao_s = (float(np.median(r)) for r in (build_runs, cam_runs, ao_runs))
    row = {
        "builder": label,
        "build_ms": build_s * 1e3,
        "Mtris/s": len(scene.triangles) / build_s / 1e6,
        "sah": stats["sah_cost"],
        "nodes": stats["nodes"],
        "leaves": stats["leaves"],
        "depth": stats["max_depth"],
        "refs/tri": stats["references_per_triangle"],
        "cam Mrays/s": len(cam[0]) / cam_s / 1e6,
        "packets Mrays/s": len(cam[0]) / float(np.median(packet_runs)) / 1e6,
        "ao Mrays/s": len(ao[0]) / ao_s / 1e6,
        "image_s": build_s + cam_s + ao_s,
    }
    if memory:
        row["peak B/tri"] = peak_build_bytes_per_triangle(scene.name, options)
    row["_runs"] = {"build_s": build_runs, "cam_s": cam_runs, "packets_s": packet_runs, "ao_s": ao_runs}
    return row


def bench_references(scene, cam, ao, runs, bvh_subset=20000):
    from reference_tracers import EmbreeTracer
    # Embree's BVH build timed as ours are: the median of `runs` builds (a first one can include
    # its thread pool's start-up, several times a build).
    commits = [EmbreeTracer(scene.triangles).commit_seconds for _ in range(runs)]
    embree = EmbreeTracer(scene.triangles)
    embree.closest(*cam)  # untimed first calls, as ours are warmed (a first call takes ~154 ms
    embree.occluded(*ao, 1.0)  # against 52-86 ms after, and would be the median of a one-run benchmark)
    cam_runs, _ = timed_runs(lambda: embree.closest(*cam), runs)
    ao_runs, _ = timed_runs(lambda: embree.occluded(*ao, 1.0), runs)
    cam_s, ao_s = float(np.median(cam_runs)), float(np.median(ao_runs))
    refs = {"embree": {"build_ms": float(np.median(commits)) * 1e3, "cam Mrays/s": len(cam[0]) / cam_s / 1e6,
                       "ao Mrays/s": len(ao[0]) / ao_s / 1e6, "_runs": {"cam_s": cam_runs, "ao_s": ao_runs}}}
    if bvh_subset:
        refs["bvhtree"] = _bvhtree_in_child(scene.name, bvh_subset)
    return refs


def _bvhtree_in_child(scene_name, subset):
    """BVHTree throughput, in a child process: importing bpy would switch Numba's threading layer here."""
    code = (
        "import sys, time, json, numpy as np; sys.path[:0] = [%r]\n"
        "import bpy\n"
        "from scenes import load_scene; from workload import camera_workload, ao_workload\n"
        "from reference_tracers import BlenderBVHTracer\n"
        "sc = load_scene(%r); o, d = camera_workload(sc); n = %d\n"
        "idx = np.random.default_rng(1).choice(len(o), n, replace=False)\n"
        "tr = BlenderBVHTracer(sc.triangles)\n"
        "t = time.perf_counter(); tt, pp = tr.closest(o[idx], d[idx]); cam = n / (time.perf_counter() - t) / 1e6\n"
        "ao_o, ao_d = ao_workload(sc.triangles, o[idx], d[idx], tt, pp)\n"
        "t = time.perf_counter(); tr.occluded(ao_o, ao_d, 1.0); ao = len(ao_o) / (time.perf_counter() - t) / 1e6\n"
        "print(json.dumps({'build_ms': tr.build_seconds * 1e3, 'cam Mrays/s': cam, 'ao Mrays/s': ao}))\n"
        % (str(HERE), scene_name, subset))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr else "failed"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def print_table(rows, refs):
    cols = [c for c in rows[0] if not c.startswith("_")]
    print(" | ".join(f"{c:>12}" for c in cols))
    for r in rows:
        print(" | ".join(f"{r[c]:>12.3f}" if isinstance(r[c], float) else f"{r[c]!s:>12}" for c in cols))
    for name, ref in refs.items():
        print(f"{name}: " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                                      for k, v in ref.items() if not k.startswith("_")))
        if "cam Mrays/s" not in ref:
            continue
        for r in rows[:len(BUILDERS)]:
            print(f"   {r['builder']:>10} / {name}: camera {r['cam Mrays/s'] / ref['cam Mrays/s']:.2f}x, "
                  f"camera packets {r['packets Mrays/s'] / ref['cam Mrays/s']:.2f}x, "
                  f"AO {r['ao Mrays/s'] / ref['ao Mrays/s']:.2f}x")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="suzanne-251k,suzanne-1m,soup-1m")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--sweep", action="store_true", help="also measure the binned builder's settings")
    ap.add_argument("--no-refs", action="store_true", help="skip Embree and BVHTree")
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory child processes")
    ap.add_argument("--config", action="append", default=[],
                    help="extra binned configuration, e.g. 'empty_bonus=0.2,max_depth=30' (repeatable)")
    ap.add_argument("--only-configs", action="store_true", help="measure only the --config rows")
    ap.add_argument("--json", help="also write all rows to this file (the old flat format)")
    ap.add_argument("--quick", action="store_true",
                    help="suzanne-251k, 3 runs, no memory or BVHTree children: checks the benchmark works")
    ap.add_argument("--out", default=str(results.OUT_DIR), help="folder of bench_core.json")
    args = ap.parse_args()
    if args.quick:
        args.scenes, args.runs, args.no_memory = "suzanne-251k", min(args.runs, 3), True

    t = time.perf_counter()
    for options in BUILDERS.values():  # each builder's kernels, so no timed build compiles
        core.build_kdtree(load_scene("suzanne-251k").triangles, **options)
    tiny = core.build_kdtree(np.eye(3, dtype=np.float32)[None])
    core.intersect(tiny, np.zeros((1, 3)), np.ones((1, 3)))
    core.occluded(tiny, np.zeros((2, 3)), np.ones((2, 3)))  # two rays from one origin: the packet kernel too
    intersect_packets(tiny, np.zeros((8, 3)), np.ones((8, 3)), 4)
    jit_seconds = time.perf_counter() - t
    print(f"JIT compile / cache load and warm-up: {jit_seconds:.2f} s (not in any figure below)")

    everything, scenes_out = {}, {}
    for name in args.scenes.split(","):
        scene = load_scene(name)
        cam = camera_workload(scene)
        probe = core.intersect(core.build_kdtree(scene.triangles), *cam)
        ao = ao_workload(scene.triangles, *cam, probe.t.astype(np.float64), probe.prim)
        print(f"\n== {name}: {len(scene.triangles):,} triangles, {len(cam[0]):,} camera rays, "
              f"{len(ao[0]):,} AO rays; threads {core_threads()}")
        configs = {} if args.only_configs else dict(BUILDERS)
        if args.sweep:
            configs.update(SWEEP)
        configs.update({c: parse_config(c) for c in args.config})
        rows = [bench_builder(scene, label, opts, cam, ao, args.runs, not args.no_memory and label in BUILDERS)
                for label, opts in configs.items()]
        refs = {} if args.no_refs else bench_references(scene, cam, ao, args.runs, 0 if args.quick else 20000)
        print_table(rows, refs)
        everything[name] = {"rows": rows, "refs": refs}
        scenes_out[name] = scene_results(scene, cam, ao, rows, refs)
    if args.json:
        Path(args.json).write_text(json.dumps(everything, indent=1))
    results.write("bench_core", {"runs": args.runs, "scenes": scenes_out}, jit_seconds, args.quick, args.out)


def scene_results(scene, cam, ao, rows, refs):
    """One scene's figures for bench_core.json: per builder the build time, SAH cost, tree statistics and
    camera and AO throughput (every run and the median), Embree's runs of the same rays as the reference."""
    embree = refs.get("embree")
    rates = lambda n, seconds: [n / s / 1e6 for s in seconds]  # noqa: E731
    builders = {}
    for r in rows:
        runs = r["_runs"]
        entry = {
            "build_ms": results.figure([s * 1e3 for s in runs["build_s"]], unit="ms"),
            "camera_mrays": results.figure(rates(len(cam[0]), runs["cam_s"]),
                                           embree and rates(len(cam[0]), embree["_runs"]["cam_s"]), "Mrays/s"),
            "camera_packets_mrays": results.figure(rates(len(cam[0]), runs["packets_s"]),
                                                   embree and rates(len(cam[0]), embree["_runs"]["cam_s"]), "Mrays/s"),
            "ao_mrays": results.figure(rates(len(ao[0]), runs["ao_s"]),
                                       embree and rates(len(ao[0]), embree["_runs"]["ao_s"]), "Mrays/s"),
            **{key: r[col] for key, col in (("sah_cost", "sah"), ("nodes", "nodes"), ("leaves", "leaves"),
                                            ("max_depth", "depth"), ("references_per_triangle", "refs/tri"),
                                            ("peak_bytes_per_triangle", "peak B/tri")) if col in r},
        }
        builders[r["builder"]] = entry
    out = {"triangles": len(scene.triangles), "camera_rays": len(cam[0]), "ao_rays": len(ao[0]),
           "threads": core_threads(), "builders": builders}
    if embree:
        out["embree"] = {"build_ms": embree["build_ms"], "threads": 1,
                         "camera_mrays": results.figure(rates(len(cam[0]), embree["_runs"]["cam_s"]), unit="Mrays/s"),
                         "ao_mrays": results.figure(rates(len(ao[0]), embree["_runs"]["ao_s"]), unit="Mrays/s")}
    if "bvhtree" in refs:
        out["bvhtree"] = refs["bvhtree"]
    return out


def parse_config(text):
    """'a=1,b=x' -> {'a': 1, 'b': 'x'} with numbers, booleans and None parsed."""
    out = {}
    for item in filter(None, text.split(",")):
        key, value = item.split("=")
        out[key.strip()] = json.loads(value) if value not in ("True", "False", "None") else eval(value)
    return out


def core_threads():
    import numba
    return numba.get_num_threads()


if __name__ == "__main__":
    main()
