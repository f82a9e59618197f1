"""Where a first render's JIT compile time goes: per-kernel compile seconds with an empty Numba cache.

Usage: python benchmarks/bench_compile.py [--top 15] [--helper on|off|both] [--runs 1] [-- RENDER_ARGS ...]

Runs `python -m kd_addon render --demo --frames 1` (or RENDER_ARGS) in a fresh process whose
NUMBA_CACHE_DIR is an empty folder, with a listener on Numba's "numba:compile" events. A kernel's time
is exclusive: the compiles of the functions it calls (each compiled once, then reused) count for those,
while code inlined into it (inline="always") counts for it, which is what makes a large inlined callee
at several call sites expensive. Prints the first frame's row, the total, and the top kernels.

The add-on's first frame compiles the rendering kernels in a helper process while it builds
(core/jit/parallel_compile.py); `--helper off` runs with KD_PREVIEW_COMPILE_HELPER=0 (all in one process),
`--helper both` alternates the two `--runs` times and prints the median first-frame and process times.
The per-kernel list counts this process's compiles only, not the helper's.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def compile_listener():
    """A Numba event listener summing each function's exclusive compile time into a dict."""
    from numba.core import event

    seconds = defaultdict(float)

    class Listener(event.Listener):
        def __init__(self):
            self.open = []

        def on_start(self, ev):
            func = ev.data["dispatcher"].py_func
            self.open.append((f"{func.__module__}.{func.__qualname__}", time.perf_counter()))

        def on_end(self, ev):
            name, start = self.open.pop()
            spent = time.perf_counter() - start
            seconds[name] += spent
            if self.open:  # a compile nested in another's: not the outer kernel's own time
                seconds[self.open[-1][0]] -= spent

    event.register("numba:compile", Listener())
    return seconds


def child(top, render_args):
    """Run the add-on's command line in this process and print the compile times at exit."""
    import atexit
    import runpy

    seconds = compile_listener()

    def report():
        print(f"COMPILE total {sum(seconds.values()):.1f} s over {len(seconds)} functions")
        for name, s in sorted(seconds.items(), key=lambda kv: -kv[1])[:top]:
            print(f"COMPILE {s:7.1f} s  {name}")

    atexit.register(report)
    sys.path.insert(0, str(ROOT))  # this checkout's kd_addon and core, not an editable install's
    sys.argv = ["kd_addon", *render_args]
    runpy.run_module("kd_addon", run_name="__main__")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--helper", choices=["on", "off", "both"], default="on")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("render_args", nargs="*")
    args = ap.parse_args()
    if args.child:
        return child(args.top, args.render_args)
    modes = ["off", "on"] if args.helper == "both" else [args.helper]
    walls, frames = {m: [] for m in modes}, {m: [] for m in modes}
    for run in range(args.runs):
        for mode in (modes if run % 2 == 0 else modes[::-1]):
            print(f"-- helper {mode}, run {run + 1}")
            wall, frame = one_run(args, mode)
            walls[mode].append(wall)
            frames[mode].append(frame)
    for mode in modes:
        print(f"helper {mode}: first frame {np.median(frames[mode]):.1f} s, process {np.median(walls[mode]):.1f} s "
              f"(medians of {len(walls[mode])}; runs: {', '.join(f'{w:.1f}' for w in walls[mode])})")


def one_run(args, mode):
    """One fresh process on an empty cache: (process wall seconds, first frame seconds)."""
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        render_args = args.render_args or ["render", "--demo", "--frames", "1", "--out", out]
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, KD_PREVIEW_COMPILE_HELPER="1" if mode == "on" else "0")
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, __file__, "--child", "--top", str(args.top), "--", *render_args],
                              cwd=ROOT, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(proc.stdout + proc.stderr)
    lines = proc.stdout.splitlines()
    rows = [line for line in lines if line.lstrip().startswith(("frame", "*1"))]
    print("\n".join(rows))
    print("\n".join(line[len("COMPILE "):] for line in lines if line.startswith("COMPILE ")))
    print(f"process wall {wall:.1f} s (empty cache)")
    columns = re.split(r"\s{2,}", rows[0].strip())  # "frame", ..., "total ms", ...
    return wall, float(rows[1].split()[columns.index("total ms")].replace(",", "")) / 1e3


if __name__ == "__main__":
    main()
