"""Seed 000's frame loop against a git revision's core, each version in processes of its own.

Usage: python benchmarks/bench_frames_by_process.py [--base HEAD] [--rounds 6] [--frames 30]
                                                    [--scene suzanne-251k]

bench_against_revision.py runs both versions in one process, so whatever is process-wide is shared
between them: the C library's heap, the memory it hands back to the OS and faults in again, the
threads' arenas. Here each round starts one child process per version (in alternating order); a child
renders `--frames` frames of seed 000's setting one after another, as an animation does (640 x 480,
the tree rebuilt, camera rays and one shadow ray a hit to a point light), with the default build and
told the frame's rays by turns. Printed: per version the medians over rounds of each round's median
build, render and time to image, the median of the per-round ratios (this tree / base), and each
child's system CPU time and minor page faults a frame. The base's core is exported once into a folder
under the system temp folder, named by its commit, where its Numba cache stays between runs.
"""
import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SIZE, LIGHT = (640, 480), (2.0, -3.0, 4.0)
CONFIGS = ("default build", "told the rays")
ROWS = ("build", "render", "time to image")


def export_base(revision):
    """The revision's core/ in a kept folder named by its commit; the folder's path."""
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", revision], check=True, capture_output=True,
                            text=True).stdout.strip()
    folder = Path(tempfile.gettempdir()) / f"kd_preview_core_{commit[:12]}"
    if not (folder / "core").is_dir():
        folder.mkdir(exist_ok=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit, "core"], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def child(root, frames, scene_name):
    """In a child process: frames of both configurations with `root`'s core; prints one JSON line."""
    sys.path[:0] = [str(root), str(HERE)]
    import core  # noqa: PLC0415
    from scenes import load_scene  # noqa: PLC0415
    scene = load_scene(scene_name)
    camera, light = core.Camera(scene.camera_matrix, scene.camera_fov), core.Light.point(LIGHT)
    options = {"default build": {}, "told the rays": {"rays": core.frame_ray_count(*SIZE, "shadow", 1, [light])}}

    def frame(config):
        start = time.perf_counter()
        tree = core.build_kdtree(scene.triangles, **options[config])
        built = time.perf_counter()
        core.render_preview(tree, camera, *SIZE, samples=1, mode="shadow", lights=[light])
        end = time.perf_counter()
        return built - start, end - built, end - start

    for config in CONFIGS * 2:  # compiles or loads the kernels, and settles the heap: not counted
        frame(config)
    before = resource.getrusage(resource.RUSAGE_SELF)
    times = {config: [] for config in CONFIGS}
    for k in range(frames):
        for config in (CONFIGS if k % 2 == 0 else CONFIGS[::-1]):
            times[config].append(frame(config))
    after = resource.getrusage(resource.RUSAGE_SELF)
    n = 2 * frames
    print(json.dumps({"ms": {c: (np.median(np.array(t), axis=0) * 1e3).tolist() for c, t in times.items()},
                      "sys_ms_per_frame": (after.ru_stime - before.ru_stime) * 1e3 / n,
                      "faults_per_frame": (after.ru_minflt - before.ru_minflt) / n}))


def run_child(root, args):
    out = subprocess.run([sys.executable, __file__, "--child", str(root), "--frames", str(args.frames),
                          "--scene", args.scene], check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--base", default="HEAD", help="git revision to compare against (default HEAD)")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--frames", type=int, default=30, help="frames of each configuration a child renders")
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args.child, args.frames, args.scene)
    versions = {"this tree": ROOT, f"base {args.base}": export_base(args.base)}
    print("compiling or loading both versions' kernels ...", flush=True)
    for root in versions.values():
        run_child(root, argparse.Namespace(frames=1, scene=args.scene))
    runs = {name: [] for name in versions}
    for k in range(args.rounds):
        for name in (list(versions) if k % 2 == 0 else list(versions)[::-1]):
            runs[name].append(run_child(versions[name], args))
    print(f"{args.scene}, {SIZE[0]}x{SIZE[1]}, {args.rounds} rounds of {args.frames} frames a configuration")
    mine, theirs = runs.values()
    for config in CONFIGS:
        for name, version_runs in runs.items():
            medians = np.median([r["ms"][config] for r in version_runs], axis=0)
            print(f"  {config:>14}, {name:>16}: " + "  ".join(f"{row} {m:6.1f} ms" for row, m in zip(ROWS, medians)))
        ratios = np.median([np.array(a["ms"][config]) / np.array(b["ms"][config]) for a, b in zip(mine, theirs)],
                           axis=0)
        print(f"  {config:>14}, {'ratio (paired)':>16}: " + "  ".join(f"{row} {r:6.3f}" for row, r in zip(ROWS, ratios)))
    for name, version_runs in runs.items():
        print(f"  {name}: system CPU {np.median([r['sys_ms_per_frame'] for r in version_runs]):.1f} ms and "
              f"{np.median([r['faults_per_frame'] for r in version_runs]):,.0f} minor page faults a frame")


if __name__ == "__main__":
    main()
