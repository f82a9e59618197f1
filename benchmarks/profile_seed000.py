"""Where seed 000's time to image goes: the build and each compiled pass of the render, per tree.

Usage: python benchmarks/profile_seed000.py [--runs 9] [--out DIR]

Seed 000's setting (suzanne-251k, 640 x 480, one camera ray and one shadow ray to a point light a pixel,
the tree rebuilt) for the default build and a build told the frame's rays, alternating run by run. Each
of the render's compiled passes is timed by a wrapper around the name preview_render and scene_packets
call it by (wall time; the passes run one after another), so the rows add up to the render but for the
Python between them ("rest"). Prints medians in ms and writes DIR/profile_seed000.json (default
benchmarks/out/, which report.py turns into docs/benchmarks.md's table).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core  # noqa: E402
import core.render.preview_render as preview_render  # noqa: E402
import core.scene.scene_packets as scene_packets  # noqa: E402
import results  # noqa: E402
from scenes import load_scene  # noqa: E402

SIZE, LIGHT = (640, 480), (2.0, -3.0, 4.0)
PASSES = ((preview_render, ("surface_frames", "add_samples", "hard_shadow_rays", "assemble_image")),
          (scene_packets, ("trace_packets",)))


def timed_passes(spent):
    """Wrap each pass so its wall time adds to spent[name]; trace_packets' first call in a frame is the
    camera pass, its second the shadow pass."""
    for module, names in PASSES:
        for name in names:
            setattr(module, name, _timer(getattr(module, name), name, spent))


def _timer(fn, name, spent):
    def run(*args, **kwargs):
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            key = name
            if name == "trace_packets":
                key = "shadow packets" if "camera packets" in spent else "camera packets"
            spent[key] = spent.get(key, 0.0) + time.perf_counter() - start
    return run


def one_frame(scene, camera, light, options, spent):
    """Rebuild and render one frame: {"build": s, "render": s, each pass: s, "rest": s}."""
    spent.clear()
    start = time.perf_counter()
    tree = core.build_kdtree(scene.triangles, **options)
    built = time.perf_counter()
    core.render_preview(tree, camera, *SIZE, samples=1, mode="shadow", lights=[light])
    render = time.perf_counter() - built
    return {"build": built - start, "render": render, **spent, "rest": render - sum(spent.values())}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=9)
    ap.add_argument("--out", default=str(results.OUT_DIR))
    args = ap.parse_args()
    scene = load_scene("suzanne-251k")
    camera, light = core.Camera(scene.camera_matrix, scene.camera_fov), core.Light.point(LIGHT)
    configs = {"default build": {}, "told the rays": {"rays": core.frame_ray_count(*SIZE, "shadow", 1, [light])}}
    spent = {}
    timed_passes(spent)
    start = time.perf_counter()
    for options in configs.values():  # loads (or compiles) the kernels: not counted
        one_frame(scene, camera, light, options, spent)
    jit_seconds = time.perf_counter() - start
    rows = {name: [] for name in configs}
    for run in range(args.runs):
        for name in (list(configs) if run % 2 == 0 else list(configs)[::-1]):
            rows[name].append(one_frame(scene, camera, light, configs[name], spent))
    report = {}
    for name, runs in rows.items():
        report[name] = {key: float(np.median([r[key] for r in runs])) * 1e3 for key in runs[0]}
        report[name]["time to image"] = float(np.median([r["build"] + r["render"] for r in runs])) * 1e3
        print(f"{name}: " + ", ".join(f"{k} {v:.1f}" for k, v in report[name].items()) + " (ms, medians)")
    results.write("profile_seed000", {"runs": args.runs, "size": list(SIZE), "light": list(LIGHT),
                                      "ms_medians": report}, jit_seconds, out_dir=args.out)


if __name__ == "__main__":
    main()
