"""The operators' modal path (the one users get from the UI), driven by hand.

In background mode Blender never delivers timer events and refuses modal
handlers, so the test feeds TIMER / ESC events to the operator's own
invoke/modal methods. The stand-ins are the window manager's
`modal_handler_add` (recorded instead of called) and the events, which carry
exactly the properties of Blender's real Event (an outside run in Blender's
GUI found the operator reading `event.timer`, which no Event has, while the
events here had one); timers, progress and the run state are Blender's real
ones.
"""

from __future__ import annotations

import json
import re
import threading
from types import SimpleNamespace

import pytest

from tests.addon_support import EVENT_PROPERTIES, event, half_plane_scene, preview_pixels
from tests import bpy_scenes as scenes  # noqa: E402

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import kd_addon  # noqa: E402

from kd_addon import background, live_update, operators, pipeline  # noqa: E402
from kd_addon.operators import KDPREVIEW_OT_render, KDPREVIEW_OT_render_animation, _JobOperator  # noqa: E402


class WindowManagerProxy:
    def __init__(self, wm):
        self._wm, self.modal_handlers = wm, []

    def modal_handler_add(self, operator):
        self.modal_handlers.append(operator)
        return True

    def __getattr__(self, name):
        return getattr(self._wm, name)


def make_context():
    real = bpy.context
    return SimpleNamespace(window_manager=WindowManagerProxy(real.window_manager), window=real.window,
                           scene=real.scene, view_layer=real.view_layer,
                           evaluated_depsgraph_get=real.evaluated_depsgraph_get)


def driver(operator_cls):
    """A plain object running `operator_cls`'s job logic (bpy operators cannot be instantiated)."""
    class Driver(_JobOperator):
        make_job = operator_cls.make_job
        finish = operator_cls.finish
        cleanup = operator_cls.cleanup

        def __init__(self):
            self.reports = []

        def report(self, kind, message):
            self.reports.append((kind, message))

    return Driver()


@pytest.fixture
def modal(addon, monkeypatch):
    monkeypatch.setattr(operators, "modal_possible", lambda context: True)
    monkeypatch.setattr(operators, "TICK_BUDGET", 0.0)  # one job tick per timer event
    return make_context()


def test_the_event_stand_in_is_blenders_event():
    assert {"type", "value", "mouse_x", "shift"} <= EVENT_PROPERTIES and "timer" not in EVENT_PROPERTIES
    with pytest.raises(AttributeError):
        event("TIMER").timer


def timer_events(op, context, limit=500):
    """Feed timer events until the operator leaves modal; return (result, statuses seen). While it
    runs it passes every event on (other modal operators' timers included)."""
    statuses = []
    for _ in range(limit):
        result = op.modal(context, event("TIMER"))
        statuses.append(context.window_manager.kd_preview_state.status)
        if result != {"PASS_THROUGH"}:
            return result, statuses
    raise AssertionError("the modal operator never finished")


def test_modal_render_ticks_to_the_end(modal, monkeypatch):
    half_plane_scene()
    redraws = []  # the run state at each panel redraw: the last must show the run finished
    monkeypatch.setattr(operators, "redraw_panels",
                        lambda context: redraws.append(context.window_manager.kd_preview_state.running))
    op = driver(KDPREVIEW_OT_render)
    assert op.invoke(modal, None) == {"RUNNING_MODAL"}
    assert modal.window_manager.modal_handlers == [op] and op._timer is not None
    state = modal.window_manager.kd_preview_state
    assert state.running and pipeline.job_running()
    assert op.modal(modal, event("MOUSEMOVE")) == {"PASS_THROUGH"}
    result, statuses = timer_events(op, modal)
    assert result == {"FINISHED"} and op._timer is None and not state.running and not pipeline.job_running()
    assert redraws[0] is True and redraws[-1] is False  # else the panel stays stale after success
    assert any(s.startswith("Tracing: ") for s in statuses)
    assert preview_pixels()[:, :32, 3].min() == 1.0
    assert json.loads(state.last_run)["samples"] == 8
    assert op.reports[-1][0] == {"INFO"}
    assert re.fullmatch(r"KD Preview: 64x32, .* ms \(.*\), \d+\.\d s with Blender's redraws", op.reports[-1][1])
    assert state.status == op.reports[-1][1]


