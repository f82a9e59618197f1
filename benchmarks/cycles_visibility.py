"""Per-object Ray Visibility, Holdout and Indirect Only against Cycles' AO pass: the preview's image of a scene whose
objects have camera or shadow rays off, or are holdouts, compared with Cycles' on the same .blend.

Usage: .venv/bin/python benchmarks/cycles_visibility.py [--size 160 120] [--samples 64] [--out DIR]

The scene (built here with bpy, saved as DIR/visibility.blend): a ground plane; a cube with camera rays
off (not seen, still occludes), lifted 0.02 off the ground so that no face is coplanar with it (a
coincident face is a degenerate case: Cycles' AO rays from the ground hit it at distance 0); a UV
sphere with shadow rays off (seen, lets AO rays through); a cylinder and a small cube with both on;
and a collection instance of a cone whose instancer has camera rays off. Printed: hit pixels of both,
pixels only one of them hits, and the RMSE between them on common hits next to Cycles' own
seed-to-seed RMSE (the noise floor), plus the same for the scene with every flag on, which shows how
much the flags change the image. Then the holdout scenes (HOLDOUT_BUILD): a ground plane, a cube
seen through a collection instance and spheres instanced by geometry nodes, each with no holdout, a
holdout member of the instanced collection, a holdout instancer, a holdout node source object, a
holdout node carrier, a holdout plain object and a plain object in a holdout collection; and the
same scene with the plain object, the collection instancer or the node carrier in an Indirect Only
collection, and a holdout in one. Cycles reads holdout and Indirect Only
from the object itself or, for an instance, from its top-level instancer only.
"""
import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from cycles_ao import read_exr, render_cycles  # noqa: E402

SETUP = r'''
import sys, bpy
from mathutils import Vector
bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
sc = bpy.context.scene
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = {w}, {h}, 100
sc.frame_start = sc.frame_end = 1
bpy.ops.mesh.primitive_plane_add(size=12)


def move_to_collection(ob, name):
    """Move ob into a new collection of the scene; return that collection's layer collection."""
    coll = bpy.data.collections.new(name)
    sc.collection.children.link(coll)
    for c in ob.users_collection:
        c.objects.unlink(ob)
    coll.objects.link(ob)
    return bpy.context.view_layer.layer_collection.children[name]


def collection_instance(ob, name, location):
    """An empty instancing a new excluded collection "Source" that holds only ob."""
    move_to_collection(ob, "Source").exclude = True
    instancer = bpy.data.objects.new(name, None)
    instancer.instance_type, instancer.instance_collection = "COLLECTION", bpy.data.collections["Source"]
    sc.collection.objects.link(instancer)
    instancer.location = location
    return instancer
'''
FINISH = r'''
cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera")); sc.collection.objects.link(cam)
cam.data.lens = 35
cam.location = (7, -7, 5)
cam.rotation_euler = (Vector((0, 0, 0.5)) - cam.location).to_track_quat("-Z", "Y").to_euler()
sc.camera = cam
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])
'''
VISIBILITY_BUILD = r'''
bpy.ops.mesh.primitive_cube_add(size=1.5, location=(0, 0, 0.77)); cube = bpy.context.object
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.7, location=(1.6, 0.4, 0.7)); sphere = bpy.context.object
bpy.ops.mesh.primitive_cylinder_add(radius=0.4, depth=2.0, location=(-1.2, 1.2, 1.0))
bpy.ops.mesh.primitive_cube_add(size=1, location=(-0.3, -1.6, 0.5), rotation=(0, 0, 0.6))
bpy.ops.mesh.primitive_cone_add(radius1=0.5, depth=1.2)
instancer = collection_instance(bpy.context.object, "ConeInstance", (2.0, -2.0, 0.6))
if sys.argv[-2] == "flags":
    cube.visible_camera = False
    sphere.visible_shadow = False
    instancer.visible_camera = False
'''
HOLDOUT_BUILD = r'''
variant = sys.argv[-2]
bpy.ops.mesh.primitive_cylinder_add(radius=0.4, depth=1.4, location=(0.8, -2.2, 0.72)); post = bpy.context.object
bpy.ops.mesh.primitive_cube_add(size=1.5); cube = bpy.context.object
instancer = collection_instance(cube, "CubeInstance", (0, 0, 0.77))
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(0, 0, -50)); sphere = bpy.context.object
bpy.ops.mesh.primitive_plane_add(size=3, location=(2.2, 0.5, 0.4)); carrier = bpy.context.object
tree = bpy.data.node_groups.new("Spheres", "GeometryNodeTree")
tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
group_in, group_out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
on_points, info = tree.nodes.new("GeometryNodeInstanceOnPoints"), tree.nodes.new("GeometryNodeObjectInfo")
info.inputs["Object"].default_value = sphere
tree.links.new(group_in.outputs[0], on_points.inputs["Points"])
tree.links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
tree.links.new(on_points.outputs[0], group_out.inputs[0])
carrier.modifiers.new("Spheres", "NODES").node_group = tree
if variant == "member":
    cube.is_holdout = True
elif variant == "instancer":
    instancer.is_holdout = True
elif variant == "node_source":
    sphere.is_holdout = True
elif variant == "node_carrier":
    carrier.is_holdout = True
elif variant == "object":
    post.is_holdout = True
elif variant == "collection":
    move_to_collection(post, "Masked").holdout = True
elif variant == "indirect_object":
    move_to_collection(post, "Indirect").indirect_only = True
elif variant == "indirect_instancer":
    move_to_collection(instancer, "Indirect").indirect_only = True
elif variant == "indirect_carrier":
    move_to_collection(carrier, "Indirect").indirect_only = True
elif variant == "indirect_holdout":
    move_to_collection(post, "Indirect").indirect_only = True
    post.is_holdout = True
'''
HOLDOUT_VARIANTS = ("none", "member", "instancer", "node_source", "node_carrier", "object", "collection",
                    "indirect_object", "indirect_instancer", "indirect_carrier", "indirect_holdout")


