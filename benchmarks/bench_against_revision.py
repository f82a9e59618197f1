"""Paired A/B of core against a git revision's core, in one process: the honest way to see a few percent
on a shared, noisy machine.

Usage: python benchmarks/bench_against_revision.py [--base HEAD] [--scene suzanne-251k] [--pairs 21]
                                                   [--threads N]

The base revision's `core/` is exported (`git archive`) into a temporary folder as the package
`core_base`, so both versions run side by side, each with its own Numba cache. Seed 000's setting
(640 x 480, rays told to the build, one point light): per pair, in alternating order, each version
builds its tree, traces the camera rays (closest hit), traces the hit points' shadow rays (any hit),
traces bench_core's AO rays (8 a hit, length 1, any hit: workload.ao_workload), renders the image (`render_preview`,
shadow mode, 1 sample) and an AO image as the Cycles comparison renders it (256 x 256, `--ao-samples`
samples, AO distance 1: the sampling kernel's AO rays). Printed: medians per version and the
median of the per-pair ratios (this tree / base), plus whether both versions gave the same hits, tree
and image. JIT compile is excluded and printed on its own line.
"""
import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT)]

import core  # noqa: E402
from core.render.camera import tiled_pixels  # noqa: E402
from scenes import load_scene  # noqa: E402
from workload import ao_workload  # noqa: E402

WIDTH, HEIGHT = 640, 480
LIGHT = (2.0, -3.0, 4.0)


def export_base(revision, folder):
    """The revision's core/ as package core_base under `folder`."""
    target = Path(folder) / "core_base"
    target.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", revision, "core"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "--strip-components=1", "-C", str(target)], input=archive, check=True)
    sys.path.insert(0, str(folder))
    import core_base  # noqa: PLC0415
    return core_base


def shadow_rays(hits, origins, directions):
    """Rays from the camera hits towards the light, started a little off the surface."""
    seen = hits.prim >= 0
    points = origins[seen] + hits.t[seen, None] * directions[seen]
    towards = np.asarray(LIGHT) - points
    distance = np.linalg.norm(towards, axis=1)
    towards /= distance[:, None]
    return points + 1e-4 * towards, towards, distance


AO_SIZE = 256  # the AO image: bench_render's Cycles comparison setting


def one_pair(version, triangles, camera_rays, rays, frame_rays, ao_samples):
    """Times (ms) of build, camera rays, shadow rays, AO rays, render and AO render for one version, and
    its results."""
    origins, directions, tmin, tmax = camera_rays
    times = []
    t = time.perf_counter()
    tree = version.build_kdtree(triangles, rays=frame_rays)
    times.append(time.perf_counter() - t)
    t = time.perf_counter()
    hits = version.intersect(tree, origins, directions, tmin, tmax)
    times.append(time.perf_counter() - t)
    t = time.perf_counter()
    blocked = version.occluded(tree, *rays[:2], 0.0, rays[2])
    times.append(time.perf_counter() - t)
    t = time.perf_counter()
    ao_blocked = version.occluded(tree, *rays[4], tmax=1.0)
    times.append(time.perf_counter() - t)
    camera, light = rays[3]
    t = time.perf_counter()
    image = version.render_preview(tree, version.Camera(*camera), WIDTH, HEIGHT, mode="shadow", samples=1,
                                   lights=[version.Light.point(light)])
    times.append(time.perf_counter() - t)
    t = time.perf_counter()
    ao_image = version.render_preview(tree, version.Camera(*camera), AO_SIZE, AO_SIZE, samples=ao_samples,
                                      ao_distance=1.0)
    times.append(time.perf_counter() - t)
    return np.array(times) * 1e3, (tree.node_arrays, hits, blocked, ao_blocked, image, ao_image)


