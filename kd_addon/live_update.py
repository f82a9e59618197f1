"""Optional re-render on frame change (scene.kd_preview.live_update, off by default).

The handler is persistent (it survives loading another file) and registered
at most once (app_handlers.py).
It renders synchronously, which makes playback wait for each frame; that is
the point of the option. It stays out while an operator renders (that
operator's own frame_set calls would otherwise re-render every frame twice)
and while Blender renders (the handler then runs on the render thread, where
touching bpy.data images is unsafe).
"""

from __future__ import annotations

import bpy

from . import app_handlers, output
from .config import make_config
from .errors import PreviewError
from .pipeline import claim, job_running, release, render_frame
from .properties import run_state, set_last_run


@bpy.app.handlers.persistent
def kd_preview_frame_change(scene, depsgraph=None):
    """frame_change_post: re-render the preview of the new frame when live update is on."""
    settings = getattr(scene, "kd_preview", None)
    if settings is None or not settings.live_update or job_running() or bpy.app.is_job_running("RENDER"):
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


def register():
    app_handlers.install("frame_change_post", kd_preview_frame_change)


def unregister():
    app_handlers.remove("frame_change_post", kd_preview_frame_change)
