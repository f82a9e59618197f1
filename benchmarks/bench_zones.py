"""What soup zones cost (core/scene/scene_policy.py, soup_zones): scattered clutter on a large ground.

A soup stores its members' world triangles in float32 relative to one anchor; members far from it
against their size go to zones anchored near them (one more soup tree and top-level instance each).
The scene: 8,000 unique cubes 2 cm across scattered over a square ground of side --ground metres, a
camera 3 m up looking down-forward. For the "flat" layout (one tree, no zones) and "auto" at each
PRECISION_RATIO given: the zone count, the build (nothing reused; paid once for a static soup) and the
render (192 x 144, 8 AO samples, medians of --runs), each ratio's render against flat's in the same run.

    python benchmarks/bench_zones.py [--ground 1000 10000] [--ratios 4096 16384 65536] [--runs 3]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import core  # noqa: E402
from core.scene import scene_policy  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results  # noqa: E402

CUBE_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                       [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def clutter(ground, count=8000, side=0.02, seed=0):
    """(meshes, matrices, camera): a ground quad and `count` unique cubes scattered over it."""
    rng = np.random.default_rng(seed)
    half = ground / 2
    quad = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], np.float32)
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float32) * side
    meshes = [core.MeshInput("ground", quad, np.array([[0, 1, 2], [0, 2, 3]]), 0)]
    meshes += [core.MeshInput(k, cube, CUBE_FACES, 0) for k in range(count)]
    matrices = np.stack([np.eye(4)] * (count + 1))
    matrices[1:, :2, 3] = rng.uniform(-half, half, (count, 2))
    tilt = np.radians(60)
    view = np.eye(4)
    view[:3, :3] = [[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]]
    view[:3, 3] = (ground / 5, ground / 5, 3)
    return meshes, matrices, core.Camera(view, 1.0)


def measure(meshes, matrices, camera, layout, runs):
    """(instances, build ms, render ms of each run) of one fresh SceneBuilder build and `runs` renders."""
    start = time.perf_counter()
    scene, _ = core.SceneBuilder(layout).build(meshes, np.arange(len(meshes)), matrices, origin=camera.position)
    build = (time.perf_counter() - start) * 1e3
    renders = []
    for _ in range(runs):
        start = time.perf_counter()
        render = core.PreviewRender(scene, camera.translated(scene.origin), 192, 144, samples=8, ao_distance=1.0)
        render.step(render.target_samples)
        renders.append((time.perf_counter() - start) * 1e3)
    return scene.stats()["instances"], build, renders


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ground", type=float, nargs="+", default=[1000.0, 10000.0])
    parser.add_argument("--ratios", type=float, nargs="+", default=[scene_policy.PRECISION_RATIO])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--out", default=str(results.OUT_DIR), help="folder of bench_zones.json")
    args = parser.parse_args()
    default_ratio = scene_policy.PRECISION_RATIO
    start = time.perf_counter()
    for layout in ("flat", "auto"):  # compile or load the kernels
        measure(*clutter(100.0, count=2000), layout, 1)
    jit_seconds = time.perf_counter() - start
    print(f"kernels compiled or loaded in {jit_seconds:.1f} s (not counted below)")
    out = []
    for ground in args.ground:
        meshes, matrices, camera = clutter(ground)
        _, flat_build, flat_renders = measure(meshes, matrices, camera, "flat", args.runs)
        rows = []
        for ratio in args.ratios:
            scene_policy.PRECISION_RATIO = ratio
            rows.append((ratio, *measure(meshes, matrices, camera, "auto", args.runs)))
        scene_policy.PRECISION_RATIO = default_ratio
        flat_renders += measure(meshes, matrices, camera, "flat", args.runs)[2]  # before and after the others
        flat_render = float(np.median(flat_renders))
        print(f"ground {ground:g} m: flat  build {flat_build:7.0f} ms  render {flat_render:5.0f} ms")
        entry = {"ground_m": ground, "flat": {"build_ms": flat_build,
                                              "render_ms": results.figure(flat_renders, unit="ms")}, "auto": []}
        for ratio, zones, build, renders in rows:
            render = float(np.median(renders))
            print(f"  auto, ratio {ratio:7g}: {zones - 1:5d} zones  build {build:7.0f} ms  render {render:5.0f} ms"
                  f"  ({render / flat_render:.2f}x flat's)")
            entry["auto"].append({"precision_ratio": ratio, "zones": int(zones - 1), "build_ms": build,
                                  "render_ms": results.figure(renders, flat_renders, "ms")})
        out.append(entry)
    results.write("bench_zones", {"runs": args.runs, "grounds": out}, jit_seconds, out_dir=args.out)


if __name__ == "__main__":
    main()
