"""Camera and light conversion against analytic values and against Blender's own camera frame."""

from __future__ import annotations

import math
import warnings
from types import SimpleNamespace

import pytest

from tests.addon_support import add_top_camera

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import core  # noqa: E402

from kd_addon import scene_input  # noqa: E402
from kd_addon.extraction_warnings import hidden_light_warnings  # noqa: E402
from kd_addon.render_visibility import RenderVisibility  # noqa: E402
from kd_addon.errors import PreviewError  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402


def camera_data(**kw):
    base = dict(type="PERSP", lens=50.0, sensor_width=36.0, sensor_height=24.0, sensor_fit="AUTO",
                ortho_scale=6.0, shift_x=0.0, shift_y=0.0, clip_start=0.1, clip_end=100.0)
    return SimpleNamespace(**dict(base, **kw))


@pytest.mark.parametrize("fit, width, height, expected_tan_half", [
    ("AUTO", 200, 100, 18 / 50),               # larger (x) gets the sensor width
    ("AUTO", 100, 200, 18 / 50),               # larger (y) gets the sensor width too
    ("HORIZONTAL", 200, 100, 18 / 50),         # x is fitted and is the larger side
    ("HORIZONTAL", 100, 200, 18 / 50 * 2),     # x fitted, y twice as long
    ("VERTICAL", 100, 200, 12 / 50),           # y fitted to the sensor height and larger
    ("VERTICAL", 200, 100, 12 / 50 * 2),       # y fitted, x twice as long
])
def test_perspective_fov_along_larger_side(fit, width, height, expected_tan_half):
    fov = scene_input.perspective_fov(50.0, 36.0, 24.0, fit, width, height)
    assert math.tan(fov / 2) == pytest.approx(expected_tan_half, rel=1e-12)


def test_auto_fit_fov_equals_blenders_angle(scene):
    cam = scenes.add_camera()
    cam.data.lens = 35.0
    fov = scene_input.perspective_fov(cam.data.lens, cam.data.sensor_width, cam.data.sensor_height, "AUTO", 640, 480)
    assert fov == pytest.approx(cam.data.angle, rel=1e-6)


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
@pytest.mark.parametrize("fit", ["AUTO", "HORIZONTAL", "VERTICAL"])
@pytest.mark.parametrize("size", [(160, 90), (90, 160), (100, 100)])
@pytest.mark.parametrize("shift", [(0.0, 0.0), (0.3, -0.2)])
@pytest.mark.parametrize("pixel_aspect", [(1.0, 1.0), (1.0, 2.0), (3.0, 1.0)])
def test_view_extent_matches_blender_view_frame(scene, kind, fit, size, shift, pixel_aspect):
    """Camera.view_frame gives the corners of Blender's own image plane (at z = -1 for perspective),
    lens shift and pixel aspect included: core's image plane from the converted camera has the same
    corners. (The aspects (1, 2) and (3, 1) turn 160 x 90 and 90 x 160 taller or wider than they are in
    pixels, so sensor fit AUTO picks the other axis.)"""
    cam = scenes.add_camera()
    cam.data.type, cam.data.sensor_fit, cam.data.lens, cam.data.ortho_scale = kind, fit, 28.0, 7.0
    cam.data.shift_x, cam.data.shift_y = shift
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = pixel_aspect
    scene.camera = cam
    corners = np.array([tuple(v) for v in cam.data.view_frame(scene=scene)])
    depth = np.abs(corners[:, 2]).max() if kind == "PERSP" else 1.0
    expected = (corners[:, 0].min() / depth, corners[:, 0].max() / depth,
                corners[:, 1].min() / depth, corners[:, 1].max() / depth)
    converted, warnings = scene_input.read_camera(scene, bpy.context.evaluated_depsgraph_get(), *size)
    assert warnings == []
    assert (converted.fov is None) == (kind == "ORTHO") and (converted.ortho_scale is None) == (kind == "PERSP")
    plane = core.Camera(**converted.keywords()).image_plane(*size)
    assert plane == pytest.approx(expected, rel=1e-5, abs=1e-6)


