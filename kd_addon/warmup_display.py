"""Showing the kernels' background compile (kernel_warmup.py) in Blender's status bar and the sidebar:
"compiling kernels (first use) 12s" until it is done, then nothing (or why it failed).

A label appended to the status bar's header (STATUSBAR_HT_header, in every Blender from 4.2 on) rather
than workspace.status_text_set, which replaces the whole bar and needs a workspace context a timer does
not have. A timer redraws the bar and the 3D viewports once a second while the compile runs; timers do
not fire in background mode, where nothing is drawn anyway.
"""

from __future__ import annotations

import bpy

from . import kernel_warmup

REDRAW_SECONDS = 1.0
REDRAWN_AREAS = {"STATUSBAR", "VIEW_3D"}


def draw_status(layout) -> None:
    """The warm-up's line in `layout` (nothing once the kernels are ready or when no compile ran)."""
    status = kernel_warmup.status()
    if status.text:
        layout.label(text=status.text, icon="ERROR" if status.state == kernel_warmup.FAILED else "TIME")


def _draw_status_bar(self, _context) -> None:
    draw_status(self.layout)


def _redraw() -> float | None:
    """Timer: redraw where the elapsed seconds show; stop once the compile has ended."""
    try:
        windows = bpy.context.window_manager.windows
    except AttributeError:  # no window manager (being freed at quit)
        return None
    for window in windows:
        for area in window.screen.areas if window.screen else ():
            if area.type in REDRAWN_AREAS:
                area.tag_redraw()
    return REDRAW_SECONDS if kernel_warmup.status().state == kernel_warmup.COMPILING else None


def register():
    bpy.types.STATUSBAR_HT_header.append(_draw_status_bar)
    if kernel_warmup.status().state == kernel_warmup.COMPILING and not bpy.app.timers.is_registered(_redraw):
        bpy.app.timers.register(_redraw, first_interval=REDRAW_SECONDS)


def unregister():
    bpy.types.STATUSBAR_HT_header.remove(_draw_status_bar)
    if bpy.app.timers.is_registered(_redraw):
        bpy.app.timers.unregister(_redraw)
