"""Render benchmark: run time against error for the AO preview, and seed 000's time-to-image setting.

Usage: python benchmarks/bench_render.py [--size 512] [--runs 3] [--reference-samples 1024]
                                         [--samples 1,2,4,...] [--no-cycles] [--out benchmarks/out]

Before any timing, every method runs once untimed (JIT compile and cache load, reported on one line).
1. A converged reference of suzanne-251k (512x512, ao_distance 1.0, --reference-samples samples, Sobol),
   cached in benchmarks/data/ under a name holding core's sources digest (a changed renderer makes a
   new one).
2. A sweep over samples per pixel, samplers (sobol, random), builders and a few builder settings:
   time (build + trace, median of --runs) and RMSE against the reference on hit pixels. The binned
   rows, with the default build and told the frame's rays (the add-on's setup: DEFAULT_METHOD), are
   repeated with the denoiser (core/render/denoise.py, time includes the filter), "... denoised".
   Written to OUT/render_sweep.csv (the run's settings in OUT/render_sweep.json) and plotted to
   OUT/render_rmse_vs_time.png with two Pareto fronts marked: raw estimates only, and with denoised rows.
   Also the denoiser's bias at convergence: RMSE between the reference and the denoised reference.
   Adaptive rows (ours with each --error-targets, at most each --adaptive-max samples, the build told the
   frame's rays as the add-on's) are timed in the same round-robin as the fixed rows of that sample
   count, with their mean samples a hit pixel; --methods keeps only some of our fixed methods (a shorter run).
3. Cycles' AO pass of the same .blend (the subdivided mesh, no modifier left to evaluate) and camera
   at matching sample counts (raw: Cycles has no denoiser for that pass), on as many threads as ours,
   timed in the same run, round-robin with our rows of the same sample count (sweep() says why), RMSE
   against the same reference; our time / Cycles' time at equal RMSE (interpolated in log-log) on the
   raw front, the front with the denoiser and our default setup alone. Also Cycles with its own adaptive
   sampling (--cycles-thresholds, at most each --adaptive-max samples; cycles_ao.render_cycles' adaptive),
   whose rows get the same ratios: against Cycles fixed and Cycles adaptive.
4. Seed 000 Table 3's setting: 640x480, camera rays and one shadow ray to a point light, the tree
   rebuilt from scratch each time; median time to image, with the default build, with the build told
   the frame's ray count (BuildOptions.rays), the latter on one thread, and Embree's build and queries
   of the same frame on one thread as the reference, in alternating runs.

Results as JSON (benchmarks/results.py, rendered into the docs by benchmarks/report.py):
benchmarks/out/bench_seed000.json (part 4: every run, medians, Embree's runs) and, unless --only-seed000,
benchmarks/out/bench_render.json (parts 2-3: the rows, the ratios against Cycles, the settings).
--quick (128x128, 1, 4 and 16 spp, one run, a 1024-spp reference, three seed 000 runs) checks that the
benchmark works; its figures are not comparable with a full run's.
"""
import argparse
import csv
import json
import platform
import sys
import time
from pathlib import Path

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
import results  # noqa: E402
from core.render.denoise import SOBOL_VARIANCE_DECAY  # noqa: E402
from core.jit.sources_digest import sources_digest  # noqa: E402
from scenes import DATA_DIR, blend_path, load_scene  # noqa: E402

TOLD = {"rays": "frame"}  # the add-on tells each frame's build the frame's rays (kd_addon/pipeline.py)
BUILD_CONFIGS = {
    "binned": {},
    "exact": {"builder": "exact"},
    "median": {"builder": "median"},
    "binned leaf_size=8": {"leaf_size": 8},
    "binned max_depth=28": {"max_depth": 28},
    "binned clip=False": {"clip": False},
    "binned rays=frame": TOLD,  # told the render's ray count (core.frame_ray_count): seed 003 §3.5
}


def reference_path(scene, size, samples, ao_distance):
    """Where the converged reference image is cached: keyed by core's sources too, so a change to the
    renderer (ray offsets, sampling) makes a new one instead of reusing a stale one."""
    digest = sources_digest(HERE.parent / "core")
    return DATA_DIR / f"ref_{scene.name}_{size}_{samples}spp_ao{ao_distance}_core-{digest}.npy"


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
    """(seconds of build + render (+ denoise), image, mean samples a hit pixel took)."""
    t = time.perf_counter()
    if options.get("rays") == "frame":  # the most rays this render traces, as a frame's build is told them
        options = {**options, "rays": core.frame_ray_count(size, size, "ao", samples)}
    tree = core.build_kdtree(scene.triangles, **options)
    render = core.PreviewRender(tree, camera, size, size, samples=samples, sampler=sampler, ao_distance=ao_distance,
                                error_target=error_target)
    render.step(render.target_samples)
    img = render.image(denoise)
    return time.perf_counter() - t, img, float(render.counts.mean())


