"""Where a light reaches, and its colour, against Cycles: area light Spread, light Temperature, portals.

Usage: .venv/bin/python benchmarks/cycles_lights.py [--size 80 60] [--samples 16]

Each variant is a 40 m floor under an orthographic camera looking straight down (16 m across) in a
black world, saved as a .blend; the preview renders it through the command line (`--mode shadow`)
and Cycles renders its Diffuse Direct pass (no bounces). Printed per variant: the fraction of pixels
each lights (above 1% of its brightest pixel; the preview's S has no power weighting, Cycles' has, so
masks and ratios are compared, not values) and the pixels only one of them lights; for the coloured
light, the G/R and B/R ratios of the floor's mean colour. The variants: a 1 m area light 5 m up with
Spread 180, 60, 20 and 10 degrees; a 2000 K sun (Temperature on, Color white and bluish); a sun whose
nodes are an Emission node of Color (0.2, 0.6, 1.0) and Strength 3 (Color white and orange); a sun plus
an area light that is a Cycles portal (emits nothing: the floor is uniform in both).
"""
import argparse
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bpy  # noqa: E402

from cycles_ao import read_exr  # noqa: E402

VARIANTS = {
    "area, spread 180": dict(spread=180.0),
    "area, spread 60": dict(spread=60.0),
    "area, spread 20": dict(spread=20.0),
    "area, spread 10": dict(spread=10.0),
    "sun 2000 K, white": dict(temperature=2000.0, color=(1.0, 1.0, 1.0)),
    "sun 2000 K, bluish": dict(temperature=2000.0, color=(0.4, 0.7, 1.0)),
    "sun Emission node": dict(emission=((0.2, 0.6, 1.0), 3.0)),
    "sun Emission, orange": dict(emission=((0.2, 0.6, 1.0), 3.0), color=(1.0, 0.5, 0.25)),
    "sun + portal": dict(portal=True),
}


def build(path, size, spread=None, temperature=None, color=(1.0, 1.0, 1.0), portal=False, emission=None):
    """Save the variant's scene (see the module docstring) to `path`."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = *size, 100
    floor = bpy.data.meshes.new("Floor")
    floor.from_pydata([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)], [], [(0, 1, 2, 3)])
    scene.collection.objects.link(bpy.data.objects.new("Floor", floor))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.type, camera.data.ortho_scale, camera.location = "ORTHO", 16.0, (0, 0, 30)
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.world = bpy.data.worlds.new("Black")
    scene.world.color = (0.0, 0.0, 0.0)  # what a world without nodes emits (Blender 4.2)
    if scene.world.node_tree is not None:  # bpy 5.0's new world has a Background node of grey 0.05, which
        for node in scene.world.node_tree.nodes:  # lit the floor by 0.04 in every channel
            if node.type == "BACKGROUND":
                node.inputs["Strength"].default_value = 0.0
    if temperature is not None or portal or emission is not None:
        sun = bpy.data.lights.new("Sun", "SUN")
        sun.color = color
        if emission is not None:  # Blender's default light tree: Emission -> Light Output
            sun.use_nodes = True
            node = next(n for n in sun.node_tree.nodes if n.type == "EMISSION")
            node.inputs["Color"].default_value = (*emission[0], 1.0)
            node.inputs["Strength"].default_value = emission[1]
        if temperature is not None:
            sun.use_temperature, sun.temperature = True, temperature
        sun_object = bpy.data.objects.new("Sun", sun)
        sun_object.rotation_euler = (0.9, 0.0, 0.0)
        scene.collection.objects.link(sun_object)
    if spread is not None or portal:
        area = bpy.data.lights.new("Area", "AREA")
        area.size, area.energy = 1.0, 500.0
        area.spread = math.radians(spread if spread is not None else 180.0)
        area.cycles.is_portal = portal
        area_object = bpy.data.objects.new("Area", area)
        area_object.location = (0, 0, 5)
        scene.collection.objects.link(area_object)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def preview(blend, out, samples):
    """The preview's (H, W, 3) shadow-mode image of frame 1 through the command line."""
    subprocess.run([sys.executable, "-m", "kd_addon", "render", str(blend), "--frames", "1", "--out", str(out),
                    "--mode", "shadow", "--samples", str(samples), "--resolution", "100", "--format", "EXR"],
                   check=True, capture_output=True, cwd=HERE.parent)
    channels, _ = read_exr(str(out / "frame_0001.exr"))
    return np.stack([channels[k] for k in "RGB"], axis=-1)


def cycles(blend, out, samples):
    """Cycles' (H, W, 3) Diffuse Direct pass of the same file (no bounces; not denoised: Cycles
    denoises the Combined pass only), read from a multilayer EXR."""
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples, scene.cycles.max_bounces = "CPU", samples, 0
    bpy.context.view_layer.use_pass_diffuse_direct = True
    bpy.ops.render.render()
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):  # Blender 5.0: multilayer is a media type first
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format, settings.color_depth = "OPEN_EXR_MULTILAYER", "32"
    path = out / "cycles.exr"
    bpy.data.images["Render Result"].save_render(str(path), scene=scene)
    channels, _ = read_exr(str(path))
    layer = next(name[:-2] for name in channels if name.endswith("Diffuse Direct.R"))
    return np.stack([channels[f"{layer}.{c}"] for c in "RGB"], axis=-1)


def lit(image):
    """Pixels above 1% of the brightest one (luminance-free: the largest channel)."""
    value = image.max(axis=-1)
    return value > 0.01 * value.max() if value.max() > 0 else np.zeros(value.shape, bool)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, nargs=2, default=(80, 60))
    parser.add_argument("--samples", type=int, default=16)
    args = parser.parse_args(argv)
    print(f"{'variant':20s} {'lit: preview':>13s} {'Cycles':>7s} {'differ':>7s}   mean colour G/R, B/R: preview | Cycles")
    with tempfile.TemporaryDirectory() as folder:
        for name, variant in VARIANTS.items():
            out = Path(folder) / name.replace(" ", "_").replace(",", "")
            out.mkdir()
            build(out / "scene.blend", args.size, **variant)
            ours, theirs = preview(out / "scene.blend", out, args.samples), cycles(out / "scene.blend", out, args.samples)
            a, b = lit(ours), lit(theirs)
            mean_ours, mean_theirs = ours.reshape(-1, 3).mean(0), theirs.reshape(-1, 3).mean(0)
            ratios = [f"{m[1] / m[0]:.3f}, {m[2] / m[0]:.3f}" if m[0] > 0 else "-" for m in (mean_ours, mean_theirs)]
            uniform = [f"{img.max(-1).std() / img.max(-1).mean():.3f}" for img in (ours, theirs)]
            print(f"{name:20s} {a.mean():13.3f} {b.mean():7.3f} {int((a != b).sum()):7d}   {ratios[0]} | {ratios[1]}"
                  f"   (spatial std/mean {uniform[0]} | {uniform[1]})")


if __name__ == "__main__":
    main()
