"""One flat kd-tree against two levels (a tree per object under a top-level tree), time to image.

Seed 000 §5 found two levels pay for several non-overlapping objects and hurt when objects overlap;
this measures both, plus many small objects and many instances of one mesh, for the three layouts of
core.SceneBuilder ("flat", "two_level" and "auto", the policy in core/scene/scene_policy.py):

  apart      16 noisy spheres of 16k triangles on a 4 x 4 grid, boxes disjoint
  near       the same 1.6 apart: each box overlaps its neighbours' by about a quarter of its width
  overlap    the same 16 spheres scattered inside one sphere's box (every box overlaps most others)
  small      2,000 objects of 128 triangles on a 3D grid (what SMALL_OBJECT is about)
  instances  1,000 instances of one 512-triangle mesh (flat copies it 1,000 times)

Time to image = build (every tree, nothing reused) + render (camera rays and AO, 512 x 512, 16
samples, AO distance a tenth of the scene's radius). Medians of --runs runs after one warm-up run
that compiles the kernels (reported apart).

    python benchmarks/bench_two_level.py [--runs 3] [--size 512] [--samples 16] [--only apart overlap]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import core  # noqa: E402
from core.scene.scene_policy import overlap_depth  # noqa: E402
from core.scene.two_level import transformed_boxes  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results  # noqa: E402


def sphere(n_lat, n_lon, rng, noise=0.05):
    """A closed lat-long sphere of radius ~1 with radial noise: (vertices, triangles)."""
    lat = np.linspace(0, np.pi, n_lat + 1)
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    r = 1.0 + noise * rng.standard_normal(la.shape)
    r[0], r[-1] = r[0].mean(), r[-1].mean()
    verts = np.stack([r * np.sin(la) * np.cos(lo), r * np.sin(la) * np.sin(lo), r * np.cos(la)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_lat), np.arange(n_lon), indexing="ij")
    a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
    c, d = a + n_lon, b + n_lon
    tris = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    return verts.astype(np.float32), tris.astype(np.int32)


def translation(p, scale=1.0, angle=0.0):
    m = np.eye(4)
    c, s = np.cos(angle), np.sin(angle)
    m[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) * scale
    m[:3, 3] = p
    return m


def scenes(rng):
    """name -> (mesh (vertices, triangles) list, mesh_of, matrices)."""
    big = [sphere(64, 128, rng) for _ in range(16)]
    grid = [translation((3.0 * (k % 4), 3.0 * (k // 4), 0.0)) for k in range(16)]
    near = [translation((1.6 * (k % 4), 1.6 * (k // 4), 0.0), angle=rng.uniform(0, 6)) for k in range(16)]
    packed = [translation(rng.uniform(-0.6, 0.6, 3), angle=rng.uniform(0, 6)) for _ in range(16)]
    small = [sphere(8, 8, rng, noise=0.2) for _ in range(2000)]
    cells = [translation((k % 13, (k // 13) % 13, k // 169), scale=0.3) for k in range(2000)]
    shared = sphere(16, 16, rng, noise=0.2)
    placed = [translation(rng.uniform(-15, 15, 3), scale=rng.uniform(0.3, 0.8), angle=rng.uniform(0, 6))
              for _ in range(1000)]
    return {
        "apart": (big, np.arange(16), np.stack(grid)),
        "near": (big, np.arange(16), np.stack(near)),
        "overlap": (big, np.arange(16), np.stack(packed)),
        "small": (small, np.arange(2000), np.stack(cells)),
        "instances": ([shared], np.zeros(1000, np.int64), np.stack(placed)),
    }


def camera_for(meshes, mesh_of, mats):
    """A camera 1.6 box-diagonals away, looking at the scene's centre from above and to the side."""
    bounds = np.array([np.concatenate([v.min(0), v.max(0)]) for v, _ in meshes])
    boxes = transformed_boxes(bounds[mesh_of], mats)
    lo, hi = boxes[:, :3].min(0), boxes[:, 3:].max(0)
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    eye = centre + radius * 1.6 * np.array([0.5, -0.8, 0.6]) / np.linalg.norm([0.5, -0.8, 0.6])
    forward = (centre - eye) / np.linalg.norm(centre - eye)
    right = np.cross(forward, (0, 0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, -forward, eye
    return core.Camera(m, 0.8), radius


def time_to_image(layout, inputs, camera, ao_distance, size, samples):
    meshes, mesh_of, mats = inputs
    t0 = time.perf_counter()
    scene = core.build_scene(meshes, mesh_of, mats, origin=camera.position, layout=layout)
    t1 = time.perf_counter()
    image = core.render_preview(scene, camera.translated(camera.position), size, size, samples=samples,
                                ao_distance=ao_distance)
    t2 = time.perf_counter()
    return (t1 - t0) * 1e3, (t2 - t1) * 1e3, image, scene


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--only", nargs="*", help="scene names to run")
    parser.add_argument("--out", default=str(results.OUT_DIR), help="folder of bench_two_level.json")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    all_scenes = scenes(rng)
    t = time.perf_counter()
    small = all_scenes["apart"]
    time_to_image("two_level", ([small[0][0]], [0], small[2][:1]), camera_for([small[0][0]], [0], small[2][:1])[0],
                  0.5, 16, 1)
    jit_seconds = time.perf_counter() - t
    print(f"JIT compile / cache load (warm-up, excluded): {jit_seconds:.1f} s")
    out = {}
    print(f"{'scene':10} {'triangles':>10} {'overlap':>8} {'layout':>10} {'meshes':>7} {'build ms':>9} "
          f"{'render ms':>10} {'total ms':>9} {'vs flat':>8}")
    for name, inputs in all_scenes.items():
        if args.only and name not in args.only:
            continue
        meshes, mesh_of, mats = inputs
        camera, radius = camera_for(*inputs)
        bounds = np.array([np.concatenate([v.min(0), v.max(0)]) for v, _ in meshes])
        depth = overlap_depth(transformed_boxes(bounds[mesh_of], mats))
        n_tris = sum(len(meshes[m][1]) for m in mesh_of)
        totals, images = {}, {}
        for layout in ("flat", "two_level", "auto"):
            runs = [time_to_image(layout, inputs, camera, radius / 10, args.size, args.samples)
                    for _ in range(args.runs)]
            build, render = np.median([r[0] for r in runs]), np.median([r[1] for r in runs])
            totals[layout] = np.median([r[0] + r[1] for r in runs])
            images[layout] = runs[0][2]
            n_meshes = len(runs[0][3].meshes)
            out.setdefault(name, {"triangles": int(n_tris), "overlap_depth": float(depth), "layouts": {}})
            out[name]["layouts"][layout] = {
                "meshes": n_meshes, "build_ms": results.figure([r[0] for r in runs], unit="ms"),
                "render_ms": results.figure([r[1] for r in runs], unit="ms"),
                "total_ms": results.figure([r[0] + r[1] for r in runs], unit="ms")}
            print(f"{name:10} {n_tris:>10,} {depth:>8.2f} {layout:>10} {n_meshes:>7} {build:>9.0f} {render:>10.0f} "
                  f"{totals[layout]:>9.0f} {totals[layout] / totals['flat']:>7.2f}x", flush=True)
        rmse = np.sqrt(np.mean((images["two_level"][..., :3] - images["flat"][..., :3]) ** 2))
        print(f"{'':10} image: {images['flat'][..., 3].mean():.0%} of pixels hit, RMSE two_level vs flat {rmse:.5f}")
        out[name]["rmse_two_level_vs_flat"] = float(rmse)
    results.write("bench_two_level", {"size": args.size, "samples": args.samples, "runs": args.runs,
                                      "scenes": out}, jit_seconds, out_dir=args.out)


if __name__ == "__main__":
    main()