def test_camera_matrix_drops_scale_and_keeps_clip(scene):
    data = camera_data(clip_start=0.5, clip_end=40.0)
    matrix = np.diag([2.0, 3.0, 4.0, 1.0])
    matrix[:3, 3] = (1e5, -2e5, 3.0)
    cam, warnings = scene_input.camera_input(data, matrix, 64, 32)
    np.testing.assert_allclose(cam.matrix_world[:3, :3], np.eye(3))
    np.testing.assert_array_equal(cam.position, (1e5, -2e5, 3.0))
    assert (cam.clip_start, cam.clip_end, warnings) == (0.5, 40.0, [])


def test_camera_problems_are_named():
    with pytest.raises(PreviewError, match="panoramic cameras are not supported"):
        scene_input.camera_input(camera_data(type="PANO"), np.eye(4), 10, 10)
    with pytest.raises(PreviewError, match="degenerate"):
        scene_input.camera_input(camera_data(), np.diag([0.0, 1.0, 1.0, 1.0]), 10, 10)
    with pytest.raises(PreviewError, match="clip start 20 is not below clip end 10, so the camera sees nothing"):
        scene_input.camera_input(camera_data(clip_start=20.0, clip_end=10.0), np.eye(4), 10, 10)


def test_no_scene_camera_is_named(scene):
    with pytest.raises(PreviewError, match="has no active camera"):
        scene_input.read_camera(scene, bpy.context.evaluated_depsgraph_get(), 10, 10)


def test_a_scene_camera_that_is_no_camera_is_named(scene):
    """Blender lets any object be the scene camera (Ctrl+Numpad 0 on an empty or a light)."""
    empty = scenes.link(bpy.data.objects.new("Rig", None))
    scene.camera = empty
    with pytest.raises(PreviewError, match="^the scene camera 'Rig' is an empty object, which the preview cannot "
                                           "look through: set a camera object as the scene camera$"):
        scene_input.read_camera(scene, bpy.context.evaluated_depsgraph_get(), 10, 10)


def test_the_scene_camera_a_problem_is_found_in_is_named(scene):
    """With timeline markers switching cameras, "panoramic cameras are not supported" must say which
    camera."""
    cam = scenes.add_camera()
    cam.name, cam.data.type, scene.camera = "Shot 2", "PANO", cam
    with pytest.raises(PreviewError, match="^scene camera 'Shot 2': panoramic cameras are not supported"):
        scene_input.read_camera(scene, bpy.context.evaluated_depsgraph_get(), 10, 10)
    cam.data.type, cam.scale = "PERSP", (0.0, 1.0, 1.0)
    with pytest.raises(PreviewError, match="^scene camera 'Shot 2': the camera's transform is degenerate"):
        scene_input.read_camera(scene, bpy.context.evaluated_depsgraph_get(), 10, 10)


HAS_TEMPERATURE = "use_temperature" in bpy.types.Light.bl_rna.properties  # Blender 4.5+


def light_object(kind, name=None, **data):
    name = name or kind.title()
    obj = scenes.link(bpy.data.objects.new(name, bpy.data.lights.new(name, kind)))
    for key, value in data.items():
        setattr(obj.data, key, value)
    return obj


