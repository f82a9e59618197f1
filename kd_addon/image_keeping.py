"""Keeping the preview image's pixels where Blender would lose them.

A generated image's pixels live only in memory. Blender's undo and redo restore
the image datablock and regenerate its pixels (black), and undoing past the
first render removes the image; a saved .blend keeps the datablock without its
pixels (black on reopen). So:
- after undo and redo, the last frame stored in this session is written back:
  like Render Result, the preview shows the last render whatever the undo step;
- before a save, the image is packed into the .blend (OpenEXR, float, lossless)
  if it changed since it was last packed and the file will keep it (it has
  users: an image editor shows it, or showed it since the file was opened,
  whose user Blender keeps until then; without the pixels the file would keep a
  black image): what Blender's own "save modified images" does on quit;
- loading a file forgets the last frame: the new file's preview is its own.
"""

from __future__ import annotations

import bpy

from . import app_handlers, output


@bpy.app.handlers.persistent
def kd_preview_undo_redo(*_args):
    """undo_post, redo_post: the last frame back into the (regenerated or removed) preview image."""
    output.restore_last_frame()


@bpy.app.handlers.persistent
def kd_preview_save_pre(*_args):
    """save_pre: pack the preview into the file when it changed and the file keeps it."""
    image = output.tagged_image()
    if image is not None and image.users > 0 and image.is_dirty:
        image.pack()


@bpy.app.handlers.persistent
def kd_preview_load_post(*_args):
    output.forget_last_frame()


HANDLERS = (("undo_post", kd_preview_undo_redo), ("redo_post", kd_preview_undo_redo),
            ("save_pre", kd_preview_save_pre), ("load_post", kd_preview_load_post))


def register():
    app_handlers.install(HANDLERS)


def unregister():
    app_handlers.remove(HANDLERS)
    output.forget_last_frame()
