"""Camera and hard-shadow packets through several instances (core/scene/instance_packets.py) against
the same rays one by one through the top level, in one process, by turns.

Usage: python benchmarks/bench_instance_packets.py [--scene suzanne-251k] [--copies 3] [--width 640]
                                                  [--height 480] [--rounds 7]

A two-level scene of N copies of the mesh side by side on a ground plate (bench_sample_packets'
copies_on_plate: N + 1 instances), seed 000's frame: the camera rays (closest hits), the shadow rays
from their hits towards a point light (any hit), and the whole render (shadow mode, one sample, the
point light) with packets and with the packets turned off (scene_packets.MOST_INSTANCES 0: every ray
through trace_scene), alternating. Answers and images must be equal. Printed and written to
benchmarks/out/bench_instance_packets.json (with the copies in the name unless 3): medians per way, the
median of the per-round ratios (packets / single rays). The untimed first round is the compile or cache
load (jit_seconds).
"""
import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
import results  # noqa: E402
from bench_sample_packets import copies_on_plate  # noqa: E402
from core.render.camera import tiled_packets, tiled_pixels  # noqa: E402
from core.trace.packet_traversal import L  # noqa: E402
from core.scene import scene_packets  # noqa: E402
from core.scene.ray_visibility import CAMERA_RAYS, SHADOW_RAYS  # noqa: E402
from core.scene.scene_queries import trace_valid_rays  # noqa: E402
from scenes import load_scene  # noqa: E402

LIGHT = (2.0, -3.0, 4.0)  # bench_render's seed 000 light


def shadow_rays(o, d, t, prim):
    """From each camera hit towards LIGHT, ending short of it, and the packet order of consecutive rays."""
    hit = prim >= 0
    points = o[hit] + t[hit, None] * d[hit]
    towards = np.asarray(LIGHT) - points
    length = np.linalg.norm(towards, axis=1)
    towards /= length[:, None]
    starts = np.ascontiguousarray(points + 1e-6 * towards)
    order = np.full(-(-len(starts) // L) * L, -1, np.int64)
    order[:len(starts)] = np.arange(len(starts))
    order.setflags(write=False)
    return starts, towards, np.zeros(len(starts)), length * (1.0 - 1e-6), order


def timed(work):
    t = time.perf_counter()
    value = work()
    return time.perf_counter() - t, value


def passes(scene, frame, camera_rays, shadow, packets):
    """{pass: (seconds, answer)} of the three passes, with or without packets; frame: (camera, width,
    height)."""
    o, d, lo, hi, order = camera_rays
    camera, width, height = frame
    most = scene_packets.MOST_INSTANCES
    if not packets:
        scene_packets.MOST_INSTANCES = 0
    try:
        if packets:
            cam = timed(lambda: scene_packets.trace_camera_packets(scene, o, d, lo, hi, order, None, CAMERA_RAYS))
            occ = timed(lambda: scene_packets.occluded_in_packets(scene, *shadow, None, SHADOW_RAYS))
        else:
            cam = timed(lambda: trace_valid_rays(scene, o, d, lo, hi, False, None, CAMERA_RAYS))
            occ = timed(lambda: trace_valid_rays(scene, *shadow[:4], True, None, SHADOW_RAYS)[2] >= 0)
        render = timed(lambda: core.render_preview(scene, camera, width, height, samples=1, mode="shadow",
                                                   lights=[core.Light.point(LIGHT)]))
    finally:
        scene_packets.MOST_INSTANCES = most
    return {"camera": cam, "shadow": occ, "render": render}


def same(a, b):
    if isinstance(a, tuple):
        return all(np.array_equal(x, y) for x, y in zip(a, b))
    return np.array_equal(a, b)


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--copies", type=int, default=3)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    loaded = load_scene(args.scene)
    camera = core.Camera(loaded.camera_matrix, loaded.camera_fov)
    frame = (camera, args.width, args.height)
    scene = copies_on_plate(loaded.triangles, args.copies)
    o, d, lo, hi = camera.rays(args.width, args.height, tiled_pixels(args.width, args.height))
    camera_rays = (o, d, lo, hi, tiled_packets(args.width, args.height))
    t, _, prim, _, _ = trace_valid_rays(scene, o, d, lo, hi, False, None, CAMERA_RAYS)
    shadow = shadow_rays(o, d, t, prim)
    start = time.perf_counter()
    first = {packets: passes(scene, frame, camera_rays, shadow, packets) for packets in (True, False)}
    jit_seconds = time.perf_counter() - start
    for name in first[True]:
        assert same(first[True][name][1], first[False][name][1]), f"packets changed the {name} answers"
    times = {name: {True: [], False: []} for name in first[True]}
    for round_ in range(args.rounds):
        for packets in ((True, False) if round_ % 2 == 0 else (False, True)):
            for name, (seconds, _) in passes(scene, frame, camera_rays, shadow, packets).items():
                times[name][packets].append(seconds)
    out = {}
    for name, runs in times.items():
        ratios = [a / b for a, b in zip(runs[True], runs[False])]
        out[name] = {"packets_ms": 1e3 * statistics.median(runs[True]),
                     "single_ms": 1e3 * statistics.median(runs[False]), "ratio": statistics.median(ratios), "packets_runs": runs[True], "single_runs": runs[False]}
        print(f"{name:>7}: packets {out[name]['packets_ms']:7.1f} ms, single rays {out[name]['single_ms']:7.1f} ms, "
              f"time ratio {out[name]['ratio']:.3f}")
    name = "bench_instance_packets" + (f"_copies{args.copies}" if args.copies != 3 else "")
    results.write(name, {"scene": args.scene, "copies": args.copies, "instances": args.copies + 1,
                         "size": [args.width, args.height], "rounds": args.rounds, "camera_rays": len(o),
                         "shadow_rays": len(shadow[0]), "passes": out}, jit_seconds)


if __name__ == "__main__":
    main()
