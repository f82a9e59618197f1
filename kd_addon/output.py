"""Getting a finished frame into Blender: the "KD Preview" image, image editors, and files.

Only called with a complete frame, so a cancelled or failed run leaves the previous preview
untouched (a sequence that does not finish puts it back: put_back_preview). The last frame stored
is remembered for image_keeping.py.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import bpy
import numpy as np

IMAGE_NAME = "KD Preview"
IMAGE_TAG = "kd_preview_image"  # custom property marking the image this add-on owns
_last_frame: np.ndarray | None = None  # the last frame stored in this file and session
_ours: int | None = None  # session_uid of the preview image this session last wrote


def preview_image(width: int, height: int) -> bpy.types.Image:
    """The float RGBA preview image, created or resized to width x height.

    Resized in place (not replaced) so image editors already showing it keep showing it. Ours is
    the image carrying IMAGE_TAG (or an untagged float "KD Preview" from an earlier version, adopted);
    a user's own image of that name is never touched: ours then gets Blender's next free name.
    """
    global _ours
    image = _current_preview()
    if image is None or not _writable(image):
        if image is not None and IMAGE_TAG in image:
            del image[IMAGE_TAG]  # saved or unpacked to a file: the user's image now, as its copies are
        image = bpy.data.images.new(IMAGE_NAME, width, height, alpha=True, float_buffer=True)
    elif tuple(image.size) != (width, height):
        image.scale(width, height)
    image[IMAGE_TAG] = True
    _ours = getattr(image, "session_uid", None)
    for other in bpy.data.images:  # copies carry the tag (Image.copy, the editor's duplicate): the user's
        if other != image and IMAGE_TAG in other:
            del other[IMAGE_TAG]
    return image


def tagged_image() -> bpy.types.Image | None:
    """Ours: the tagged image this session wrote last (by session_uid, which a copy does not share); in a
    file just opened, a tagged one, one we can write named IMAGE_NAME first."""
    tagged = [im for im in bpy.data.images if im.get(IMAGE_TAG)]
    mine = [im for im in tagged if _ours is not None and getattr(im, "session_uid", None) == _ours]
    writable = [im for im in tagged if _writable(im)]
    return next(iter(mine + [im for im in writable if im.name == IMAGE_NAME] + writable + tagged), None)


def _current_preview() -> bpy.types.Image | None:
    """Ours (tagged), or an untagged float "KD Preview" an earlier version made, which preview_image adopts."""
    image = tagged_image()
    if image is None:
        named = bpy.data.images.get(IMAGE_NAME)
        if named is not None and named.source == "GENERATED" and named.is_float:
            image = named
    return image


def _writable(image: bpy.types.Image) -> bool:
    """A float image whose pixels live in memory (generated) or in the .blend (packed on save by
    image_keeping.py): one unpacked to a file is the user's now."""
    return image.is_float and (image.source == "GENERATED" or image.packed_file is not None)


def blender_pixels(image: np.ndarray) -> np.ndarray:
    """(H, W, 4) rows top-down -> flat float32 in Blender's bottom-up row order."""
    return np.ascontiguousarray(image[::-1], dtype=np.float32).ravel()


def store_preview(image: np.ndarray, *, open_view: bool = True) -> bpy.types.Image:
    """Write a finished frame into the preview image and show it in an image editor (with
    `open_view`, one opened as Blender opens its render view when no window has any).

    The frame is remembered (not copied: callers pass a finished frame and never change it)."""
    global _last_frame
    target = _write(image)
    _last_frame = image
    show_in_image_editor(target, open_view=open_view)
    return target


def restore_last_frame() -> bpy.types.Image | None:
    """Write the last stored frame back into the preview image (re-created if it is gone), shown
    only in an image editor showing nothing: the user's choice of image stays. None before any."""
    if _last_frame is None:
        return None
    target = _write(_last_frame)
    show_in_image_editor(target, take_busy_editor=False, open_view=False)
    return target


def preview_state() -> tuple:
    """What the preview holds now, for put_back_preview: the last frame stored (None before any) and
    the preview image's name, size and pixels (None when there is no preview image)."""
    image = _current_preview()
    if image is None:
        return _last_frame, None
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    return _last_frame, (image.name, tuple(image.size), pixels)


def put_back_preview(state: tuple) -> None:
    """Make the preview what preview_state() found: a sequence that failed or was cancelled passed its
    finished frames through the preview image on their way to disk (save_frame), and left the last
    of them there under the panel's figures of the run before. An image made since
    is removed; one the user has made their own since (renamed, unpacked to a file) is left alone."""
    global _last_frame
    last_frame, saved = state
    _last_frame = last_frame
    image = _current_preview()
    if image is None:
        return
    if saved is None:
        bpy.data.images.remove(image)
        return
    name, size, pixels = saved
    if image.name != name or not _writable(image):
        return
    if tuple(image.size) != size:
        image.scale(*size)
    image.pixels.foreach_set(pixels)
    image.update()


def forget_last_frame() -> None:
    global _last_frame
    _last_frame = None


def _write(image: np.ndarray) -> bpy.types.Image:
    height, width = image.shape[:2]
    target = preview_image(width, height)
    target.pixels.foreach_set(blender_pixels(image))
    target.update()
    return target


