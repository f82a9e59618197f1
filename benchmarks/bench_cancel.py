"""Cancel latency: how long after a cancel request the pipeline returns, during a build and during tracing.

Usage: python benchmarks/bench_cancel.py [--cells 707] [--runs 5] [--size 960x540]

The scene (bpy module): a wavy sheet of 2 cells^2 triangles (1M by default) under a camera. For each
run a frame job starts through pipeline.run_job; a timer thread raises the cancel flag at a random
moment inside the phase being measured (during the kd-tree build, or during tracing once the renderer
exists), and the latency is the time from the flag to run_job raising Cancelled. Before the worker
thread (kd_addon/background.py) the build blocked the caller, so a cancel waited for the rest of the
build: the build time is printed alongside as that old bound. Medians and maxima over --runs; JIT is
absorbed by a warm-up frame that is not measured.
"""
import argparse
import sys
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import bpy  # noqa: E402

from kd_addon import pipeline  # noqa: E402
from kd_addon.config import make_config  # noqa: E402
from kd_addon.errors import Cancelled  # noqa: E402
from tests import bpy_scenes  # noqa: E402


def sheet_scene(cells, width, height):
    bpy_scenes.reset()
    bpy_scenes.add_wavy_sheet("Sheet", cells, location=(0.0, 0.0, 0.0))
    camera = bpy_scenes.add_camera("Cam")
    camera.location = (0.0, 0.0, 3.0)
    scene = bpy.context.scene
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = width, height
    return scene


def new_job(scene, config):
    return pipeline.FrameJob(scene, bpy.context.evaluated_depsgraph_get(), config)


def cancel_latency(scene, config, phase, rng):
    """(latency s, True if the worker was still busy when run_job returned) for one cancel in `phase`."""
    job = new_job(scene, config)
    flag = {"at": None}
    started = threading.Event()

    def cancel():
        in_phase = job.renderer is None if phase == "build" else job.renderer is not None
        if in_phase and job._pending is not None and not started.is_set():
            started.set()
            delay = rng.uniform(0.05, 0.4)
            threading.Timer(delay, lambda: flag.__setitem__("at", time.perf_counter())).start()
        return flag["at"] is not None

    try:
        pipeline.run_job(job, cancel)
    except Cancelled:
        returned = time.perf_counter()
    else:
        return None, False  # the phase ended before the timer fired
    busy = job._pending is not None and not job._pending.finished
    if job._pending is not None:
        job._pending.wait(1e9)  # let the abandoned work end before the next run
    return returned - flag["at"], busy


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=707)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--size", default="960x540")
    ap.add_argument("--samples", type=int, default=256)
    args = ap.parse_args()
    width, height = map(int, args.size.split("x"))
    scene = sheet_scene(args.cells, width, height)
    config = make_config(argparse.Namespace(resolution_percentage=100, samples=args.samples))
    warm = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(),
                                 make_config(argparse.Namespace(resolution_percentage=100, samples=2)))
    print(f"scene: {warm.triangles:,} triangles, {width}x{height}, poll interval {pipeline.POLL_SECONDS * 1e3:.0f} ms")
    builds = []
    for _ in range(args.runs):
        builds.append(pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(),
                                            make_config(argparse.Namespace(resolution_percentage=100,
                                                                           samples=1))).build_ms)
    print(f"build: median {np.median(builds):.0f} ms (a cancel waited up to this long before the worker thread)")
    rng = np.random.default_rng(1)
    for phase in ("build", "trace"):
        values, busy = [], 0
        while len(values) < args.runs:
            latency, was_busy = cancel_latency(scene, config, phase, rng)
            if latency is not None:
                values.append(latency * 1e3)
                busy += was_busy
        print(f"cancel during {phase}: latency median {np.median(values):.1f} ms, max {max(values):.1f} ms over "
              f"{len(values)} runs ({busy} returned while the worker was still busy)")


if __name__ == "__main__":
    main()
