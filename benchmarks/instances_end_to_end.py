"""bench_instances.py --end-to-end: scattered icospheres rendered through the pipeline, per process.

`main` starts one process per (count, path) and run, paths alternating, and collects what `child`
prints: the first and the static frame's extract / build / trace, the top level's build time and
references per instance, and the peak memory (ru_maxrss) of the process.
"""
from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

HERE = Path(__file__).resolve().parent
SETTINGS = dict(mode="ao+shadow", samples=4, resolution_percentage=100)
WIDTH, HEIGHT = 480, 270
# The warm-up frame's instances: enough references for the parallel top of the builder (top_levels.py,
# PARALLEL_MIN_REFS), whose kernels a smaller frame never loads: the measured frame would pay for them.
WARM_UP = 20000


def scatter_scene(count: int, subdivisions: int = 3):
    """`count` icospheres on a square grid of points 1 apart (random rotation, scale 0.2-0.45) over a
    ground plane, a camera looking down at them at an angle and a sun: the issue's scatter scene."""
    import bpy
    from tests import bpy_scenes

    bpy_scenes.reset()
    side = int(math.ceil(math.sqrt(count)))
    group = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    grid = nodes.new("GeometryNodeMeshGrid")
    grid.inputs["Vertices X"].default_value, grid.inputs["Vertices Y"].default_value = side, side
    grid.inputs["Size X"].default_value = grid.inputs["Size Y"].default_value = side - 1
    points = nodes.new("GeometryNodeMeshToPoints")
    links.new(grid.outputs["Mesh"], points.inputs["Mesh"])
    keep = nodes.new("GeometryNodeDeleteGeometry")  # exactly `count` points: drop indices >= count
    keep.domain = "POINT"
    index, compare = nodes.new("GeometryNodeInputIndex"), nodes.new("FunctionNodeCompare")
    compare.data_type, compare.operation = "INT", "GREATER_EQUAL"
    compare.inputs[3].default_value = count
    links.new(index.outputs[0], compare.inputs[2])
    links.new(points.outputs[0], keep.inputs["Geometry"])
    links.new(compare.outputs[0], keep.inputs["Selection"])
    ico = nodes.new("GeometryNodeMeshIcoSphere")
    ico.inputs["Subdivisions"].default_value = subdivisions
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(keep.outputs[0], on_points.inputs["Points"])
    links.new(ico.outputs["Mesh"], on_points.inputs["Instance"])
    for socket, low, high in (("Rotation", -3.2, 3.2), ("Scale", 0.2, 0.45)):
        value = nodes.new("FunctionNodeRandomValue")
        value.data_type = "FLOAT_VECTOR" if socket == "Rotation" else "FLOAT"
        value.inputs["Min" if socket == "Rotation" else 2].default_value = (low,) * 3 if socket == "Rotation" else low
        value.inputs["Max" if socket == "Rotation" else 3].default_value = (high,) * 3 if socket == "Rotation" else high
        links.new(value.outputs["Value" if socket == "Rotation" else 1], on_points.inputs[socket])
    links.new(on_points.outputs["Instances"], nodes.new("NodeGroupOutput").inputs[0])
    host = bpy_scenes.add_mesh("Scatter", [], [], location=(-(side - 1) / 2, -(side - 1) / 2, 0.5))
    host.modifiers.new("Scatter", "NODES").node_group = group
    half = side / 2 + 1
    bpy_scenes.add_mesh("Ground", [(-half, -half, 0), (half, -half, 0), (half, half, 0), (-half, half, 0)],
                        [(0, 1, 2, 3)])
    camera = bpy_scenes.add_camera("Cam")
    camera.location = (0, -side * 0.55, side * 0.45)
    camera.rotation_euler = (math.radians(55), 0, 0)
    scene = bpy.context.scene
    scene.camera = camera
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.rotation_euler = (0.6, 0.2, 0.3)
    scene.collection.objects.link(sun)
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    return scene


def _frame_figures(result) -> dict:
    stats = result.tree_stats
    instances = max(stats.get("instances", 0), 1)
    return {"extract_ms": result.extract_ms, "build_ms": result.build_ms, "trace_ms": result.trace_ms,
            "total_ms": result.total_ms, "image_reused": result.image_reused,
            "top_build_ms": stats.get("top_build_ms"), "top_references_per_instance": stats.get("top_references", 0)
            / instances, "instances": stats.get("instances"), "triangles": result.triangles}


def child(count: int, path: str) -> dict:
    """One process: a warm-up frame (kernels, WARM_UP), then the scatter scene's first and static frames."""
    import bpy
    from kd_addon import bulk_instances, tree_cache
    from kd_addon.config import make_config
    from kd_addon.pipeline import render_frame

    bulk_instances.ENABLED = path == "bulk"
    config = make_config(SimpleNamespace(**SETTINGS))
    scene = scatter_scene(WARM_UP)
    render_frame(scene, bpy.context.evaluated_depsgraph_get(), config)  # kernels loaded or compiled here
    tree_cache.clear()
    scene = scatter_scene(count)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    first = render_frame(scene, depsgraph, config)
    static = render_frame(scene, depsgraph, config)
    assert static.image_reused, "the static frame rendered anew"
    return {"count": count, "path": path, "first": _frame_figures(first), "static": _frame_figures(static),
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "peak_before_scene_mb": before / 1024,
            "load": os.getloadavg()[0]}


def _run_child(count: int, path: str) -> dict:
    out = subprocess.run([sys.executable, str(HERE / "bench_instances.py"), "--child", str(count), path],
                         capture_output=True, text=True, check=False, env={**os.environ, "PYTHONPATH": str(HERE.parent)})
    if out.returncode != 0:
        raise RuntimeError(f"count {count}, path {path}: {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(counts, runs, paths) -> None:
    import results

    figures = {}
    start = time.perf_counter()
    for count in counts:
        runs_of = {p: [] for p in paths}
        for _ in range(runs if count < 1_000_000 else max(1, runs // 2)):
            for path in paths:
                runs_of[path].append(_run_child(count, path))
        for path, done in runs_of.items():
            figures[f"{count}_{path}"] = _summary(done)
            _print(count, path, figures[f"{count}_{path}"])
    results.write("bench_instances", figures, jit_seconds=0.0, quick=runs < 3)
    print(f"({time.perf_counter() - start:.0f} s)")


def _summary(done: list) -> dict:
    out = {"runs": len(done), "load": [d["load"] for d in done], "peak_mb": _median(d["peak_mb"] for d in done)}
    for frame in ("first", "static"):
        for key in ("extract_ms", "build_ms", "trace_ms", "total_ms", "top_build_ms", "top_references_per_instance"):
            values = [d[frame][key] for d in done if d[frame][key] is not None]
            out[f"{frame}_{key}"] = _median(values) if values else None
    out["triangles"] = done[0]["first"]["triangles"]
    return out


def _median(values) -> float:
    return float(np.median(list(values)))


def _print(count, path, f) -> None:
    print(f"{count:>9,} {path:>5}  first {f['first_total_ms']:8.0f} ms (extract {f['first_extract_ms']:7.0f}, build "
          f"{f['first_build_ms']:7.0f} [top {f['first_top_build_ms'] or 0:6.0f}, {f['first_top_references_per_instance']:.2f}"
          f" refs/inst], trace {f['first_trace_ms']:6.0f})  static {f['static_total_ms']:7.0f} ms (extract "
          f"{f['static_extract_ms']:6.0f})  peak {f['peak_mb']:6.0f} MB  load {f['load']}")
