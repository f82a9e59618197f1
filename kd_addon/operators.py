"""Render and Render Animation operators.

Both drive a job with `tick()`. From the UI they run modal (a timer ticks the job, so Blender stays
responsive and Esc cancels between ticks); in background mode timers never fire, so the job runs to
the end inside `execute`. Cancel and failure leave the preview image, the disk and the frame as they were.
"""

from __future__ import annotations

import time
from pathlib import Path

import bpy

from . import output
from .config import make_config
from .errors import Cancelled, PreviewError, Superseded
from .pipeline import FrameJob, claim, release, release_any, run_job
from .properties import run_state, set_last_run
from .sequence import SequenceJob
from .signals_held import signals_held

# What a run reports when Blender freed the scene it renders (scene_removed).
REMOVED_DURING_RUN = "the scene was removed or reloaded during the render (deleted, an undo): render again"
TICK_SECONDS = 0.01  # timer interval
TICK_BUDGET = 0.05  # seconds of work per timer event before handing control back to Blender
_running = None  # the operator running modal, so that disabling the add-on can end it (unregister)


def modal_possible(context) -> bool:
    """Timers only fire with a UI; in background mode (and the bpy module) they never do."""
    return not bpy.app.background and context.window is not None


def redraw_panels(context) -> None:
    for window in context.window_manager.windows:
        for area in window.screen.areas if window.screen else ():
            if area.type in {"VIEW_3D", "IMAGE_EDITOR"}:
                area.tag_redraw()