def test_an_operator_called_after_it_finished_leaves_the_next_run_alone(modal):
    """With Render In: New Window (Blender 5.2) a finish that opens the render window inside modal()
    makes Blender keep calling the finished operator; its next timer event must not publish its frame
    again, print its report again or mark the next, running render as not running."""
    scene = half_plane_scene()
    first = driver(KDPREVIEW_OT_render)
    first.invoke(modal, None)
    assert timer_events(first, modal)[0] == {"FINISHED"}
    reports, frame = list(first.reports), preview_pixels().copy()
    scene.kd_preview.ao_distance = 3.0
    second = driver(KDPREVIEW_OT_render)
    second.invoke(modal, None)
    second.modal(modal, event("TIMER"))
    state = modal.window_manager.kd_preview_state
    for kind in ("TIMER", "MOUSEMOVE", "ESC", "TIMER"):
        assert first.modal(modal, event(kind)) == {"FINISHED", "PASS_THROUGH"}  # removed, event passed on
    first.cancel(modal)
    assert state.running and pipeline.job_running() and first.reports == reports
    assert timer_events(second, modal)[0] == {"FINISHED"}
    assert np.abs(preview_pixels() - frame).max() > 0.0  # the second render's frame (longer AO rays)


def test_esc_cancels_and_keeps_the_previous_image(modal):
    scene = half_plane_scene()
    bpy.ops.kdpreview.render()
    before = preview_pixels().copy()
    scene.kd_preview.ao_distance = 3.0
    op = driver(KDPREVIEW_OT_render)
    op.invoke(modal, None)
    for _ in range(4):  # first event only shows the status, then build, then two trace steps
        assert op.modal(modal, event("TIMER")) == {"PASS_THROUGH"}
    assert op.modal(modal, event("ESC")) == {"CANCELLED"}
    state = modal.window_manager.kd_preview_state
    assert state.status.startswith("Cancelled") and not state.running and not pipeline.job_running()
    assert op._timer is None
    assert (preview_pixels() == before).all()


def test_esc_during_animation_restores_the_frame(modal, tmp_path):
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end, scene.frame_current = 1, 3, 7
    scene.kd_preview.output_dir = str(tmp_path)
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(modal, None)
    while not (tmp_path / "frame_0001.png").exists():
        assert op.modal(modal, event("TIMER")) == {"PASS_THROUGH"}
    assert op.modal(modal, event("ESC")) == {"CANCELLED"}
    assert scene.frame_current == 7
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frame_0001.png", "report.json"]
    report = json.loads((tmp_path / "report.json").read_text())  # the frames written, marked incomplete
    assert (report["complete"], report["frames_requested"], len(report["frames"])) == (False, 3, 1)


def test_esc_during_animation_keeps_the_previous_preview(modal, tmp_path):
    """The frames written pass through the preview image; Esc puts back the one shown before the run
    (not the last frame written, under the figures of the run before)."""
    scene = half_plane_scene()
    bpy.ops.kdpreview.render()
    before, last_run = preview_pixels().copy(), modal.window_manager.kd_preview_state.last_run
    scene.frame_start, scene.frame_end = 1, 3
    scene.kd_preview.ao_distance = 3.0
    scene.kd_preview.output_dir = str(tmp_path)
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(modal, None)
    while not (tmp_path / "frame_0001.png").exists():
        assert op.modal(modal, event("TIMER")) == {"PASS_THROUGH"}
    assert not np.array_equal(preview_pixels(), before)  # frame 1, on its way to disk
    assert op.modal(modal, event("ESC")) == {"CANCELLED"}
    assert np.array_equal(preview_pixels(), before)
    assert modal.window_manager.kd_preview_state.last_run == last_run


