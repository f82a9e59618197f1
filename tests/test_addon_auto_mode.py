"""The default mode, "auto": AO + Shadows where one of the scene's lights emits, AO where none does
(docs/choices.md#automatic-mode-ao-and-shadows-where-a-light-emits). Each image is checked against the
same frame rendered in the mode "auto" should have picked, which is an independent render."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from kd_addon import pipeline
from kd_addon.config import DEFAULTS, make_config
from kd_addon.errors import PreviewError
from tests.addon_support import half_plane_scene


def render(scene, mode):
    scene.kd_preview.mode = mode
    return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))


def test_the_default_mode_is_auto(addon):
    assert DEFAULTS.mode == "auto" and bpy.context.scene.kd_preview.mode == "auto"


def test_files_saved_before_auto_keep_their_mode(addon):
    """An enum is saved as its number: the modes a file could hold before "auto" keep theirs."""
    items = bpy.context.scene.kd_preview.bl_rna.properties["mode"].enum_items
    assert {item.identifier: item.value for item in items} == {"auto": 3, "ao": 0, "shadow": 1, "ao+shadow": 2}


def test_auto_renders_ao_and_shadows_when_a_light_emits(addon):
    scene = half_plane_scene()
    auto, chosen = render(scene, "auto"), render(scene, "ao+shadow")
    assert auto.mode == "ao+shadow" and chosen.mode == "ao+shadow"
    np.testing.assert_array_equal(auto.image, chosen.image)
    assert not np.array_equal(auto.image, render(scene, "ao").image)  # the sun's shadows are in it


@pytest.mark.parametrize("lights", ["none", "dark"])
def test_auto_renders_ao_when_no_light_emits(addon, lights):
    """No light at all, or only one that emits nothing (power 0): AO, with no error; the explicit
    shadow modes still say what is missing."""
    scene = half_plane_scene()
    sun = bpy.data.objects["Sun"]
    if lights == "none":
        bpy.data.objects.remove(sun)
    else:
        sun.data.energy = 0.0
    auto = render(scene, "auto")
    assert auto.mode == "ao" and not [w for w in auto.warnings if "light" in w]
    np.testing.assert_array_equal(auto.image, render(scene, "ao").image)
    if lights == "none":
        with pytest.raises(PreviewError, match="mode 'ao\\+shadow' needs a light"):
            render(scene, "ao+shadow")


def test_auto_names_a_light_core_refuses(addon):
    """A light that emits but cannot be used (a sun scaled to zero along its Z has no direction) leaves
    "auto" at AO, as a dark one does, but the frame says which light and why."""
    scene = half_plane_scene()
    bpy.data.objects["Sun"].scale = (1.0, 1.0, 0.0)
    auto = render(scene, "auto")
    assert auto.mode == "ao"
    assert [w for w in auto.warnings if "light 'Sun' left out" in w and "sun direction" in w
            and "mode Automatic renders AO" in w]
    np.testing.assert_array_equal(auto.image, render(scene, "ao").image)


def test_ao_stays_a_choice(addon):
    scene = half_plane_scene()
    result = render(scene, "ao")
    assert result.mode == "ao" and result.summary()["mode"] == "ao"
