"""Optional re-render on frame change and on edits (scene.kd_preview.live_update, off by default).

Frame changes: the handler renders synchronously, so playback waits for each frame (the point of the
option). It stays out while an operator renders (Render Animation's own frame_set calls) and while
Blender renders (the handler then runs on the render thread, where touching images is unsafe, and a
farm's or script's render would pay for a preview a frame); a frame the user moves to during a render
is left to the edit timer. A render that blocks (`blender -b`, bpy.ops.render.render from a script) is
no job to bpy.app.is_job_running: its frame changes are told by their depsgraph's mode ("RENDER"), and
the one with which Blender puts the start frame back after a render is skipped too
(render_restores_frame).

Edits: each depsgraph update (re)starts a timer, so a drag renders once, when it pauses for
EDIT_DELAY; the timer runs the Render operator modal, so Esc cancels. A running Live Update render
whose image the edits changed is ended and the edited scene renders at once; a render the user
started is waited for. Unchanged images are reused; the preview's own image writes are ignored.

Handlers are persistent (they survive loading another file) and registered at
most once (app_handlers.py); the timer is not (loading a file drops it).
"""

from __future__ import annotations

import bpy

from . import app_handlers, background, operators, output
from .config import make_config
from .errors import PreviewError
from .pipeline import claim, image_key_now, job_running, release, render_frame
from .properties import run_state, set_last_run

EDIT_DELAY = 0.3  # seconds without edits before live update renders them
# Modal tools that edit as the mouse moves (grab/rotate/scale, gizmo drags, fly/walk navigation, sculpt
# and paint strokes, loop cut): their edit renders when they end, not at every slow mouse move.
INTERACTIVE_TOOLS = {"TRANSFORM", "VIEW3D", "MESH", "SCULPT", "PAINT", "GIZMO", "GIZMOGROUP"}


_frame_to_restore = None  # the frame a render started at, until the first frame change outside renders


@bpy.app.handlers.persistent
def kd_preview_render_started(scene, *_args):
    """render_init: Blender starts a render (a still, an animation; a blocking one too), and after it
    sets the frame it started at back."""
    global _frame_to_restore
    _frame_to_restore = getattr(scene, "frame_current", None)


def render_restores_frame(scene) -> bool:
    """Whether this frame change, the first outside a render since one started, goes back to the frame
    that render started at: Blender restoring it, no move of the user's (taken once either way)."""
    global _frame_to_restore
    restored, _frame_to_restore = _frame_to_restore, None
    return restored is not None and restored == scene.frame_current


def blender_renders(depsgraph=None) -> bool:
    """Whether Blender renders now: a render job (F12 in the interface), or a render that blocks, whose
    frame changes come with the render's depsgraph (a flag kept from render_init to render_complete
    would stay set after a render that fails before its first frame, which fires neither end handler)."""
    return bpy.app.is_job_running("RENDER") or (depsgraph is not None and depsgraph.mode == "RENDER")


@bpy.app.handlers.persistent
def kd_preview_frame_change(scene, depsgraph=None):
    """frame_change_post: re-render the preview of the new frame when live update is on."""
    if blender_renders(depsgraph) or render_restores_frame(scene):
        return
    settings = getattr(scene, "kd_preview", None)
    if settings is None or not settings.live_update:
        return
    if job_running():
        if operators.running_frame_render() is not None:  # the user changed the frame during a Render run:
            schedule_render()  # the new frame renders after it (or instead of it, if Live Update started it)
        return
    # a cancelled run's kernel call: read the scene after it
    if not background.wait_for_work(background.SCENE_READ_WAIT):
        schedule_render()
        return
    state, token = run_state(), object()
    claim(token)
    try:
        result = render_frame(scene, depsgraph or bpy.context.evaluated_depsgraph_get(), make_config(settings))
    except PreviewError as error:
        state.status = f"Error: {error}"
        return
    finally:
        release(token)
    output.store_preview(result.image, open_view=False)  # no windows opening during playback
    set_last_run(state, result.summary())
    state.status = f"Live: frame {result.frame}, {result.total_ms:.0f} ms"


@bpy.app.handlers.persistent
def kd_preview_scene_edit(scene, depsgraph=None):
    """depsgraph_update_post: after an edit, (re)schedule one render of it when live update is on."""
    settings = getattr(scene, "kd_preview", None)
    if settings is None or not settings.live_update or depsgraph is None or len(depsgraph.updates) == 0:
        return
    schedule_render()


def setting_changed(settings) -> None:
    """properties.py's update callback: a setting changed (or Live Update was switched on)."""
    if settings.live_update:
        schedule_render()


def schedule_render() -> None:
    """(Re)start the timer that renders the scene once edits pause for EDIT_DELAY."""
    _stop_timer()
    bpy.app.timers.register(render_edits, first_interval=EDIT_DELAY)


def _stop_timer() -> None:
    if bpy.app.timers.is_registered(render_edits):
        bpy.app.timers.unregister(render_edits)


def render_edits():
    """The timer: render the edited scene with the Render operator, in the first window (a timer has
    no window of its own); return the delay to try again while another render runs, else None."""
    window = next(iter(bpy.context.window_manager.windows), None)
    settings = getattr(window.scene, "kd_preview", None) if window is not None else None
    if settings is None or not settings.live_update:
        return None
    # (a render that blocks runs no timer: only a render job can be running here, so no depsgraph to ask)
    if blender_renders() or interactive_tool_running([op.bl_idname for op in window.modal_operators]):
        return EDIT_DELAY  # Blender renders (and may set frames) or a tool edits: read the scene after
    if not background.wait_for_work(background.SCENE_READ_WAIT):
        return EDIT_DELAY  # a build or trace step is still on the worker (SCENE_READ_WAIT)
    with bpy.context.temp_override(window=window):
        live = operators.running_frame_render(live=True)
        if live is not None:
            if not _made_stale(live, window.scene, settings):
                return None  # the running render's frame is the edited scene's (a selection, say)
            live.supersede(bpy.context)
        elif job_running():
            return EDIT_DELAY
        try:
            bpy.ops.kdpreview.render("INVOKE_DEFAULT", live=True)
        except RuntimeError:  # bpy.ops raises the operator's error report; the panel's status shows it
            pass
    return None


def _made_stale(live, scene, settings) -> bool:
    """Whether the edits since a Live Update render read the scene change its image (its job's image
    key against the scene's now; one more extraction). Not before it read the scene: it reads it as
    edited. A scene that cannot be read now counts as changed: the new render says why."""
    key = live.frame_key()
    if key is None:
        return False
    try:
        return image_key_now(scene, bpy.context.evaluated_depsgraph_get(), make_config(settings)) != key
    except Exception:  # not raised here: Blender would drop the timer and the edit stay unrendered;
        return True  # the new render reads the scene again and reports it (a bug as a traceback)


def interactive_tool_running(idnames) -> bool:
    """Whether any of these modal operators ("TRANSFORM_OT_translate" or "transform.translate") is
    one of INTERACTIVE_TOOLS."""
    def group(idname: str) -> str:
        return idname.split("_OT_")[0] if "_OT_" in idname else idname.split(".")[0].upper()
    return any(group(idname) in INTERACTIVE_TOOLS for idname in idnames)


HANDLERS = (("frame_change_post", kd_preview_frame_change), ("depsgraph_update_post", kd_preview_scene_edit),
            ("render_init", kd_preview_render_started))


def register():
    app_handlers.install(HANDLERS)


def unregister():
    app_handlers.remove(HANDLERS)
    _stop_timer()
