"""Settings -> core options: defaults, mapping, validation messages, frame ranges (no rendering)."""

from __future__ import annotations

import math
from dataclasses import fields
from types import SimpleNamespace

import bpy
import pytest

from kd_addon import config
from kd_addon.config import DEFAULTS, SettingsError, frame_size, make_config
from kd_addon.errors import PreviewError
from kd_addon.sequence import parse_frames


def test_defaults_map_to_core_keywords():
    cfg = make_config(SimpleNamespace())
    assert cfg.build_options == {"builder": "binned", "leaf_size": 2, "bins": 32, "max_depth": None, "threads": None,
                                 "lazy": False}
    assert cfg.render_options == {"mode": "auto", "samples": 16, "ao_distance": 1.0, "error_target": None,
                                  "threads": None, "seed": 0}
    assert cfg.resolution_percentage == 50 and cfg.file_extension == ".png"


def test_the_report_writes_automatic_as_auto_and_off_as_null():
    """report.json's one convention: "auto" for a setting the add-on decides, null for one turned off,
    the value itself otherwise (the render options' None and the settings' 0 were two conventions)."""
    defaults = make_config(SimpleNamespace()).report_settings()
    assert {k: defaults[k] for k in ("mode", "max_depth", "threads", "error_target", "memory_limit_mb")} == {
        "mode": "auto", "max_depth": "auto", "threads": "auto", "error_target": None, "memory_limit_mb": None}
    assert {k: v for k, v in defaults.items() if k not in config.AUTOMATIC_WHEN and k not in config.OFF_WHEN} == {
        k: v for k, v in make_config(SimpleNamespace()).as_dict().items()
        if k not in config.AUTOMATIC_WHEN and k not in config.OFF_WHEN}
    chosen = make_config(SimpleNamespace(mode="ao", max_depth=20, threads=2, error_target=0.01,
                                         memory_limit_mb=512)).report_settings()
    assert (chosen["mode"], chosen["max_depth"], chosen["threads"], chosen["error_target"],
            chosen["memory_limit_mb"]) == ("ao", 20, 2, 0.01, 512)
    assert set(defaults) == set(config.SETTING_NAMES)


def test_denoise_is_off_by_default_and_not_a_render_keyword():
    """The denoiser is applied when the image is read (PreviewRender.image(denoise=...)), so it is a
    property of the config, not one of PreviewRender's keywords."""
    assert make_config(SimpleNamespace()).denoise is False
    cfg = make_config(SimpleNamespace(denoise=True))
    assert cfg.denoise is True and "denoise" not in cfg.render_options and cfg.as_dict()["denoise"] is True


def test_zero_means_automatic_and_values_pass_through():
    cfg = make_config(SimpleNamespace(max_depth=20, threads=2, error_target=0.01, builder="exact", bins=64,
                                      leaf_size=4, mode="ao+shadow", samples=7, ao_distance=2.5,
                                      output_format="OPEN_EXR", lazy=True))
    assert cfg.build_options == {"builder": "exact", "leaf_size": 4, "bins": 64, "max_depth": 20, "threads": 2,
                                 "lazy": True}
    assert cfg.render_options["threads"] == 2 and cfg.render_options["error_target"] == 0.01
    assert cfg.render_options["mode"] == "ao+shadow" and cfg.file_extension == ".exr"


@pytest.mark.parametrize("name, value, words", [
    ("mode", "normals", "mode must be one of auto, ao, shadow, ao+shadow"),
    ("builder", "sah", "builder must be one of binned, exact, median"),
    ("samples", 0, "samples must be an integer from 1"),
    ("samples", 2.5, "samples must be an integer"),
    ("resolution_percentage", 0, "resolution_percentage must be an integer from 1 to 100"),
    ("max_depth", 61, "max_depth must be an integer from 0 to 60 (0 = automatic)"),
    ("bins", 1, "bins must be an integer from 2"),
    ("threads", -1, "threads must be an integer from 0 to 1024 (0 = all cores)"),
    ("ao_distance", 0.0, "ao_distance must be a finite number greater than 0"),
    ("ao_distance", math.nan, "ao_distance must be a finite number"),
    ("error_target", -0.1, "error_target must be a finite number 0 or more (0 = off)"),
    ("output_format", "JPEG", "output_format must be one of PNG, OPEN_EXR"),
    ("denoise", "yes", "denoise must be True or False"),
])
def test_bad_settings_are_named(name, value, words):
    with pytest.raises(SettingsError, match=None) as info:
        make_config(SimpleNamespace(**{name: value}))
    assert words in str(info.value)
    assert isinstance(info.value, PreviewError)


