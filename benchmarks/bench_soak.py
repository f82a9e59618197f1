"""Soak benchmark: every frame of a randomly deforming animation rendered many times through the add-on's
pipeline; no failure, and the resident memory (RSS) must not grow.

Usage: python benchmarks/bench_soak.py [--loops 10] [--frames 24] [--cells 160] [--size 160x90]

The scene (bpy module): a cells x cells sheet whose vertices are pushed by four shape keys of random
offsets with randomly keyed values (so every frame has new geometry and a new kd-tree), a wave
modifier on top, a cube standing on it and a camera. Each render goes through pipeline.render_frame and
output.store_preview, as live update does. RSS is read from /proc/self/status after every frame; the
table prints it at the end of every loop, and the growth is measured from the end of the first loop
(which includes the kernel load and Blender's own first-use allocations) to the end of the last.
"""
import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import bpy  # noqa: E402

from kd_addon import output, pipeline  # noqa: E402
from kd_addon.config import make_config  # noqa: E402


def rss_mib():
    """Current resident set size in MiB (Linux /proc; the peak from getrusage elsewhere)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def deforming_scene(cells, frames, seed=7):
    """The sheet with random shape keys keyed at random values every few frames, a wave, a cube, a camera."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    rng = np.random.default_rng(seed)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cells, y_subdivisions=cells, size=6)
    sheet = bpy.context.active_object
    sheet.shape_key_add(name="Basis")
    n = len(sheet.data.vertices)
    for k in range(4):
        key = sheet.shape_key_add(name=f"Random{k}")
        co = np.empty(3 * n, np.float32)
        key.data.foreach_get("co", co)
        co[2::3] += rng.normal(0.0, 0.15, n).astype(np.float32)
        key.data.foreach_set("co", co)
        for frame in range(1, frames + 1, 3):
            key.value = float(rng.uniform(0, 1))
            key.keyframe_insert("value", frame=frame)
    wave = sheet.modifiers.new("Wave", "WAVE")
    wave.height, wave.width, wave.speed = 0.3, 1.5, 0.1
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0.8))
    camera = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(camera)
    camera.location, camera.rotation_euler = (0.0, -7.0, 4.0), (np.radians(60), 0.0, 0.0)
    scene.camera = camera
    scene.frame_start, scene.frame_end = 1, frames
    return scene


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--loops", type=int, default=10)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--cells", type=int, default=160, help="sheet subdivisions (2 cells^2 triangles)")
    ap.add_argument("--size", default="160x90")
    ap.add_argument("--samples", type=int, default=8)
    args = ap.parse_args()
    width, height = map(int, args.size.split("x"))
    scene = deforming_scene(args.cells, args.frames)
    scene.render.resolution_x, scene.render.resolution_y = width, height
    config = make_config(argparse.Namespace(resolution_percentage=100, samples=args.samples, ao_distance=1.0))
    print(f"soak: {args.loops} loops x {args.frames} frames, {width}x{height}, {args.samples} spp, pid {os.getpid()}")
    print(f"{'loop':>4} {'renders':>8} {'triangles':>10} {'mean ms':>8} {'RSS MiB':>8} {'min..max MiB':>14}")
    ends, failures, renders = [], 0, 0
    previous = None
    for loop in range(1, args.loops + 1):
        samples, times, triangles = [], [], 0
        for frame in range(1, args.frames + 1):
            scene.frame_set(frame)
            t = time.perf_counter()
            try:
                result = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), config)
                output.store_preview(result.image)
                triangles = result.triangles
                if previous is not None and frame > 1 and np.array_equal(previous, result.image):
                    raise RuntimeError(f"frame {frame} gave the same image as the frame before: not deforming")
                previous = result.image
            except Exception as error:  # counted and shown: a soak must report, not stop at, failures
                failures += 1
                print(f"  loop {loop} frame {frame}: {type(error).__name__}: {error}")
            times.append((time.perf_counter() - t) * 1e3)
            samples.append(rss_mib())
            renders += 1
        ends.append(samples[-1])
        print(f"{loop:>4} {renders:>8} {triangles:>10,} {np.mean(times):>8.1f} {samples[-1]:>8.1f} "
              f"{min(samples):>6.1f}..{max(samples):<6.1f}", flush=True)
    growth = ends[-1] - ends[0]
    per_loop = np.polyfit(np.arange(len(ends)), ends, 1)[0] if len(ends) > 2 else growth
    print(f"failures: {failures} of {renders} renders")
    print(f"RSS growth from the end of loop 1 to the end of loop {args.loops}: {growth:+.1f} MiB "
          f"(fitted slope {per_loop:+.2f} MiB per loop of {args.frames} frames)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