def test_esc_during_an_animation_frames_kernel_call_restores_the_frame_without_evaluating_the_scene(modal, tmp_path):
    """Esc while a frame's build still runs puts the start frame back without frame_set, which would
    evaluate the scene beside the worker's call (the crash of background.SCENE_READ_WAIT;
    docs/choices.md#the-scene-is-read-only-between-kernel-calls). Only the frame is set then; the
    scene is evaluated at it once read, as frame_set would have."""
    scene = half_plane_scene()
    box = bpy.data.objects["Box"]
    for frame, x in ((1, -2.0), (7, -1.0)):
        box.location.x = x
        box.keyframe_insert("location", index=0, frame=frame)
    scene.frame_start, scene.frame_end = 1, 2
    scene.frame_set(7)
    scene.kd_preview.output_dir = str(tmp_path)
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(modal, None)
    while op._job.job is None or op._job.job._pending is None:  # frame 1 set, its build on the worker
        assert op.modal(modal, event("TIMER")) == {"PASS_THROUGH"}
    assert box.location.x == -2.0
    release = threading.Event()
    busy = background.BackgroundCall(threading.Lock(), release.wait)  # the frame's call, still running
    try:
        assert op.modal(modal, event("ESC")) == {"CANCELLED"}
        assert scene.frame_current == 7 and box.location.x == -2.0  # set, not evaluated
    finally:
        release.set()
    assert busy.wait(5.0) and background.wait_for_work(60.0)  # frame 1's abandoned build too
    bpy.context.evaluated_depsgraph_get()
    assert box.location.x == -1.0  # evaluated at frame 7 once read
    assert op.reports[-1][0] == {"WARNING"} and not pipeline.job_running()


def test_a_cancelled_animation_that_wrote_nothing_leaves_no_folder_it_made(modal, tmp_path):
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 1, 2
    scene.kd_preview.output_dir = str(tmp_path / "new" / "frames")
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(modal, None)
    for _ in range(2):  # the status shown, then the first tick: the folder, then frame 1's scene read
        assert op.modal(modal, event("TIMER")) == {"PASS_THROUGH"}
    assert (tmp_path / "new" / "frames").is_dir() and op._job.results == []  # made before frame 1 renders
    assert op.modal(modal, event("ESC")) == {"CANCELLED"}
    assert list(tmp_path.iterdir()) == []


def test_an_animation_refused_as_already_running_makes_no_folder(modal, tmp_path):
    scene = half_plane_scene()
    scene.kd_preview.output_dir = str(tmp_path / "new")
    pipeline.claim(object())  # another run holds the claim
    try:
        op = driver(KDPREVIEW_OT_render_animation)
        assert op.invoke(modal, None) == {"CANCELLED"} and "already running" in op.reports[0][1]
    finally:
        pipeline.release_any()
    assert list(tmp_path.iterdir()) == []


def test_a_view_layer_removed_during_an_animation_ends_it_with_a_message(modal, tmp_path):
    """Review: a ViewLayer kept across ticks and deleted meanwhile crashed Blender (segfault)."""
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 1, 2
    scene.kd_preview.output_dir = str(tmp_path)
    scene.view_layers.new("Spare")
    context = make_context()
    context.view_layer = scene.view_layers["Spare"]
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(context, None)
    scene.view_layers.remove(scene.view_layers["Spare"])
    assert timer_events(op, context)[0] == {"CANCELLED"}
    assert "view layer 'Spare' of scene 'Scene' was removed during the render" in op.reports[-1][1]
    assert scene.frame_current == 1 and not pipeline.job_running()


def test_a_view_layer_renamed_during_an_animation_is_still_rendered(modal, tmp_path):
    """It ended the animation as "removed or renamed" (the layer was looked up by name at each frame)."""
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 1, 2
    scene.kd_preview.output_dir = str(tmp_path)
    scene.kd_preview.rebuild_all = True  # a static scene: with reuse, frame 2 would take frame 1's image
    extra = scenes.new_collection("Extra")
    scenes.add_cube("ExtraBox", scale=0.5, location=(-3.0, 0.0, 0.5), collection=extra)
    spare = scene.view_layers.new("Spare")  # renders Extra; the first layer excludes it
    scene.view_layers[0].layer_collection.children["Extra"].exclude = True
    context = make_context()
    context.view_layer = spare
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(context, None)
    for _ in range(3):  # frame 1 read through "Spare"
        assert op.modal(context, event("TIMER")) == {"PASS_THROUGH"}
    spare.name = "Renamed"
    assert timer_events(op, context)[0] == {"FINISHED"}
    report = json.loads((tmp_path / "report.json").read_text())
    assert [f["triangles"] for f in report["frames"]] == [26, 26]  # Spare's (with ExtraBox), not the first layer's


