"""Instances reached through a render-hidden instancer, against Cycles' hit masks.

Usage: .venv/bin/python benchmarks/cycles_dupli_paths.py [--size 144 108] [--out DIR]

Blender makes no instances from a render-hidden object, at any depth of nesting, and none from a
render-hidden child collection's members; the viewport's depsgraph, which the preview reads, makes
them (kd_addon/dupli_paths.py). Each case builds a scene with the test suite's builders
(tests/bpy_scenes.py: add_two_path_scene, add_object_info_of_instancer,
add_hidden_source_beside_nested_instances, add_hidden_member_named_and_nested; tests/test_extract_visibility.py
asserts the extraction of the same scenes), adds a camera looking down at them, saves it, renders it with the
preview's command line and with Cycles (transparent film, the narrowest pixel filter) and prints the
hit pixels of both and how many differ. Exit 1 when a case differs in more pixels than its
silhouettes could explain (MAX_EDGE_PIXELS).
"""
import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import bpy  # noqa: E402

from cycles_ao import read_exr, render_cycles  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402

MAX_EDGE_PIXELS = 4  # pixels a silhouette may differ by (Cycles' filter against the preview's pixel centres)


def cases():
    for top in scenes.TWO_PATH_TOPS:
        for hiding in scenes.TWO_PATH_HIDINGS:
            yield f"two paths: {hiding}, through a {top}", lambda t=top, h=hiding: scenes.add_two_path_scene(t, h)
    for source in scenes.OBJECT_INFO_SOURCES:
        for hidden in (False, True):
            label = f"object info of a {'render-hidden ' if hidden else ''}{source}"
            yield label, lambda s=source, h=hidden: scenes.add_object_info_of_instancer(s, h)
    for first in (True, False):
        yield (f"hidden source {'before' if first else 'after'} nested instances",
               lambda f=first: scenes.add_hidden_source_beside_nested_instances(f))
    yield "hidden member named directly and nested", scenes.add_hidden_member_named_and_nested


def save_case(build, path, size):
    scene = scenes.reset()
    build()
    camera = scenes.add_camera("Cam")  # straight down at the builders' scenes (x -3.3..3.3, y -0.3..2.3)
    camera.data.type, camera.data.ortho_scale, camera.location = "ORTHO", 9.0, (0.0, 1.0, 10.0)
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = *size, 100
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def preview_alpha(blend, out):
    subprocess.run([sys.executable, "-m", "kd_addon", "render", str(blend), "--frames", "1", "--out", str(out),
                    "--mode", "ao", "--samples", "1", "--resolution", "100", "--format", "EXR"],
                   check=True, capture_output=True, cwd=HERE.parent)
    return read_exr(str(out / "frame_0001.exr"))[0]["A"]


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--size", type=int, nargs=2, default=(144, 108))
    ap.add_argument("--out", default=None, help="folder for the .blend files and frames (default: a temporary one)")
    args = ap.parse_args()
    failures = 0
    with tempfile.TemporaryDirectory(prefix="kd_dupli_paths_") as tmp:
        out = Path(args.out or tmp)
        out.mkdir(parents=True, exist_ok=True)
        for i, (label, build) in enumerate(cases()):
            blend = out / f"case_{i:02d}.blend"
            save_case(build, blend, args.size)
            preview = preview_alpha(blend, out / f"case_{i:02d}") > 0.5
            cycles = render_cycles(blend, *args.size, 1).alpha > 0.5
            differ = int((preview ^ cycles).sum())
            failures += differ > MAX_EDGE_PIXELS
            print(f"{label:70s} preview {int(preview.sum()):5d}  cycles {int(cycles.sum()):5d}  differ {differ}"
                  f"{'' if differ <= MAX_EDGE_PIXELS else '  DIFFERENT'}", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