def test_defaults_agree_with_core():
    import core
    from core.build import options

    core_defaults = core.BuildOptions()
    assert (DEFAULTS.builder, DEFAULTS.leaf_size, DEFAULTS.bins) == (
        core_defaults.builder, core_defaults.leaf_size, core_defaults.bins)
    assert config.BUILDERS == options.BUILDERS and config.MAX_DEPTH == options.DEPTH_LIMIT
    core.BuildOptions(**make_config(SimpleNamespace()).build_options)  # core accepts the mapping


def test_property_group_mirrors_settings(addon):
    settings = bpy.context.scene.kd_preview
    for f in fields(config.Settings):
        assert getattr(settings, f.name) == pytest.approx(getattr(DEFAULTS, f.name)), f.name
    modes = [item.identifier for item in settings.bl_rna.properties["mode"].enum_items]
    builders = [item.identifier for item in settings.bl_rna.properties["builder"].enum_items]
    formats = [item.identifier for item in settings.bl_rna.properties["output_format"].enum_items]
    assert tuple(modes) == config.MODES and tuple(builders) == config.BUILDERS
    assert tuple(formats) == tuple(config.OUTPUT_FORMATS)
    assert settings.live_update is False
    settings.mode, settings.samples, settings.threads = "ao+shadow", 5, 3
    cfg = make_config(settings)
    assert cfg.render_options["mode"] == "ao+shadow" and cfg.render_options["samples"] == 5
    assert cfg.build_options["threads"] == 3


def test_every_integer_the_panel_accepts_is_a_valid_setting(addon):
    """The panel's bounds match the render's checks: no value the panel takes (Leaf Size, Memory Limit,
    ...) is refused by the render."""
    settings = bpy.context.scene.kd_preview
    for prop in settings.bl_rna.properties:
        if prop.type != "INT":
            continue
        for value in (prop.hard_min, prop.hard_max):
            setattr(settings, prop.identifier, value)
            make_config(settings)  # raises SettingsError naming the setting if it refuses the value
        setattr(settings, prop.identifier, prop.default)


def test_frame_size_floors_like_blender_and_rejects_zero():
    assert frame_size(1920, 1080, 50) == (960, 540)
    assert frame_size(1001, 11, 10) == (100, 1)
    with pytest.raises(SettingsError, match="would be 0x0 pixels"):
        frame_size(4, 4, 1)


@pytest.mark.parametrize("text, frames", [
    ("7", [7]), ("1-4", [1, 2, 3, 4]), ("1-9:4", [1, 5, 9]), ("1-3,10,2", [1, 2, 3, 10]), ("-2-0", [-2, -1, 0]),
])
def test_parse_frames(text, frames):
    assert parse_frames(text) == frames


@pytest.mark.parametrize("text", ["5-2", "a-b", "1-3:0", "", "1..3"])
def test_bad_frame_ranges_are_named(text):
    with pytest.raises(PreviewError, match="bad frame range"):
        parse_frames(text)


@pytest.mark.parametrize("text, named", [("1048573-1048576", 1048576), ("2000000", 2000000), ("-1048580", -1048580),
                                          ("1-200000000000", 200000000000), ("5,-1048575-0", -1048575)])
def test_frames_blender_cannot_go_to_are_named_before_any_list_is_made(text, named):
    """Blender's frame_set clamps frames beyond +-1048574 silently, so such frames would render the last
    frame again under each requested name (and a huge range would be listed in full first)."""
    with pytest.raises(PreviewError, match=f"frame {named} is outside Blender's frame range"):
        parse_frames(text)
    assert parse_frames("1048570-1048574:4") == [1048570, 1048574] and parse_frames("-1048574") == [-1048574]


def test_an_enum_stored_as_a_number_that_names_no_item_is_named(addon):
    """Blender reads an enum whose stored number names none of its items (a file from another version, a
    script's `settings["mode"] = 7`) as ''; the message names the number instead of "got ''"."""
    settings = bpy.context.scene.kd_preview
    settings["mode"] = 7
    try:
        assert settings.mode == ""
        with pytest.raises(SettingsError) as info:
            make_config(settings)
        assert "mode must be one of auto, ao, shadow, ao+shadow; got stored item number 7" in str(info.value)
    finally:
        del settings["mode"]
    assert settings.mode == DEFAULTS.mode