def test_a_scene_removed_during_an_animation_ends_it_with_a_message(modal, tmp_path):
    """The next frame's frame_set raised ReferenceError out of the modal handler (a traceback), and the
    cleanup that restores the start frame raised it again. An undo, which reloads every ID, does the same."""
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 1, 2
    scene.kd_preview.output_dir = str(tmp_path)
    scene.kd_preview.rebuild_all = True  # a static scene: with reuse, frame 2 would take frame 1's image
    spare = bpy.data.scenes.new("Spare")  # Blender keeps at least one scene
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(modal, None)
    while not (tmp_path / "frame_0001.png").exists():
        assert op.modal(modal, event("TIMER")) == {"PASS_THROUGH"}
    bpy.data.scenes.remove(scene)
    assert timer_events(op, modal)[0] == {"CANCELLED"}
    assert op.reports[-1] == ({"ERROR"}, operators.REMOVED_DURING_RUN) and not pipeline.job_running()
    report = json.loads((tmp_path / "report.json").read_text())  # frame 1's, marked incomplete
    assert (report["scene"], report["complete"], len(report["frames"])) == ("Scene", False, 1)
    assert spare.name == "Spare"


def test_modal_animation_runs_every_frame(modal, tmp_path):
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 1, 2
    scene.kd_preview.output_dir = str(tmp_path)
    scene.kd_preview.rebuild_all = True  # the scene is static: with reuse, frame 2 would take frame 1's image
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(modal, None)
    result, statuses = timer_events(op, modal)
    assert result == {"FINISHED"}
    assert any(s.startswith("Frame 2 (2/2): Tracing") for s in statuses)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frame_0001.png", "frame_0002.png", "report.json"]


def test_live_update_leaves_the_restored_start_frame_of_an_animation_unrendered(modal, tmp_path, monkeypatch):
    """After Render Animation with Live Update on, setting the start frame again must not make the frame
    handler render it synchronously (598 ms of frozen UI in Blender 5.2.2), as the preview already shows
    it: the job is released only after the frame is set. The preview stays as it was."""
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end, scene.frame_current = 1, 2, 5
    scene.kd_preview.output_dir = str(tmp_path)
    scene.kd_preview.live_update = True
    bpy.ops.kdpreview.render()
    before = preview_pixels().copy()
    handler_renders = []
    monkeypatch.setattr(live_update, "render_frame", lambda *args: handler_renders.append(args))
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(modal, None)
    assert timer_events(op, modal)[0] == {"FINISHED"} and scene.frame_current == 5
    assert handler_renders == [] and not pipeline.job_running()
    assert np.array_equal(preview_pixels(), before)
    scene.frame_set(4)  # with no run, the handler renders a frame change as before
    assert len(handler_renders) == 1


def test_a_modal_animation_renders_the_scene_it_was_invoked_for(modal, tmp_path):
    """Render Animation invoked for another scene than the window's (a script's temp_override) reads
    that scene's depsgraph at every tick, not the window scene's, whose objects would otherwise show
    under the other scene's name and camera."""
    half_plane_scene()  # the window's scene: a ground quad and a box, 14 triangles
    other = bpy.data.scenes.new("Other")
    other.camera = bpy.context.scene.camera
    other.render.resolution_x, other.render.resolution_y = 16, 8
    scenes.link(bpy.data.objects.new("OtherQuad", bpy.data.objects["Ground"].data.copy()), other.collection)
    other.frame_start, other.frame_end = 1, 2
    other.kd_preview.output_dir = str(tmp_path)
    context = SimpleNamespace(window_manager=modal.window_manager, window=modal.window, scene=other,
                              view_layer=other.view_layers[0])
    op = driver(KDPREVIEW_OT_render_animation)
    op.invoke(context, None)
    assert timer_events(op, context)[0] == {"FINISHED"}
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["scene"] == "Other" and [f["triangles"] for f in report["frames"]] == [2, 2]


