"""Render benchmark: run time against error for the AO preview, and seed 000's time-to-image setting.

Usage: python benchmarks/bench_render.py [--size 512] [--runs 3] [--reference-samples 1024]
                                         [--samples 1,2,4,...] [--no-cycles] [--out benchmarks/out]

1. A converged reference of suzanne-251k (512x512, ao_distance 1.0, --reference-samples samples, Sobol),
   cached in benchmarks/data/.
2. A sweep over samples per pixel, samplers (sobol, random), builders and a few builder settings:
   time (build + trace, median of --runs, JIT compile excluded and reported once) and RMSE against the
   reference on hit pixels. The binned rows are repeated with the denoiser (core/denoise.py, time
   includes the filter), "... denoised". Written to OUT/render_sweep.csv and plotted to
   OUT/render_rmse_vs_time.png with two Pareto fronts marked: raw estimates only, and with denoised rows.
   Also the denoiser's bias at convergence: RMSE between the reference and the denoised reference.
3. Cycles' AO pass of the same .blend and camera at matching sample counts (raw, Cycles' denoiser off),
   timed in the same run, round-robin with our rows of the same sample count (sweep() says why), RMSE
   against the same reference; our time / Cycles' time at equal RMSE
   (interpolated on our Pareto front in log-log), for the raw front and the front with the denoiser.
4. Seed 000 Table 3's setting: 640x480, camera rays and one shadow ray to a point light, the tree
   rebuilt from scratch each time; median time to image, with the default build and with the build
   told the frame's ray count (BuildOptions.rays), in alternating runs.
"""
import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
from core.denoise import SOBOL_VARIANCE_DECAY  # noqa: E402
from scenes import DATA_DIR, blend_path, load_scene  # noqa: E402

BUILD_CONFIGS = {
    "binned": {},
    "exact": {"builder": "exact"},
    "median": {"builder": "median"},
    "binned leaf_size=8": {"leaf_size": 8},
    "binned max_depth=28": {"max_depth": 28},
    "binned clip=False": {"clip": False},
}


def reference_path(scene, size, samples, ao_distance):
    """Where the converged reference image is cached."""
    return DATA_DIR / f"ref_{scene.name}_{size}_{samples}spp_ao{ao_distance}.npy"


def reference_image(scene, camera, size, samples, ao_distance):
    path = reference_path(scene, size, samples, ao_distance)
    if path.exists():
        return np.load(path)
    print(f"computing the {samples}-sample reference (cached at {path}) ...", flush=True)
    tree = core.build_kdtree(scene.triangles, builder="exact")
    img = core.render_preview(tree, camera, size, size, samples=samples, ao_distance=ao_distance, seed=12345)
    np.save(path, img)
    return img


def rmse(img, ref):
    mask = ref[..., 3] > 0.5
    return float(np.sqrt(np.mean((img[..., 0][mask] - ref[..., 0][mask]) ** 2)))


def one_render(scene, camera, size, options, samples, sampler, ao_distance, error_target=None, denoise=False):
    """(seconds of build + render (+ denoise), image)."""
    t = time.perf_counter()
    tree = core.build_kdtree(scene.triangles, **options)
    img = core.render_preview(tree, camera, size, size, samples=samples, sampler=sampler,
                              ao_distance=ao_distance, error_target=error_target, denoise=denoise)
    return time.perf_counter() - t, img


def our_methods():
    """(method name, build options, sampler, denoise) of every swept configuration of ours."""
    methods = []
    for label, options in BUILD_CONFIGS.items():
        for sampler in ("sobol", "random") if label == "binned" else ("sobol",):
            for denoise in (False, True) if label == "binned" else (False,):
                methods.append((f"kd {label} {sampler}" + (" denoised" if denoise else ""), options, sampler,
                                denoise))
    return methods


