"""Extraction of a final render's own depsgraph, as the render engine reads it (extract.py, render mode).

A render depsgraph has evaluated the render's geometry and chosen its objects and instances already; the
viewport reconstruction (render_visibility.py, dupli_paths.py, viewport_evaluation.py) must drop nothing of
it. Each scene is extracted inside a render and compared, object by object, with that render's own mesh
entries (tests/render_depsgraph.py, which applies only the camera and shadow ray flags), and no warning
may speak of the viewport.
"""

from __future__ import annotations

import bpy
import pytest

from tests import bpy_scenes as scenes
from tests.render_depsgraph import differences, extraction_in_render
from tests.test_extract_render_paths import EARLIER_SCENES


def hidden_in_viewports():
    scenes.add_cube("Shown")
    scenes.add_cube("Disabled", location=(3, 0, 0)).hide_viewport = True
    scenes.add_cube("EyeHidden", location=(-3, 0, 0)).hide_set(True)
    hidden = scenes.new_collection("HiddenInViewports")
    hidden.hide_viewport = True
    scenes.add_cube("InHiddenCollection", location=(0, 3, 0), collection=hidden)
    scenes.add_cube("RenderHidden", location=(0, -3, 0)).hide_render = True


def render_only_modifiers():
    cube = scenes.add_cube("Subdivided")
    subsurf = cube.modifiers.new("Subdivision", "SUBSURF")
    subsurf.levels, subsurf.render_levels = 0, 2
    solid = scenes.add_cube("Arrayed", location=(4, 0, 0))
    array = solid.modifiers.new("Array", "ARRAY")
    array.show_viewport, array.count = False, 3
    bevelled = scenes.add_cube("ViewportOnly", location=(-4, 0, 0))
    bevel = bevelled.modifiers.new("Bevel", "BEVEL")
    bevel.show_render = False


def particles_at_display_percentage():
    rock = scenes.add_cube("Rock", scale=0.1, location=(0, 0, -20))
    emitter = scenes.add_particle_emitter("Emitter", count=40, obj=rock)
    emitter.particle_systems[0].settings.display_percentage = 25


def instances_of_members_disabled_in_viewports():
    source = scenes.new_collection("Source", exclude=True)
    scenes.add_cube("Member", scale=0.3, collection=source)
    scenes.add_cube("MemberDisabled", scale=0.3, offset=(1, 0, 0), collection=source).hide_viewport = True
    scenes.add_collection_instance("Instancer", source, location=(5, 0, 0))
    hidden_instancer = scenes.add_collection_instance("InstancerDisabled", source, location=(-5, 0, 0))
    hidden_instancer.hide_viewport = True
    scenes.add_gn_instancer("Nodes", location=(0, 6, 0))


def instancer_shown_only_in_renders():
    parent = scenes.add_cube("Parent")
    parent.instance_type = "VERTS"
    parent.show_instancer_for_viewport, parent.show_instancer_for_render = False, True
    child = scenes.add_cube("Child", scale=0.2)
    child.parent = parent


SCENES = ([("hidden in viewports", hidden_in_viewports), ("render-only modifiers", render_only_modifiers),
           ("particles at a display percentage", particles_at_display_percentage),
           ("members disabled in viewports", instances_of_members_disabled_in_viewports),
           ("instancer shown only in renders", instancer_shown_only_in_renders)]
          + EARLIER_SCENES)


@pytest.mark.parametrize("build", [b for _, b in SCENES], ids=[n for n, _ in SCENES])
def test_a_render_depsgraph_is_extracted_as_it_is(scene, build):
    build()
    extracted, entries = extraction_in_render()
    assert differences(extracted, entries) == []
    assert not [w for w in extracted.warnings if "viewport" in w]


def test_the_render_path_keeps_what_the_viewport_path_loses(scene):
    """The same scene through the viewport's depsgraph: the object disabled in viewports is missing and
    named, the render-only level is not applied and named; the render path has both, unnamed."""
    hidden_in_viewports()
    render_only_modifiers()
    from kd_addon.extract import extract_scene
    viewport = extract_scene(bpy.context.evaluated_depsgraph_get())
    rendered, _ = extraction_in_render()
    assert "Disabled" not in viewport.object_names and "Disabled" in rendered.object_names
    assert "InHiddenCollection" in rendered.object_names and "EyeHidden" in rendered.object_names
    assert "RenderHidden" not in rendered.object_names
    by_name = {inst.name: rendered.geometries[inst.geometry_key] for inst in rendered.instances}
    assert len(by_name["Subdivided"].triangles) == 6 * 16 * 2
    assert any("hidden in the viewport" in w for w in viewport.warnings)
    assert any("levels in the viewport" in w for w in viewport.warnings)


@pytest.mark.skipif(bpy.app.version < (4, 3, 0), reason="Blender 4.3's grease pencil API makes the strokes")
def test_grease_pencil_in_a_final_render_is_named_as_drawn_over_the_image(scene):
    """Blender draws grease pencil over any engine's final image, so there the warning says that the
    rays pass through it, not that it is left out (the panel's image does leave it out)."""
    scenes.add_cube("Shown")
    pencil = bpy.data.grease_pencils.new("Pencil")
    drawing = pencil.layers.new("Layer").frames.new(1).drawing
    drawing.add_strokes([3])
    scenes.link(bpy.data.objects.new("Pencil", pencil))
    from kd_addon.extract import extract_scene
    viewport = extract_scene(bpy.context.evaluated_depsgraph_get())
    rendered, _ = extraction_in_render()
    assert "object 'Pencil' is grease pencil, not triangles: left out of the preview" in viewport.warnings
    assert ("object 'Pencil' is grease pencil, not triangles: Blender draws it over the image, but the preview's "
            "rays pass through it (no AO or shadow)") in rendered.warnings
    bpy.context.view_layer.use_grease_pencil = False  # Filter > Grease Pencil off: no render draws it
    rendered, _ = extraction_in_render()
    assert not [w for w in rendered.warnings if "'Pencil'" in w]
