"""Random geometry-nodes scatter scenes, the bulk path's ground (kd_addon/bulk_instances.py), against a
render's own depsgraph (tests/render_depsgraph.py) and, through the extraction_path fixture, against
the per-entry walk row for row.

Each seed builds carriers whose nodes put meshes on points: one primitive, several picked per point
(Geometry to Instance, Pick Instance), an object instanced by Object Info (render-hidden or not, its
ray flags off or not), nested a level deeper, with random rotations and scales, some points given a
NaN scale; the carriers' own ray flags, holdout, Show Instancer and Disable in Renders vary.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from kd_addon import bulk_instances
from kd_addon.extract import extract_scene
from tests import bpy_scenes as scenes
from tests.render_depsgraph import differences, render_entries

pytestmark = [pytest.mark.usefixtures("extraction_path"),
              pytest.mark.skipif(not bulk_instances.AVAILABLE, reason="bpy has no Object.evaluated_geometry()")]

PRIMITIVES = (("GeometryNodeMeshCube", {}), ("GeometryNodeMeshIcoSphere", {"Subdivisions": 1}),
              ("GeometryNodeMeshCylinder", {"Vertices": 7}), ("GeometryNodeMeshCone", {"Vertices": 5}))


class _ScatterScene:
    def __init__(self, seed):
        self.rng = np.random.default_rng(seed)
        self.targets = []

    def chance(self, p):
        return bool(self.rng.random() < p)

    def build(self):
        for i in range(int(self.rng.integers(0, 3))):
            target = scenes.add_cube(f"Target{i}", location=tuple(self.rng.uniform(-4, 4, 3)))
            target.hide_render = self.chance(0.3)
            target.visible_shadow = not self.chance(0.2)
            self.targets.append(target)
        if self.chance(0.5):
            scenes.add_cube("Plain", location=(0, 0, -3))
        for i in range(int(self.rng.integers(1, 4))):
            self.carrier(f"Carrier{i}")

    def carrier(self, name):
        host = scenes.add_mesh(name, [], [], location=tuple(self.rng.uniform(-5, 5, 3)))
        host.rotation_euler = tuple(self.rng.uniform(-1, 1, 3))
        host.modifiers.new("Scatter", "NODES").node_group = self.tree(name)
        host.visible_camera = not self.chance(0.2)
        host.visible_shadow = not self.chance(0.2)
        host.is_holdout = self.chance(0.15)
        host.show_instancer_for_render = not self.chance(0.2)
        host.hide_render = self.chance(0.1)

    def tree(self, name):
        group = bpy.data.node_groups.new(f"{name}Nodes", "GeometryNodeTree")
        group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
        nodes, links = group.nodes, group.links
        instances = self.scatter(nodes, links, self.source(nodes, links), int(self.rng.integers(1, 40)))
        if self.chance(0.4):  # a level deeper: the scattered instances scattered again
            instances = self.scatter(nodes, links, instances, int(self.rng.integers(1, 5)))
        links.new(instances, nodes.new("NodeGroupOutput").inputs[0])
        return group

    def source(self, nodes, links):
        """The instance socket: a primitive, several to pick from, or an object as an instance."""
        if self.targets and self.chance(0.3):
            info = nodes.new("GeometryNodeObjectInfo")
            info.inputs["Object"].default_value = self.targets[int(self.rng.integers(len(self.targets)))]
            info.inputs["As Instance"].default_value = True
            return info.outputs["Geometry"]
        count = 1 if self.chance(0.5) else int(self.rng.integers(2, 4))
        to_instance = nodes.new("GeometryNodeGeometryToInstance")
        for _ in range(count):
            kind, inputs = PRIMITIVES[int(self.rng.integers(len(PRIMITIVES)))]
            node = nodes.new(kind)
            for key, value in inputs.items():
                node.inputs[key].default_value = value
            links.new(node.outputs["Mesh"], to_instance.inputs[0])
        return to_instance.outputs[0]

    def scatter(self, nodes, links, instance, count):
        grid = nodes.new("GeometryNodeMeshLine")
        grid.inputs["Count"].default_value = count
        grid.inputs["Offset"].default_value = tuple(self.rng.uniform(-2, 2, 3))
        on_points = nodes.new("GeometryNodeInstanceOnPoints")
        on_points.inputs["Pick Instance"].default_value = True
        links.new(grid.outputs["Mesh"], on_points.inputs["Points"])
        links.new(instance, on_points.inputs["Instance"])
        for socket, low, high in (("Rotation", -3.0, 3.0), ("Scale", 0.2, 1.5)):
            value = nodes.new("FunctionNodeRandomValue")
            value.data_type = "FLOAT_VECTOR"
            value.inputs["Min"].default_value = (low,) * 3
            value.inputs["Max"].default_value = (high,) * 3
            value.inputs["Seed"].default_value = int(self.rng.integers(1000))
            links.new(value.outputs["Value"], on_points.inputs[socket])
        index = nodes.new("FunctionNodeRandomValue")
        index.data_type = "INT"
        integer_socket(index.inputs, "Min").default_value = 0
        integer_socket(index.inputs, "Max").default_value = 3
        links.new(integer_socket(index.outputs, "Value"), on_points.inputs["Instance Index"])
        return on_points.outputs["Instances"]



def integer_socket(sockets, name):
    """The integer socket `name` of a Random Value node: Blender 4.2 to 5.0 list one socket per data type
    (the others disabled), 5.1 on only the chosen type's."""
    return next(s for s in sockets if s.name == name and s.type == "INT" and s.enabled)

