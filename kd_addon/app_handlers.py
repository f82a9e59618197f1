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


def remove(kind: str, function) -> None:
    """Remove every copy of `function` from bpy.app.handlers.<kind> (e.g. "frame_change_post")."""
    handlers = getattr(bpy.app.handlers, kind)
    for handler in [h for h in handlers if _same(h, function)]:
        handlers.remove(handler)


def install(kind: str, function) -> None:
    """Add `function` to bpy.app.handlers.<kind>, replacing any earlier copy."""
    remove(kind, function)
    getattr(bpy.app.handlers, kind).append(function)
