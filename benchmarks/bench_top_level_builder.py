"""The top level's box builder (core/build/box_tree.py) against the general kd builder run over the same
instance boxes (the top level before it: builder._build_arrays with clipping off), paired in one process.

bench_top_level.py's scatter (`count` noisy spheres on a grid 1 apart, random rotations, scales 0.2-0.45,
seen at an angle from above). Per run, in alternating order, each builder builds the top level over the
same boxes (build ms, references an instance, nodes), and both scenes, differing only in their top level,
render the same AO image (480x270, 4 spp; trace ms) and answer the same random rays through the scatter
(core.intersect_scene; hits must agree). Printed: medians and the medians of the per-run ratios
(box builder / general). Kernels are compiled (or loaded) by a warm-up first, reported apart.

    python benchmarks/bench_top_level_builder.py [--counts 100000,1000000] [--runs 3] [--threads N]
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
from bench_top_level import camera, scatter  # noqa: E402
from bench_two_level import sphere  # noqa: E402
from core.build.builder import _build_arrays  # noqa: E402
from core.build.options import make_options  # noqa: E402
from core.jit.threads import thread_count  # noqa: E402
from core.scene import two_level  # noqa: E402


def general_top_level(boxes, opts):
    """The top level as the general kd builder made it (two_level.build_top_level before the box builder):
    the triangle builder with clipping off over the boxes, same costs and budget."""
    keep = np.flatnonzero(boxes[:, 0] <= boxes[:, 3]).astype(np.int32)
    sub = np.ascontiguousarray(boxes[keep])
    bounds = np.concatenate([sub[:, :3].min(axis=0), sub[:, 3:].max(axis=0)]).astype(np.float32)
    placeholder = np.zeros((len(keep), 3, 3), np.float32)
    budget = min(opts.duplication_budget or np.inf, two_level.TOP_LEVEL_DUPLICATION)
    box_opts = make_options({**opts.as_dict(), "clip": False, "lazy": False, "duplication_budget": budget,
                             "intersection_cost": opts.intersection_cost * two_level.INSTANCE_TEST_COST})
    with thread_count(opts.threads) as threads:
        (axis, split, child, count, leaf), _ = _build_arrays(placeholder, np.arange(len(keep), dtype=np.int32),
                                                             sub, bounds, box_opts, threads, {})
    return axis, split, child, count, keep[leaf].astype(np.int32), bounds


BUILDERS = {"general": general_top_level, "boxes": two_level.build_top_level}


def random_rays(side, count, rng):
    """Rays from 3 above the scatter slanting down to the ground up to 5 away: each passes many boxes."""
    half = side / 2
    origins = np.column_stack([rng.uniform(-half, half, (count, 2)), np.full(count, 3.0)])
    directions = np.column_stack([rng.uniform(-5.0, 5.0, (count, 2)), np.full(count, -3.0)])
    return origins, directions


def one(name, scene, boxes, opts, cam, rays):
    """(build ms, trace ms, rays ms, references an instance, nodes, image, hits) with builder `name`."""
    t0 = time.perf_counter()
    scene.top = BUILDERS[name](boxes, opts)
    t1 = time.perf_counter()
    image = core.render_preview(scene, cam, 480, 270, samples=4, ao_distance=1.0)
    t2 = time.perf_counter()
    hits = core.intersect_scene(scene, *rays)
    t3 = time.perf_counter()
    axis, count = scene.top[0], scene.top[3]
    refs = int(count[axis == two_level.LEAF].sum()) / len(boxes)
    return (t1 - t0) * 1e3, (t2 - t1) * 1e3, (t3 - t2) * 1e3, refs, len(axis), image, hits


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", default="100000,1000000")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--rays", type=int, default=200000)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    vertices, triangles = sphere(16, 16, rng, noise=0.2)
    tree = core.build_kdtree(vertices[triangles].astype(np.float32))
    opts = make_options({"threads": args.threads})
    t = time.perf_counter()
    for warm in (1000, 20000):
        mats, side = scatter(warm, rng)
        scene = two_level.build_two_level([tree], np.zeros(len(mats), np.int64), mats)
        for name in BUILDERS:
            one(name, scene, scene.world_boxes, opts, camera(side), random_rays(side, 1000, rng))
    print(f"JIT compile / cache load: {time.perf_counter() - t:.1f} s")
    figures = {}
    header = f"{'instances':>10} {'builder':>8} {'build ms':>9} {'refs/inst':>9} {'nodes':>10} {'trace ms':>9} {'rays ms':>8}"
    for count in map(int, args.counts.split(",")):
        mats, side = scatter(count, rng)
        scene = two_level.build_two_level([tree], np.zeros(len(mats), np.int64), mats)
        cam, rays = camera(side), random_rays(side, args.rays, rng)
        done = {name: [] for name in BUILDERS}
        for run in range(args.runs):
            order = list(BUILDERS) if run % 2 == 0 else list(BUILDERS)[::-1]
            outs = {name: one(name, scene, scene.world_boxes, opts, cam, rays) for name in order}
            g, b = outs["general"], outs["boxes"]
            assert np.array_equal(g[5], b[5]), "the two top levels rendered different images"
            same = np.array_equal(g[6].instance, b[6].instance) and np.array_equal(g[6].t, b[6].t)
            assert same, "the two top levels gave different hits"
            for name, out in outs.items():
                done[name].append(out[:5])
        print(header)
        for name, runs in done.items():
            med = np.median(np.array(runs), axis=0)
            print(f"{count:>10,} {name:>8} {med[0]:>9.0f} {med[3]:>9.2f} {int(med[4]):>10,} {med[1]:>9.0f} {med[2]:>8.0f}")
        ratio = np.median(np.array(done["boxes"]) / np.array(done["general"]), axis=0)
        print(f"{count:>10,} {'ratio':>8} {ratio[0]:>9.3f} {ratio[3]:>9.3f} {ratio[4]:>10.3f} {ratio[1]:>9.3f} {ratio[2]:>8.3f}")
        for i, key in ((0, "top_build"), (1, "trace"), (2, "rays")):
            figures[f"{count}_{key}"] = results.figure([r[i] / 1e3 for r in done["boxes"]],
                                                       [r[i] / 1e3 for r in done["general"]])
        figures[f"{count}_references_per_instance"] = {"boxes": done["boxes"][0][3], "general": done["general"][0][3]}
    results.write("bench_top_level_builder", figures, time.perf_counter() - t, quick=args.runs < 3)


if __name__ == "__main__":
    main()