def sweep(scene, camera, ref, args):
    """Every method at every sample count, Cycles included (unless --no-cycles).

    The machine's speed drifts by up to 1.5x over a long run (shared host), so each sample count is
    measured on its own, round-robin: run r of every method, Cycles' too, before run r + 1, and the
    median of --runs is kept. A method and the Cycles render it is compared with are timed minutes,
    not half an hour, apart."""
    rows = []
    for spp in args.samples:
        times, images = {}, {}
        for _ in range(args.runs):
            for method, options, sampler, denoise in our_methods():
                seconds, images[method] = one_render(scene, camera, args.size, options, spp, sampler,
                                                     args.ao_distance, denoise=denoise)
                times.setdefault(method, []).append(seconds)
            if not args.no_cycles:
                images[CYCLES], seconds = cycles_image(scene, ref, args, spp)
                times.setdefault(CYCLES, []).append(seconds)
        for method in times:
            rows.append({"method": method, "samples": spp, "seconds": float(np.median(times[method])),
                         "rmse": rmse(images[method], ref)})
            print(f"  {method:>32} spp {spp:>4}: {rows[-1]['seconds']:8.3f} s  RMSE {rows[-1]['rmse']:.5f}",
                  flush=True)
    for target in args.error_targets:  # adaptive: pixels stop once their standard error is below target
        runs = [one_render(scene, camera, args.size, {}, max(args.samples), "sobol", args.ao_distance,
                           error_target=target) for _ in range(args.runs)]
        rows.append({"method": "kd binned sobol adaptive", "samples": max(args.samples),
                     "seconds": float(np.median([r[0] for r in runs])), "rmse": rmse(runs[-1][1], ref),
                     "error_target": target})
        print(f"  {rows[-1]['method']:>32} target {target:g}: {rows[-1]['seconds']:8.3f} s  RMSE {rows[-1]['rmse']:.5f}",
              flush=True)
    return rows


CYCLES = "cycles ao pass"


def cycles_image(scene, ref, args, spp):
    """Cycles' AO pass as an (H, W, 4) image like ours (AO in R), and its render seconds."""
    from cycles_ao import render_cycles_ao
    img, seconds = render_cycles_ao(blend_path(scene.name), args.size, args.size, spp,
                                    ao_distance=args.ao_distance, threads=args.threads)
    full = np.zeros_like(ref)
    full[..., 0] = img
    return full, seconds


def pareto(rows):
    """Rows not beaten in both time and error by another row."""
    front = []
    for r in sorted(rows, key=lambda r: (r["seconds"], r["rmse"])):
        if not front or r["rmse"] < front[-1]["rmse"]:
            front.append(r)
    return front


def our_fronts(rows):
    """Our two Pareto fronts, raw rows only and with the denoised ones (Cycles' rows left out)."""
    ours = [r for r in rows if r["method"] != CYCLES]
    return {"Pareto front, raw (KD Preview)": pareto([r for r in ours if "denoised" not in r["method"]]),
            "Pareto front, with denoiser (KD Preview)": pareto(ours)}


def time_at_rmse(front, target):
    """Our time at a given RMSE, interpolated on the Pareto front in log-log (None if out of range)."""
    e = np.log([r["rmse"] for r in front])
    t = np.log([r["seconds"] for r in front])
    if not e.min() <= np.log(target) <= e.max():
        return None
    order = np.argsort(e)
    return float(np.exp(np.interp(np.log(target), e[order], t[order])))


def denoiser_bias(scene, camera, ref, args):
    """RMSE between the reference and the reference denoised: how much the filter moves a converged
    image. AO samples are 0 or 1, so the reference's grey sums of squares equal its sums."""
    tree = core.build_kdtree(scene.triangles)
    render = core.PreviewRender(tree, camera, args.size, args.size, samples=1, ao_distance=args.ao_distance)
    n = args.reference_samples
    value = ref.reshape(-1, 4)[render.pixels, 0].astype(np.float64)
    counts = np.full(len(value), n, np.int64)
    img = core.denoise_pixels(args.size, args.size, render.pixels, render.points, render.normals,
                              np.repeat(value[:, None] * n, 3, axis=1), value * n, counts,
                              variance_decay=SOBOL_VARIANCE_DECAY)  # the reference is a Sobol render
    return rmse(img, ref)


