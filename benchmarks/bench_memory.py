"""Memory benchmark: a 5-million-triangle scene built and rendered, peak bytes per triangle, and the
calibration of core/memory.py's estimates.

Usage:
    python benchmarks/bench_memory.py                 # 5M triangles: build ms, render ms, peak bytes/triangle
    python benchmarks/bench_memory.py --calibrate     # measured peak build bytes/triangle per scene and
                                                      # builder, render bytes/pixel, against the estimates

Every measurement runs in a fresh child process (importing numpy and core, never bpy) that loads its
triangles from an .npy file, warms the kernels up on a small slice (so the JIT is not measured), then
reads ru_maxrss (the peak resident set, a high-water mark) before and after the measured call: the
growth is what the call needed at its peak. Generating scenes in the parent keeps their float64
temporaries out of the child's high-water mark.
"""
import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

DATA = HERE / "data"
FIVE_M_CAMERA = np.array([[1.0, 0, 0, 0], [0, 0, -1, -14.0], [0, 1, 0, 0.2], [0, 0, 0, 1]])  # looks along +Y
RENDER = dict(width=960, height=540, samples=16, ao_distance=0.5)


# -- scenes (parent side) ------------------------------------------------------


def wavy_grid(n, amplitude=0.05):
    """About n triangles of a displaced height field over [0, 1]^2 (a regular, open surface); amplitude 0
    gives a flat subdivided plane, the worst case of the binned builder (see docs/reliability.md)."""
    k = int(np.sqrt(n / 2))
    x, y = np.meshgrid(np.linspace(0, 1, k + 1), np.linspace(0, 1, k + 1), indexing="ij")
    p = np.stack([x, y, amplitude * np.sin(25 * x) * np.cos(25 * y)], -1).astype(np.float32)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])


def five_suzannes():
    """Five copies of suzanne-1m side by side: 5,038,090 triangles of a real subdivided model."""
    from scenes import load_scene
    tris = load_scene("suzanne-1m").triangles
    return np.concatenate([tris + np.array([dx, 0, 0], np.float32) for dx in (-5.0, -2.5, 0.0, 2.5, 5.0)])


def dense_soup(n=100_000):
    """n random triangles 0.05 wide in a 2-unit cube: 4.5-6.7 references a triangle, the scene that set
    the exact builder's estimate (docs/reliability.md)."""
    rng = np.random.default_rng(0)
    return rng.uniform(-1.0, 1.0, (n, 1, 3)) + rng.normal(0.0, 0.05, (n, 3, 3))


def flat_cards(n=200_000, seed=0):
    """n triangles ~0.05 across over a sqrt(n / 50,000)-wide square (the density of bench_duplication's
    50,000 cards in a unit square), all in z = 0: the duplication budget's case."""
    rng = np.random.default_rng(seed)
    width = np.sqrt(n / 50_000)
    return (rng.random((n, 1, 3)) * width + 0.05 * rng.standard_normal((n, 3, 3))) * [1, 1, 0]


def scene_file(name):
    """The scene's triangles as data/<name>.npy (written once)."""
    path = DATA / f"{name}.npy"
    if not path.is_file():
        from scenes import load_scene
        makers = {"grid-1m": lambda: wavy_grid(1_000_000), "five-suzannes-5m": five_suzannes,
                  "flat-grid-1m": lambda: wavy_grid(1_000_000, amplitude=0.0),
                  "soup-1m": lambda: load_scene("soup-1m").triangles,
                  "suzanne-1m": lambda: load_scene("suzanne-1m").triangles,
                  "dense-soup-100k": dense_soup, "flat-cards-200k": flat_cards,
                  "soup-10m": lambda: __import__("scenes")._build_soup(10_000_000, seed=20_261_205)[0],
                  "grid-10m": lambda: wavy_grid(10_000_000)}
        DATA.mkdir(exist_ok=True)
        np.save(path, np.ascontiguousarray(makers[name](), dtype=np.float32))
    return path