def same(a, b):
    (nodes_a, hits_a, blocked_a, ao_a, image_a, ao_image_a) = a
    (nodes_b, hits_b, blocked_b, ao_b, image_b, ao_image_b) = b
    return {"tree": all(np.array_equal(x, y) for x, y in zip(nodes_a, nodes_b)),
            "hits": all(np.array_equal(x, y) for x, y in zip(hits_a, hits_b)),
            "shadow rays": np.array_equal(blocked_a, blocked_b), "AO rays": np.array_equal(ao_a, ao_b),
            "image": np.array_equal(image_a, image_b), "AO image": np.array_equal(ao_image_a, ao_image_b)}


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--base", default="HEAD", help="git revision to compare against (default HEAD)")
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--pairs", type=int, default=21)
    ap.add_argument("--threads", type=int, default=None, help="Numba threads (default: all)")
    ap.add_argument("--ao-samples", type=int, default=16, help="samples of the AO image (default 16)")
    args = ap.parse_args()
    if args.threads:
        import numba  # noqa: PLC0415
        numba.set_num_threads(args.threads)
    scene = load_scene(args.scene)
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    camera_rays = camera.rays(WIDTH, HEIGHT, tiled_pixels(WIDTH, HEIGHT))
    frame_rays = core.frame_ray_count(WIDTH, HEIGHT, "shadow", 1, [core.Light.point(LIGHT)])
    with tempfile.TemporaryDirectory() as folder:
        base = export_base(args.base, folder)
        print("compiling or loading both versions' kernels (the base's are compiled afresh in a temporary "
              "folder each run: minutes) ...", flush=True)
        versions = {"this tree": core, f"base {args.base}": base}
        hits = core.intersect(core.build_kdtree(scene.triangles, rays=frame_rays), *camera_rays)
        rays = (*shadow_rays(hits, camera_rays[0], camera_rays[1]),
                ((scene.camera_matrix, scene.camera_fov), LIGHT),
                ao_workload(scene.triangles, *camera_rays[:2], hits.t.astype(np.float64), hits.prim))
        t = time.perf_counter()
        results = {name: one_pair(v, scene.triangles, camera_rays, rays, frame_rays, args.ao_samples)[1]
                   for name, v in versions.items()}
        print(f"JIT compile / cache load of both versions: {time.perf_counter() - t:.1f} s (excluded); {args.scene}, "
              f"{WIDTH}x{HEIGHT}, {len(rays[2]):,} shadow rays, {len(rays[4][0]):,} AO rays, {args.pairs} pairs")
        print("identical results:", same(*results.values()))
        times = {name: [] for name in versions}
        for pair in range(args.pairs):
            order = list(versions.items()) if pair % 2 == 0 else list(versions.items())[::-1]
            for name, version in order:
                pair_times = one_pair(version, scene.triangles, camera_rays, rays, frame_rays, args.ao_samples)[0]
                times[name].append(pair_times)
    mine, theirs = (np.array(t) for t in times.values())
    ratios = np.median(mine / theirs, axis=0)
    for name, t in times.items():
        m = np.median(np.array(t), axis=0)
        print(f"{name:>16}: build {m[0]:6.1f} ms  camera rays {m[1]:6.1f} ms  shadow rays {m[2]:6.1f} ms  "
              f"AO rays {m[3]:6.1f} ms  render {m[4]:6.1f} ms  AO render {m[5]:6.1f} ms  "
              f"build+render {np.median(np.array(t)[:, 0] + np.array(t)[:, 4]):6.1f} ms")
    both = np.median((mine[:, 0] + mine[:, 4]) / (theirs[:, 0] + theirs[:, 4]))
    print(f"{'ratio (paired)':>16}: build {ratios[0]:6.3f}     camera rays {ratios[1]:6.3f}     shadow rays "
          f"{ratios[2]:6.3f}     AO rays {ratios[3]:6.3f}     render {ratios[4]:6.3f}     AO render "
          f"{ratios[5]:6.3f}     build+render {both:6.3f}")


if __name__ == "__main__":
    main()
