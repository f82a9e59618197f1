"""Extraction cost of many instances of one mesh (geometry-nodes instancing, bpy module).

Usage: python benchmarks/bench_instances.py [--counts 1000,10000,100000] [--runs 3]

Each instance is a 2-triangle quad placed by Instance on Points on a line of points, so the cost is all
per instance: extract_scene walks depsgraph.object_instances in Python (one entry per instance) and
world_triangles() transforms and gathers the instances of each mesh with numpy. Medians of --runs.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import bpy  # noqa: E402

from kd_addon.extract import extract_scene  # noqa: E402
from tests import bpy_scenes  # noqa: E402


def tiles_scene(count):
    """`count` quads (0.5 x 0.5) on a line of points 1 apart, from one geometry-nodes modifier."""
    bpy_scenes.reset()
    host = bpy_scenes.add_mesh("Host", [], [])
    host.modifiers.new("Tiles", "NODES").node_group = bpy_scenes.tile_line_group(count)
    return bpy.context.evaluated_depsgraph_get()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", default="1000,10000,100000")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    print(f"{'instances':>10} {'triangles':>10} {'extract ms':>11} {'us/instance':>12} {'world_triangles ms':>19}")
    for count in map(int, args.counts.split(",")):
        depsgraph = tiles_scene(count)
        extract, world = [], []
        for _ in range(args.runs):
            t = time.perf_counter()
            result = extract_scene(depsgraph)
            extract.append(time.perf_counter() - t)
            t = time.perf_counter()
            result.world_triangles()
            world.append(time.perf_counter() - t)
        assert result.object_count == count, (result.object_count, count)
        e, w = np.median(extract) * 1e3, np.median(world) * 1e3
        print(f"{count:>10,} {result.triangle_count:>10,} {e:>11.1f} {e * 1e3 / count:>12.1f} {w:>19.1f}")


if __name__ == "__main__":
    main()
