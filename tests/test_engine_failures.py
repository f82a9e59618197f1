"""Failures a final render does not expect: they fail the frame with a message and keep the last good
file, and never crash the process (kd_addon/engine_final.py, FinalRender.run)."""
import bpy
import pytest

from kd_addon import engine_final, kernel_warmup, pipeline
from tests.test_engine_final import engine_scene, read_rgba


def test_a_cache_folder_the_note_cannot_read_does_not_fail_the_render(addon, tmp_path, monkeypatch):
    """The background render's compile note reads the kernel cache folder; where that read fails (an
    unreadable folder: OSError), the frame still renders and is written, without the note."""
    def unreadable():
        raise PermissionError("cache folder not readable")

    monkeypatch.setattr(kernel_warmup, "second_stage_cached", unreadable)
    monkeypatch.setattr(engine_final, "_uncompiled_noted", False)
    engine_scene(tmp_path)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert (read_rgba(tmp_path / "frame.exr")[..., 3] == 1.0).any()  # the frame, not an empty image


def test_an_unexpected_failure_is_reported_and_writes_nothing(addon, tmp_path, monkeypatch, capfd):
    """An exception the add-on does not expect (here from the frame's worker) fails the frame with its
    type and message, prints its traceback, and keeps the last good file: left to leave render(), the
    bpy module crashed writing the multilayer EXR."""
    engine_scene(tmp_path)
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    before = (tmp_path / "frame.exr").read_bytes()

    def failing_tick(job):
        raise RuntimeError("a fault for the test")

    monkeypatch.setattr(pipeline.FrameJob, "tick", failing_tick)
    with pytest.raises(RuntimeError, match=r"KD Preview: the frame failed: RuntimeError: a fault for the test"):
        bpy.ops.render.render(write_still=True)
    assert (tmp_path / "frame.exr").read_bytes() == before
    assert "Traceback" in capfd.readouterr().err
