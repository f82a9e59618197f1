"""Which collection members geometry nodes instance in a final render, against the preview's extraction.

Usage: .venv/bin/python benchmarks/cycles_node_references.py

kd_addon/node_instances.py reads a host's node trees to tell a collection instanced whole (its
render-hidden members are not rendered) from objects instanced directly (rendered even when
render-hidden). Each case here builds a scene with the test suite's builders (tests/bpy_scenes.py),
renders it with Cycles (64x32, orthographic, transparent film) and prints, per object, whether
Cycles covers its pixel and whether the preview's extraction has it; exit 1 on any disagreement.
The cases:
- nested socket / nested modifier input: a reusable group whose Collection input feeds Collection
  Info, called with the collection on the Group node's socket or passed down from the modifier;
- unconnected / muted link: an Object Info node instancing a render-hidden object chosen by a Switch
  node, beside a Collection Info node naming that object's collection that reaches no output.
"""
import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402

from kd_addon.extract import extract_scene  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402

WIDTH, HEIGHT, ORTHO_SCALE = 64, 32, 4.0
PLACES = {"Shown": (-1.0, 0.0), "Hidden": (1.0, 0.0)}  # where each member's instance lands


def _source():
    """Excluded collection 'Src': 'Shown' at x = -1, a render-hidden 'Hidden' at x = +1."""
    source = scenes.new_collection("Src", exclude=True)
    for name, (x, y) in PLACES.items():
        scenes.add_cube(name, scale=0.4, location=(x, y, 0), collection=source)
    bpy.data.objects["Hidden"].hide_render = True
    return source


def _spare_collection_info_host(source, muted):
    """Object Info (As Instance, Relative) of the object a Switch picks ('Hidden'), plus a Collection
    Info node naming `source` that is unconnected or linked through a muted link only."""
    elsewhere = scenes.add_cube("Elsewhere", scale=0.1, location=(0, 0, -50))
    host = scenes.add_mesh("Host", [], [])
    tree = bpy.data.node_groups.new("HostTree", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    switch = tree.nodes.new("GeometryNodeSwitch")
    switch.input_type = "OBJECT"
    switch.inputs["False"].default_value, switch.inputs["True"].default_value = bpy.data.objects["Hidden"], elsewhere
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "RELATIVE"
    info.inputs["As Instance"].default_value = True
    tree.links.new(switch.outputs[0], info.inputs["Object"])
    join = tree.nodes.new("GeometryNodeJoinGeometry")
    tree.links.new(info.outputs["Geometry"], join.inputs[0])
    tree.links.new(join.outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
    spare = tree.nodes.new("GeometryNodeCollectionInfo")
    spare.inputs["Collection"].default_value = source
    if muted:
        tree.links.new(spare.outputs[0], join.inputs[0]).is_muted = True
    host.modifiers.new("GN", "NODES").node_group = tree


CASES = {
    "nested socket": lambda src: scenes.add_nested_info_host("Host", src),
    "nested modifier input": lambda src: scenes.add_nested_info_host("Host", src, via_modifier_input=True),
    "unconnected": lambda src: _spare_collection_info_host(src, muted=False),
    "muted link": lambda src: _spare_collection_info_host(src, muted=True),
}


def _cycles_coverage(scene, folder):
    """{member: whether Cycles' alpha covers its pixel}."""
    camera = scenes.add_camera("Cam")
    camera.data.type, camera.data.ortho_scale, camera.location = "ORTHO", ORTHO_SCALE, (0, 0, 10)
    scene.camera = camera
    render = scene.render
    render.resolution_x, render.resolution_y, render.resolution_percentage = WIDTH, HEIGHT, 100
    render.engine, render.film_transparent = "CYCLES", True
    scene.cycles.samples, scene.cycles.device = 1, "CPU"
    render.image_settings.file_format, render.image_settings.color_mode = "PNG", "RGBA"
    render.filepath = str(Path(folder) / "coverage.png")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(render.filepath)
    alpha = np.array(image.pixels[:]).reshape(HEIGHT, WIDTH, 4)[..., 3]
    to_pixel = WIDTH / ORTHO_SCALE
    return {name: bool(alpha[int(HEIGHT / 2 + y * to_pixel), int(WIDTH / 2 + x * to_pixel)] > 0.5)
            for name, (x, y) in PLACES.items()}


def main():
    argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split())).parse_args()  # --help
    disagreements = 0
    with tempfile.TemporaryDirectory() as folder:
        for case, build in CASES.items():
            scene = scenes.reset()
            build(_source())
            extracted = extract_scene()
            preview = {name: any(i.name == name and i.instancer == "Host" for i in extracted.instances)
                       for name in PLACES}
            cycles = _cycles_coverage(scene, folder)
            agree = preview == cycles
            disagreements += not agree
            print(f"{case:24s} cycles {cycles}  preview {preview}  {'ok' if agree else 'DIFFERENT'}"
                  + (f"  warnings {extracted.warnings}" if extracted.warnings else ""))
    return 1 if disagreements else 0


if __name__ == "__main__":
    sys.exit(main())