def make_blend(path, size, body, variant):
    """Save the scene SETUP + body + FINISH builds, with `variant` as its argument, to path."""
    code = (SETUP + body + FINISH).format(w=size[0], h=size[1])
    subprocess.run([sys.executable, "-c", code, variant, str(path)], check=True, capture_output=True)


def preview(blend, out, samples):
    """The preview's (H, W, 4) image of frame 1 through the command line, as a user renders it."""
    subprocess.run([sys.executable, "-m", "kd_addon", "render", str(blend), "--frames", "1-1", "--out", str(out),
                    "--mode", "ao", "--samples", str(samples), "--ao-distance", "1.0", "--resolution", "100",
                    "--format", "EXR"], check=True, capture_output=True, cwd=HERE.parent)
    channels, _ = read_exr(str(out / "frame_0001.exr"))
    return np.stack([channels[k] for k in "RGBA"], axis=-1)


def rmse(a, b, mask):
    return float(np.sqrt(np.mean((a[mask] - b[mask]) ** 2)))


def compare(blend, out, size, samples):
    kd = preview(blend, out, samples)
    cy = [render_cycles(blend, *size, samples, seed=s) for s in (0, 1)]
    kd_hit, cy_hit = kd[..., 3] > 0.5, cy[0].alpha > 0.5
    both = kd_hit & cy_hit
    return dict(kd_hits=int(kd_hit.sum()), cycles_hits=int(cy_hit.sum()), only_one=int((kd_hit ^ cy_hit).sum()),
                rmse=rmse(kd[..., 0], cy[0].ao, both),
                cycles_noise=rmse(cy[0].ao, cy[1].ao, both & (cy[1].alpha > 0.5))), cy[0].ao


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--size", type=int, nargs=2, default=(160, 120))
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--out", default=None, help="folder for the .blend files and frames (default: a temporary one)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="kd_visibility_") as tmp:
        out = Path(args.out or tmp)
        out.mkdir(parents=True, exist_ok=True)
        images = {}
        for flags in (True, False):
            name = "visibility" if flags else "all_visible"
            make_blend(out / f"{name}.blend", args.size, VISIBILITY_BUILD, "flags" if flags else "none")
            figures, images[flags] = compare(out / f"{name}.blend", out / name, args.size, args.samples)
            print_figures(f"{name:12}", figures)
        change = rmse(images[True], images[False], np.ones_like(images[True], bool))
        print(f"Cycles, flags on against all visible: RMSE {change:.4f} (how much the flags change the image)")
        for variant in HOLDOUT_VARIANTS:
            make_blend(out / f"holdout_{variant}.blend", args.size, HOLDOUT_BUILD, variant)
            figures, _ = compare(out / f"holdout_{variant}.blend", out / f"holdout_{variant}", args.size, args.samples)
            print_figures(f"holdout {variant:18}", figures)


def print_figures(label, figures):
    print(f"{label} " + "  ".join(f"{k} {v:.4f}" if isinstance(v, float) else f"{k} {v}" for k, v in figures.items()))

if __name__ == "__main__":
    main()
