"""What a final render through the KD_PREVIEW engine costs against the panel's render of the same frame.

The built-in demo scene (kd_addon/demo_scene.py) at the given size, mode ao+shadow: per round, alternating,
(a) the panel's Render (bpy.ops.kdpreview.render, viewport depsgraph), (b) F12 (bpy.ops.render.render,
render depsgraph, Combined only, written as an uncompressed EXR), (c) F12 with the AO and Shadow passes
(two extra terms traced over the same trees). The three share their kept trees and last image
(tree_cache), so each run renders the other one of frames 1 and 2 than the run before it: every run traces
its frame anew, keeping what an animation keeps from the frame before (trees, unchanged pixels). Prints
medians and ratios to (a); the first round (kernel compile or cache load) is left out.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_engine.py [--size 320x180] [--rounds 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import bpy

import kd_addon
from kd_addon.demo_scene import build_demo_scene


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", default="320x180")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    kd_addon.register()
    scene = build_demo_scene(bpy.context.scene)
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
    scene.kd_preview.resolution_percentage, scene.kd_preview.mode = 100, "ao+shadow"
    scene.render.engine = "KD_PREVIEW"
    settings = scene.render.image_settings
    settings.file_format, settings.exr_codec = "OPEN_EXR", "NONE"
    scene.render.filepath = tempfile.mkdtemp() + "/frame"
    layer = scene.view_layers[0]

    def panel():
        assert bpy.ops.kdpreview.render() == {"FINISHED"}

    def final(passes):
        layer.use_pass_ambient_occlusion = layer.use_pass_shadow = passes
        assert bpy.ops.render.render(write_still=True) == {"FINISHED"}

    runs = {"panel": panel, "F12": lambda: final(False), "F12 + AO, Shadow passes": lambda: final(True)}
    times = {name: [] for name in runs}
    count = 0
    for round_ in range(args.rounds + 1):
        for name, run in runs.items():
            count += 1
            scene.frame_set(1 + count % 2)
            elapsed = _timed(run)
            if round_:
                times[name].append(elapsed)
    base = statistics.median(times["panel"])
    print(f"demo scene {width}x{height}, ao+shadow, {scene.kd_preview.samples} samples, medians of {args.rounds}:")
    for name, values in times.items():
        median = statistics.median(values)
        print(f"  {name:26s} {median * 1e3:8.1f} ms  {median / base:5.2f}x the panel")
    kd_addon.unregister()


if __name__ == "__main__":
    main()
