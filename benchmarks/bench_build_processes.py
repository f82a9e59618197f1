"""The default build of this tree against a git revision's, in separate processes taken by turns.

Usage: python benchmarks/bench_build_processes.py --base REV --base-folder DIR [--rounds 4] [--builds 15]
       [--threads 2] [--scene suzanne-251k]

bench_build_against_revision.py alternates the two versions in one process; on a host other sessions
load, its paired medians moved by 4-10% with identical code
(docs/choices.md#where-the-build-stands-after-keeping-its-freed-memory).
Here each round starts one process per version (this tree, then the base, exported once into
--base-folder as bench_build_against_revision.py does, so its compiled kernels stay cached); each
process makes 3 warm-up builds and `--builds` timed ones and reports the minimum and median wall time and
process CPU time of a build. Printed: each process's figures, then per version the median of the
processes' minima and the ratio this tree / base of those medians.
"""
import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def child(version, revision, base_folder, scene, threads, builds):
    """One process's builds: JSON with the minimum and median wall and CPU time of a build (ms)."""
    sys.path.insert(0, str(HERE))
    if version == "base":
        from bench_build_against_revision import exported_once  # noqa: PLC0415
        core = exported_once(revision, base_folder)
    else:
        sys.path.insert(0, str(HERE.parent))
        import core  # noqa: PLC0415
    from scenes import load_scene  # noqa: PLC0415
    triangles = load_scene(scene).triangles
    for _ in range(3):
        core.build_kdtree(triangles, threads=threads)
    wall, cpu = [], []
    for _ in range(builds):
        w, c = time.perf_counter(), time.process_time()
        core.build_kdtree(triangles, threads=threads)
        wall.append((time.perf_counter() - w) * 1e3)
        cpu.append((time.process_time() - c) * 1e3)
    print(json.dumps({"version": version, "wall_min": min(wall), "wall_median": float(np.median(wall)),
                      "cpu_min": min(cpu), "cpu_median": float(np.median(cpu))}))


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--base", required=True)
    ap.add_argument("--base-folder", required=True)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--builds", type=int, default=15)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--child", choices=("this", "base"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.base, args.base_folder, args.scene, args.threads, args.builds)
        return
    sys.path.insert(0, str(HERE))
    from bench_build_against_revision import exported_once  # noqa: PLC0415
    exported_once(args.base, args.base_folder)  # exported (and its marker written) before the rounds
    runs = {"this": [], "base": []}
    for _ in range(args.rounds):
        for version in runs:
            out = subprocess.run([sys.executable, __file__, "--child", version, "--base", args.base,
                                  "--base-folder", args.base_folder, "--scene", args.scene,
                                  "--threads", str(args.threads), "--builds", str(args.builds)],
                                 check=True, capture_output=True, text=True).stdout
            figures = json.loads(out.strip().splitlines()[-1])
            runs[version].append(figures)
            print(" ".join(f"{k} {v:.1f}" if isinstance(v, float) else f"{k} {v}" for k, v in figures.items()),
                  flush=True)
    for key in ("cpu_min", "wall_min"):
        this, base = (float(np.median([r[key] for r in runs[v]])) for v in ("this", "base"))
        print(f"{key}: median over processes, this tree {this:.1f} ms, base {args.base} {base:.1f} ms, "
              f"ratio {this / base:.3f}")


if __name__ == "__main__":
    main()
