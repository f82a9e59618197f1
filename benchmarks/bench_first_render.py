"""First-render latency of the add-on's pipeline: cold (empty Numba cache) and warm (cache filled).

Usage: python benchmarks/bench_first_render.py [--runs 3] [--frames 1-2]

Each run is a fresh `python -m kd_addon render` process on the built-in demo scene, the way a user's first
render in a new Blender session goes. "cold" points NUMBA_CACHE_DIR at an empty folder, so every kernel is
compiled; "warm" re-uses the folder the cold run filled, so kernels are only loaded. Printed per mode
(medians over --runs): the first frame's total (extract + build + trace, from report.json, which is where
compile or load time lands), the second frame's total (nothing left to compile: the steady state), and the
process's wall time (Python start, `import bpy`, demo scene, both frames, PNG writing).
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

ROOT = Path(__file__).resolve().parent.parent


def run_once(cache_dir, frames):
    """(first frame total ms, second frame total ms, wall s) of one fresh process."""
    with tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "kd_addon", "render", "--frames", frames, "--out", out],
                       cwd=ROOT, env=env, check=True, capture_output=True, text=True)
        wall = time.perf_counter() - start
        rows = json.loads((Path(out) / "report.json").read_text())["frames"]
    return rows[0]["total_ms"], rows[-1]["total_ms"], wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--frames", default="1-2")
    args = ap.parse_args()
    results = {"cold": [], "warm": []}
    for _ in range(args.runs):
        with tempfile.TemporaryDirectory() as cache:
            results["cold"].append(run_once(cache, args.frames))
            results["warm"].append(run_once(cache, args.frames))
    print(f"demo scene, frames {args.frames}, {args.runs} runs each (medians)")
    print(f"{'cache':>6} {'first frame ms':>15} {'next frame ms':>14} {'process wall s':>15}")
    for mode, rows in results.items():
        first, steady, wall = np.median(np.array(rows), axis=0)
        print(f"{mode:>6} {first:>15.0f} {steady:>14.0f} {wall:>15.1f}")


if __name__ == "__main__":
    main()
