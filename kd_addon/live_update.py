"""Optional re-render on frame change (scene.kd_preview.live_update, off by default).

The handler is persistent (it survives loading another file) and registered
at most once: register/unregister match it by module and name, so even a
copy left behind by a reloaded module is removed rather than stacked.
It renders synchronously, which makes playback wait for each frame; that is
the point of the option. It stays out while an operator renders (that
operator's own frame_set calls would otherwise re-render every frame twice)
and while Blender renders (the handler then runs on the render thread, where
touching bpy.data images is unsafe).
"""

from __future__ import annotations

import bpy

from . import output
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
    output.store_preview(result.image)
    set_last_run(state, result.summary())
    state.status = f"Live: frame {result.frame}, {result.total_ms:.0f} ms"


def _ours(handler) -> bool:
    return getattr(handler, "__name__", "") == kd_preview_frame_change.__name__ and \
        getattr(handler, "__module__", "") == __name__


def remove_handlers() -> None:
    handlers = bpy.app.handlers.frame_change_post
    for handler in [h for h in handlers if _ours(h)]:
        handlers.remove(handler)


def register():
    remove_handlers()
    bpy.app.handlers.frame_change_post.append(kd_preview_frame_change)


def unregister():
    remove_handlers()
