"""Adding and removing the add-on's bpy.app.handlers, at most one copy each.

A handler is matched by module and name, not identity, so a copy left behind by
a reloaded module (F3 > Reload Scripts, disable/enable) is removed rather than
stacked beside the new one.
"""

from __future__ import annotations

import bpy


def _same(handler, function) -> bool:
    return getattr(handler, "__name__", "") == function.__name__ and \
        getattr(handler, "__module__", "") == function.__module__


def remove(handlers) -> None:
    """Remove every copy of each (kind, function) pair's function from bpy.app.handlers.<kind>
    (kind e.g. "frame_change_post")."""
    for kind, function in handlers:
        registered = getattr(bpy.app.handlers, kind)
        for handler in [h for h in registered if _same(h, function)]:
            registered.remove(handler)


def install(handlers) -> None:
    """Add each (kind, function) pair's function to bpy.app.handlers.<kind>, replacing earlier copies."""
    remove(handlers)
    for kind, function in handlers:
        getattr(bpy.app.handlers, kind).append(function)