class _JobOperator:
    """Runs the job `make_job` returns, modal from the UI and synchronous otherwise."""

    def make_job(self, context):
        raise NotImplementedError

    def finish(self, context, job) -> str:
        """Publish a finished job; return the message to report."""
        raise NotImplementedError

    def cleanup(self, job, error) -> None:
        """Called after success (error None), cancel and failure alike."""

    def cancelled_status(self, job) -> str:
        return "Cancelled: the previous preview is unchanged"

    # -- synchronous ----------------------------------------------------------

    def execute(self, context):
        job = self._start(context)
        if job is None:
            return {"CANCELLED"}
        error = None
        try:
            run_job(job, progress=lambda fraction, status: self._show(context, fraction, status))
        except PreviewError as failure:
            error = failure
        except KeyboardInterrupt:
            error = Cancelled("cancelled")
        except Exception as bug:
            if not scene_removed(job):
                self._end(context, job, bug)
                raise
            error = PreviewError(REMOVED_DURING_RUN)
        return self._end(context, job, error)

    # -- modal ----------------------------------------------------------------

    def invoke(self, context, event):
        if not modal_possible(context):
            return self.execute(context)
        job = self._start(context)
        if job is None:
            return {"CANCELLED"}
        self._job, self._started, self._ended = job, False, False
        self._invoked_at = time.perf_counter()
        wm = context.window_manager
        self._timer = wm.event_timer_add(TICK_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        global _running
        _running = self
        wm.progress_begin(0, 100)
        self._show(context, 0.0, job.status)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        """Tick the job on timer events. Blender's Event does not say which timer fired, so any
        window timer ticks it (a tick is budgeted, so a foreign timer costs at most TICK_BUDGET), and
        every event is passed on, so other modal operators get their own timers and input."""
        if self._ended:
            # Blender kept calling an operator that already finished: it does when the finish opened a
            # window (render.view_show, Render In: New Window; seen in Blender 5.2). Its job is published;
            # finishing it again would publish an old frame over a newer one and clear a new run's state.
            return {"FINISHED", "PASS_THROUGH"}
        if event.type == "ESC":
            return self._end_modal(context, Cancelled("cancelled"))
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if not self._started:  # let the status ("Compiling kernels…") draw before blocking work
            self._started = True
            return {"PASS_THROUGH"}
        try:
            finished = self._tick_for(TICK_BUDGET)
        except PreviewError as error:
            return self._end_modal(context, error)
        except Exception as error:
            if scene_removed(self._job):
                return self._end_modal(context, PreviewError(REMOVED_DURING_RUN))
            self._end_modal(context, error)  # keep Blender usable: stop the timer, release the job, show the bug
            raise
        if finished:
            return self._end_modal(context, None)
        self._show(context, self._job.progress, self._job.status)
        return {"PASS_THROUGH"}

    def cancel(self, context):
        """Blender calls this when the modal operator is killed (e.g. the file is closed)."""
        if not self._ended:
            self._end_modal(context, Cancelled("cancelled"))

    def frame_key(self):
        """The image key of the frame this run renders (pipeline.FrameJob.image_key); None before it
        read the scene."""
        return getattr(self._job, "image_key", None)

    def supersede(self, context) -> None:
        """End this run for a newer one, as Esc would (nothing written) but without the warning: a
        newer edit made its frame stale (Live Update)."""
        if not self._ended:
            self._end_modal(context, Superseded("superseded"))

    def _tick_for(self, budget: float) -> bool:
        deadline = time.perf_counter() + budget
        while not self._job.tick():
            if time.perf_counter() > deadline:
                return False
        return True

    def _end_modal(self, context, error):
        self._ended = True
        wm = context.window_manager
        if getattr(self, "_timer", None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        return self._end(context, self._job, error)

    # -- shared ---------------------------------------------------------------

    def _start(self, context):
        try:
            job = self.make_job(context)
            claim(job)
        except PreviewError as error:
            self._fail(context, error)
            return None
        state = run_state(context)
        state.running, state.progress = True, 0.0
        return job

    def _end(self, context, job, error):
        global _running
        if _running is self:
            _running = None
        state = run_state(context)
        try:
            try:
                # Still claimed: Render Animation's cleanup sets the start frame again, and Live Update's
                # frame handler, seeing no run, would render that frame synchronously (frozen UI) although
                # the preview already shows it; an edit made meanwhile is left to the edit timer.
                self.cleanup(job, error)
            finally:
                release(job)
                state.running = False
                redraw_panels(context)  # on every outcome (a tag: the panel draws the final status later)
            if error is None:
                message = None
                try:
                    with signals_held():  # a Ctrl-C lands after the frame is stored and the figures set
                        message = self.finish(context, job) + self._wall_time()
                        state.status, state.progress = message, 1.0
                except KeyboardInterrupt as interrupt:  # after a finished run: as execute does, no traceback
                    if interrupt.__context__ is not None:  # raised over finish()'s own error: that one counts
                        raise interrupt.__context__ from None
                    error = Cancelled("cancelled") if message is None else None
                if error is None:
                    self.report({"INFO"}, message)
                    return {"FINISHED"}
        except PreviewError as late_error:
            error = late_error
        if isinstance(error, Superseded):
            state.status = "Live: restarting for the newer edit…"
            return {"CANCELLED"}
        if isinstance(error, Cancelled):
            state.status = self.cancelled_status(job)
            self.report({"WARNING"}, state.status)
            return {"CANCELLED"}
        return self._fail(context, error)

    def _wall_time(self) -> str:
        """A modal run's time from the click, with Blender's redraws between ticks, which the frame's
        own figures leave out; "" when the run was synchronous (then the two agree)."""
        invoked_at = getattr(self, "_invoked_at", None)
        return "" if invoked_at is None else f", {time.perf_counter() - invoked_at:.1f} s with Blender's redraws"

    def _fail(self, context, error):
        run_state(context).status = f"Error: {error}"
        if isinstance(error, PreviewError):
            self.report({"ERROR"}, str(error))
        redraw_panels(context)
        return {"CANCELLED"}

    def _show(self, context, fraction: float, status: str) -> None:
        state = run_state(context)
        state.progress, state.status = fraction, status
        if modal_possible(context):
            context.window_manager.progress_update(int(100 * fraction))
            redraw_panels(context)


class KDPREVIEW_OT_render(_JobOperator, bpy.types.Operator):
    """Ray-trace an ambient-occlusion / shadow preview of the current frame into the "KD Preview" image"""

    bl_idname = "kdpreview.render"
    bl_label = "Render Preview"
    bl_options = {"REGISTER"}

    live: bpy.props.BoolProperty(
        name="Live", default=False, options={"HIDDEN", "SKIP_SAVE"},
        description="Started by Live Update: opens no image editor, and a newer edit replaces it")

    def make_job(self, context):
        scene = context.scene
        return FrameJob(scene, depsgraph_source(scene, context.view_layer), make_config(scene.kd_preview))

    def finish(self, context, job) -> str:
        result = job.result()
        output.store_preview(result.image, open_view=not getattr(self, "live", False))
        summary = result.summary()
        set_last_run(run_state(context), summary)
        speed = "last image reused" if result.image_reused else f"{result.mrays_per_s:.2f} Mrays/s"
        return (f"KD Preview: {result.width}x{result.height}, {result.triangles:,} triangles, "
                f"{result.total_ms:.0f} ms ({speed})")


class KDPREVIEW_OT_render_animation(_JobOperator, bpy.types.Operator):
    """Render the scene's frame range to an image sequence and report.json in the output folder"""

    bl_idname = "kdpreview.render_animation"
    bl_label = "Render Preview Animation"
    bl_options = {"REGISTER"}

    def make_job(self, context):
        scene = context.scene
        settings = scene.kd_preview
        config = make_config(settings)
        frames = list(range(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step)))
        return SequenceJob(scene, config, frames, output_folder(settings.output_dir),
                           depsgraph_source(scene, context.view_layer))

    def cleanup(self, job, error) -> None:
        job.close(error)

    def cancelled_status(self, job) -> str:
        if job.done:  # the cancel came while the last report was written: nothing was put back
            return f"Cancelled after the last frame: all {len(job.results)} frames are written and shown"
        return super().cancelled_status(job)

    def finish(self, context, job) -> str:
        last = job.results[-1].summary()
        last["animation"] = {"frames": len(job.results), "report": str(job.report_path)}
        set_last_run(run_state(context), last)
        return f"KD Preview: {len(job.results)} frames written to {job.out_dir}"


def scene_removed(job) -> bool:
    """Whether Blender freed the scene `job` renders (deleted, or reloaded by an undo): then the run's
    ReferenceError is that, not a bug of the add-on's."""
    try:
        job.scene.name
    except ReferenceError:
        return True
    return False


def depsgraph_source(scene, view_layer):
    """A function returning the evaluated depsgraph of `scene`'s `view_layer` when called (any
    arguments ignored: SequenceJob passes the scene), whatever the context then: a modal run's later
    ticks would get the window's, not the one a script's temp_override invoked it with. Neither
    `context` nor the ViewLayer may be kept beyond invoke (a layer deleted meanwhile crashes Blender):
    the layer is kept as its address and looked up at each call, so a renamed layer is still found."""
    name, address = view_layer.name, view_layer.as_pointer()
    return lambda *_scene: evaluated_depsgraph(scene, name, address)


def evaluated_depsgraph(scene, layer_name: str, layer_address: int):
    """The evaluated depsgraph of the view layer of `scene` at `layer_address` (ViewLayer.as_pointer(),
    compared, never dereferenced); PreviewError naming `layer_name` when the scene no longer has it."""
    view_layer = next((layer for layer in scene.view_layers if layer.as_pointer() == layer_address), None)
    if view_layer is None:
        raise PreviewError(f"view layer '{layer_name}' of scene '{scene.name}' was removed during the render")
    with bpy.context.temp_override(scene=scene, view_layer=view_layer):
        return bpy.context.evaluated_depsgraph_get()


def running_frame_render(*, live: bool = False):
    """The modal run rendering one frame (Render, not Render Animation), while it runs; else None.
    `live`: only one that Live Update started."""
    op = _running
    try:
        if op is None or op._ended or not isinstance(op._job, FrameJob):
            return None
        return op if getattr(op, "live", False) or not live else None
    except ReferenceError:  # Blender freed it (the add-on's unregister clears the rest)
        return None


def output_folder(path: str) -> Path:
    """The output folder as an absolute path; a "//" path needs a saved .blend to be relative to."""
    if path.startswith("//") and not bpy.data.filepath:
        raise PreviewError(f"the output folder '{path}' is relative to the .blend file, which is not saved: "
                           "save the file or choose an absolute folder")
    if not path.strip():
        raise PreviewError("the output folder is empty: choose one in the KD Preview panel")
    return Path(bpy.path.abspath(path))


def end_running_operator() -> None:
    """End a modal run as Esc would. Disabling the add-on unregisters the operator, and Blender then
    drops its modal handler without calling cancel(), which would leave the job claimed and every
    later render "already running" until Blender restarted."""
    global _running
    op, _running = _running, None
    if op is not None:
        try:
            op._end_modal(bpy.context, Cancelled("cancelled"))
        except ReferenceError:  # Blender already freed the operator: its claim and state go below
            pass
    release_any()
    try:  # the run state is stored in the window manager, so it outlives the add-on
        for wm in bpy.data.window_managers:
            wm.kd_preview_state.running = False
    except AttributeError:  # bpy.data is restricted while Blender starts up
        pass


CLASSES = (KDPREVIEW_OT_render, KDPREVIEW_OT_render_animation)

# Registers in order and unregisters in reverse.
register, _unregister_classes = bpy.utils.register_classes_factory(CLASSES)


def unregister():
    end_running_operator()
    _unregister_classes()