def show_in_image_editor(image: bpy.types.Image, *, take_busy_editor: bool = True,
                         open_view: bool = False) -> None:
    """Redraw editors showing the preview; if none does, switch an image editor showing nothing to
    it, else (take_busy_editor) the first image editor; if there is none (the default Layout
    workspace has none) and `open_view`, open one where Blender shows renders."""
    editors = image_editors() or (open_render_view() if open_view else [])
    showing = [area for area in editors if area.spaces.active.image == image]
    if not showing:
        showing = [area for area in editors if area.spaces.active.image is None][:1]
        showing = showing or (editors[:1] if take_busy_editor else [])
        for area in showing:
            area.spaces.active.image = image
    for area in showing:
        area.tag_redraw()


def image_editors() -> list:
    return [area for window in bpy.context.window_manager.windows
            for area in window.screen.areas if area.type == "IMAGE_EDITOR"]


def open_render_view() -> list:
    """Image editors opened by render.view_show, as F12 opens them (Preferences > Interface >
    Temporary Editors > Render In: a new window, full screen, the largest area, or nowhere), showing
    Render Result, which the caller replaces with the preview. Without a window (background mode,
    or a handler's restricted context) nothing opens."""
    if bpy.app.background or bpy.context.window is None:
        return []
    try:
        bpy.ops.render.view_show("INVOKE_DEFAULT")
    except RuntimeError:  # the operator's poll failed in this context
        return []
    return image_editors()


def save_frame(image: np.ndarray, path: Path, file_format: str) -> Path:
    """Save a finished frame as PNG (16-bit sRGB RGBA: Blender writes a float image's PNG that deep)
    or OPEN_EXR (linear float RGBA) without changing the preview image's own file path."""
    target = store_preview(image)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Written beside it, then renamed over it: a run killed mid-write (SIGKILL, a full disk) leaves the
    # earlier run's frame whole, never a truncated file under its name.
    partial = partial_path(path)
    try:
        if file_format == "OPEN_EXR":
            _save_linear_exr(target, partial)
        else:
            _save_png(image, partial)
        check_written(partial, file_format)
        replace_file(partial, path)
    finally:
        remove_partial(partial)
    return path


PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # a PNG's last chunk: empty IEND and its CRC


def check_written(partial: Path, file_format: str) -> None:
    """An OSError unless Blender wrote the whole file: Image.save() of a PNG does not fail on a full disk,
    it leaves an empty or cut file, which must not be renamed over an earlier run's whole frame."""
    if not partial.is_file():
        raise OSError(f"Blender did not write {partial}")
    with open(partial, "rb") as written:
        size = written.seek(0, os.SEEK_END)
        written.seek(max(0, size - len(PNG_END)))
        tail = written.read()
    if size == 0 or (file_format != "OPEN_EXR" and tail != PNG_END):
        raise OSError(f"Blender wrote {partial.name} incomplete ({size} bytes): is the disk full?")


def remove_partial(partial: Path) -> None:
    """Remove a write's leftover, if any. Best effort: with the folder gone or replaced by a file the write
    itself has failed, and its error is the one to report (a second one here would hide it)."""
    try:
        partial.unlink(missing_ok=True)
    except OSError:
        pass


def partial_path(path: Path) -> Path:
    """Where `path` is written before it is renamed over: hidden, with the same extension (Blender picks
    no format by it, but viewers do), and not matching a `frame_*` pattern should a kill leave it."""
    return path.with_name(f".{path.stem}.partial{path.suffix}")


def replace_file(partial: Path, path: Path, attempts: int = 20) -> None:
    """os.replace, retried for a second on PermissionError: on Windows it fails while another process
    (an image viewer, a script reading report.json) has the target open."""
    for attempt in range(attempts):
        try:
            os.replace(partial, path)
            return
        except PermissionError:
            if attempt == attempts - 1:
                raise
            time.sleep(0.05)


def _save_png(image: np.ndarray, path: Path) -> None:
    """Image.save() of a scratch image holding the frame: Blender 4.2 has no save_copy, and its save()
    turns the image it writes into a file image at that path (the preview image would be replaced by a
    new one at the next frame, and image editors would show the file instead)."""
    height, width = image.shape[:2]
    scratch = bpy.data.images.new("KD Preview PNG", width, height, alpha=True, float_buffer=True)
    try:
        scratch.pixels.foreach_set(blender_pixels(image))
        scratch.file_format = "PNG"
        scratch.save(filepath=str(path))
    finally:
        bpy.data.images.remove(scratch)


def _save_linear_exr(target: bpy.types.Image, path: Path) -> None:
    """Image.save() of a generated float image writes sRGB-encoded values even to OPEN_EXR (bpy 5.0:
    0.5 is stored as 0.7354), so EXRs go through save_render, which keeps scene-linear values, with
    the EXR settings of a scratch scene: the user's own render output settings are not touched."""
    scratch = bpy.data.scenes.new("KD Preview EXR settings")
    try:
        settings = scratch.render.image_settings
        settings.file_format = "OPEN_EXR"
        settings.color_mode = "RGBA"
        settings.color_depth = "32"
        target.save_render(str(path), scene=scratch)
    finally:
        bpy.data.scenes.remove(scratch)