def child(*args):
    """Run this script's child mode; return the JSON it prints."""
    out = subprocess.run([sys.executable, __file__, "--child", *map(str, args)], capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


# -- measurements (child side) -------------------------------------------------


def peak_kib():
    """The process's resident-set high-water mark in KiB. On Linux VmHWM, this address space's own: ru_maxrss
    also carries the parent's peak across fork and exec, which hid the growth of a child started by a
    process that had held more (a parent that had just generated a 10M-triangle scene)."""
    try:
        with open("/proc/self/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def measure_build(path, builder):
    import core
    tris = np.load(path)
    core.build_kdtree(tris[:20000], builder=builder)
    base = peak_kib()
    t = time.perf_counter()
    tree = core.build_kdtree(tris, builder=builder)
    ms = (time.perf_counter() - t) * 1e3
    grow = (peak_kib() - base) * 1024
    return {"triangles": len(tris), "build_ms": ms, "bytes_per_triangle": grow / len(tris),
            "refs_per_triangle": tree.stats()["references_per_triangle"]}


# the render paths' different buffers: case -> (render mode, instances the floor is split into)
PIXEL_CASES = {"ao": ("ao", 1), "shadow": ("shadow", 1), "ao+shadow": ("ao+shadow", 1),
               "shadow, 2 instances": ("shadow", 2)}


def measure_render_pixels(width, height, case="ao"):
    """A floor covering the whole view (every pixel hit, the worst case for the hit buffers), rendered one
    sample a pixel: AO; hard shadows of four point lights (the camera and shadow packets and the stored
    weights); AO with those lights; and hard shadows with the floor as two instances (their packets' lane
    buffers)."""
    import core
    from core.scene.two_level import build_two_level
    tris = np.array([[[-50, -50, 0], [50, -50, 0], [50, 50, 0]], [[-50, -50, 0], [50, 50, 0], [-50, 50, 0]]],
                    np.float32)
    mode, instances = PIXEL_CASES[case]
    tree = core.build_kdtree(tris)
    if instances == 2:
        tree = build_two_level([core.build_kdtree(tris[:1]), core.build_kdtree(tris[1:])], [0, 1],
                               np.stack([np.eye(4)] * 2))
    lights = [core.Light.point((x, y, 4.0)) for x in (-3.0, 3.0) for y in (-3.0, 3.0)] if "shadow" in mode else []
    camera = core.Camera(np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]]), fov=0.8)
    core.render_preview(tree, camera, 32, 32, samples=1, mode=mode, lights=lights)
    base = peak_kib()
    render = core.PreviewRender(tree, camera, width, height, samples=1, mode=mode, lights=lights)
    render.step(1)
    render.image()
    grow = (peak_kib() - base) * 1024
    return {"pixels": width * height, "bytes_per_pixel": grow / (width * height)}


