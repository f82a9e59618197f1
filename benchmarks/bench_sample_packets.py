"""The sampling kernel's packets (core/render/sample_packets.py) against the same renders without them,
in one process, by turns.

Usage: python benchmarks/bench_sample_packets.py [--scene suzanne-251k] [--size 256] [--samples 16] [--rounds 7]
                                                [--copies N]

On a prebuilt tree (default build; with --copies N a two-level scene of N copies of the mesh side by
side, 1.2 of its width apart, on a ground plate: N + 1 instances), `PreviewRender.step(samples)` of three renders: mode ao (AO within
1), mode shadow with lights of extent (a point light of radius 0.25 and a sun of 2 degrees: Blender's
defaults are a 0.1 m point and a 0.526 degree sun), and ao+shadow with the same lights. Each render
runs with packets (the renderer's own rule) and without (`packed` None: every ray alone through the
scene), alternating; the images must be equal. Printed and written to benchmarks/out/bench_sample_packets.json:
per render the median step time of each way, the median of the per-round ratios, the rays a second, and
how many of the packed render's rays no packet answered (PreviewRender.rays_alone).
The untimed first round is the compile or cache load (jit_seconds).
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
from scenes import load_scene  # noqa: E402

LIGHTS = (core.Light.point((2.0, -3.0, 4.0), radius=0.25), core.Light.sun((-0.3, 0.6, -1.0), angle=np.radians(2.0)))
RENDERS = {"ao": dict(mode="ao", ao_distance=1.0), "shadow": dict(mode="shadow", lights=LIGHTS),
           "ao+shadow": dict(mode="ao+shadow", ao_distance=1.0, lights=LIGHTS)}


def step(tree, camera, size, samples, settings, packets):
    """(seconds of step(samples), image, rays traced, rays no packet answered) of one render; packets False
    forces the kernel without them."""
    rule = core.PreviewRender._sample_packets
    if not packets:
        core.PreviewRender._sample_packets = lambda self, batch: None
    try:
        render = core.PreviewRender(tree, camera, size, size, samples=samples, **settings)
        t = time.perf_counter()
        render.step(samples)
        seconds = time.perf_counter() - t
    finally:
        core.PreviewRender._sample_packets = rule
    return seconds, render.image(), render.rays_traced, render.rays_alone


def copies_on_plate(triangles, copies):
    """A TwoLevelScene: `copies` instances of the mesh's tree along x, centred on the first (the camera's
    view), and a ground plate under them."""
    lo, hi = triangles.reshape(-1, 3).min(axis=0), triangles.reshape(-1, 3).max(axis=0)
    width = float(hi[0] - lo[0])
    a, b = (lo - 4.0 * width).astype(np.float32), (hi + 4.0 * width).astype(np.float32)
    z = np.float32(lo[2] - 0.05 * width)
    plate = np.array([[[a[0], a[1], z], [b[0], a[1], z], [b[0], b[1], z]],
                      [[a[0], a[1], z], [b[0], b[1], z], [a[0], b[1], z]]], np.float32)
    matrices = [np.eye(4) for _ in range(copies + 1)]
    for k in range(copies):
        matrices[k][0, 3] = 1.2 * width * (k - (copies - 1) / 2.0)
    mesh = core.build_kdtree(triangles)
    return core.build_two_level([mesh, core.build_kdtree(plate)], [0] * copies + [1], np.stack(matrices))


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--copies", type=int, default=0, help="N copies of the mesh and a ground plate as instances")
    args = ap.parse_args()
    scene = load_scene(args.scene)
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    tree = core.build_kdtree(scene.triangles) if not args.copies else copies_on_plate(scene.triangles, args.copies)
    t = time.perf_counter()
    for settings in RENDERS.values():
        images = [step(tree, camera, args.size, args.samples, settings, packets)[1] for packets in (True, False)]
        assert np.array_equal(*images), "packets changed the image"
    jit_seconds = time.perf_counter() - t
    out = {}
    for name, settings in RENDERS.items():
        times, rays, alone = {True: [], False: []}, 0, 0
        for round_ in range(args.rounds):
            for packets in ((True, False) if round_ % 2 == 0 else (False, True)):
                seconds, _, rays, left = step(tree, camera, args.size, args.samples, settings, packets)
                times[packets].append(seconds)
                alone = left if packets else alone
        ratios = [a / b for a, b in zip(times[True], times[False])]
        out[name] = {"packets_ms": 1e3 * statistics.median(times[True]),
                     "single_ms": 1e3 * statistics.median(times[False]),
                     "ratio": statistics.median(ratios), "rays": rays, "rays_alone": alone,
                     "packets_runs": times[True], "single_runs": times[False]}
        print(f"{name:>10}: packets {out[name]['packets_ms']:7.1f} ms, single rays {out[name]['single_ms']:7.1f} ms, "
              f"time ratio {out[name]['ratio']:.3f} ({rays / statistics.median(times[True]) / 1e6:.2f} "
              f"against {rays / statistics.median(times[False]) / 1e6:.2f} Mrays/s; {alone / rays:.2%} of the rays "
              f"fell to single rays)")
    name = "bench_sample_packets" + (f"_copies{args.copies}" if args.copies else "")
    results.write(name, {"scene": args.scene, "size": args.size, "samples": args.samples, "copies": args.copies,
                         "rounds": args.rounds, "renders": out}, jit_seconds)


if __name__ == "__main__":
    main()
