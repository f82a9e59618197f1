"""The top level over many instance boxes: build time, references per instance and trace time against
the top level's duplication budget (core/scene/two_level.py, build_top_level).

A scatter like the issue's: `count` instances of one 480-triangle noisy sphere on a square grid of
points 1 apart, random rotations and scales 0.2-0.45 (neighbouring boxes nearly touch), seen at an
angle from above; AO at 480x270, 4 samples. Every budget's image must equal the first's (the top
level changes which instances a ray visits, never what it hits). Budgets alternate within each run;
medians of --runs; the kernels are compiled by a warm-up build and render first (reported apart).

    python benchmarks/bench_top_level.py [--counts 100000,1000000] [--budgets 3,16,2] [--runs 3]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
import core  # noqa: E402
import results  # noqa: E402
from bench_two_level import sphere  # noqa: E402
from core.scene import two_level  # noqa: E402


def scatter(count: int, rng):
    side = int(np.ceil(np.sqrt(count)))
    xy = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:count] - (side - 1) / 2
    angles = rng.uniform(-np.pi, np.pi, (count, 3))
    scale = rng.uniform(0.2, 0.45, count)
    cx, cy, cz = np.cos(angles).T
    sx, sy, sz = np.sin(angles).T
    rot = np.empty((count, 3, 3))
    rot[:, 0] = np.stack([cy * cz, sx * sy * cz - cx * sz, cx * sy * cz + sx * sz], -1)
    rot[:, 1] = np.stack([cy * sz, sx * sy * sz + cx * cz, cx * sy * sz - sx * cz], -1)
    rot[:, 2] = np.stack([-sy, sx * cy, cx * cy], -1)
    mats = np.tile(np.eye(4), (count, 1, 1))
    mats[:, :3, :3] = rot * scale[:, None, None]
    mats[:, :2, 3], mats[:, 2, 3] = xy, 0.5
    return mats, side


def camera(side):
    eye = np.array([0.0, -side * 0.55, side * 0.45])
    angle = np.radians(55)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = (1, 0, 0), (0, np.cos(angle), np.sin(angle)), (0, -np.sin(angle), np.cos(angle))
    m[:3, 3] = eye
    return core.Camera(m, 0.7)


def build_two_level_with_budget(tree, mats, budget):
    """The top level built with `budget` in place of two_level.TOP_LEVEL_DUPLICATION."""
    kept = two_level.TOP_LEVEL_DUPLICATION
    two_level.TOP_LEVEL_DUPLICATION = budget
    try:
        return two_level.build_two_level([tree], np.zeros(len(mats), np.int64), mats)
    finally:
        two_level.TOP_LEVEL_DUPLICATION = kept


def one(tree, mats, budget, cam):
    t0 = time.perf_counter()
    scene = build_two_level_with_budget(tree, mats, budget)
    t1 = time.perf_counter()
    image = core.render_preview(scene, cam, 480, 270, samples=4, ao_distance=1.0)
    t2 = time.perf_counter()
    stats = scene.stats()
    return (t1 - t0) * 1e3, (t2 - t1) * 1e3, stats["top_references"] / len(mats), stats["top_nodes"], image


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", default="100000,1000000")
    ap.add_argument("--budgets", default="3,16,2")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    vertices, triangles = sphere(16, 16, rng, noise=0.2)
    tree = core.build_kdtree(vertices[triangles].astype(np.float32))
    budgets = [float(b) for b in args.budgets.split(",")]
    t = time.perf_counter()
    mats, side = scatter(1000, rng)
    one(tree, mats, budgets[0], camera(side))
    jit = time.perf_counter() - t
    figures = {}
    print(f"{'instances':>10} {'budget':>7} {'top build ms':>13} {'refs/inst':>10} {'top nodes':>10} {'trace ms':>9}")
    for count in map(int, args.counts.split(",")):
        mats, side = scatter(count, rng)
        cam = camera(side)
        runs = {b: [] for b in budgets}
        first_image = None
        for _ in range(args.runs):
            for budget in budgets:
                build, trace, refs, nodes, image = one(tree, mats, budget, cam)
                if first_image is None:
                    first_image = image
                assert np.array_equal(image, first_image), f"budget {budget} changed the image"
                runs[budget].append((build, trace, refs, nodes))
        for budget, done in runs.items():
            build, trace = np.median([d[0] for d in done]), np.median([d[1] for d in done])
            refs, nodes = done[0][2], done[0][3]
            print(f"{count:>10,} {budget:>7g} {build:>13.0f} {refs:>10.2f} {nodes:>10,} {trace:>9.0f}")
            figures[f"{count}_budget_{budget:g}"] = {
                "top_build": results.figure([d[0] / 1e3 for d in done]), "trace": results.figure([d[1] / 1e3 for d in done]),
                "references_per_instance": refs, "top_nodes": nodes}
    results.write("bench_top_level", figures, jit, quick=args.runs < 3)


if __name__ == "__main__":
    main()
