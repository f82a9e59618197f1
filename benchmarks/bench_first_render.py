"""First-render latency: cold (empty Numba cache) and warm (cache filled), in a fresh process each time.

Usage: python benchmarks/bench_first_render.py [--runs 3] [--frames 1-2] [--how cli|blender|both]
                                               [--source DIR ...] [--idle]

"cli": a fresh `python -m kd_addon render` on the built-in demo scene; printed per cache state (medians
over --runs): the first frame's total (from report.json), the second frame's (the steady state) and
the process's wall time.

"blender": a fresh bpy-module process as a new user's Blender: the factory startup scene (cube, light,
camera), the add-on registered (as when the extension is enabled; in the bpy module, which runs in
background mode, the render starts the kernels' compile, as Blender's UI does at enable), then Render
(`kdpreview.render`) at once, mode ao+shadow, default settings otherwise. Printed: the seconds from registering to the image
(what the user waits for), the frame's own total as the panel reports it, the time the frame waited
for the kernels' compile and load (reported apart from the frame), its Mrays/s, and the Numba compiles
this process ran during Render (the rest ran in other processes). `--idle` waits for the background
compile (started as Blender's UI starts it) before clicking Render (a user who enables the add-on and
renders minutes later).

`--source` takes one or more checkouts (default: this one), e.g. `--source /work/main .` to compare a
revision before this change with it in the same run: runs alternate between sources, cold then warm
on one cache folder each time (`--cache DIR`: a folder already filled). `--warmup both` alternates KD_PREVIEW_WARMUP=1 and 0 (the kernels loaded
before the frame and reported apart, or loaded by the frame itself as before), and `--warm-only` skips
the cold runs (one cold run fills the cache first, unmeasured).
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

import results as result_files

ROOT = Path(__file__).resolve().parent.parent

BLENDER_CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import bpy
from numba.core import event
compiles = []
class Listener(event.Listener):
    def on_start(self, ev): compiles.append(ev.data["dispatcher"].py_func.__qualname__)
    def on_end(self, ev): pass
bpy.ops.wm.read_homefile(use_factory_startup=True)
import kd_addon
t0 = time.perf_counter()
kd_addon.register()
register_ms = (time.perf_counter() - t0) * 1e3
if sys.argv[2] == "idle":  # as Blender's UI does at enable (the bpy module runs in background mode)
    from kd_addon import kernel_warmup
    kernel_warmup.start()
    kernel_warmup.wait()
event.register("numba:compile", Listener())
bpy.context.scene.kd_preview.mode = "ao+shadow"
t1 = time.perf_counter()
assert bpy.ops.kdpreview.render() == {"FINISHED"}
click_s = time.perf_counter() - t1
last = json.loads(bpy.context.window_manager.kd_preview_state.last_run)
print("RESULT " + json.dumps(dict(register_ms=register_ms, enable_to_image_s=time.perf_counter() - t0,
      click_to_image_s=click_s, frame_ms=last["total_ms"], kernels_ms=last.get("compile_ms", 0.0)
      + last.get("load_ms", 0.0), mrays=last["mrays_per_s"], compiles_here=len(compiles))))
kd_addon.unregister()
"""


def run_cli(source, cache_dir, frames):
    """(first frame total ms, second frame total ms, wall s) of one fresh `python -m kd_addon` process."""
    with tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(source))
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "kd_addon", "render", "--frames", frames, "--out", out],
                       cwd=source, env=env, check=True, capture_output=True, text=True)
        wall = time.perf_counter() - start
        rows = json.loads((Path(out) / "report.json").read_text())["frames"]
    return rows[0]["total_ms"], rows[-1]["total_ms"], wall


