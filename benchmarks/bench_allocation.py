"""Would spreading samples by each pixel's noise lower the error for the same rays? An experiment, not a feature.

Usage: python benchmarks/bench_allocation.py [--size 512] [--budgets 8,16,32,64,128] [--kappas 0.03,...]

Issue 3 compares our time with Cycles' at equal RMSE. Both trace the same estimator (cosine-weighted AO,
one ray a sample, Sobol), so at equal samples the RMSEs match (within 3%) and the ratio is the ratio of
per-sample costs, unless ours could reach the same RMSE with fewer rays. The one way to do that without
bias from neighbours (which the denoiser takes) is to give noisy pixels more samples and quiet ones fewer.
For i.i.d. samples the allocation that minimises the mean squared error over pixels for a fixed number
of rays gives pixel i samples in proportion to its standard deviation sigma_i (Neyman allocation); over
the suzanne reference's hit pixels, with sigma_i^2 = p(1 - p) at AO p, that would save 1.8x the rays.

Stopping rule used here (it fits PreviewRender's checkpoints, where every sampling pixel has the same
count n): a pixel stops once sigma_i / n < kappa, i.e. once one more sample would lower its squared
error by less than kappa^2 (the marginal gain sigma^2 / n^2); every pixel then ends near
n_i = sigma_i / kappa, in proportion to sigma_i. sigma_i comes from the sample variance with the
renderer's Laplace floor (render.py). The error_target mode stops at sigma_i / sqrt(n) < target instead,
n_i proportional to sigma_i^2: right for a bound on every pixel's error, not for the mean.

Printed: uniform renders at each budget, and the stopping rule at each kappa, as RMSE against the
benchmark's 1,024-spp reference (bench_render.py makes it) and rays per hit pixel (camera rays
included). The counts are exact; no time is measured, so the machine's load does not matter.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from core.render import preview_render as render_module  # noqa: E402
from bench_render import reference_path, rmse  # noqa: E402
from scenes import load_scene  # noqa: E402


class MarginalGainRender(render_module.PreviewRender):
    """PreviewRender whose error_target is read as kappa: a pixel stops once sigma / n < kappa."""

    def _retire_converged(self):
        if self.samples_done < self.min_samples:
            return
        n = self.counts[self.active].astype(np.float64)
        mean = self.sums[self.active].mean(axis=1) / n
        var = np.maximum(self.sq_sums[self.active] / n - mean * mean, 0.0) * n / np.maximum(n - 1, 1)
        q = 1.0 / (n + 2.0)  # the renderer's Laplace floor
        var = np.maximum(var, q * (1.0 - q))
        self.active = self.active[np.sqrt(var) / n >= self.error_target]


def rays_per_hit_pixel(render):
    return render.stats()["rays"] / render.hit_pixels


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--ao-distance", type=float, default=1.0)
    ap.add_argument("--reference-samples", type=int, default=1024)
    ap.add_argument("--budgets", default="8,16,32,64,128")
    ap.add_argument("--kappas", default="0.03,0.015,0.008,0.004,0.002")
    args = ap.parse_args()
    scene = load_scene("suzanne-251k")
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    path = reference_path(scene, args.size, args.reference_samples, args.ao_distance)
    if not path.exists():
        sys.exit(f"no reference at {path}: run benchmarks/bench_render.py first (it computes and caches it)")
    ref = np.load(path)
    tree = core.build_kdtree(scene.triangles)
    size, dist = args.size, args.ao_distance
    print(f"suzanne-251k {size}x{size}, ao_distance {dist}, Sobol; RMSE on hit pixels against {path.name}")
    for budget in (int(b) for b in args.budgets.split(",")):
        render = core.PreviewRender(tree, camera, size, size, samples=budget, ao_distance=dist)
        render.step(budget)
        print(f"  uniform {budget:>4} spp:          RMSE {rmse(render.image(), ref):.5f}  "
              f"rays/hit pixel {rays_per_hit_pixel(render):8.2f}", flush=True)
    for kappa in (float(k) for k in args.kappas.split(",")):
        render = MarginalGainRender(tree, camera, size, size, samples=1024, ao_distance=dist, error_target=kappa,
                                    min_samples=4)
        render.step(1024)
        print(f"  sigma/n < {kappa:<6g} (<= 1024 spp): RMSE {rmse(render.image(), ref):.5f}  "
              f"rays/hit pixel {rays_per_hit_pixel(render):8.2f}", flush=True)


if __name__ == "__main__":
    main()
