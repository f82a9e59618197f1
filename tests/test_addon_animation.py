"""Render Animation and its frame files and report in background mode, on scenes with a known answer.

half_plane_scene (tests/addon_support.py): an orthographic camera sees a plane over exactly the left
half of the image (x in [-4, 0] of an 8 x 4 view) with a 1 x 1 x 1 cube standing on it, so the hit
mask and the places where AO must be 1 (open plane, cube top) or below 1 (plane next to the cube)
are known.
"""

from __future__ import annotations

import json

import bpy
import numpy as np
import pytest

from kd_addon.config import make_config
from kd_addon.errors import PreviewError
from kd_addon.output import IMAGE_NAME, save_frame
from kd_addon.properties import run_state
from tests import bpy_scenes as scenes
from tests.addon_support import column_of, exr_channels, half_plane_scene, preview_pixels


def test_animation_writes_frames_and_report(addon, tmp_path):
    scene = half_plane_scene()
    box = bpy.data.objects["Box"]
    box.keyframe_insert("location", frame=1)
    box.location.x = -1.0
    box.keyframe_insert("location", frame=3)
    scene.frame_start, scene.frame_end, scene.frame_current = 1, 3, 2
    scene.kd_preview.output_dir = str(tmp_path / "seq")
    scene.kd_preview.output_format = "OPEN_EXR"
    assert bpy.ops.kdpreview.render_animation() == {"FINISHED"}
    assert scene.frame_current == 2  # put back
    names = sorted(p.name for p in (tmp_path / "seq").iterdir())
    assert names == ["frame_0001.exr", "frame_0002.exr", "frame_0003.exr", "report.json"]
    report = json.loads((tmp_path / "seq" / "report.json").read_text())
    assert [row["frame"] for row in report["frames"]] == [1, 2, 3]
    for row in report["frames"]:
        for key in ("triangles", "objects", "extract_ms", "build_ms", "trace_ms", "total_ms", "rays",
                    "mrays_per_s", "tree", "file"):
            assert key in row, key
        assert row["total_ms"] >= row["extract_ms"] + row["build_ms"] + row["trace_ms"]
        assert "build_ms" not in row["tree"]  # the trees' own build times, kept ones included: not this frame's
    assert report["settings"]["output_format"] == "OPEN_EXR" and report["resolution"] == [64, 32]
    assert report["totals"]["frames"] == 3 and report["totals"]["rays"] == sum(r["rays"] for r in report["frames"])
    exr = bpy.data.images.load(str(tmp_path / "seq" / "frame_0003.exr"))
    pixels = np.empty(64 * 32 * 4, np.float32)
    exr.pixels.foreach_get(pixels)
    img = pixels.reshape(32, 64, 4)[::-1]
    assert (img[:, :32, 3] == 1.0).all() and (img[:, 32:, 3] == 0.0).all()
    assert img[16, column_of(-1.0), 0] == pytest.approx(1.0, abs=1e-3)  # box moved to x = -1: its top is open


@pytest.mark.parametrize("start", [1, 3])
def test_settings_keyed_over_the_frames_are_named_and_the_starting_ones_kept(addon, tmp_path, start):
    """Animation renders with the settings it starts with, at the current frame (report.json records one
    set); settings keyed to differ are named once, in the first frame where they do."""
    scene = half_plane_scene()
    settings = scene.kd_preview
    settings.samples = 2
    settings.keyframe_insert("samples", frame=1)
    settings.samples = 8
    settings.keyframe_insert("samples", frame=3)
    scene.frame_start, scene.frame_end = 1, 3
    settings.output_dir = str(tmp_path / "seq")
    scene.frame_set(start)
    assert bpy.ops.kdpreview.render_animation() == {"FINISHED"}
    report = json.loads((tmp_path / "seq" / "report.json").read_text())
    assert report["settings"]["samples"] == (2 if start == 1 else 8)
    notes = [[w for w in row["warnings"] if "keyed to change over the frames" in w] for row in report["frames"]]
    assert [len(n) for n in notes] == ([0, 1, 0] if start == 1 else [1, 0, 0])  # samples 2, 5, 8
    assert all(all(row["warnings"]) for row in report["frames"])  # no empty warning once it is said
    said = notes[1 if start == 1 else 0][0]
    assert "(samples)" in said and "keeps the values it started with" in said and "Ctrl-F12" in said


def test_exr_frames_hold_the_linear_values(tmp_path):
    """The EXR holds the image's own (linear) floats: Image.save() would store 0.5 as 0.7354 (sRGB)."""
    scenes.reset()
    image = np.zeros((3, 5, 4), np.float32)
    image[..., 0] = np.linspace(0.0, 1.0, 5)
    image[..., 1], image[..., 2], image[..., 3] = 0.25, 0.5, 1.0
    image[2, 4] = 0.0  # one background pixel, bottom right
    save_frame(image, tmp_path / "f.exr", "OPEN_EXR")
    channels = exr_channels(tmp_path / "f.exr")
    stored = np.stack([channels[c] for c in "RGBA"], axis=-1)
    assert np.array_equal(stored, image)
    assert [s.name for s in bpy.data.scenes] == ["Scene"]  # the scratch scene for the settings is gone