@pytest.mark.parametrize("seed", range(24))
def test_scatter_scene_matches_a_render_depsgraph(scene, seed, extraction_path):
    """Object by object the render's triangles, and on the bulk path read in bulk (the fixture compares
    every row with the walk's)."""
    _ScatterScene(seed).build()
    extracted = extract_scene()
    assert extracted.path == extraction_path
    placement = all(ob.show_instancer_for_render for ob in bpy.data.objects)
    assert differences(extracted, render_entries(), placement) == []


def test_non_finite_instance_transforms_are_left_out_and_named(scene, extraction_path):
    """Points given an infinite scale place nothing; the warning names the carrier once and counts them,
    as the walk does."""
    host = scenes.add_mesh("Host", [], [])
    group = scenes.gn_line_instances_group(4, (2, 0, 0), 1.0)
    on_points = next(n for n in group.nodes if n.bl_idname == "GeometryNodeInstanceOnPoints")
    index = group.nodes.new("GeometryNodeInputIndex")
    scale = index.outputs[0]
    for _ in range(2):  # index * 1e38 * 1e38: 0 on the first point, infinite on the others
        multiply = group.nodes.new("ShaderNodeMath")
        multiply.operation = "MULTIPLY"
        multiply.inputs[1].default_value = 1e38
        group.links.new(scale, multiply.inputs[0])
        scale = multiply.outputs[0]
    group.links.new(scale, on_points.inputs["Scale"])
    host.modifiers.new("GN", "NODES").node_group = group
    extracted = extract_scene()
    assert extracted.path == extraction_path
    assert extracted.object_count == 1
    assert [w for w in extracted.warnings if "non-finite transform" in w] == [  # the others are kept: say so
        "object 'Host': 3 instances with a non-finite transform (NaN or infinite location, rotation or scale) left out"]



def test_a_carrier_placed_at_nan_is_named_once(scene, extraction_path):
    """A carrier whose own location is NaN takes its instances with it: one warning for the object, not
    a second one counting its instances as if the others stayed."""
    host = scenes.add_gn_instancer("Host", count=5, offset=(1.5, 0.2, 0))
    host.location.x = math.nan
    extracted = extract_scene()
    assert extracted.path == extraction_path and extracted.triangle_count == 0
    assert [w for w in extracted.warnings if "non-finite" in w] == [
        "object 'Host' has a non-finite transform (NaN or infinite location, rotation or scale); left out"]


def test_unchanged_instances_keep_their_rows_and_changed_ones_are_read_anew(scene, extraction_path):
    """A second reading of the same state keeps the rows (same token: the image key stays); moving the
    points, the carrier or changing the instanced mesh gives new rows, each checked against the walk."""
    host = scenes.add_gn_instancer("Host", count=50, offset=(1.5, 0.2, 0))
    tokens = [extract_scene().table().token, extract_scene().table().token]
    line = next(n for n in host.modifiers["GN"].node_group.nodes if n.bl_idname == "GeometryNodeMeshLine")
    line.inputs["Offset"].default_value = (1.5, 0.3, 0)
    tokens.append(extract_scene().table().token)
    host.location.z += 1
    tokens.append(extract_scene().table().token)
    cube = next(n for n in host.modifiers["GN"].node_group.nodes if n.bl_idname == "GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (0.5, 0.5, 0.5)
    extracted = extract_scene()
    tokens.append(extracted.table().token)
    assert tokens[0] == tokens[1]
    assert len(set(tokens[1:4])) == 3
    assert (tokens[4] != tokens[3]) == (extraction_path == "bulk")  # the walk's token is the rows' content
    assert np.ptp(extracted.world_triangles()[:12].reshape(-1, 3), axis=0).max() == pytest.approx(0.5)


def test_lights_instanced_by_geometry_nodes_are_still_found(scene, extraction_path):
    """read_lights skips the instance entries only where no instance is anything but a mesh: a light
    placed by Object Info on points lights the scene on both paths."""
    from kd_addon.scene_input import read_lights

    lamp = scenes.add_light("Lamp")
    scenes.add_gn_instancer("Meshes", count=5)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert [light.name for light in read_lights(depsgraph)] == ["Lamp"]
    host = scenes.add_info_node_host("Lights", lamp)
    host.location = (3, 0, 0)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert sorted(light.name for light in read_lights(depsgraph)) == ["Lamp", "Lamp (instanced by Lights)"]
