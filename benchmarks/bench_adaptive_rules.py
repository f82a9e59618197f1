"""Stopping rules for the error target, compared by samples at equal RMSE (no timing).

Usage: python benchmarks/bench_adaptive_rules.py [--size 256] [--reference-samples 1024]

suzanne-251k's AO (ao_distance 1): a converged reference (another seed), and one render's per-pixel sums
after every power of two of samples up to 256. A rule that checks pixels at powers of two and stops some
of them gives each pixel the estimate of its prefix at its stop count, so every rule and target is
evaluated on the same samples without rendering again: its RMSE against the reference, its mean samples
a hit pixel, the fixed sample count with the same RMSE (interpolated in log-log) and their ratio (the
gain), and how far the stopped pixels are off. Rules:
- "own, 1/n": a pixel's own variance with Laplace's floor, the mean's variance var / n (the rule before);
- "own, n^-1.5": the same with Sobol's variance decay;
- "5x5, n^-1.5": convergence.standard_errors (pooled over the 5x5 neighbourhood), what the renderer uses.
Also the best any allocation could do with per-pixel errors c_i n^-1.5 known beforehand (Neyman).
"""
import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from core.render.convergence import sample_variances, standard_errors  # noqa: E402
from scenes import load_scene  # noqa: E402

COUNTS = (8, 16, 32, 64, 128, 256)


def prefixes(tree, camera, size, samples):
    """The render and its (sums, sq_sums) after each count in COUNTS (the same samples, stepped)."""
    render = core.PreviewRender(tree, camera, size, size, samples=samples)
    out = {}
    for n in COUNTS:
        render.step(n - render.samples_done)
        out[n] = (render.sums.copy(), render.sq_sums.copy())
    return render, out


def own_errors(sums, sq_sums, counts, decay):
    n = counts.astype(np.float64)
    mean = sums.mean(axis=1) / n
    var = np.maximum(sq_sums / n - mean * mean, 0.0) * n / np.maximum(n - 1, 1)
    q = 1.0 / (n + 2.0)
    return np.sqrt(np.maximum(var, q * (1.0 - q)) / n ** (1.0 + decay))


RULES = {
    "own, 1/n": lambda r, s, q, c: own_errors(s, q, c, 0.0),
    "own, n^-1.5": lambda r, s, q, c: own_errors(s, q, c, 0.5),
    "5x5, n^-1.5": lambda r, s, q, c: standard_errors(r.width, r.height, r.pixels, sample_variances(s, q, c), c, 0.5),
}


def run_rule(render, pre, rule, target, most):
    """(estimate per hit pixel, stop count per hit pixel) of `rule` at `target`, at most `most` samples."""
    m = len(render.pixels)
    stop = np.full(m, most)
    active = np.ones(m, bool)
    for n in (c for c in COUNTS if c < most):
        take = np.where(active, n, stop)  # stopped pixels keep their prefix (as in the renderer)
        sums = _at(pre, take, 0)
        sq = _at(pre, take, 1)
        done = active & (RULES[rule](render, sums, sq, take) < target)
        stop[done] = n
        active &= ~done
    return _at(pre, stop, 0)[:, 0] / stop, stop


def _at(pre, counts, k):
    """Each pixel's prefix array k (0 sums, 1 sq_sums) at its own count."""
    out = np.empty_like(pre[COUNTS[0]][k])
    for c in COUNTS:
        sel = counts == c
        out[sel] = pre[c][k][sel]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--reference-samples", type=int, default=1024)
    args = ap.parse_args()
    scene = load_scene("suzanne-251k")
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    tree = core.build_kdtree(scene.triangles)
    ref_render = core.PreviewRender(tree, camera, args.size, args.size, samples=args.reference_samples, seed=12345)
    ref_render.step(args.reference_samples)
    ref = ref_render.sums[:, 0] / ref_render.counts
    render, pre = prefixes(tree, camera, args.size, COUNTS[-1])
    fixed = np.array([np.sqrt(np.mean((pre[n][0][:, 0] / n - ref) ** 2)) for n in COUNTS])
    print("fixed:", ", ".join(f"{n} spp RMSE {e:.5f}" for n, e in zip(COUNTS, fixed)))

    def fixed_equal(e):
        return float(np.exp(np.interp(np.log(e), np.log(fixed[::-1]), np.log(np.array(COUNTS[::-1], float)))))

    c = (pre[64][0][:, 0] / 64 - ref) ** 2 * 64 ** 1.5
    print(f"Neyman with known per-pixel errors (c_i from the 64-spp error): at most "
          f"{(np.mean(c ** 0.4) ** 2.5 / np.mean(c)) ** (-1 / 1.5):.2f}x fewer samples")
    print(f"{'rule':>12} {'max':>4} {'target':>6} {'RMSE':>8} {'mean spp':>8} {'fixed spp':>9} {'gain':>5} "
          f"{'stopped RMSE':>12} {'> 3 targets':>11}")
    for rule in RULES:
        for most in (64, 128):
            for target in (0.03, 0.02, 0.015, 0.012, 0.01):
                est, stop = run_rule(render, pre, rule, target, most)
                e = np.sqrt(np.mean((est - ref) ** 2))
                stopped = stop < most
                off = (est - ref)[stopped]
                srmse = np.sqrt(np.mean(off ** 2)) if stopped.any() else 0.0
                far = np.mean(np.abs(off) > 3 * target) if stopped.any() else 0.0
                print(f"{rule:>12} {most:>4} {target:>6} {e:8.5f} {stop.mean():8.1f} {fixed_equal(e):9.1f} "
                      f"{fixed_equal(e) / stop.mean():5.2f} {srmse:12.5f} {far:11.4f}")


if __name__ == "__main__":
    main()