@pytest.mark.parametrize("file_format, name", [("PNG", "f.png"), ("OPEN_EXR", "f.exr")])
def test_a_frame_that_fails_to_save_leaves_the_earlier_file_whole(tmp_path, monkeypatch, file_format, name):
    """Frames are written beside their name and renamed over it, so a save that fails (or a run killed)
    halfway leaves the earlier run's file as it was, and no partial file."""
    from kd_addon import output
    scenes.reset()
    image = np.full((3, 5, 4), 0.5, np.float32)
    path = save_frame(image, tmp_path / name, file_format)
    before = path.read_bytes()

    def half_written(_image, partial, *args):
        partial.write_bytes(before[: len(before) // 2])
        raise OSError("disk full")

    monkeypatch.setattr(output, "_save_linear_exr" if file_format == "OPEN_EXR" else "_save_png", half_written)
    with pytest.raises(OSError, match="disk full"):
        save_frame(np.zeros((3, 5, 4), np.float32), path, file_format)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [name]


@pytest.mark.parametrize("cut", [0, 100])
def test_a_png_blender_wrote_incomplete_without_an_error_is_refused_and_the_earlier_file_kept(
        tmp_path, monkeypatch, cut):
    """On a full disk Blender's PNG save returns normally and leaves an empty or cut file (an exploratory
    run on a 300 KiB tmpfs: an empty frame renamed over the earlier run's whole one, and no error)."""
    from kd_addon import output
    scenes.reset()
    path = save_frame(np.full((30, 50, 4), 0.5, np.float32), tmp_path / "f.png", "PNG")
    before = path.read_bytes()
    real = output._save_png

    def cut_short(image, partial):
        real(image, partial)
        partial.write_bytes(partial.read_bytes()[:cut])

    monkeypatch.setattr(output, "_save_png", cut_short)
    with pytest.raises(OSError, match=f"Blender wrote .f.partial.png incomplete \\({cut} bytes\\): is the disk full"):
        save_frame(np.zeros((30, 50, 4), np.float32), path, "PNG")
    assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["f.png"]


def test_an_output_folder_replaced_by_a_file_mid_run_is_named_and_the_scene_put_back(addon, tmp_path,
                                                                                      monkeypatch):
    """The leftover's removal failed too (not a folder) and its error, raised from close(), hid the write's
    and left the scene on the run's frame (an exploratory run)."""
    from kd_addon import sequence
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(3)  # not a frame the run stops at: close() must put it back
    out = tmp_path / "seq"
    scene.kd_preview.output_dir = str(out)
    real = sequence.SequenceJob._write

    def folder_gone(job, result):
        if len(job.results) == 1:  # frame 2: the folder is a file now
            for child in out.iterdir():
                child.unlink()
            out.rmdir()
            out.write_text("not a folder")
        return real(job, result)

    monkeypatch.setattr(sequence.SequenceJob, "_write", folder_gone)
    with pytest.raises(RuntimeError, match="frame 2: could not write"):
        bpy.ops.kdpreview.render_animation()
    assert scene.frame_current == 3 and "Error: frame 2: could not write" in run_state(bpy.context).status


def test_a_report_that_fails_on_the_last_frame_is_written_when_the_sequence_closes(addon, tmp_path,
                                                                                     monkeypatch):
    """A signal (or a full disk) while the last frame's report is written: close() writes it (review:
    the folder held both frames and the report listed one, incomplete). Reports while the sequence
    runs are best effort: the first frame's failing report does not stop it."""
    from kd_addon import sequence
    scene = half_plane_scene()
    real = sequence.write_report
    calls = []

    def flaky(out_dir, scene_name, config, results, *rest, **keywords):
        calls.append(len(results))
        if len(calls) <= 2:  # frame 1's report (disk full), then frame 2's (a signal)
            raise (PreviewError("disk full") if len(calls) == 1 else KeyboardInterrupt)
        return real(out_dir, scene_name, config, results, *rest, **keywords)

    monkeypatch.setattr(sequence, "write_report", flaky)
    job = sequence.SequenceJob(scene, make_config(scene.kd_preview), [1, 2], tmp_path / "seq",
                               lambda _scene: bpy.context.evaluated_depsgraph_get())
    with pytest.raises(KeyboardInterrupt):
        while not job.tick():
            pass
    job.close()
    assert calls == [1, 2, 2]
    report = json.loads((tmp_path / "seq" / "report.json").read_text())
    assert report["complete"] is True and [f["file"] for f in report["frames"]] == ["frame_0001.png", "frame_0002.png"]
    assert sorted(p.name for p in (tmp_path / "seq").iterdir()) == ["frame_0001.png", "frame_0002.png", "report.json"]


def test_a_cancel_while_the_last_report_is_written_says_the_frames_are_this_runs(addon, tmp_path, monkeypatch):
    """The frames were all written and shown: "the previous preview is unchanged" would be untrue
    (an exploratory run's Ctrl-C after the last frame)."""
    from kd_addon import sequence
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 1, 2
    scene.kd_preview.output_dir = str(tmp_path / "seq")
    real, calls = sequence.write_report, []

    def interrupted_last(out_dir, scene_name, config, results, *rest, **keywords):
        calls.append(len(results))
        if len(results) == 2 and calls.count(2) == 1:
            raise KeyboardInterrupt
        return real(out_dir, scene_name, config, results, *rest, **keywords)

    monkeypatch.setattr(sequence, "write_report", interrupted_last)
    assert bpy.ops.kdpreview.render_animation() == {"CANCELLED"}
    assert run_state(bpy.context).status == "Cancelled after the last frame: all 2 frames are written and shown"
    assert json.loads((tmp_path / "seq" / "report.json").read_text())["complete"] is True


def _fail_at_frame_3(scene):
    """Key the camera's clip end below its clip start at frame 3: frames 1 and 2 render, 3 stops the run."""
    camera = scene.camera.data
    camera.clip_start = 0.1
    for frame, value in ((2, 100.0), (3, 0.05)):
        camera.clip_end = value
        camera.keyframe_insert("clip_end", frame=frame)
    scene.frame_start, scene.frame_end = 1, 3


def test_a_failed_animation_puts_the_preview_and_its_figures_back(addon, tmp_path):
    """An animation that fails at frame 3 must not leave frame 2 in the preview image (its frames pass
    through it on their way to disk) under the panel's figures of the render before. The frames
    written stay on disk; the preview is the one before the run."""
    scene = half_plane_scene()
    _fail_at_frame_3(scene)
    scene.frame_set(1)
    scene.kd_preview.ao_distance = 0.2
    bpy.ops.kdpreview.render()
    before, state = preview_pixels().copy(), bpy.context.window_manager.kd_preview_state
    last_run = state.last_run
    scene.kd_preview.ao_distance = 3.0  # frames of the animation differ from the preview
    scene.kd_preview.output_dir = str(tmp_path)
    with pytest.raises(RuntimeError, match="frame 3.*clip start 0.1 is not below clip end 0.05"):
        bpy.ops.kdpreview.render_animation()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frame_0001.png", "frame_0002.png", "report.json"]
    assert np.array_equal(preview_pixels(), before) and state.last_run == last_run
    assert scene.frame_current == 1


def test_a_failed_first_animation_leaves_no_preview_image(addon, tmp_path):
    scene = half_plane_scene()
    _fail_at_frame_3(scene)
    scene.kd_preview.output_dir = str(tmp_path)
    with pytest.raises(RuntimeError, match="clip start"):
        bpy.ops.kdpreview.render_animation()
    assert IMAGE_NAME not in bpy.data.images and len(list(tmp_path.iterdir())) == 3


def test_animation_needs_a_saved_file_for_relative_output(addon):
    half_plane_scene()
    with pytest.raises(RuntimeError, match="relative to the .blend file, which is not saved"):
        bpy.ops.kdpreview.render_animation()


def test_a_ctrl_c_while_a_finished_frame_is_stored_lands_after_it(addon, monkeypatch):
    """An exploratory run's Ctrl-C landed inside the preview's update: the image was resized but held the
    old pixels, the status stayed "Tracing", and a traceback came out. The store and the figures now
    finish first, and the run ends as finished."""
    import signal
    from kd_addon import output
    scene = half_plane_scene()
    real = output.store_preview

    def interrupted_store(image, **keywords):
        signal.raise_signal(signal.SIGINT)  # Python's handler: KeyboardInterrupt here, without the hold
        return real(image, **keywords)

    monkeypatch.setattr(output, "store_preview", interrupted_store)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert bpy.ops.kdpreview.render() == {"FINISHED"}  # the interrupt came once the frame was done
    finally:
        signal.signal(signal.SIGINT, previous)
    monkeypatch.setattr(output, "store_preview", real)
    status = run_state(bpy.context).status
    assert status.startswith("KD Preview: 64x32"), status
    stored = preview_pixels()
    assert bpy.ops.kdpreview.render() == {"FINISHED"}  # the same frame again, uninterrupted
    np.testing.assert_array_equal(stored, preview_pixels())


def test_a_ctrl_c_held_over_an_error_while_a_frame_is_stored_reports_the_error(addon, monkeypatch):
    """The held interrupt is raised over finish()'s own error; the error is what the user sees (a review
    found `message` unbound there: a traceback instead)."""
    import signal
    from kd_addon import output
    half_plane_scene()

    def failing_store(image, **keywords):
        signal.raise_signal(signal.SIGINT)
        raise PreviewError("the preview image cannot be written")

    monkeypatch.setattr(output, "store_preview", failing_store)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(RuntimeError, match="the preview image cannot be written") as error:
            bpy.ops.kdpreview.render()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert "Traceback" not in str(error.value)
    assert run_state(bpy.context).status == "Error: the preview image cannot be written"