def our_methods(only=None):
    """(method name, build options, sampler, denoise) of every swept configuration of ours (those named in
    `only` when given)."""
    methods = []
    for label, options in BUILD_CONFIGS.items():
        for sampler in ("sobol", "random") if label == "binned" else ("sobol",):
            for denoise in (False, True) if label in DENOISED_BUILDS else (False,):
                methods.append((f"kd {label} {sampler}" + (" denoised" if denoise else ""), options, sampler,
                                denoise))
    return [m for m in methods if only is None or m[0] in only]


def renders_of(spp, args):
    """{(method, error target): a function of no argument returning (seconds, image, mean samples)}: every
    render timed at `spp` samples, ours, our adaptive ones (their most samples `spp`, when spp is one of
    --adaptive-max) and, unless --no-cycles, Cycles' fixed and adaptive ones likewise."""
    scene, camera, ref = args.scene, args.camera, args.ref
    jobs = {}
    for method, options, sampler, denoise in our_methods(args.methods):
        jobs[(method, None)] = lambda o=options, sa=sampler, d=denoise: one_render(
            scene, camera, args.size, o, spp, sa, args.ao_distance, denoise=d)
    adaptive = spp in args.adaptive_max
    for target in args.error_targets if adaptive else ():
        jobs[(ADAPTIVE, target)] = lambda t=target: one_render(scene, camera, args.size, TOLD, spp, "sobol",
                                                               args.ao_distance, error_target=t)
    if not args.no_cycles:
        jobs[(CYCLES, None)] = lambda: cycles_image(scene, ref, args, spp)
        for threshold in args.cycles_thresholds if adaptive else ():
            jobs[(CYCLES_ADAPTIVE, threshold)] = lambda t=threshold: cycles_image(scene, ref, args, spp, t)
    return jobs


def sweep(scene, camera, ref, args):
    """Every method at every sample count, Cycles included (unless --no-cycles).

    The machine's speed drifts by up to 1.5x over a long run (shared host), so each sample count is
    measured on its own, round-robin: run r of every method, Cycles' too, before run r + 1, and the
    median of --runs is kept. A method and the Cycles render it is compared with are timed minutes,
    not half an hour, apart. Every run's seconds go to sweep.runs, by (method, samples, error target)."""
    sweep.runs = {}
    args.scene, args.camera, args.ref = scene, camera, ref
    rows = []
    for spp in args.samples:
        jobs = renders_of(spp, args)
        times, images, mean_samples = {}, {}, {}
        for _ in range(args.runs):
            for key, job in jobs.items():
                seconds, images[key], mean_samples[key] = job()
                times.setdefault(key, []).append(seconds)
        for (method, target), seconds in times.items():
            sweep.runs[(method, spp, target)] = seconds
            rows.append({"method": method, "samples": spp, "seconds": float(np.median(seconds)),
                         "rmse": rmse(images[(method, target)], ref), "error_target": target,
                         "mean_samples": mean_samples[(method, target)]})
            label = method if target is None else f"{method} {target:g}"
            mean = rows[-1]["mean_samples"]
            print(f"  {label:>38} spp {spp:>4}: {rows[-1]['seconds']:8.3f} s  RMSE {rows[-1]['rmse']:.5f}"
                  + (f"  mean spp {mean:.1f}" if target is not None and mean is not None else ""), flush=True)
    return rows


CYCLES = "cycles ao pass"
CYCLES_ADAPTIVE = "cycles ao pass adaptive"  # Cycles' adaptive sampling, error_target its adaptive_threshold
ADAPTIVE = "kd binned rays=frame sobol adaptive"  # ours with an error target, as the add-on renders it
DEFAULT_METHOD = "kd binned rays=frame sobol"  # what the add-on renders with (Denoise off)
DENOISED_BUILDS = ("binned", "binned rays=frame")  # the builds whose rows are repeated with the denoiser


def is_cycles(row):
    return row["method"] in (CYCLES, CYCLES_ADAPTIVE)


