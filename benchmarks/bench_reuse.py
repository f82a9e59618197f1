"""Reuse across frames: per-frame time with reuse against --rebuild-all (target: at most 0.3x).

The animation (built with bpy, saved to benchmarks/out/reuse/reuse.blend): about 10% of the
triangles deform, the rest are static (four subdivided spheres and a ground plane) or move rigidly
(two subdivided Suzannes with keyed location and rotation). The deforming mesh (--deformer) is a
150 x 150 grid with an animated Wave modifier ("grid": a near-planar height field, the builder's
hard case at 7.7 references per triangle and 3-4x the build time per triangle of the other meshes)
or a sphere with the same modifier ("sphere"). Each mode renders the frames with `python -m kd_addon render` in a fresh process; the
per-frame `total_ms` (extract + build + trace) comes from report.json. Frame 1 (kernel load) and
frame 2 (where reuse learns which objects change and splits them from the static rest) are shown
but left out of the medians. Modes alternate, --runs times, for each resolution:samples pair of
--settings. With reuse, pixels whose rays cannot reach the moving or deforming objects keep last
frame's samples (core/render/pixel_reuse.py), so the trace shrinks too; the share of pixels kept is printed.
Also measured: the fingerprint (kd_addon.scene_records.geometry_fingerprint) that decides whether a mesh
changed.

    python benchmarks/bench_reuse.py [--frames 12] [--runs 2] [--settings 50:16,25:4] [--deformer grid]
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "benchmarks" / "out" / "reuse"


def build_scene(path: Path, deformer: str) -> dict:
    """Build and save the animation; returns triangle counts per kind."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=40)
    for k, (x, y) in enumerate(((-6, 6), (6, 6), (-6, -6), (6, -6))):
        bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=2.0, location=(x, y, 2.0))
        bpy.context.object.modifiers.new("Subsurf", "SUBSURF").levels = 1
        bpy.context.object.name = f"Static{k}"
    for k, x in enumerate((-3.0, 3.0)):
        bpy.ops.mesh.primitive_monkey_add(location=(x, 0.0, 1.5))
        mover = bpy.context.object
        mover.name = f"Mover{k}"
        mover.modifiers.new("Subsurf", "SUBSURF").levels = 3
        for frame, angle in ((1, 0.0), (48, 2 * math.pi)):
            mover.location.y = -4.0 + 8.0 * (frame - 1) / 47
            mover.rotation_euler.z = angle
            mover.keyframe_insert("location", frame=frame)
            mover.keyframe_insert("rotation_euler", frame=frame)
    if deformer == "grid":
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=150, y_subdivisions=150, size=10, location=(0, 0, 0.3))
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=150, ring_count=150, radius=1.5, location=(0, 0, 1.8))
    sheet = bpy.context.object
    sheet.name = "Wave"
    wave = sheet.modifiers.new("Wave", "WAVE")
    wave.height, wave.width, wave.speed = 0.4, 1.5, 0.15
    bpy.ops.object.camera_add(location=(0, -22, 14), rotation=(math.radians(58), 0, 0))
    scene.camera = bpy.context.object
    bpy.ops.object.light_add(type="SUN", rotation=(0.5, 0.3, 0))
    scene.render.resolution_x, scene.render.resolution_y = 960, 540
    scene.frame_start, scene.frame_end = 1, 48
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return triangle_counts(bpy.context.evaluated_depsgraph_get())


def triangle_counts(depsgraph) -> dict:
    from kd_addon.extract import extract_scene

    extracted = extract_scene(depsgraph)
    counts = {"static": 0, "rigid": 0, "deforming": 0}
    for inst in extracted.instances:
        kind = "deforming" if inst.name == "Wave" else "rigid" if inst.name.startswith("Mover") else "static"
        counts[kind] += extracted.geometries[inst.geometry_key].triangle_count
    return counts


