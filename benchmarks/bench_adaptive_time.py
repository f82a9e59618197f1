"""The error target's time at equal RMSE against fixed sampling, paired: build + render, alternating runs.

Usage: python benchmarks/bench_adaptive_time.py [--runs 6] [--size 256] [--reference-samples 512]
                                                [--configs 64,128,128:0.015,128:0.012,64:0.012]

suzanne-251k's AO (ao_distance 1) against bench_render's cached reference. Each config is `samples` (fixed)
or `samples:error_target` (adaptive, at most `samples`); run r of every config before run r + 1, in turns
reversed every other run, medians of --runs. For each adaptive row also the fixed rows' time at its RMSE,
interpolated in log-log between the fixed configs (powers of two: Sobol's error between them is worse
than the interpolation, so this favours the fixed rows slightly).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from bench_render import reference_image, rmse  # noqa: E402
from scenes import load_scene  # noqa: E402


def one_run(scene, camera, size, samples, target):
    """(seconds of build + render, image, mean samples a hit pixel took)."""
    t = time.perf_counter()
    tree = core.build_kdtree(scene.triangles)
    render = core.PreviewRender(tree, camera, size, size, samples=samples, error_target=target)
    render.step(samples)
    seconds = time.perf_counter() - t
    return seconds, render.image(), float(render.counts.mean())


def fixed_time_at(rows, error):
    """The fixed rows' time at `error`, log-log interpolated (None outside their range)."""
    fixed = sorted((r for r in rows if r["target"] is None), key=lambda r: r["rmse"])
    e = np.log([r["rmse"] for r in fixed])
    if len(fixed) < 2 or not e[0] <= np.log(error) <= e[-1]:
        return None
    return float(np.exp(np.interp(np.log(error), e, np.log([r["seconds"] for r in fixed]))))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--reference-samples", type=int, default=512)
    ap.add_argument("--configs", default="64,128,128:0.015,128:0.012,64:0.012")
    args = ap.parse_args()
    configs = [(int(c.split(":")[0]), float(c.split(":")[1]) if ":" in c else None) for c in args.configs.split(",")]
    scene = load_scene("suzanne-251k")
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    ref = reference_image(scene, camera, args.size, args.reference_samples, 1.0)
    one_run(scene, camera, 8, 8, 0.05)  # compile
    times, images, means = {c: [] for c in configs}, {}, {}
    for run in range(args.runs):
        for c in configs if run % 2 == 0 else configs[::-1]:
            seconds, images[c], means[c] = one_run(scene, camera, args.size, *c)
            times[c].append(seconds)
    rows = [{"samples": c[0], "target": c[1], "seconds": float(np.median(times[c])), "rmse": rmse(images[c], ref),
             "mean": means[c], "all": times[c]} for c in configs]
    for r in rows:
        kind = "fixed" if r["target"] is None else f"target {r['target']:g}"
        line = (f"{r['samples']:>5} spp {kind:>13}: {r['seconds']:.3f} s  RMSE {r['rmse']:.5f}  mean spp "
                f"{r['mean']:6.1f}  runs {', '.join(f'{s:.2f}' for s in r['all'])}")
        fixed = fixed_time_at(rows, r["rmse"]) if r["target"] is not None else None
        if fixed is not None:
            line += f"  fixed at this RMSE {fixed:.3f} s, ratio {r['seconds'] / fixed:.3f}"
        print(line)


if __name__ == "__main__":
    main()
