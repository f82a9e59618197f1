"""Paired A/B of the default build (`core.build_kdtree(tris)`, no options) against a git revision's
core, on 2 threads and on 1, in one process.

Usage: python benchmarks/bench_build_against_revision.py [--base HEAD] [--scene suzanne-251k] [--pairs 9]
       [--base-folder DIR]

bench_against_revision.py times the build told the rays (seed 000's setting), which turns clipping and
snapping off; this one times the default build. The base's core is exported as `core_base` the same
way (its kernels compiled afresh, excluded; with --base-folder it is exported there once and reused, so its
compiled kernels stay cached between runs). Printed per thread count: medians of each version, the
median of the per-pair ratios (this tree / base), each tree's SAH cost and whether the trees are equal.
On 1 thread the build runs in the calling thread, so its CPU time (time.thread_time) is printed too:
on a host other processes load, it moves far less than the wall time.
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_against_revision import export_base

import core  # noqa: E402  (bench_against_revision put the worktree on sys.path)
from scenes import load_scene  # noqa: E402


def paired(versions, triangles, threads, pairs, clock=time.perf_counter):
    """Per-version build times (ms, by `clock`) over `pairs` alternating pairs."""
    times = {name: [] for name in versions}
    for pair in range(pairs):
        order = list(versions.items()) if pair % 2 == 0 else list(versions.items())[::-1]
        for name, version in order:
            t = clock()
            version.build_kdtree(triangles, threads=threads)
            times[name].append((clock() - t) * 1e3)
    return {name: np.array(t) for name, t in times.items()}


def exported_once(revision, folder):
    """The revision's core as core_base from `folder`, exported there on the first call only."""
    folder = Path(folder)
    marker = folder / "revision.txt"
    if marker.exists():
        if marker.read_text() != revision:
            raise SystemExit(f"{folder} holds revision {marker.read_text()}, not {revision}: use another folder")
        sys.path.insert(0, str(folder))
        import core_base  # noqa: PLC0415
        return core_base
    folder.mkdir(parents=True, exist_ok=True)
    base = export_base(revision, folder)
    marker.write_text(revision)
    return base


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--base", default="HEAD")
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--pairs", type=int, default=9)
    ap.add_argument("--base-folder", default=None, help="export the base here once and reuse it")
    args = ap.parse_args()
    triangles = load_scene(args.scene).triangles
    with tempfile.TemporaryDirectory() as folder:
        base = exported_once(args.base, args.base_folder) if args.base_folder else export_base(args.base, folder)
        versions = {"this tree": core, f"base {args.base}": base}
        t = time.perf_counter()
        trees = {name: v.build_kdtree(triangles, threads=2) for name, v in versions.items()}
        print(f"JIT compile / cache load: {time.perf_counter() - t:.1f} s (excluded); {args.scene}, {args.pairs} pairs")
        same = all(np.array_equal(a, b) for a, b in zip(*(tr.node_arrays for tr in trees.values())))
        one = [v.build_kdtree(triangles, threads=1).node_arrays for v in versions.values()]
        same_one = all(np.array_equal(a, b) for a, b in zip(*one))
        print("SAH cost:", {n: round(tr.stats()["sah_cost"], 4) for n, tr in trees.items()},
              "same tree (2 threads):", same, "(1 thread):", same_one)
        for threads, clock in ((2, time.perf_counter), (1, time.perf_counter), (1, time.thread_time)):
            for v in versions.values():
                v.build_kdtree(triangles, threads=threads)
            times = paired(versions, triangles, threads, args.pairs, clock)
            mine, theirs = times.values()
            medians = "  ".join(f"{name} {np.median(t):6.1f} ms" for name, t in times.items())
            what = "CPU time" if clock is time.thread_time else "wall"
            print(f"threads {threads} ({what}): {medians}  ratio (paired) {np.median(mine / theirs):.3f}",
                  flush=True)


if __name__ == "__main__":
    main()