def fingerprint_cost(repeats=7) -> tuple[float, int]:
    """Median ms to fingerprint every mesh of the open scene's frame, and the vertex count."""
    import bpy

    from kd_addon.extract import extract_scene
    from kd_addon.scene_records import geometry_fingerprint

    extracted = extract_scene(bpy.context.evaluated_depsgraph_get())
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        for geom in extracted.geometries.values():
            geometry_fingerprint(geom)
        times.append((time.perf_counter() - t) * 1e3)
    return float(np.median(times)), sum(len(g.vertices) for g in extracted.geometries.values())


def run_mode(blend: Path, frames: int, rebuild_all: bool, resolution: int, samples: int) -> list[dict]:
    out = OUT / ("rebuild_all" if rebuild_all else "reuse")
    cmd = [sys.executable, "-m", "kd_addon", "render", str(blend), "--frames", f"1-{frames}", "--out", str(out),
           "--resolution", str(resolution), "--samples", str(samples)]
    cmd += ["--rebuild-all"] if rebuild_all else []
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    return json.loads((out / "report.json").read_text())["frames"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--deformer", choices=("grid", "sphere"), default="grid")
    parser.add_argument("--settings", default="50:16,25:4",
                        help="comma list of resolution_percentage:samples (the scene is 960 x 540)")
    args = parser.parse_args(argv)
    blend = OUT / "reuse.blend"
    counts = build_scene(blend, args.deformer)
    total = sum(counts.values())
    print("triangles: " + ", ".join(f"{k} {v:,} ({v / total:.0%})" for k, v in counts.items()))
    fp_ms, n_verts = fingerprint_cost()
    print(f"fingerprint of every mesh: {fp_ms:.1f} ms per frame for {n_verts:,} vertices "
          f"({fp_ms / n_verts * 1e6:.1f} ms per million vertices)")
    for setting in args.settings.split(","):
        resolution, samples = (int(x) for x in setting.split(":"))
        print(f"\n{resolution}% resolution, {samples} samples:")
        compare(blend, args.frames, args.runs, resolution, samples)


def compare(blend, frames, runs, resolution, samples):
    rows = {False: [], True: []}
    for _ in range(runs):
        for mode in (False, True):
            rows[mode].append(run_mode(blend, frames, mode, resolution, samples))
    print(f"{'frame':>5} | {'reuse total ms':>14} {'build':>7} {'kept/built':>10} | {'rebuild-all ms':>14} {'build':>7}")
    med = lambda rs, key: float(np.median([r[key] for r in rs]))  # noqa: E731
    for f in range(frames):
        a = [r[f] for r in rows[False]]
        b = [r[f] for r in rows[True]]
        print(f"{a[0]['frame']:>5} | {med(a, 'total_ms'):>14.0f} {med(a, 'build_ms'):>7.0f} "
              f"{a[0]['objects_reused']:>4}/{a[0]['objects_rebuilt']:<5} | {med(b, 'total_ms'):>14.0f} "
              f"{med(b, 'build_ms'):>7.0f}")
    steady = lambda mode, key: float(np.median([r[key] for run in rows[mode] for r in run[2:]]))  # noqa: E731
    kept = [r["pixels_reused"] for run in rows[False] for r in run[2:]]
    rays = [r["rays"] / max(1, r["rays"] + r["rays_reused"]) for run in rows[False] for r in run[2:]]
    print(f"with reuse, frames 3-{frames}: median {np.median(kept):,.0f} pixels kept; rays traced "
          f"{np.median(rays):.0%} of a full frame's")
    for key in ("total_ms", "build_ms", "trace_ms", "extract_ms"):
        reuse, rebuild = steady(False, key), steady(True, key)
        print(f"median {key} over frames 3-{frames}: reuse {reuse:.0f} ms, rebuild-all {rebuild:.0f} ms, "
              f"ratio {reuse / rebuild:.2f}x" + ("  (target <= 0.3x)" if key == "total_ms" else ""))

if __name__ == "__main__":
    main()
