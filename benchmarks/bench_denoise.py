"""The denoiser's cost and gain: filter time and RMSE, raw against denoised, on suzanne-251k.

Usage: python benchmarks/bench_denoise.py [--runs 5] [--size 512] [--samples 1,4,16,64] [--threads N]

For each sample count a Sobol render (binned tree built once, ao_distance 1.0: camera pass and samples)
is timed --runs times, then the filter (`core.denoise_pixels` on the render's accumulators, what
`PreviewRender.image(denoise=True)` runs) --runs times; the medians are printed with the filter's time
as a share of the render's. RMSE is taken on
hit pixels against the cached 1,024-spp reference that bench_render.py writes (skipped when it is
missing). A first untimed filter call absorbs the JIT compile, reported on its own line.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from bench_render import reference_path, rmse  # noqa: E402
from core.render.denoise import SOBOL_VARIANCE_DECAY  # noqa: E402
from scenes import load_scene  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--samples", default="1,4,16,64")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    scene = load_scene("suzanne-251k")
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    ref_path = reference_path(scene, args.size, 1024, 1.0)
    ref = np.load(ref_path) if ref_path.exists() else None
    tree = core.build_kdtree(scene.triangles)

    def filtered(render):
        return core.denoise_pixels(args.size, args.size, render.pixels, render.points, render.normals,
                                   render.sums, render.sq_sums, render.counts,
                                   variance_decay=SOBOL_VARIANCE_DECAY, threads=args.threads)

    warm = core.PreviewRender(tree, camera, 16, 16, samples=1)
    warm.step(1)
    t = time.perf_counter()
    core.denoise_pixels(16, 16, warm.pixels, warm.points, warm.normals, warm.sums, warm.sq_sums, warm.counts)
    print(f"JIT compile / cache load: {time.perf_counter() - t:.2f} s (excluded)")
    print(f"{'spp':>5} {'render s':>9} {'filter ms':>10} {'share':>6} {'RMSE raw':>9} {'denoised':>9}")
    for spp in (int(s) for s in args.samples.split(",")):
        render_times = []
        for _ in range(args.runs):  # the camera pass (in the constructor) and the samples
            t = time.perf_counter()
            render = core.PreviewRender(tree, camera, args.size, args.size, samples=spp, threads=args.threads)
            render.step(spp)
            render_times.append(time.perf_counter() - t)
        render_s = float(np.median(render_times))
        times = []
        for _ in range(args.runs):
            t = time.perf_counter()
            img = filtered(render)
            times.append(time.perf_counter() - t)
        ms = float(np.median(times)) * 1e3
        errors = (f"{rmse(render.image(), ref):9.5f} {rmse(img, ref):9.5f}" if ref is not None
                  else f"{'-':>9} {'-':>9}")
        print(f"{spp:>5} {render_s:9.3f} {ms:10.1f} {ms / 1e3 / render_s:6.0%} {errors}", flush=True)


if __name__ == "__main__":
    main()