def run_blender(source, cache_dir, idle, warmup="1"):
    """The RESULT dict of one fresh bpy-module process (see the module docstring)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(source), KD_PREVIEW_WARMUP=warmup)
    proc = subprocess.run([sys.executable, "-c", BLENDER_CHILD, str(source), "idle" if idle else "at-once"],
                          cwd=source, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(proc.stdout[-3000:] + proc.stderr[-3000:])
    return json.loads(next(line for line in proc.stdout.splitlines() if line.startswith("RESULT "))[7:])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--frames", default="1-2")
    ap.add_argument("--how", choices=["cli", "blender", "both"], default="both")
    ap.add_argument("--source", nargs="+", default=[str(ROOT)])
    ap.add_argument("--idle", action="store_true")
    ap.add_argument("--warmup", choices=["on", "off", "both"], default="on")
    ap.add_argument("--warm-only", action="store_true")
    ap.add_argument("--cache", help="with --warm-only: a Numba cache folder that already holds the kernels")
    args = ap.parse_args()
    if args.warm_only and args.how != "blender":
        ap.error("--warm-only measures the blender way only (--how blender)")
    sources = [Path(s).resolve() for s in args.source]
    hows = ["cli", "blender"] if args.how == "both" else [args.how]
    switches = {"on": ["1"], "off": ["0"], "both": ["1", "0"]}[args.warmup]
    states = ["warm"] if args.warm_only else ["cold", "warm"]
    results = {(how, s, c, w): [] for how in hows for s in sources for c in states for w in switches}
    with tempfile.TemporaryDirectory() as scratch:
        shared = args.cache or scratch
        if args.warm_only and not args.cache:
            for source in sources:
                run_blender(source, shared, False)
        for run in range(args.runs):
            for source in sources if run % 2 == 0 else sources[::-1]:
                for how in hows:
                    for switch in switches if run % 2 == 0 else switches[::-1]:
                        measure(args, results, run, how, source, switch, shared if args.warm_only else None, states)
    print(f"\n{args.runs} runs each (medians)")
    for (how, source, cache_state, switch), rows in results.items():
        if how == "cli":  # (KD_PREVIEW_WARMUP: the command line's frame starts the compile itself either way)
            first, steady, wall = np.median(np.array(rows), axis=0)
            print(f"cli     {cache_state} {source}: first frame {first:.0f} ms, next frame {steady:.0f} ms, "
                  f"process {wall:.1f} s (demo scene, frames {args.frames})")
        else:
            med = {key: float(np.median([r[key] for r in rows])) for key in rows[0]}
            print(f"blender {cache_state} {source} KD_PREVIEW_WARMUP={switch}: enable to image "
                  f"{med['enable_to_image_s']:.1f} s (register {med['register_ms']:.0f} ms), frame {med['frame_ms']:.0f} ms, kernels "
                  f"{med['kernels_ms'] / 1e3:.1f} s apart from it, {med['mrays']:.2f} Mrays/s, "
                  f"{med['compiles_here']:.0f} compiles in Blender's process" + (" (idle first)" if args.idle else ""))
    if len(sources) == 1 and "blender" in hows and not args.idle:
        write_blender_figures(results, hows, states, switches, sources[0])


def write_blender_figures(results, hows, states, switches, source):
    """benchmarks/out/bench_first_render.json: the blender way's figures per cache state (the README's
    first-use line, benchmarks/report.py), for the kernels loaded before the frame (KD_PREVIEW_WARMUP=1)."""
    switch = switches[0]
    out = {}
    for state in states:
        rows = results["blender", source, state, switch]
        out[state] = {key: result_files.figure([r[key] for r in rows], unit=unit) for key, unit in (
            ("enable_to_image_s", "s"), ("kernels_ms", "ms"), ("frame_ms", "ms"), ("mrays", "Mrays/s"))}
    out["warmup"] = switch
    result_files.write("bench_first_render", out, jit_seconds=0.0)


def measure(args, results, run, how, source, switch, cache, states):
    """One cold and one warm run on a new cache folder, or (`cache` given) one warm run on it."""
    with tempfile.TemporaryDirectory() as fresh:
        for cache_state in states:
            folder = cache or fresh
            row = (run_cli(source, folder, args.frames) if how == "cli"
                   else run_blender(source, folder, args.idle, switch))
            print(f"run {run + 1} {how} {source} {cache_state} KD_PREVIEW_WARMUP={switch}: {row}", flush=True)
            results[how, source, cache_state, switch].append(row)


if __name__ == "__main__":
    main()