def test_modal_failure_is_reported_and_released(modal):
    scene = half_plane_scene()
    scene.kd_preview.mode = "shadow"
    bpy.data.objects.remove(bpy.data.objects["Sun"])
    op = driver(KDPREVIEW_OT_render)
    op.invoke(modal, None)
    result, _ = timer_events(op, modal)
    assert result == {"CANCELLED"} and op._timer is None and not pipeline.job_running()
    assert op.reports == [({"ERROR"}, op.reports[0][1])] and "needs a light" in op.reports[0][1]


@pytest.mark.parametrize("bug", [RuntimeError, ReferenceError])
def test_a_bug_inside_a_modal_tick_ends_the_run_and_the_next_render_works(modal, monkeypatch, bug):
    """An unexpected exception in a tick is shown (raised to Blender) but must not leave the add-on
    claimed: before, an error at the top of modal() left 'running' set, the progress frozen and
    every later render refused as 'already running' until Blender restarted. A ReferenceError while
    the scene still exists is such a bug too, not a removed scene."""
    half_plane_scene()
    op = driver(KDPREVIEW_OT_render)
    op.invoke(modal, None)
    op.modal(modal, event("TIMER"))  # shows the status

    def broken_tick():
        raise bug("a bug")
    monkeypatch.setattr(op._job, "tick", broken_tick)
    with pytest.raises(bug, match="a bug"):
        op.modal(modal, event("TIMER"))
    state = modal.window_manager.kd_preview_state
    assert op._timer is None and not state.running and not pipeline.job_running()
    assert state.status == "Error: a bug"
    assert bpy.ops.kdpreview.render() == {"FINISHED"}


def test_disabling_the_addon_mid_render_ends_the_run(modal):
    """Blender drops an unregistered operator's modal handler without calling cancel(), which would
    leave the job claimed, and after re-enabling every render would say "already running" until a
    restart (Blender 5.2.2). Disabling ends the run as Esc would."""
    half_plane_scene()
    op = driver(KDPREVIEW_OT_render)
    op.invoke(modal, None)
    for _ in range(3):  # the status, then the build, then a trace step
        assert op.modal(modal, event("TIMER")) == {"PASS_THROUGH"}
    assert pipeline.job_running() and modal.window_manager.kd_preview_state.running
    kd_addon.unregister()
    kd_addon.register()
    assert not pipeline.job_running() and not bpy.context.window_manager.kd_preview_state.running
    assert op._timer is None
    assert bpy.ops.kdpreview.render() == {"FINISHED"}


def started_modal(operator_cls, monkeypatch, *, live=False, ticks=2):
    """An operator run going modal, `ticks` timer events in (2: the status shown, then the scene read
    and the build started), while the rest of the test runs as background mode does (bpy.ops
    synchronous). `live`: as Live Update starts it."""
    monkeypatch.setattr(operators, "TICK_BUDGET", 0.0)  # one job tick per timer event
    context = make_context()
    op = driver(operator_cls)
    op.live = live
    with monkeypatch.context() as patched:
        patched.setattr(operators, "modal_possible", lambda context: True)
        assert op.invoke(context, None) == {"RUNNING_MODAL"}
    for _ in range(ticks):
        assert op.modal(context, event("TIMER")) == {"PASS_THROUGH"}
    return op, context


def column_at(x: float) -> int:
    """The half-plane scene's pixel column at world x (its view spans x in [-4, 4] over 64 columns)."""
    return int((x + 4.0) / 8.0 * 64)