def test_lights_convert_with_analytic_directions(scene):
    point = light_object("POINT", energy=250.0, shadow_soft_size=0.4, color=(1.0, 0.5, 0.25))
    point.location = (1, 2, 3)
    sun = light_object("SUN", energy=4.0, angle=0.1)
    sun.rotation_euler = (math.pi / 2, 0.0, 0.0)  # -Z turned about X by 90 degrees -> +Y
    sun.scale = (3.0, 3.0, 3.0)  # scale must not change the unit direction
    spot = light_object("SPOT", energy=900.0, spot_size=0.8, spot_blend=0.3, shadow_soft_size=0.0)
    spot.location = (0, 0, 5)
    area = light_object("AREA", energy=50.0, shape="RECTANGLE", size=2.0, size_y=0.5, spread=math.radians(30))
    area.location = (4, 0, 2)
    disk = light_object("AREA", name="Disk", shape="DISK", size=1.5)
    warm = light_object("POINT", name="Warm", color=(0.5, 1.0, 1.0))
    if HAS_TEMPERATURE:
        warm.data.use_temperature, warm.data.temperature = True, 2000.0
    depsgraph = bpy.context.evaluated_depsgraph_get()
    lights = {light.name: light for light in scene_input.read_lights(depsgraph)}
    assert set(lights) == {"Point", "Sun", "Spot", "Area", "Disk", "Warm"}
    p = lights["Point"].keywords
    assert lights["Point"].kind == "point" and p["radius"] == pytest.approx(0.4) and p["power"] == 250.0
    np.testing.assert_allclose(p["position"], (1, 2, 3))
    assert p["color"] == pytest.approx((1.0, 0.5, 0.25))
    s = lights["Sun"].keywords
    np.testing.assert_allclose(s["direction"], (0, 1, 0), atol=1e-6)
    assert (s["angle"], s["strength"]) == (pytest.approx(0.1), 4.0)
    sp = lights["Spot"].keywords
    np.testing.assert_allclose(sp["direction"], (0, 0, -1), atol=1e-7)
    assert (sp["spot_size"], sp["spot_blend"]) == (pytest.approx(0.8), pytest.approx(0.3))
    a = lights["Area"].keywords
    assert (a["shape"], a["size"], a["size_y"], a["power"]) == ("RECTANGLE", 2.0, 0.5, 50.0)
    assert a["spread"] == pytest.approx(math.radians(30))
    np.testing.assert_allclose(a["matrix_world"][:3, 3], (4, 0, 2))
    assert lights["Disk"].keywords["size_y"] is None
    assert lights["Disk"].keywords["spread"] == pytest.approx(math.pi)  # Blender's default: 180 degrees
    if not HAS_TEMPERATURE:  # Blender before 4.5: Color alone
        assert lights["Warm"].keywords["color"] == pytest.approx((0.5, 1.0, 1.0))
        return
    # Temperature on: Color times the blackbody's colour, its largest channel 1 (scene_input.light_color)
    tint = np.array(warm.data.temperature_color)
    np.testing.assert_allclose(lights["Warm"].keywords["color"], tint / tint.max() * (0.5, 1, 1), rtol=1e-6)
    red, green, blue = lights["Warm"].keywords["color"]
    assert red > green > 10 * blue  # a 2000 K light is orange, even with its Color bluish


def emission_node(light_object_):
    return next(n for n in scenes.light_nodes_on(light_object_.data).nodes if n.type == "EMISSION")


def node_light(name, change=None, color=(1.0, 1.0, 1.0)):
    """A point light with Blender's default node tree (Emission -> Light Output), then change(node,
    nodes, links) applied to it."""
    ob = light_object("POINT", name=name, color=color)
    node = emission_node(ob)
    if change is not None:
        change(node, ob.data.node_tree.nodes, ob.data.node_tree.links)
    return ob


def set_inputs(color=None, strength=None):
    def change(node, nodes, links):
        if color is not None:
            node.inputs["Color"].default_value = (*color, 1.0)
        if strength is not None:
            node.inputs["Strength"].default_value = strength
    return change


def through_reroute(node, nodes, links):
    output = next(n for n in nodes if n.type == "OUTPUT_LIGHT")
    reroute = nodes.new("NodeReroute")
    links.new(node.outputs[0], reroute.inputs[0])
    links.new(reroute.outputs[0], output.inputs[0])
    node.inputs["Color"].default_value = (0.0, 0.5, 1.0, 1.0)


def cycles_output_beside_an_active_eevee_one(node, nodes, links):
    node.inputs["Color"].default_value = (0.0, 1.0, 0.0, 1.0)
    eevee = nodes.new("ShaderNodeOutputLight")  # active, but Cycles renders the other (target All)
    eevee.target, eevee.is_active_output = "EEVEE", True


def only_an_eevee_output(node, nodes, links):
    next(n for n in nodes if n.type == "OUTPUT_LIGHT").target = "EEVEE"


def diffuse_into_the_output(node, nodes, links):
    output = next(n for n in nodes if n.type == "OUTPUT_LIGHT")
    links.new(nodes.new("ShaderNodeBsdfDiffuse").outputs[0], output.inputs[0])