def cycles_image(scene, ref, args, spp, threshold=None):
    """As one_render: Cycles' render seconds, its AO pass as an (H, W, 4) image like ours (AO in R) and the
    mean samples a hit pixel took (None without adaptive sampling); with `threshold`, Cycles' adaptive sampling at that
    adaptive_threshold and automatic minimum samples, at most `spp`."""
    from cycles_ao import render_cycles_ao, render_cycles_ao_adaptive
    if threshold is None:
        img, seconds = render_cycles_ao(blend_path(scene.name), args.size, args.size, spp,
                                        ao_distance=args.ao_distance, threads=args.threads)
        mean = None
    else:
        img, seconds, mean = render_cycles_ao_adaptive(blend_path(scene.name), args.size, args.size, spp, threshold,
                                                       ao_distance=args.ao_distance, threads=args.threads)
    full = np.zeros_like(ref)
    full[..., 0] = img
    return seconds, full, mean


def pareto(rows):
    """Rows not beaten in both time and error by another row."""
    front = []
    for r in sorted(rows, key=lambda r: (r["seconds"], r["rmse"])):
        if not front or r["rmse"] < front[-1]["rmse"]:
            front.append(r)
    return front


def our_fronts(rows):
    """Our two Pareto fronts, raw rows only and with the denoised ones (Cycles' rows left out)."""
    ours = [r for r in rows if not is_cycles(r)]
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


def ratio_text(front, cycles_row):
    """Our time / Cycles' time at Cycles' RMSE on `front`. Where Cycles is less accurate than our fastest
    point, that point's ratio is an upper bound ("<= x"); where it is more accurate than all of ours,
    there is none."""
    ours = time_at_rmse(front, cycles_row["rmse"])
    if ours is not None:
        return f"{ours / cycles_row['seconds']:.3f}"
    fastest = min(front, key=lambda r: r["seconds"])
    if cycles_row["rmse"] > fastest["rmse"]:
        return f"<= {fastest['seconds'] / cycles_row['seconds']:.3f}"
    return "none (ours less accurate)"


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