def measure_five_million(path, builder):
    """Build and render the 5M scene; peak RSS over the loaded triangles, per triangle."""
    import core
    tris = np.load(path)
    camera = core.Camera(FIVE_M_CAMERA, fov=0.69)
    small = core.build_kdtree(tris[:20000], builder=builder)
    core.render_preview(small, camera, 16, 16, samples=1)  # JIT / cache load, not measured
    base = peak_kib()
    t = time.perf_counter()
    tree = core.build_kdtree(tris, builder=builder)
    build_ms = (time.perf_counter() - t) * 1e3
    after_build = peak_kib()
    t = time.perf_counter()
    image = core.render_preview(tree, camera, RENDER["width"], RENDER["height"], samples=RENDER["samples"],
                                ao_distance=RENDER["ao_distance"])
    render_ms = (time.perf_counter() - t) * 1e3
    peak = peak_kib()
    estimate = core.memory.build_bytes(len(tris), builder) + core.memory.render_bytes(RENDER["width"],
                                                                                      RENDER["height"])
    t = time.perf_counter()
    try:
        core.build_kdtree(tris, builder=builder, memory_limit=estimate // 2)
        refused_ms = None
    except core.MemoryLimitError:
        refused_ms = (time.perf_counter() - t) * 1e3
    return {"triangles": len(tris), "build_ms": build_ms, "render_ms": render_ms,
            "build_bytes_per_triangle": (after_build - base) * 1024 / len(tris),
            "peak_bytes_per_triangle": (peak - base) * 1024 / len(tris),
            "peak_rss_mib": peak / 1024, "triangles_mib": tris.nbytes / 2**20,
            "estimate_bytes_per_triangle": estimate / len(tris), "refused_in_ms": refused_ms,
            "hit_fraction": float(image[..., 3].mean()), "nodes": tree.stats()["nodes"]}


def run_child(argv):
    kind = argv[0]
    if kind == "build":
        result = measure_build(argv[1], argv[2])
    elif kind == "pixels":
        result = measure_render_pixels(int(argv[1]), int(argv[2]), argv[3])
    else:
        result = measure_five_million(argv[1], argv[2])
    print(json.dumps(result))


# -- reports -------------------------------------------------------------------


def calibrate(scenes, builders, runs):
    import core
    print(f"{'scene':<18} {'builder':<8} {'build ms':>9} {'refs/tri':>9} {'peak B/tri':>11} {'estimate':>9}")
    worst = {}
    for name in scenes:
        path = scene_file(name)
        for builder in builders:
            rows = [child("build", path, builder) for _ in range(runs)]
            per_tri = float(np.median([r["bytes_per_triangle"] for r in rows]))
            worst[builder] = max(worst.get(builder, 0.0), per_tri)
            estimate = core.memory.build_bytes(1_000_000, builder) / 1e6
            print(f"{name:<18} {builder:<8} {np.median([r['build_ms'] for r in rows]):>9.0f} "
                  f"{rows[0]['refs_per_triangle']:>9.2f} {per_tri:>11.1f} {estimate:>9.1f}", flush=True)
    for builder, value in worst.items():
        print(f"worst {builder}: {value:.1f} B/tri measured; core.memory.BUILD_BYTES_PER_TRIANGLE "
              f"{core.memory.BUILD_BYTES_PER_TRIANGLE[builder]:.0f} x margin {core.memory.MARGIN}")
    for width, height in ((960, 540), (1920, 1080)):
        for case in PIXEL_CASES:
            px = float(np.median([child("pixels", width, height, case)["bytes_per_pixel"] for _ in range(runs)]))
            print(f"render {width}x{height} {case}: {px:.1f} B/pixel measured; core.memory.RENDER_BYTES_PER_PIXEL "
                  f"{core.memory.RENDER_BYTES_PER_PIXEL:.0f} x margin {core.memory.MARGIN}", flush=True)


def five_million(builder, runs):
    path = scene_file("five-suzannes-5m")
    rows = [child("five", path, builder) for _ in range(runs)]
    med = {k: float(np.median([r[k] for r in rows])) for k in rows[0] if rows[0][k] is not None}
    print(f"five-suzannes-5m ({rows[0]['triangles']:,} triangles, {builder}), medians of {runs} child runs:")
    print(f"  build {med['build_ms']:.0f} ms, render {RENDER['width']}x{RENDER['height']} "
          f"{RENDER['samples']} spp AO {med['render_ms']:.0f} ms ({med['hit_fraction']:.0%} of pixels hit)")
    print(f"  peak RSS growth: build {med['build_bytes_per_triangle']:.0f} B/tri, build + render "
          f"{med['peak_bytes_per_triangle']:.0f} B/tri (estimate {med['estimate_bytes_per_triangle']:.0f}); "
          f"peak RSS {med['peak_rss_mib']:.0f} MiB incl. {med['triangles_mib']:.0f} MiB of triangles")
    print(f"  memory_limit = estimate / 2: refused in {med['refused_in_ms']:.2f} ms, before allocating")


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        return run_child(sys.argv[2:])
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--calibrate", action="store_true")
    ap.add_argument("--scenes", default="soup-1m,suzanne-1m,grid-1m,flat-grid-1m,dense-soup-100k")
    ap.add_argument("--builders", default="binned,median,exact")
    ap.add_argument("--builder", default="binned", help="builder for the 5M run")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    if args.calibrate:
        calibrate([name for name in args.scenes.split(",") if name], args.builders.split(","), args.runs)
    else:
        five_million(args.builder, args.runs)


if __name__ == "__main__":
    main()