def test_a_lights_plain_emission_node_is_applied_and_other_nodes_are_named(scene):
    """As Cycles emits a light with nodes (light_nodes.py): its Color times a plain Emission node's
    Color, through reroutes too; Blender's default tree changes nothing; a colour above 1 is scaled to
    1, keeping its hue. Trees Cycles emits nothing from carry the reason (the light is then left out);
    others (a linked input, another shader) are not applied and named, the light keeping its Color."""
    applied = {"Plain": (node_light("Plain", color=(1.0, 0.5, 0.25)), (1.0, 0.5, 0.25)),
               "Tinted": (node_light("Tinted", set_inputs((0.5, 1.0, 0.2), 4.0), (1.0, 0.5, 0.25)),
                          (0.5, 0.5, 0.05)),
               "Bright": (node_light("Bright", set_inputs((4.0, 2.0, 1.0))), (1.0, 0.5, 0.25)),
               "Rerouted": (node_light("Rerouted", through_reroute), (0.0, 0.5, 1.0)),
               "CyclesOutput": (node_light("CyclesOutput", cycles_output_beside_an_active_eevee_one),
                                (0.0, 1.0, 0.0))}
    dark = {"StrengthZero": (set_inputs(strength=0.0), "Strength is 0"),
            "Negative": (set_inputs(strength=-2.0), "Strength is -2"),
            "MutedNode": (lambda node, nodes, links: setattr(node, "mute", True), "is muted"),
            "MutedLink": (lambda node, nodes, links: setattr(node.outputs[0].links[0], "is_muted", True),
                          "link feeding its Light Output is muted"),
            "Unplugged": (lambda node, nodes, links: links.remove(node.outputs[0].links[0]),
                          "nothing is connected to its Light Output"),
            "EeveeOnly": (only_an_eevee_output, "no Light Output that Cycles renders")}
    for name, (change, _) in dark.items():
        node_light(name, change)
    unapplied = {"Textured": lambda node, nodes, links: links.new(nodes.new("ShaderNodeTexNoise").outputs["Color"],
                                                                  node.inputs["Color"]),
                 "Diffuse": diffuse_into_the_output}
    for name, change in unapplied.items():
        node_light(name, change, color=(0.5, 0.5, 1.0))
    lights = {light.name: light for light in scene_input.read_lights(bpy.context.evaluated_depsgraph_get())}
    for name, (_, color) in applied.items():
        assert lights[name].keywords["color"] == pytest.approx(color), name
        assert not lights[name].unapplied and not lights[name].emits_nothing, name
    for name, (_, reason) in dark.items():
        assert reason in lights[name].emits_nothing and not lights[name].unapplied, name
    for name in unapplied:
        assert lights[name].keywords["color"] == pytest.approx((0.5, 0.5, 1.0)), name  # its Color alone
        assert not lights[name].emits_nothing, name
        assert any("shader nodes" in what for what in lights[name].unapplied), name


def test_reading_lights_uses_nothing_blender_deprecates(scene):
    """Blender 5.1 deprecated a light's Use Nodes (every light's tree is used; 6.0 removes it): the add-on
    reads the tree without touching the property there, so a deprecation warning on 5.1 and later
    means a light read that breaks on 6.0. On 5.0 and before it reads Use Nodes and still warns of
    nothing."""
    for kind in ("POINT", "SUN", "SPOT", "AREA"):
        emission_node(light_object(kind, name=kind.title()))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lights = scene_input.read_lights(bpy.context.evaluated_depsgraph_get())
    assert len(lights) == 4
    assert [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)] == []


def test_render_hidden_lights_are_left_out(scene):
    light_object("POINT", name="Shown")
    light_object("POINT", name="Hidden").hide_render = True
    hidden_coll = scenes.new_collection("Off")
    hidden_coll.hide_render = True
    scenes.link(bpy.data.objects.new("InOff", bpy.data.lights.new("InOff", "SUN")), hidden_coll)
    names = [light.name for light in scene_input.read_lights(bpy.context.evaluated_depsgraph_get())]
    assert names == ["Shown"]


def test_lights_of_a_background_scene_are_read(scene):
    """Cycles lights the scene with its Background Scene's sun (mean 0.77 against 0.05 without), so
    the preview reads the Background Scene's lights too (without them shadow mode finds no light)."""
    background = bpy.data.scenes.new("Set")
    scene.background_set = background
    scenes.link(bpy.data.objects.new("SetSun", bpy.data.lights.new("SetSun", "SUN")), background.collection)
    scenes.link(bpy.data.objects.new("Off", bpy.data.lights.new("Off", "SUN")), background.collection).hide_render = True
    assert [light.name for light in scene_input.read_lights(bpy.context.evaluated_depsgraph_get())] == ["SetSun"]


