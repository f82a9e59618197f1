"""Lights without extent: one shadow ray a pixel against one a sample, paired in one process.

Usage: python benchmarks/bench_hard_lights.py [--scene suzanne-251k] [--samples 16] [--mode shadow]
                                              [--lights 1] [--runs 7]

A point light of radius 0 (lights.DELTA) gives every sample of a pixel the same shadow ray, so the
renderer traces it at sample 0 and repeats its visibility (render_kernels.py, repeated rays). The
reference is the same render with the flag cleared, which draws sample numbers and traces every
sample's ray as before. Both take their samples one step at a time, as the add-on does. Printed:
median render time of each, the median of the per-run ratios, rays traced, and whether the images
are identical. JIT compile is excluded and printed on its own line.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
import results as bench_results  # noqa: E402
from core.render.lights import DELTA  # noqa: E402
from scenes import load_scene  # noqa: E402

WIDTH, HEIGHT = 640, 480


def render(tree, camera, settings, repeat):
    r = core.PreviewRender(tree, camera, WIDTH, HEIGHT, **settings)
    if not repeat:
        r.lights[:, DELTA] = 0.0
    while not r.done:
        r.step(1)
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--mode", default="shadow", choices=["shadow", "ao+shadow"])
    ap.add_argument("--lights", type=int, default=1)
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--out", default=str(bench_results.OUT_DIR), help="folder of bench_hard_lights.json")
    args = ap.parse_args()
    scene = load_scene(args.scene)
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    lights = [core.Light.point((2.0 - k, -3.0, 4.0 + 0.5 * k)) for k in range(args.lights)]
    settings = dict(samples=args.samples, mode=args.mode, lights=lights)
    tree = core.build_kdtree(scene.triangles)
    t = time.perf_counter()
    core.render_preview(tree, camera, 8, 8, **settings)
    jit_seconds = time.perf_counter() - t
    print(f"JIT compile / cache load: {time.perf_counter() - t:.2f} s (excluded); {args.scene}, {WIDTH}x{HEIGHT}, "
          f"{args.mode}, {args.samples} spp, {args.lights} point light(s) of radius 0")
    times = {True: [], False: []}
    results = {}
    for run in range(args.runs):
        for repeat in ((True, False) if run % 2 == 0 else (False, True)):
            t = time.perf_counter()
            results[repeat] = render(tree, camera, settings, repeat)
            times[repeat].append(time.perf_counter() - t)
    same = np.array_equal(results[True].image(), results[False].image())
    ratio = np.median(np.array(times[True]) / np.array(times[False]))
    for repeat, name in ((True, "repeated (this tree)"), (False, "every sample traced")):
        print(f"  {name:<22} {np.median(times[repeat]) * 1e3:7.0f} ms median   rays traced "
              f"{results[repeat].rays_traced:,}")
    print(f"  ratio (paired) {ratio:.3f}; identical images: {same}")
    bench_results.write("bench_hard_lights", {
        "scene": args.scene, "size": [WIDTH, HEIGHT], "mode": args.mode, "samples": args.samples,
        "lights": args.lights, "identical_images": bool(same), "paired_ratio": float(ratio),
        "repeated": {"seconds": bench_results.figure(times[True], times[False]),
                     "rays_traced": int(results[True].rays_traced)},
        "every_sample": {"seconds": bench_results.figure(times[False]), "rays_traced": int(results[False].rays_traced)},
    }, jit_seconds, out_dir=args.out)


if __name__ == "__main__":
    main()