def plot(rows, fronts, path, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 6))
    for method in sorted({r["method"] for r in rows}):
        ordered = sorted((r for r in rows if r["method"] == method),  # by sample count, then target
                         key=lambda r: (r["samples"], -float(r.get("error_target") or 0)))
        pts = [(r["seconds"], r["rmse"]) for r in ordered]
        style = dict(color="red", marker="s", ms=4, lw=2) if method == CYCLES else dict(marker="o", ms=3, lw=1)
        if method == CYCLES_ADAPTIVE:
            style = dict(color="darkred", marker="^", ms=4, lw=1, ls=":")
        ax.plot(*zip(*pts), label=method, **style)
    for (label, front), style in zip(fronts.items(), ("k--", "k:")):
        ax.plot([r["seconds"] for r in front], [r["rmse"] for r in front], style, lw=2, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time to image: build + trace (+ denoise) (s), median")
    ax.set_ylabel("RMSE against the converged reference (hit pixels)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def warm_up(scene, camera, args):
    """One untimed 8x8 run of every method (each builder over the whole scene: its parallel top levels
    use kernels a small scene does not; the denoiser, the random sampler, the adaptive mode), shadow
    mode, and unless --no-cycles or --only-seed000 one small Cycles render, so no timed run compiles
    (with an empty cache the exact builder's first build takes 58 s, and the denoised rows' first runs
    would pay their compile)."""
    tree = core.build_kdtree(scene.triangles)
    core.render_preview(tree, camera, 8, 8, samples=1, mode="shadow", lights=[core.Light.point((0, 0, 3))])
    if args.only_seed000:
        return
    for _, options, sampler, denoise in our_methods(args.methods):
        one_render(scene, camera, 8, options, 1, sampler, args.ao_distance, denoise=denoise)
    for target in args.error_targets[:1]:
        one_render(scene, camera, 8, {}, 2, "sobol", args.ao_distance, error_target=target)
    if not args.no_cycles:
        from cycles_ao import render_cycles_ao
        render_cycles_ao(blend_path(scene.name), 8, 8, 1, ao_distance=args.ao_distance, threads=args.threads)


SEED000_SIZE = (640, 480)
SEED000_LIGHT = (2.0, -3.0, 4.0)


def seed000_time_to_image(scene, runs, size=SEED000_SIZE):
    """Camera rays plus one shadow ray to a point light per hit, tree rebuilt from scratch: median
    (time, build time) of the default build and of a build told the frame's ray count (the `rays`
    option: one camera and at most one shadow ray a pixel), and of the latter on one thread, and the
    same frame's rays through Embree (seed000_embree), all in alternating runs: the reference measured
    in the same run, not only the 2007 paper's figure."""
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    light = core.Light.point(SEED000_LIGHT)
    rays = core.frame_ray_count(*size, "shadow", 1, [light])
    configs = {"default build": {}, "rays=W*H*2": {"rays": rays}, "rays=W*H*2, 1 thread": {"rays": rays, "threads": 1}}
    times = {name: [] for name in [*configs, EMBREE]}
    builds = {name: [] for name in times}
    embree_frame = seed000_embree_frame(scene, camera, size)
    for run in range(runs):
        for name in (list(times) if run % 2 == 0 else list(times)[::-1]):
            if name == EMBREE:
                seconds, build = seed000_embree(scene, *embree_frame)
                times[name].append(seconds)
                builds[name].append(build)
                continue
            t = time.perf_counter()
            tree = core.build_kdtree(scene.triangles, **configs[name])
            builds[name].append(time.perf_counter() - t)
            core.render_preview(tree, camera, size[0], size[1], samples=1, mode="shadow", lights=[light],
                                threads=configs[name].get("threads"))
            times[name].append(time.perf_counter() - t)
    seed000_time_to_image.runs = {name: {"seconds": times[name], "build_seconds": builds[name]} for name in times}
    return {name: (float(np.median(times[name])), float(np.median(builds[name]))) for name in times}


EMBREE = "Embree (1 thread)"


def seed000_embree_frame(scene, camera, size):
    """The frame's camera rays, and the shadow rays Embree traces for them: from each hit facing the
    light (N.L > 0, the rays ours traces), started 1e-4 towards it, ending 1e-4 short of it."""
    from reference_tracers import EmbreeTracer
    origins, directions, _, _ = camera.rays(*size)
    t, prim = EmbreeTracer(scene.triangles).closest(origins, directions)
    hit = prim >= 0
    points = origins[hit] + t[hit, None] * directions[hit]
    tri = scene.triangles[prim[hit]].astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal *= -np.sign(np.einsum("ij,ij->i", normal, directions[hit]))[:, None]  # facing the camera
    towards = np.asarray(SEED000_LIGHT) - points
    distance = np.linalg.norm(towards, axis=1)
    towards /= distance[:, None]
    lit = np.einsum("ij,ij->i", normal, towards) > 0.0
    return (origins, directions), (points[lit] + 1e-4 * towards[lit], towards[lit], distance[lit] - 2e-4)


def seed000_embree(scene, camera_rays, shadow_rays):
    """(seconds, build seconds) of Embree on the frame: its BVH build (the commit, TBB-parallel), the
    camera rays' closest hits and the shadow rays' occlusion, traced on one thread (embreex's loop is
    serial). Not counted: embreex's serial copy of the triangles into Embree's buffers (~0.4 s, more
    than Embree's build: a cost of the binding, not of Embree), shading, ray setup and the image, so
    this is a lower bound of an Embree-based renderer's time to image."""
    from reference_tracers import EmbreeTracer
    tracer = EmbreeTracer(scene.triangles)
    t = time.perf_counter()
    tracer.closest(*camera_rays)
    tracer.occluded(*shadow_rays)
    return tracer.commit_seconds + time.perf_counter() - t, tracer.commit_seconds


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--reference-samples", type=int, default=1024)
    ap.add_argument("--samples", default="1,2,4,8,16,32,64,128,256")
    ap.add_argument("--error-targets", default="0.03,0.02,0.015,0.012,0.01",
                    help="adaptive rows: a pixel stops below this estimated standard error")
    ap.add_argument("--adaptive-max", default=None,
                    help="the most samples of the adaptive rows, ours and Cycles' (comma list of --samples "
                         "values; default the largest two)")
    ap.add_argument("--cycles-thresholds", default="0.1,0.05,0.02,0.01",
                    help="Cycles' adaptive rows: its adaptive_threshold (empty: none)")
    ap.add_argument("--methods", default=None,
                    help="only these of our fixed methods (comma list of names, e.g. "
                         "'kd binned rays=frame sobol,kd binned rays=frame sobol denoised'; the first is required)")
    ap.add_argument("--ao-distance", type=float, default=1.0)
    ap.add_argument("--threads", type=int, default=numba.get_num_threads(),
                    help="Cycles' thread count (default: Numba's, which ours uses)")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--only-seed000", action="store_true")
    ap.add_argument("--out", default=str(HERE / "out"))
    ap.add_argument("--replot", action="store_true", help="only redraw OUT's plot from OUT/render_sweep.csv")
    ap.add_argument("--quick", action="store_true",
                    help="128x128, 1/4/16 spp, 1 run, 3 seed 000 runs: checks the benchmark and its JSON work")
    args = ap.parse_args()
    if args.replot:
        return replot(Path(args.out))
    if args.quick:
        args.size, args.runs, args.samples, args.error_targets = 128, 1, "1,4,16", "0.05"
    args.samples = [int(s) for s in args.samples.split(",")]
    args.error_targets = [float(s) for s in args.error_targets.split(",") if s]
    args.cycles_thresholds = [float(s) for s in args.cycles_thresholds.split(",") if s]
    args.adaptive_max = (sorted(args.samples)[-2:] if args.adaptive_max is None
                         else [int(s) for s in args.adaptive_max.split(",")])
    args.methods = None if args.methods is None else [m.strip() for m in args.methods.split(",")]
    if args.methods is not None and DEFAULT_METHOD not in args.methods:
        ap.error(f"--methods must include {DEFAULT_METHOD!r} (the default setup's ratio)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    scene = load_scene("suzanne-251k")
    camera = core.Camera(scene.camera_matrix, scene.camera_fov)
    t = time.perf_counter()
    warm_up(scene, camera, args)
    args.jit_seconds = time.perf_counter() - t
    print(f"JIT compile / cache load, one untimed run of each method: {args.jit_seconds:.2f} s (excluded from "
          "all timings)")

    print("seed 000 Table 3 setting (640x480, camera + 1 shadow ray, rebuild); paper: 0.235 s on 1 core, "
          f"0.062 s on 4 cores (2007); target <= 0.15 s; {numba.get_num_threads()} threads unless said:")
    seed000 = seed000_time_to_image(scene, 3 if args.quick else max(args.runs, 5))
    for name, (seconds, build) in seed000.items():
        print(f"  {name:<22} {seconds:.3f} s median (build {build:.3f} s)")
    print(f"  ours on 1 thread / Embree on 1 thread: {seed000['rays=W*H*2, 1 thread'][0] / seed000[EMBREE][0]:.2f} "
          f"(Embree's time: its BVH build, camera and shadow queries only)")
    Path(args.out).mkdir(parents=True, exist_ok=True)
    write_seed000(seed000_time_to_image.runs, args)
    if args.only_seed000:
        return

    if args.reference_samples < max(1024, 4 * max(args.samples)):
        print(f"warning: a {args.reference_samples}-sample reference is not converged against {max(args.samples)}-sample "
              "renders (the issue asks for >= 1024 samples): RMSE figures of this run are a smoke test only")
    ref = reference_image(scene, camera, args.size, args.reference_samples, args.ao_distance)
    rows = sweep(scene, camera, ref, args)
    fronts = our_fronts(rows)
    bias = denoiser_bias(scene, camera, ref, args)
    print(f"\ndenoiser bias at convergence: RMSE(denoised reference, reference) = {bias:.5f}")
    by = {(r["method"], r["samples"]): r for r in rows}
    print("\nLow discrepancy against random (binned), RMSE ratio random / sobol:")
    for spp in args.samples:
        a, b = by.get(("kd binned sobol", spp)), by.get(("kd binned random", spp))
        if a and b:
            print(f"  {spp:>4} spp: {b['rmse'] / a['rmse']:.2f}x")
    ratios_out = []
    if not args.no_cycles:
        crow = [r for r in rows if is_cycles(r)]
        default = pareto([r for r in rows if r["method"] == DEFAULT_METHOD])
        print("\nOur time / Cycles' time at equal RMSE (target <= 0.2; Cycles' AO pass raw: it has no denoiser):\n"
              f"  on our raw front, on the front with our denoiser, and on our default setup alone "
              f"({DEFAULT_METHOD!r}: the front picks, per sample count, the fastest of several setups that give\n"
              "  the same image, so noise helps it)")
        print(f"  {'':>59} {'ours raw':>12} {'ours denoised':>14} {'ours default':>14}")
        for r in crow:
            ratios = [ratio_text(front, r) for front in (*fronts.values(), default)]
            ratios_out.append({"cycles_samples": r["samples"], "cycles_rmse": r["rmse"],
                               "cycles_seconds": r["seconds"], "ours_raw": ratios[0],
                               "ours_denoised": ratios[1], "ours_default": ratios[2],
                               "cycles_adaptive_threshold": r["error_target"],
                               "cycles_mean_samples": r["mean_samples"]})
            kind = "fixed" if r["error_target"] is None else f"adaptive {r['error_target']:g}"
            print(f"  Cycles {kind:>14} {r['samples']:>4} spp (RMSE {r['rmse']:.4f}, {r['seconds']:6.2f} s): "
                  f"{ratios[0]:>12} {ratios[1]:>14} {ratios[2]:>14}")
    with open(out / "render_sweep.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["method", "samples", "seconds", "rmse", "error_target", "mean_samples"])
        w.writeheader()
        w.writerows(rows)
    meta = run_description(args)
    (out / "render_sweep.json").write_text(json.dumps(meta, indent=1))
    plot(rows, fronts, out / "render_rmse_vs_time.png", plot_title(meta))
    sweep_runs = sweep.runs
    results.write("bench_render", {
        "scene": "suzanne-251k", "size": args.size, "ao_distance": args.ao_distance, "runs": args.runs,
        "reference_samples": args.reference_samples, "samples": args.samples, "cycles": not args.no_cycles,
        "cycles_threads": args.threads, "core_sources": meta["core_sources"],
        "rows": [{**r, "all_seconds": sweep_runs.get((r["method"], r["samples"], r.get("error_target")))}
                 for r in rows],
        "time_ratio_at_equal_rmse": ratios_out, "default_method": DEFAULT_METHOD, "denoiser_bias_rmse": bias,
    }, args.jit_seconds, args.quick, out)
    print(f"\nwrote {out / 'render_sweep.csv'}, {out / 'render_sweep.json'} (the run's settings) and "
          f"{out / 'render_rmse_vs_time.png'}")


def write_seed000(runs, args):
    """bench_seed000.json: per configuration every run's time to image and build time, their medians,
    and the Embree reference of the same runs."""
    embree = runs[EMBREE]
    configs = {}
    for name, r in runs.items():
        configs[name] = {"seconds": results.figure(r["seconds"], None if name == EMBREE else embree["seconds"]),
                         "build_seconds": results.figure(r["build_seconds"])}
    results.write("bench_seed000", {
        "scene": "suzanne-251k", "size": list(SEED000_SIZE), "light": list(SEED000_LIGHT),
        "what": "rebuild + camera rays + one shadow ray a hit to a point light", "reference": EMBREE,
        "configs": configs,
    }, args.jit_seconds, args.quick, args.out)


def run_description(args):
    """What a sweep's CSV came from (written beside it: a smoke run's CSV looks like a real one)."""
    return {"scene": "suzanne-251k", "size": args.size, "ao_distance": args.ao_distance, "runs": args.runs,
            "reference_samples": args.reference_samples, "samples": args.samples,
            "error_targets": args.error_targets, "cycles": not args.no_cycles, "cycles_threads": args.threads,
            "numba_threads": numba.get_num_threads(), "jit_seconds": round(args.jit_seconds, 2),
            "core_sources": sources_digest(HERE.parent / "core"), "host": platform.node(),
            "cpu": platform.processor() or platform.machine(), "date": time.strftime("%Y-%m-%d %H:%M:%S")}


def plot_title(meta):
    return (f"{meta['scene']}, {meta['size']}x{meta['size']} AO, ao_distance {meta['ao_distance']:g}, "
            f"reference {meta['reference_samples']} spp, medians of {meta['runs']}")


def replot(out):
    """Redraw the plot from a sweep's CSV (no rendering)."""
    with open(out / "render_sweep.csv", newline="") as f:
        rows = [{**r, "samples": int(r["samples"]), "seconds": float(r["seconds"]), "rmse": float(r["rmse"])}
                for r in csv.DictReader(f)]
    fronts = our_fronts(rows)
    meta = out / "render_sweep.json"
    title = plot_title(json.loads(meta.read_text())) if meta.is_file() else "suzanne-251k AO (settings not recorded)"
    plot(rows, fronts, out / "render_rmse_vs_time.png", title)
    print(f"wrote {out / 'render_rmse_vs_time.png'}")


if __name__ == "__main__":
    main()