def test_a_newer_edit_replaces_a_stale_live_render(addon, monkeypatch):
    """Live Update: an edit that changes the image of the live render running ends it (nothing written,
    no warning) and renders the edited scene at once. Before, the stale frame ran to its end and the
    edit rendered after it."""
    scene = half_plane_scene()
    scene.kd_preview.live_update = True
    bpy.ops.kdpreview.render()
    before = preview_pixels().copy()
    scene.kd_preview.ao_distance = 3.0
    stale, context = started_modal(KDPREVIEW_OT_render, monkeypatch, live=True)
    assert stale.frame_key() is not None and pipeline.job_running()
    bpy.data.objects["Box"].location.x = -1.0  # the edit, made while the live render traces
    assert live_update.render_edits() is None
    assert stale._ended and stale._timer is None and stale.reports == []
    assert stale.modal(context, event("TIMER")) == {"FINISHED", "PASS_THROUGH"}  # Blender then drops it
    assert not pipeline.job_running() and not context.window_manager.kd_preview_state.running
    image = preview_pixels()  # the edited scene, rendered by the timer (synchronously in background mode)
    assert image[16, column_at(-1.0), 0] == pytest.approx(1.0, abs=1e-3)  # the moved box's open top
    assert image[16, column_at(-2.0), 0] < 0.9 and before[16, column_at(-2.0), 0] == 1.0  # where it stood
    state = context.window_manager.kd_preview_state
    assert state.status.startswith("KD Preview: 64x32") and "last image reused" not in state.status
    bpy.ops.kdpreview.render()  # the image is the scene's as it is now, AO Distance 3 included:
    assert "last image reused" in state.status


def test_the_edit_timer_reads_the_scene_only_between_kernel_calls(addon, monkeypatch):
    """The bpy module crashed (SIGSEGV in evaluated_depsgraph_get, ~1 run in 10, CI once) when the timer
    evaluated the scene while the worker ran a kernel call's Python code. A call still running after
    SCENE_READ_WAIT makes the timer try again later, without touching the depsgraph."""
    scene = half_plane_scene()
    scene.kd_preview.live_update = True
    release = threading.Event()
    busy = background.BackgroundCall(threading.Lock(), release.wait)  # a kernel call that has not ended
    monkeypatch.setattr(background, "SCENE_READ_WAIT", 0.01)
    try:
        assert live_update.render_edits() == live_update.EDIT_DELAY and "KD Preview" not in bpy.data.images
    finally:
        release.set()
    assert busy.wait(5.0)
    assert live_update.render_edits() is None and "KD Preview" in bpy.data.images  # then it renders


@pytest.mark.parametrize("operator_cls", [KDPREVIEW_OT_render, KDPREVIEW_OT_render_animation])
def test_a_run_started_beside_a_cancelled_runs_kernel_call_reads_the_scene_after_it(modal, monkeypatch, tmp_path,
                                                                                    operator_cls):
    """A Render clicked while a cancelled run's build still runs must not evaluate the depsgraph at
    invoke (nor Render Animation set its first frame at its first tick) beside the worker's call: the
    crash of SCENE_READ_WAIT (docs/choices.md#the-scene-is-read-only-between-kernel-calls). The run
    waits, saying so, and reads the scene once the call has ended."""
    scene = half_plane_scene()
    scene.frame_start, scene.frame_end = 2, 2
    scene.kd_preview.output_dir = str(tmp_path)
    assert scene.frame_current == 1
    reads = []  # at each depsgraph evaluation: was a kernel call still running?
    evaluated_depsgraph = operators.evaluated_depsgraph
    monkeypatch.setattr(operators, "evaluated_depsgraph", lambda *args: reads.append(
        background.abandoned_work_running()) or evaluated_depsgraph(*args))
    context = make_context()
    context.evaluated_depsgraph_get = lambda: reads.append(
        background.abandoned_work_running()) or bpy.context.evaluated_depsgraph_get()
    release = threading.Event()
    busy = background.BackgroundCall(threading.Lock(), release.wait)  # the cancelled run's call
    try:
        op = driver(operator_cls)
        assert op.invoke(context, None) == {"RUNNING_MODAL"}
        for _ in range(4):
            assert op.modal(context, event("TIMER")) == {"PASS_THROUGH"}
        assert reads == [] and scene.frame_current == 1 and pipeline.job_running()
        assert pipeline.WAITING_STATUS in context.window_manager.kd_preview_state.status
    finally:
        release.set()
    assert busy.wait(5.0)
    assert timer_events(op, context)[0] == {"FINISHED"}
    assert reads and not any(reads) and op.reports[-1][0] == {"INFO"}


