"""Lazy (on-demand) against eager kd-tree builds: time to image (build + camera rays + AO samples).

Usage: python benchmarks/bench_lazy.py [--runs 3] [--size 512] [--samples 4] [--subtree-sizes 4096,...]
                                       [--scenes wall,low-wall,suzanne] [--speculative]

Scenes (seed 003 §5.2-5.3: on-demand building pays with occlusion, and should cost little without it):
- wall:     a 3x3 grid of suzanne-251k monkeys (copies translated in numpy, 2.27M triangles) on a floor,
            behind a wall that fills the camera's view (the hidden instances of seed 003's Figure 5).
- low-wall: the same with the wall's top at z = 0, so the upper halves of the monkeys show over it.
- suzanne:  the plain suzanne-251k view (no occluder): lazy should cost at most ~10% extra.

Time to image = build_kdtree + render_preview (512x512 camera rays, then `samples` cosine-weighted AO
rays per hit, ao_distance 1.0). Eager and lazy runs alternate, and each figure is the median of --runs
runs. "excl. top" is the same ratio without the parallel top levels, which both builds share
unchanged: on a loaded machine that phase's parallel kernels stall for up to a second at random and
swamp small differences. A first untimed run of each absorbs the JIT compile, reported on its own
line. The lazy image must equal the eager one bit for bit (checked every run). "nodes" is the lazy tree's node count after
the image against the (identical, fully built) eager tree's.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import core  # noqa: E402
from scenes import load_scene  # noqa: E402

MONKEY_TRIANGLES = 251_904  # suzanne-251k's first triangles; the last two are its ground plane
GRID_SPACING = 3.0
AO_DISTANCE = 1.0


def quad(center, u, v):
    c, u, v = (np.asarray(x, np.float64) for x in (center, u, v))
    p = [c - u - v, c + u - v, c + u + v, c - u + v]
    return np.array([[p[0], p[1], p[2]], [p[0], p[2], p[3]]], np.float32)


def wall_scene(base, wall_top):
    """3x3 monkeys (rows at y = 0, 3, 6), a floor at z = -1 and a wall in front of the first row."""
    monkey = base.triangles[:MONKEY_TRIANGLES]
    copies = [monkey + np.array([dx, dy, 0.0], np.float32)
              for dy in (0.0, GRID_SPACING, 2 * GRID_SPACING) for dx in (-GRID_SPACING, 0.0, GRID_SPACING)]
    wall_y = float(monkey[..., 1].min()) - 0.5
    half_height = (wall_top + 1.0) / 2.0
    wall = quad((0.0, wall_y, wall_top - half_height), (8.0, 0.0, 0.0), (0.0, 0.0, half_height))
    floor = quad((0.0, 3.0, -1.0), (8.0, 0.0, 0.0), (0.0, 8.0, 0.0))
    return np.ascontiguousarray(np.concatenate(copies + [floor, wall]))


def scenes(names):
    base = load_scene("suzanne-251k")
    camera = core.Camera(base.camera_matrix, base.camera_fov)
    make = {"wall": lambda: wall_scene(base, 3.0), "low-wall": lambda: wall_scene(base, 0.0),
            "suzanne": lambda: base.triangles}
    for name in names:
        yield name, make[name](), camera


def time_to_image(tris, camera, size, samples, options):
    """(build s, render s, image, tree) of one build + render."""
    start = time.perf_counter()
    tree = core.build_kdtree(tris, **options)
    built = time.perf_counter()
    image = core.render_preview(tree, camera, size, size, samples=samples, ao_distance=AO_DISTANCE)
    return built - start, time.perf_counter() - built, image, tree


def bench_scene(name, tris, camera, args, variants):
    eager_runs, lazy_runs = [], {label: [] for label in variants}
    jit = {}
    for run in range(args.runs + 1):  # run 0: JIT warm-up, not counted
        t0 = time.perf_counter()
        b, r, reference, eager = time_to_image(tris, camera, args.size, args.samples, {})
        if run == 0:
            jit["eager"] = time.perf_counter() - t0
        else:
            eager_runs.append((b, r, eager.stats()["top_ms"] / 1e3))
        for label, options in variants.items():
            t0 = time.perf_counter()
            b, r, image, tree = time_to_image(tris, camera, args.size, args.samples, options)
            if not np.array_equal(image, reference):
                raise AssertionError(f"{name} {label}: lazy image differs from the eager one")
            s = tree.stats()
            if run == 0:
                jit[label] = time.perf_counter() - t0
            else:
                lazy_runs[label].append((b, r, s["lazy_build_ms"] / 1e3, s["nodes"], s["subtrees_built"],
                                         s["subtrees_total"], s["lazy_rounds"], s["top_ms"] / 1e3))
        print(f"  {name} run {run}{' (JIT warm-up)' if run == 0 else ''} done", flush=True)
    return eager_runs, lazy_runs, jit, eager.node_count


def print_rows(name, n_tris, eager_runs, lazy_runs, jit, eager_nodes):
    eb, er, etop = np.median(np.array(eager_runs), axis=0)
    print(f"\n{name}: {n_tris:,} triangles; eager build {eb:.2f} s + render {er:.2f} s = {eb + er:.2f} s "
          f"({eager_nodes:,} nodes); first runs incl. JIT: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in jit.items()))
    print(f"{'variant':<26}{'build s':>9}{'render s':>10}{'(lazy bld)':>11}{'image s':>9}{'ratio':>7}"
          f"{'saved':>7}{'excl. top':>10}{'nodes built':>20}{'subtrees':>14}{'rounds':>8}")
    for label, runs in lazy_runs.items():
        a = np.array(runs)
        b, r, lb = np.median(a[:, 0]), np.median(a[:, 1]), np.median(a[:, 2])
        nodes, sb, st, rounds = (int(np.median(a[:, k])) for k in (3, 4, 5, 6))
        ratio = (b + r) / (eb + er)
        no_top = np.median(a[:, 0] + a[:, 1] - a[:, 7]) / np.median(np.array(eager_runs) @ [1, 1, -1])
        print(f"{label:<26}{b:>9.2f}{r:>10.2f}{lb:>11.2f}{b + r:>9.2f}{ratio:>7.2f}{1 - ratio:>7.0%}"
              f"{no_top:>10.2f}{f'{nodes:,} ({nodes / eager_nodes:.0%})':>20}{f'{sb}/{st}':>14}{rounds:>8}")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--samples", type=int, default=4)
    p.add_argument("--subtree-sizes", default="4096")
    p.add_argument("--scenes", default="wall,low-wall,suzanne")
    p.add_argument("--speculative", action="store_true", help="also time lazy_speculative=True")
    args = p.parse_args()
    variants = {}
    for k in (int(x) for x in args.subtree_sizes.split(",")):
        variants[f"lazy subtree_size={k}"] = {"lazy": True, "lazy_subtree_size": k}
        if args.speculative:
            variants[f"lazy {k} speculative"] = {"lazy": True, "lazy_subtree_size": k,
                                                 "lazy_speculative": True}
    print(f"bench_lazy: {args.size}x{args.size}, {args.samples} AO samples/pixel, ao_distance {AO_DISTANCE}, "
          f"medians of {args.runs} runs, {core.build_kdtree.__module__} threads: all")
    for name, tris, camera in scenes(args.scenes.split(",")):
        print_rows(name, len(tris), *bench_scene(name, tris, camera, args, variants))


if __name__ == "__main__":
    main()
