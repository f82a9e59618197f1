"""Extraction cost of many instances of one mesh (geometry-nodes instancing, bpy module), and the
end-to-end frame time of scattered instances.

Usage: python benchmarks/bench_instances.py [--counts 1000,10000,100000] [--runs 3]
       python benchmarks/bench_instances.py --end-to-end [--counts 10000,100000,1000000] [--runs 3]
       python benchmarks/bench_instances.py --big-mesh [--runs 3]

Default mode: each instance is a 2-triangle quad placed by Instance on Points on a line of points, so
the cost is all per instance: extract_scene reads the instances (the bulk path, kd_addon/bulk_instances.py,
and the per-entry walk over depsgraph.object_instances, alternating) and world_triangles() transforms
and gathers the instances of each mesh with numpy. Medians of --runs: the bulk path's later readings of
the unchanged depsgraph keep the first one's rows (a static frame's extraction).

--end-to-end: icospheres (320 triangles) scattered by Instance on Points over a square grid of points
with random rotations and scales, on a ground plane, rendered through kd_addon.pipeline.render_frame at
480x270, 4 samples, ao+shadow: a first frame (kernels already loaded by a small warm-up frame) and a
static frame (nothing changed), each split into extract / build / trace, with the top level's build
time and references per instance, and the process's peak memory. Each (count, path) runs in a fresh
process, paths alternating, --runs times; medians. Writes benchmarks/out/bench_instances.json.

--big-mesh: one 10-million-triangle mesh, a random soup and a displaced grid (bench_memory.py's scenes,
written once under benchmarks/data/), built with the default binned builder in a fresh process a run
(kernels warmed on a slice first): build time, references and peak bytes a triangle (growth of the
resident-set high-water mark over the loaded triangles). Writes benchmarks/out/bench_big_mesh.json.
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import bpy  # noqa: E402

import instances_end_to_end as end_to_end  # noqa: E402
from kd_addon import bulk_instances  # noqa: E402
from kd_addon.extract import extract_scene  # noqa: E402
from tests import bpy_scenes  # noqa: E402


def tiles_scene(count):
    """`count` quads (0.5 x 0.5) on a line of points 1 apart, from one geometry-nodes modifier."""
    bpy_scenes.reset()
    host = bpy_scenes.add_mesh("Host", [], [])
    host.modifiers.new("Tiles", "NODES").node_group = bpy_scenes.tile_line_group(count)
    return bpy.context.evaluated_depsgraph_get()


def extraction(counts, runs):
    """The default mode: extraction alone, bulk against walk on the same depsgraph, alternating."""
    print(f"{'instances':>10} {'path':>5} {'triangles':>10} {'extract ms':>11} {'us/instance':>12} "
          f"{'world_triangles ms':>19}")
    for count in counts:
        depsgraph = tiles_scene(count)
        times = {"bulk": ([], []), "walk": ([], [])}
        for _ in range(runs):
            for path in times:
                bulk_instances.ENABLED = path == "bulk"
                t = time.perf_counter()
                result = extract_scene(depsgraph)
                times[path][0].append(time.perf_counter() - t)
                t = time.perf_counter()
                result.world_triangles()
                times[path][1].append(time.perf_counter() - t)
                assert result.object_count == count, (result.object_count, count)
                assert result.path == path or not bulk_instances.AVAILABLE, (result.path, path)
        for path, (extract, world) in times.items():
            e, w = np.median(extract) * 1e3, np.median(world) * 1e3
            print(f"{count:>10,} {path:>5} {result.triangle_count:>10,} {e:>11.1f} {e * 1e3 / count:>12.1f} "
                  f"{w:>19.1f}")


def big_mesh(runs):
    """Build time and peak bytes a triangle of 10M-triangle meshes, each run in a fresh process."""
    import bench_memory
    import results

    figures = {}
    for name in ("soup-10m", "grid-10m"):
        rows = [bench_memory.child("build", bench_memory.scene_file(name), "binned") for _ in range(runs)]
        figures[name] = {key: float(np.median([r[key] for r in rows])) for key in rows[0]}
        figures[name]["build_ms_runs"] = [r["build_ms"] for r in rows]
        f = figures[name]
        print(f"{name}: {f['triangles']:,.0f} triangles, build {f['build_ms']:.0f} ms (median of {runs}), "
              f"{f['refs_per_triangle']:.2f} references and {f['bytes_per_triangle']:.0f} peak bytes a triangle")
    results.write("bench_big_mesh", figures, jit_seconds=0.0, quick=runs < 3)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", default=None)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--end-to-end", action="store_true", help="frames through the pipeline (module docstring)")
    ap.add_argument("--paths", default="bulk,walk", help="instance reading paths to compare (end-to-end)")
    ap.add_argument("--big-mesh", action="store_true", help="10M-triangle meshes: build time, bytes a triangle")
    ap.add_argument("--child", nargs=2, metavar=("COUNT", "PATH"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(end_to_end.child(int(args.child[0]), args.child[1])))
    elif args.big_mesh:
        big_mesh(args.runs)
    elif args.end_to_end:
        end_to_end.main([int(c) for c in (args.counts or "10000,100000,1000000").split(",")], args.runs,
                        args.paths.split(","))
    else:
        extraction([int(c) for c in (args.counts or "1000,10000,100000").split(",")], args.runs)


if __name__ == "__main__":
    main()
