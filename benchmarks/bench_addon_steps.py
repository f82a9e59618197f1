"""The add-on's sampling steps: growing batches (kd_addon/sampling_steps.py) against one sample a step.

A frame of one object (suzanne-251k's .blend: one mesh), or with --demo frame 1 of the built-in demo
scene (17 objects in 16 instances), rendered through the add-on's pipeline (pipeline.render_frame, as
the panel, F12 and the command line render), mode ao and 16 samples by default; the sampling kernel's AO
packets apply to batches of 8+ samples on both. Per round, alternating: (a) growing batches, (b) every
step one sample (STEP_GROWTH 0), the add-on's stepping before batches, (c) growing batches without AO
packets (the sampling kernel's other version), which tells the packets' share. Each run
changes the AO distance by a hair so that the frame is traced anew on the kept tree. Before the rounds,
the warm-up's packed stage (core/jit/first_frame.compile_second_stage) makes sure the packed version
is loaded, as the add-on's background compile leaves it. Prints medians of the frames' trace and total
times, the ratios (b) / (a) and (c) / (a), and the steps each took; writes benchmarks/out/bench_addon_steps.json.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_addon_steps.py [--demo] [--size 480x360] [--samples 16]
                                                                     [--mode ao] [--rounds 7]
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import bpy  # noqa: E402

import kd_addon  # noqa: E402
from kd_addon import corelib, pipeline, sampling_steps  # noqa: E402
from kd_addon.config import make_config  # noqa: E402
from kd_addon.demo_scene import build_demo_scene  # noqa: E402
import results  # noqa: E402
from scenes import load_scene  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="suzanne-251k", help="a benchmark scene's .blend (scenes.py)")
    parser.add_argument("--demo", action="store_true", help="the built-in demo scene instead")
    parser.add_argument("--size", default="480x360")
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--mode", default="ao", choices=["ao", "shadow", "ao+shadow"])
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    if args.demo:
        scene = build_demo_scene(bpy.context.scene)
    else:
        bpy.ops.wm.open_mainfile(filepath=str(load_scene(args.scene).blend_path))
        scene = bpy.context.scene
    kd_addon.register()
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
    settings = scene.kd_preview
    settings.resolution_percentage, settings.mode, settings.samples, settings.ao_distance = 100, args.mode, args.samples, 1.0
    t0 = time.perf_counter()
    core = corelib.load_core()
    importlib.import_module(core.__name__ + ".jit.first_frame").compile_second_stage()
    jit_seconds = time.perf_counter() - t0
    steps = {}
    preview_render = core.PreviewRender
    step = preview_render.step
    preview_render.step = lambda self, n=1: steps.setdefault(self, []).append(n) or step(self, n)
    growth, packets = sampling_steps.STEP_GROWTH, preview_render._sample_packets
    ways = {"growing batches": growth, "one sample a step": 0, "growing batches, no packets": growth}
    times = {name: {"trace": [], "total": []} for name in ways}
    taken = {}
    count = 0
    for round_ in range(args.rounds + 1):
        for name in (ways if round_ % 2 == 0 else list(ways)[::-1]):
            sampling_steps.STEP_GROWTH = ways[name]
            preview_render._sample_packets = packets if "no packets" not in name else (lambda self, batch: None)
            count += 1
            settings.ao_distance = 1.0 + 1e-6 * count  # a new frame on the kept tree
            steps.clear()
            result = pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(settings))
            taken[name] = list(steps.values())[-1]
            if round_ > 0:  # the first round builds the tree and loads kernels
                times[name]["trace"].append(result.trace_ms)
                times[name]["total"].append(result.total_ms)
    sampling_steps.STEP_GROWTH, preview_render._sample_packets = growth, packets
    kd_addon.unregister()
    medians = {name: {k: statistics.median(v) for k, v in t.items()} for name, t in times.items()}
    for name in ways:
        print(f"{name:>31}: trace {medians[name]['trace']:7.1f} ms  total {medians[name]['total']:7.1f} ms  "
              f"steps {taken[name]}")
    a, b, c = medians["growing batches"], medians["one sample a step"], medians["growing batches, no packets"]
    print(f"one sample a step / growing batches: trace {b['trace'] / a['trace']:.3f}, total {b['total'] / a['total']:.3f}")
    print(f"no packets / growing batches: trace {c['trace'] / a['trace']:.3f}, total {c['total'] / a['total']:.3f}")
    name = "bench_addon_steps" + ("_demo" if args.demo else "") + ("" if args.mode == "ao" else "_" + args.mode.replace("+", "_"))
    results.write(name, {
        "scene": "demo" if args.demo else args.scene, "size": [width, height], "samples": args.samples, "mode": args.mode,
        "rounds": args.rounds, "steps": taken,
        "trace_ms": {name: results.figure(t["trace"], unit="ms") for name, t in times.items()},
        "total_ms": {name: results.figure(t["total"], unit="ms") for name, t in times.items()},
        "ratio_total_single_to_batched": b["total"] / a["total"],
        "ratio_trace_single_to_batched": b["trace"] / a["trace"],
        "ratio_total_no_packets_to_batched": c["total"] / a["total"],
    }, jit_seconds)


if __name__ == "__main__":
    main()