def plot(rows, fronts, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 6))
    for method in sorted({r["method"] for r in rows}):
        pts = sorted((r["seconds"], r["rmse"]) for r in rows if r["method"] == method)
        style = dict(color="red", marker="s", ms=4, lw=2) if method == CYCLES else dict(marker="o", ms=3, lw=1)
        ax.plot(*zip(*pts), label=method, **style)
    for (label, front), style in zip(fronts.items(), ("k--", "k:")):
        ax.plot([r["seconds"] for r in front], [r["rmse"] for r in front], style, lw=2, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time to image: build + trace (+ denoise) (s), median")
    ax.set_ylabel("RMSE against the converged reference (hit pixels)")
    ax.set_title("suzanne-251k, 512x512 AO, ao_distance 1.0")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def seed000_time_to_image(scene, runs, size=(640, 480)):
    """Camera rays plus one shadow ray to a point light per hit, tree rebuilt from scratch: median
    (time, build time) of the default build and of a build told the frame's ray count (the `rays`
    option: one camera and at most one shadow ray a pixel), in alternating runs."""
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    light = core.Light.point((2.0, -3.0, 4.0))
    configs = {"default build": {}, "rays=W*H*2": {"rays": core.frame_ray_count(*size, "shadow", 1, [light])}}
    times = {name: [] for name in configs}
    builds = {name: [] for name in configs}
    for run in range(runs):
        for name in (list(configs) if run % 2 == 0 else list(configs)[::-1]):
            t = time.perf_counter()
            tree = core.build_kdtree(scene.triangles, **configs[name])
            builds[name].append(time.perf_counter() - t)
            core.render_preview(tree, camera, size[0], size[1], samples=1, mode="shadow", lights=[light])
            times[name].append(time.perf_counter() - t)
    return {name: (float(np.median(times[name])), float(np.median(builds[name]))) for name in configs}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--reference-samples", type=int, default=1024)
    ap.add_argument("--samples", default="1,2,4,8,16,32,64,128,256")
    ap.add_argument("--error-targets", default="0.1,0.05,0.02",
                    help="adaptive rows: at most max(--samples) samples, a pixel stops below this standard error")
    ap.add_argument("--ao-distance", type=float, default=1.0)
    ap.add_argument("--threads", type=int, default=2, help="Cycles' thread count (ours uses all cores)")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--only-seed000", action="store_true")
    ap.add_argument("--out", default=str(HERE / "out"))
    ap.add_argument("--replot", action="store_true", help="only redraw OUT's plot from OUT/render_sweep.csv")
    args = ap.parse_args()
    if args.replot:
        return replot(Path(args.out))
    args.samples = [int(s) for s in args.samples.split(",")]
    args.error_targets = [float(s) for s in args.error_targets.split(",") if s]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    scene = load_scene("suzanne-251k")
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    t = time.perf_counter()
    warm = core.build_kdtree(scene.triangles)  # the whole scene: its parallel top levels use more kernels
    core.render_preview(warm, camera, 8, 8, samples=1)
    core.render_preview(warm, camera, 8, 8, samples=1, mode="shadow", lights=[core.Light.point((0, 0, 3))])
    print(f"JIT compile / cache load: {time.perf_counter() - t:.2f} s (excluded from all timings)")

    print("seed 000 Table 3 setting (640x480, camera + 1 shadow ray, rebuild); paper: 0.235 s on 1 core, "
          "0.062 s on 4 cores (2007); target <= 0.15 s:")
    for name, (seconds, build) in seed000_time_to_image(scene, max(args.runs, 5)).items():
        print(f"  {name:<14} {seconds:.3f} s median (build {build:.3f} s)")
    if args.only_seed000:
        return

    ref = reference_image(scene, camera, args.size, args.reference_samples, args.ao_distance)
    rows = sweep(scene, camera, ref, args)
    fronts = our_fronts(rows)
    print(f"\ndenoiser bias at convergence: RMSE(denoised reference, reference) = "
          f"{denoiser_bias(scene, camera, ref, args):.5f}")
    by = {(r["method"], r["samples"]): r for r in rows}
    print("\nLow discrepancy against random (binned), RMSE ratio random / sobol:")
    for spp in args.samples:
        a, b = by.get(("kd binned sobol", spp)), by.get(("kd binned random", spp))
        if a and b:
            print(f"  {spp:>4} spp: {b['rmse'] / a['rmse']:.2f}x")
    if not args.no_cycles:
        crow = [r for r in rows if r["method"] == CYCLES]
        print("\nOur time / Cycles' time at equal RMSE (target <= 0.2; Cycles raw, no denoiser):")
        print(f"  {'':>44} {'ours raw':>12} {'ours denoised':>14}")
        for r in crow:
            ratios = []
            for front in fronts.values():
                ours = time_at_rmse(front, r["rmse"])
                ratios.append(f"{ours / r['seconds']:.3f}" if ours else "out of range")
            print(f"  Cycles {r['samples']:>4} spp (RMSE {r['rmse']:.4f}, {r['seconds']:6.2f} s): "
                  f"{ratios[0]:>12} {ratios[1]:>14}")
    with open(out / "render_sweep.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["method", "samples", "seconds", "rmse", "error_target"])
        w.writeheader()
        w.writerows(rows)
    plot(rows, fronts, out / "render_rmse_vs_time.png")
    print(f"\nwrote {out / 'render_sweep.csv'} and {out / 'render_rmse_vs_time.png'}")


def replot(out):
    """Redraw the plot from a sweep's CSV (no rendering)."""
    with open(out / "render_sweep.csv", newline="") as f:
        rows = [{**r, "samples": int(r["samples"]), "seconds": float(r["seconds"]), "rmse": float(r["rmse"])}
                for r in csv.DictReader(f)]
    fronts = our_fronts(rows)
    plot(rows, fronts, out / "render_rmse_vs_time.png")
    print(f"wrote {out / 'render_rmse_vs_time.png'}")


if __name__ == "__main__":
    main()