def test_a_background_scene_light_hidden_in_the_viewport_is_named(scene):
    """As the scene's own lights (test_addon_render): a final render uses it, the preview cannot."""
    background = bpy.data.scenes.new("Set")
    scene.background_set = background
    scenes.link(bpy.data.objects.new("SetSun", bpy.data.lights.new("SetSun", "SUN")), background.collection)
    hidden = scenes.link(bpy.data.objects.new("SetLamp", bpy.data.lights.new("SetLamp", "POINT")),
                         background.collection)
    hidden.hide_viewport = True
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert [light.name for light in scene_input.read_lights(depsgraph)] == ["SetSun"]
    assert hidden_light_warnings(depsgraph, RenderVisibility(depsgraph)) == [
        "light 'SetLamp' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): "
        "the preview leaves it out, a final render uses it"]


def test_instanced_lights_are_read_at_their_instances(scene):
    """A light inside an instanced collection lights the scene in Cycles, so the preview reads it:
    one light per render-visible instance, at the instance's place."""
    source = scenes.new_collection("Rig", exclude=True)  # excluded: only its instances render
    lamp = scenes.link(bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT")), source)
    lamp.location = (1.0, 0.0, 2.0)
    for name, x, hidden in (("A", 10.0, False), ("B", 20.0, False), ("C", 30.0, True)):
        empty = scenes.link(bpy.data.objects.new(name, None))
        empty.instance_type, empty.instance_collection = "COLLECTION", source
        empty.location, empty.hide_render = (x, 0.0, 0.0), hidden
    lights = scene_input.read_lights(bpy.context.evaluated_depsgraph_get())
    found = sorted((light.name, tuple(np.round(light.keywords["position"], 6))) for light in lights)
    assert found == [("Lamp (instanced by A)", (11.0, 0.0, 2.0)), ("Lamp (instanced by B)", (21.0, 0.0, 2.0))]


@pytest.mark.parametrize("hidden", ["light", "child collection"])
def test_an_instanced_light_the_viewport_does_not_make_is_named(scene, hidden):
    """A light member of an instanced collection, disabled in viewports (or in a child collection that
    is): Cycles lights the scene with it (153 pixels), the viewport makes none, so the preview names
    it. A render-hidden one is left out in both, so not named."""
    source = scenes.new_collection("Rig", exclude=True)
    holder = source
    if hidden == "child collection":
        holder = bpy.data.collections.new("Inner")
        source.children.link(holder)
    lamp = scenes.link(bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "SPOT")), holder)
    quiet = scenes.link(bpy.data.objects.new("Quiet", bpy.data.lights.new("Quiet", "POINT")), source)
    quiet.hide_viewport = quiet.hide_render = True
    (holder if hidden == "child collection" else lamp).hide_viewport = True
    scenes.add_collection_instance("Inst", source, location=(5, 0, 0))
    add_top_camera(location=(0, 0, 5))
    inputs = scene_input.read_scene(scene, bpy.context.evaluated_depsgraph_get(), 32, 32)
    assert inputs.lights == []
    assert inputs.hidden_lights == [
        "light 'Lamp' in collection 'Rig' (instanced by 'Inst') is not instanced in the viewport (disabled "
        "in viewports, or a collection on its path is): the preview leaves it out, a final render uses it"]