def test_an_edit_leaves_a_live_render_of_the_same_image_and_a_users_render_running(addon, monkeypatch):
    scene = half_plane_scene()
    scene.kd_preview.live_update = True
    live, context = started_modal(KDPREVIEW_OT_render, monkeypatch, live=True, ticks=1)
    bpy.data.objects["Box"].location.x = -1.0
    bpy.context.view_layer.update()  # as Blender's event loop does before the next event
    assert live_update.render_edits() is None and not live._ended  # not read yet: it reads the edit
    live.modal(context, event("TIMER"))
    assert live.frame_key() is not None
    bpy.data.objects["Box"].select_set(True)  # an update that changes no pixel
    bpy.context.view_layer.update()
    assert live_update.render_edits() is None and not live._ended and pipeline.job_running()
    assert timer_events(live, context)[0] == {"FINISHED"} and live.reports[-1][0] == {"INFO"}
    assert preview_pixels()[16, column_at(-1.0), 0] == pytest.approx(1.0, abs=1e-3)  # it read the moved box
    assert preview_pixels()[16, column_at(-2.0), 0] < 0.9
    bpy.data.images.remove(bpy.data.images["KD Preview"])
    scene.kd_preview.ao_distance = 2.0  # else Render would reuse the last image at once
    users, context = started_modal(KDPREVIEW_OT_render, monkeypatch)  # Render, clicked
    bpy.data.objects["Box"].location.x = -2.0
    bpy.context.view_layer.update()
    assert live_update.render_edits() == live_update.EDIT_DELAY and not users._ended  # waits for it
    assert timer_events(users, context)[0] == {"FINISHED"} and "KD Preview" in bpy.data.images


def test_a_frame_change_during_a_render_renders_after_it_or_instead_of_a_live_one(addon, monkeypatch):
    """Moving to frame 2 while a live render of frame 1 runs must not leave the preview on frame 1 for
    good: the frame handler stays out while a job runs, and a frame change alone makes no depsgraph
    update list (Blender 5.2.2), so the handler leaves the frame to the edit timer."""
    scene = half_plane_scene()
    box = bpy.data.objects["Box"]
    for frame, x in ((1, -2.0), (2, -1.0), (3, -3.0)):
        box.location.x = x
        box.keyframe_insert("location", index=0, frame=frame)
    scene.frame_set(1)
    scene.kd_preview.live_update = True
    timers, state = bpy.app.timers, bpy.context.window_manager.kd_preview_state
    stale, _ = started_modal(KDPREVIEW_OT_render, monkeypatch, live=True)
    scene.frame_set(2)
    assert timers.is_registered(live_update.render_edits) and not stale._ended
    timers.unregister(live_update.render_edits)
    assert live_update.render_edits() is None and stale._ended  # frame 1's render is stale: replaced
    assert json.loads(state.last_run)["frame"] == 2
    image = preview_pixels()
    assert image[16, column_at(-1.0), 0] == pytest.approx(1.0, abs=1e-3) and image[16, column_at(-2.0), 0] < 0.9
    scene.kd_preview.ao_distance = 2.0  # else Render would reuse frame 2's image at once
    users, context = started_modal(KDPREVIEW_OT_render, monkeypatch)  # Render, clicked
    scene.frame_set(3)
    assert timers.is_registered(live_update.render_edits)
    timers.unregister(live_update.render_edits)
    assert live_update.render_edits() == live_update.EDIT_DELAY and not users._ended  # waits for it
    assert timer_events(users, context)[0] == {"FINISHED"} and json.loads(state.last_run)["frame"] == 2
    assert live_update.render_edits() is None and json.loads(state.last_run)["frame"] == 3
