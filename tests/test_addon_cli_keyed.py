"""The command line and keyed KD Preview settings: keyed to change over a run's frames (named, the saved
frame's values used), driven or in NLA strips, and edited after their keys (kd_addon/keyed_settings.py)."""

from __future__ import annotations

import json

import pytest

from tests.addon_support import add_sun, floor_scene

import bpy  # noqa: E402

import kd_addon  # noqa: E402
from kd_addon import cli  # noqa: E402


def frame_rows(out):
    return json.loads((out / "report.json").read_text())["frames"]


@pytest.mark.parametrize("saved_at", [1, 3])
def test_settings_keyed_over_the_frames_are_named_and_the_saved_frames_kept(tmp_path, capsys, saved_at):
    """The command line reads the settings once, at the frame the file was saved at (as Animation reads the
    current frame's): settings keyed to differ on the run's frames are named on its first frame, even for
    one frame; one that an option replaces, or one keyed constant, is not."""
    scene = floor_scene(40, 30)
    add_sun()
    kd_addon.register()
    try:
        settings = scene.kd_preview
        for frame, samples, distance, seed in ((1, 2, 0.5, 3), (3, 4, 2.0, 3)):
            settings.samples, settings.ao_distance, settings.seed = samples, distance, seed
            for name in ("samples", "ao_distance", "seed"):
                settings.keyframe_insert(name, frame=frame)
        scene.frame_set(saved_at)
        blend = tmp_path / "keyed.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        kd_addon.unregister()
    runs = {"range": ["--frames", "1-3"], "one": ["--frames", str(4 - saved_at)],
            "given": ["--frames", "1-3", "--ao-distance", "1", "--samples", "2"], "same": ["--frames", str(saved_at)]}
    for run, frames in runs.items():
        out = tmp_path / run
        assert cli.execute(["render", str(blend), "--out", str(out), *frames]) == 0
        report = json.loads((out / "report.json").read_text())
        notes = [[w for w in row["warnings"] if "keyed to change over the frames" in w] for row in report["frames"]]
        err = capsys.readouterr().err
        if run in ("same", "given"):
            assert not any(notes) and "keyed" not in err, run
            continue
        assert report["settings"]["samples"] == (2 if saved_at == 1 else 4)
        assert [len(n) for n in notes] == [1] + [0] * (len(notes) - 1), run
        assert "(ao_distance, samples)" in notes[0][0] and f"values at frame {saved_at}" in notes[0][0]
        assert "keyed to change over the frames (ao_distance, samples)" in err


def test_driven_settings_are_named_and_muted_curves_and_panel_switches_are_not(tmp_path):
    """A driver sets its setting on every frame, so it is named; a muted curve animates nothing, and Live
    Update is the panel's switch, not a render setting."""
    scene = floor_scene(40, 30)
    kd_addon.register()
    try:
        settings = scene.kd_preview
        for frame, value in ((1, 2), (3, 4)):
            settings.samples, settings.live_update = value, value == 2
            settings.keyframe_insert("samples", frame=frame)
            settings.keyframe_insert("live_update", frame=frame)
        scene.driver_add("kd_preview.seed").driver.expression = "frame"
        for curve in _action_curves(scene.animation_data):
            curve.mute = curve.data_path == "kd_preview.samples"
        blend = tmp_path / "driven.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        kd_addon.unregister()
    assert cli.execute(["render", str(blend), "--out", str(tmp_path / "o"), "--frames", "1-3"]) == 0
    notes = [w for w in frame_rows(tmp_path / "o")[0]["warnings"] if "keyed to change" in w]
    assert len(notes) == 1 and "over the frames (seed) are not followed" in notes[0], notes


def _action_curves(data):
    """Every F-curve of the scene's action, muted ones too."""
    from kd_addon.animation_curves import _action_curves as curves_of

    return curves_of(data, data.action, getattr(data, "action_slot", None))

@pytest.mark.parametrize("edit", ["samples", "mode", "none"])
def test_settings_edited_after_their_keys_are_named(tmp_path, capsys, edit):
    """A keyed setting edited and saved without a new key renders with the edited value from the
    command line, while Blender (and the render engine's animation) puts the key back at the next frame
    change: the run says so. An interpolated integer between keys is not an edit."""
    scene = floor_scene(40, 30)
    add_sun()
    kd_addon.register()
    try:
        settings = scene.kd_preview
        for frame, samples, mode in ((1, 2, "ao"), (5, 6, "ao")):
            settings.samples, settings.mode = samples, mode
            settings.keyframe_insert("samples", frame=frame)
            settings.keyframe_insert("mode", frame=frame)
        scene.frame_set(2)  # samples interpolated between 2 and 6
        if edit == "samples":
            settings.samples = 9
        elif edit == "mode":
            settings.mode = "shadow"
        blend = tmp_path / "edited.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        kd_addon.unregister()
    out = tmp_path / "out"
    assert cli.execute(["render", str(blend), "--out", str(out), "--frames", "2", "--resolution", "10"]) == 0
    report = json.loads((out / "report.json").read_text())
    notes = [w for w in report["frames"][0]["warnings"] if "edited after they were keyed" in w]
    err = capsys.readouterr().err
    if edit == "none":
        assert not notes and "edited after" not in err
        return
    assert report["settings"][edit] == {"samples": 9, "mode": "shadow"}[edit]
    assert len(notes) == 1 and f"edited after they were keyed ({edit})" in notes[0], notes
    assert "not their keys at frame 2" in err

@pytest.mark.parametrize("case", ["driven", "clamped"])
def test_keyed_values_blender_itself_changed_are_not_called_edits(tmp_path, capsys, case):
    """A stored value that is not its curve's because Blender made it so is no edit: a driver also sets
    the setting, or the curve runs past the setting's bounds (stored clamped)."""
    scene = floor_scene(40, 30)
    kd_addon.register()
    try:
        settings = scene.kd_preview
        for frame, percent in ((1, 20), (5, 40)):
            settings.resolution_percentage = percent
            settings.keyframe_insert("resolution_percentage", frame=frame)
        if case == "clamped":  # a key beyond the setting's bound (100), as an edited key value leaves it
            key = next(c for c in _action_curves(scene.animation_data)
                       if c.data_path == "kd_preview.resolution_percentage").keyframe_points[1]
            key.co.y = key.handle_left.y = key.handle_right.y = 150
        else:
            settings.driver_add("resolution_percentage").driver.expression = "30"
        scene.frame_set(5)
        stored = settings["resolution_percentage"]
        blend = tmp_path / f"{case}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        kd_addon.unregister()
    assert stored != 40  # Blender's value, not the curve's
    assert cli.execute(["render", str(blend), "--out", str(tmp_path / "o"), "--frames", "5", "--samples", "1"]) == 0
    assert "edited after they were keyed" not in capsys.readouterr().err