def test_an_instancers_diffuse_switch_darkens_its_lights(scene):
    """Cycles ANDs an instance's ray visibility with its instancer's: an instancer with Diffuse off
    leaves its lights dark on diffuse surfaces (0 lit pixels against 120 with it on); the light's own
    switch does the same, and a light with both on lights."""
    source = scenes.new_collection("Rig", exclude=True)
    scenes.link(bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT")), source)
    instancer = scenes.add_collection_instance("Inst", source)
    (light,) = scene_input.read_lights(bpy.context.evaluated_depsgraph_get())
    assert light.no_diffuse == "" and light.unapplied == ()
    instancer.visible_diffuse = False
    (light,) = scene_input.read_lights(bpy.context.evaluated_depsgraph_get())
    assert light.no_diffuse == "its instancer 'Inst''s Ray Visibility > Diffuse is off"
    assert light.unapplied == ()
    instancer.visible_diffuse = True
    bpy.data.objects["Lamp"].visible_diffuse = False
    (light,) = scene_input.read_lights(bpy.context.evaluated_depsgraph_get())
    assert light.no_diffuse == "its Ray Visibility > Diffuse is off"


def test_a_light_child_of_a_vertex_instancing_parent_lights_only_from_the_instances(scene):
    """As for meshes (render_visibility.py): a final render hides the child at its own place and keeps the
    copies the parent makes at its vertices."""
    parent = scenes.add_mesh("Parent", [(1, 0, 0), (10, 0, 0)], [], edges=[(0, 1)])
    parent.instance_type = "VERTS"
    lamp = light_object("POINT", name="Lamp")
    lamp.location = (0.0, 0.0, 5.0)
    lamp.parent = parent
    lights = scene_input.read_lights(bpy.context.evaluated_depsgraph_get())
    found = sorted((light.name, tuple(np.round(light.keywords["position"], 6))) for light in lights)
    assert found == [("Lamp (instanced by Parent)", (1.0, 0.0, 5.0)), ("Lamp (instanced by Parent)", (10.0, 0.0, 5.0))]


def test_cast_shadow_and_spot_scale_reach_core(scene):
    """Blender's Cast Shadow switch and a spot's object scale (its cone is elliptical in Cycles)."""
    sun = light_object("SUN")
    sun.data.use_shadow = False
    spot = light_object("SPOT", spot_size=0.8)
    spot.scale = (2.0, 1.0, 0.5)
    lights = {light.name: light for light in scene_input.read_lights(bpy.context.evaluated_depsgraph_get())}
    assert lights["Sun"].keywords["cast_shadow"] is False and lights["Spot"].keywords["cast_shadow"] is True
    np.testing.assert_allclose(lights["Spot"].keywords["axes"], np.diag([2.0, 1.0, 0.5]), atol=1e-6)
    light = core.Light.spot(**lights["Spot"].keywords)
    assert not core.Light.sun(**lights["Sun"].keywords).cast_shadow and light.cast_shadow


def test_lights_are_accepted_by_core(scene):
    import core

    for kind in ("POINT", "SUN", "SPOT", "AREA"):
        light_object(kind)
    for light in scene_input.read_lights(bpy.context.evaluated_depsgraph_get()):
        getattr(core.Light, light.kind)(**light.keywords).translated(np.ones(3))


def test_lights_at_blenders_largest_angles_are_accepted_by_core(scene):
    """180 degrees, the most Blender allows for a spot's size, a sun's angle and an area light's
    spread, is stored as float32 pi, a hair above np.pi: core takes each as pi."""
    import core

    light_object("SPOT", spot_size=math.pi)
    light_object("SUN", angle=math.pi)
    light_object("AREA", spread=math.pi)
    lights = {light.kind: light for light in scene_input.read_lights(bpy.context.evaluated_depsgraph_get())}
    assert lights["spot"].keywords["spot_size"] > math.pi  # what Blender stores
    spot = core.Light.spot(**lights["spot"].keywords)
    sun = core.Light.sun(**lights["sun"].keywords)
    area = core.Light.area(**lights["area"].keywords)
    assert spot.params["spot_size"] == sun.params["angle"] == area.params["spread"] == math.pi


def test_read_scene_uses_the_evaluated_camera(scene):
    cam = add_top_camera(location=(0, 0, 5), lens=50.0)
    cam.data.lens = 25.0
    cam.data.keyframe_insert("lens", frame=1)
    cam.data.lens = 100.0
    cam.data.keyframe_insert("lens", frame=10)
    scene.frame_set(10)
    inputs = scene_input.read_scene(scene, bpy.context.evaluated_depsgraph_get(), 100, 50)
    assert math.tan(inputs.camera.fov / 2) == pytest.approx(18 / 100, rel=1e-6)
    assert inputs.lights == [] and inputs.warnings == []


def test_settings_the_preview_does_not_apply_are_named(scene):
    """A render region, motion blur and depth of field change a final render but not the preview: each
    is named. Non-square pixels are applied (test_view_extent_matches_blender_view_frame), so they are
    not."""
    camera = add_top_camera(location=(0, 0, 5), lens=50.0)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert scene_input.read_scene(scene, depsgraph, 100, 50).warnings == []
    scene.render.use_border = True
    scene.render.pixel_aspect_x = 2.0
    scene.render.use_motion_blur = True
    camera.data.dof.use_dof = True
    assert scene_input.read_scene(scene, bpy.context.evaluated_depsgraph_get(), 100, 50).warnings == [
        "the Render Region (Output > Format) is ignored by the preview: it renders the whole frame",
        "motion blur is ignored by the preview: it renders the frame's instant",
        f"the depth of field of camera '{camera.name}' is ignored by the preview: it renders a pinhole camera, "
        "everything in focus"]
