"""Time to image of build settings: rebuild plus render, alternating settings run by run.

Usage: python benchmarks/bench_time_to_image.py [--scene suzanne-251k] [--samples 1] [--mode shadow]
                                               [--runs 11] [CONFIG_JSON ...]

Each CONFIG_JSON is a dict of build options (default: '{}' and '{"rays": "frame"}'); "rays": "frame" stands
for the frame's ray count (core.frame_ray_count), with one point light. Per setting: median build time,
median render time, median time to image, and the median of the per-run ratios to the first setting
(the runs alternate their order, so drifts of a shared machine fall on every setting alike).
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from scenes import load_scene  # noqa: E402

WIDTH, HEIGHT = 640, 480


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--samples", type=int, default=1)
    ap.add_argument("--mode", default="shadow", choices=["ao", "shadow", "ao+shadow"])
    ap.add_argument("--runs", type=int, default=11)
    ap.add_argument("configs", nargs="*", default=['{}', '{"rays": "frame"}'])
    args = ap.parse_args()
    scene = load_scene(args.scene)
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    lights = [core.Light.point((2.0, -3.0, 4.0))]
    frame_rays = core.frame_ray_count(WIDTH, HEIGHT, args.mode, args.samples, lights)
    configs = []
    for text in args.configs:
        config = json.loads(text)
        if config.get("rays") == "frame":
            config["rays"] = frame_rays
        configs.append(config)
    render = dict(samples=args.samples, mode=args.mode, lights=lights)
    t = time.perf_counter()
    for config in configs:  # the whole scene: its parallel top levels use kernels a small one does not
        core.render_preview(core.build_kdtree(scene.triangles, **config), camera, 8, 8, **render)
    print(f"JIT compile / cache load: {time.perf_counter() - t:.2f} s (excluded); {args.scene}, {WIDTH}x{HEIGHT}, "
          f"{args.samples} spp {args.mode}, frame ray count {frame_rays:,}")
    builds, totals = [[] for _ in configs], [[] for _ in configs]
    for run in range(args.runs):
        order = list(range(len(configs)))
        for i in (order if run % 2 == 0 else order[::-1]):
            t = time.perf_counter()
            tree = core.build_kdtree(scene.triangles, **configs[i])
            builds[i].append(time.perf_counter() - t)
            core.render_preview(tree, camera, WIDTH, HEIGHT, **render)
            totals[i].append(time.perf_counter() - t)
    for i, config in enumerate(configs):
        b, total = np.array(builds[i]), np.array(totals[i])
        stats = core.build_kdtree(scene.triangles, **config).stats()
        print(f"{json.dumps(config):<28} build {np.median(b) * 1e3:6.0f} ms  render {np.median(total - b) * 1e3:6.0f} ms  "
              f"total {np.median(total) * 1e3:6.0f} ms  ratio {np.median(total / np.array(totals[0])):.3f}  "
              f"nodes {stats['nodes']:,}  SAH {stats['sah_cost']:.1f}")


if __name__ == "__main__":
    main()
