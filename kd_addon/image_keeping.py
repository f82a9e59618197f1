"""Keeping the preview image's pixels where Blender would lose them.

A generated image's pixels live only in memory: undo and redo regenerate them black, and a saved
.blend keeps the datablock without them. So after undo and redo the last frame of this session is
written back (like Render Result); before a save a changed image that the file will keep (it has
users) is packed as lossless float OpenEXR; loading a file forgets the last frame.
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
