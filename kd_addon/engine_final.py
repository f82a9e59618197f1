"""A final render through the render engine (F12, Ctrl-F12, `blender -b f.blend -E KD_PREVIEW -f/-a`).

Blender drives it: it sets the frame, hands `render()` the render's own depsgraph (extraction reads it as
it is: extract.py), and writes the RenderResult filled here to the output path in the scene's format,
frame by frame for an animation. The frame is the existing pipeline's FrameJob (trees and pixels kept
across consecutive frames, tree_cache.py) at the scene's resolution and %, for the scene camera cropped to
the Render Region. The result is opened only once the frame is finished, so a cancel (test_break, polled
every pipeline.POLL_SECONDS) or an error leaves no partial image to write.

Every view of a multiview render (render_views.py) is rendered and written. Passes: Combined (RGBA, alpha
1 where a surface is hit; opaque over the world's viewport colour with Film > Transparent off) always;
with the view layer's passes on, Depth (view-axis distance), AO and Shadow: the mode's own term is the
Combined image, the other term is traced as a second job over the same trees (its own lane of
tree_cache, so each keeps its pixels across frames).
"""

from __future__ import annotations

import re
import time
import traceback
from dataclasses import replace
from typing import NamedTuple

import bpy
import numpy as np

from . import compile_command, tree_cache
from .config import make_config
from .errors import Cancelled, NoLightError, PreviewError
from .pipeline import FrameJob, FrameResult, FrameView, claim, release, waits_for_a_compile
from .render_views import Eye, eye_camera, eye_of, final_lanes, lane_of, view_names
from .scene_input import CameraInput, read_camera

# (pass name, channels, channel ids, Blender's pass type, the view layer switch that asks for it)
PASSES = (("AO", 3, "RGB", "COLOR", "use_pass_ambient_occlusion"),
          ("Shadow", 3, "RGB", "COLOR", "use_pass_shadow"),
          ("Depth", 1, "Z", "VALUE", "use_pass_z"))
TERM_OF_PASS = {"AO": "ao", "Shadow": "shadow"}
NO_HIT_DEPTH = 1e10  # what Blender's Depth pass holds where nothing is hit


def requested_passes(view_layer) -> list[tuple]:
    """The PASSES rows the view layer asks for."""
    return [row for row in PASSES if getattr(view_layer, row[4], False)]


def passes_left_out(view_layer) -> list[str]:
    """The names of the passes the view layer asks for (its use_pass_* switches, its AOVs) that the engine
    does not make: Blender makes only those an engine registers, so they would be missing without a word."""
    made = {row[4] for row in PASSES} | {"use_pass_combined", "use_pass_cryptomatte_accurate"}  # the last: an option
    names = [prop.name for prop in view_layer.bl_rna.properties
             if prop.identifier.startswith("use_pass_") and prop.identifier not in made
             and getattr(view_layer, prop.identifier) is True]
    return names + [f"AOV {aov.name}" for aov in getattr(view_layer, "aovs", ())]


def border_region(render, width: int, height: int) -> tuple[int, int, int, int] | None:
    """(x, y from the top, w, h) in pixels of the Render Region of a width x height frame, None without
    one; Blender rounds the region's edges down (its render result is that size, checked by a test)."""
    if not render.use_border:
        return None
    x0, x1 = int(render.border_min_x * width), int(render.border_max_x * width)
    y0, y1 = int(render.border_min_y * height), int(render.border_max_y * height)  # from the bottom
    if x1 <= x0 or y1 <= y0:
        raise PreviewError("the Render Region (Output > Format) is empty: widen it or turn Render Region off")
    return x0, height - y1, x1 - x0, y1 - y0


def crop_camera(camera: CameraInput, width: int, height: int, region: tuple[int, int, int, int]) -> CameraInput:
    """The camera whose w x h image is the `region` (x, y from the top, w, h) of `camera`'s width x height
    image, pixel for pixel: the same pixel size, the image plane cut to the region (core.Camera's
    image_plane: extents along the larger side, the shift in units of it)."""
    x, y, w, h = region
    tall = height * camera.pixel_aspect  # core.Camera._half_extent
    half = np.tan(camera.fov / 2.0) if camera.fov is not None else camera.ortho_scale / 2.0
    half_w, half_h = (half, half * tall / width) if width >= tall else (half * width / tall, half)
    larger = 2.0 * max(half_w, half_h)
    left = camera.shift[0] * larger - half_w + x * 2.0 * half_w / width
    top = camera.shift[1] * larger + half_h - y * 2.0 * half_h / height
    sub_w, sub_h = w * 2.0 * half_w / width, h * 2.0 * half_h / height
    sub_larger = max(sub_w, sub_h)
    shift = ((left + sub_w / 2.0) / sub_larger, (top - sub_h / 2.0) / sub_larger)
    if camera.fov is not None:
        return replace(camera, fov=float(2.0 * np.arctan(sub_larger / 2.0)), shift=shift)
    return replace(camera, ortho_scale=float(sub_larger), shift=shift)


def final_view(scene, depsgraph, width: int, height: int, eye: Eye | None = None) -> tuple[FrameView, list[str]]:
    """(the frame a final render makes, the camera's warnings): the scene camera at width x height (the
    scene's resolution and %), moved to a multiview render's `eye` (render_views.py), cut to the Render
    Region (Blender pastes a region without Crop back into the whole frame)."""
    camera, warnings = read_camera(scene, depsgraph, width, height, eye.camera_object if eye is not None else None)
    camera = eye_camera(camera, eye, width, height)
    region = border_region(scene.render, width, height)
    if region is None:
        return FrameView(width, height, camera), warnings
    return FrameView(region[2], region[3], crop_camera(camera, width, height, region)), warnings


def to_rect(image: np.ndarray) -> np.ndarray:
    """An (H, W, C) image with row 0 at the top as the flat float32 array a RenderPass's rect takes
    (rows from the bottom)."""
    return np.ascontiguousarray(image[::-1], np.float32).reshape(-1)


def stats_line(result: FrameResult) -> str:
    """The engine's stats line: frame size, triangles, build and trace times, speed."""
    first = " (includes loading kernels)" if result.first_run else ""
    reused = " | image reused" if result.image_reused else ""
    return (f"KD Preview | {result.width}x{result.height} | {result.triangles:,} triangles | build "
            f"{result.build_ms:.1f} ms | trace {result.trace_ms:.1f} ms{first} | {result.mrays_per_s:.2f} Mrays/s"
            f"{reused}")


class RenderedView(NamedTuple):
    """One view of a final render: its frame, the warnings to report, the Combined result and the pass
    images ({pass name: (H, W, C)})."""

    view: FrameView
    warnings: list
    result: FrameResult
    images: dict


class FinalRender:
    """One render() call: the frame, its passes, and the RenderResult."""

    def __init__(self, engine, depsgraph):
        self.engine, self.depsgraph, self.scene = engine, depsgraph, depsgraph.scene
        self.lanes: set[str] = set()  # the tree_cache lanes this frame rendered

    def run(self) -> None:
        """Render the frame, each of its views; a PreviewError is reported (no traceback), a cancel writes
        nothing. Ctrl-C in a script driving the bpy module (a KeyboardInterrupt here: Blender's own
        binary takes SIGINT itself) is reported as an error, so Blender writes nothing for the frame (it
        wrote an empty image over the output when the exception left render()) and the script's render
        call fails instead of going on. Any other exception (a fault of the add-on's, or of the machine's)
        is reported the same way, its traceback printed, and never leaves render()
        (docs/choices.md#a-final-renders-unexpected-failures-reported-not-raised)."""
        try:
            self._run()
        except Exception as error:  # noqa: BLE001 (the last guard before Blender's own render call)
            traceback.print_exc()
            self._report_error(f"the frame failed: {type(error).__name__}: {error} (traceback in the console); "
                               "nothing written for this frame")

    def _run(self) -> None:
        _note_uncompiled()
        try:
            config = make_config(self.scene.kd_preview)
            passes = requested_passes(self.depsgraph.view_layer)
            names = view_names(self.scene.render)
            # before the memory check counts them: the lanes this frame may render, then those it did
            self._keep_lanes({self._lane(name, term) for name in names for term in ["", *self._terms(passes)]})
            views = {name: self._view(config, name, passes) for name in names}
            first = next(iter(views.values()))
            self._keep_lanes(self.lanes)
        except Cancelled:
            self.engine.update_stats("", "KD Preview | cancelled")
            return
        except PreviewError as error:
            self._report_error(str(error))
            return
        except KeyboardInterrupt:
            self._report_error("interrupted (Ctrl-C): nothing written for this frame")
            return
        left_out = passes_left_out(self.depsgraph.view_layer)
        if left_out:
            first.warnings.append(f"passes this engine does not make are left out: {', '.join(left_out)} (it makes "
                                  f"Combined, {', '.join(row[0] for row in PASSES)})")
        background = film_background(self.scene, self.depsgraph)
        if background is not None and first.result.holdouts:
            background = None
            first.warnings.append("Film > Transparent off is not applied to a frame with holdout objects: where "
                                  "nothing is hit stays transparent, as the holdouts' pixels are (turn Film > "
                                  "Transparent on to silence this)")
        for warning in dict.fromkeys(w for rendered in views.values() for w in rendered.warnings):
            self._report_warning(warning)  # once, though every view warns alike
        self._write(views, first, background)
        self.engine.update_stats("", stats_line(first.result))

    def _view(self, config, name: str, passes: list[tuple]) -> RenderedView:
        """View `name` ("" without multiview) rendered, with its passes."""
        eye = eye_of(self.engine, self.depsgraph, name)
        view, camera_warnings = final_view(self.scene, self.depsgraph, self.engine.resolution_x,
                                           self.engine.resolution_y, eye)
        label = f"Combined {name}".rstrip()
        result = self._frame(config, view, self._lane(name), label)
        images, pass_warnings = self._pass_images(config, view, result, passes, name)
        return RenderedView(view, camera_warnings + result.warnings + pass_warnings, result, images)

    def _lane(self, view_name: str, term: str = "") -> str:
        return lane_of(self.depsgraph.view_layer.name, view_name, term)

    @staticmethod
    def _terms(passes: list[tuple]) -> list[str]:
        """The render terms of the requested passes that may need a trace of their own."""
        return [TERM_OF_PASS[row[0]] for row in passes if row[0] in TERM_OF_PASS]

    def _keep_lanes(self, lanes) -> None:
        """Drop the lanes of this view layer's final renders that are not among `lanes`."""
        tree_cache.keep_lanes(self.scene, "", lanes, final_lanes(self.depsgraph.view_layer.name))

    def _report_error(self, text: str) -> None:
        """The frame failed: Blender shows `text` and writes nothing for it; an animation's names the frame
        it stopped at (Blender's own report names none), as the panel's Animation does."""
        where = f"frame {self.scene.frame_current}: " if self.engine.is_animation else ""
        self.engine.report({"ERROR"}, f"KD Preview: {where}{text}")
        self.engine.error_set(f"KD Preview: {where}{text}")

    def _report_warning(self, text: str) -> None:
        self.engine.report({"WARNING"}, f"KD Preview: {text}")

    def _frame(self, config, view: FrameView, lane: str, label: str) -> FrameResult:
        """One FrameJob to the end, polling test_break between its short ticks."""
        job = FrameJob(self.scene, self.depsgraph, config, view=view, lane=lane)
        self.lanes.add(lane)
        claim(job)  # no panel or Live Update run beside it (a frame change during an animation render)
        try:
            t0, said = time.perf_counter(), ""
            while not job.tick():
                if self.engine.test_break():
                    raise Cancelled("cancelled")
                self.engine.update_progress(job.progress)
                status = job.status
                self.engine.update_stats("", f"KD Preview | {label} | {status} | {time.perf_counter() - t0:.1f} s")
                said = _say_compile_wait(status, said)
            return job.result()
        finally:
            release(job)

    def _pass_images(self, config, view: FrameView, result: FrameResult, passes: list[tuple],
                     view_name: str) -> tuple[dict, list[str]]:
        """({pass name: (H, W, C) image} of the requested passes of view `view_name`, warnings)."""
        images, warnings = {}, []
        for name, channels, *_ in passes:
            if name == "Depth":
                depth = result.depth if result.depth is not None else np.full((view.height, view.width), np.inf)
                images[name] = np.where(np.isfinite(depth), depth, NO_HIT_DEPTH)[..., None]
                continue
            term = TERM_OF_PASS[name]
            if result.mode == term:  # the mode rendered ("auto" resolved): its term is the Combined image
                images[name] = result.image[..., :channels]
                continue
            term_config = make_config(replace(config.settings, mode=term))
            try:
                images[name] = self._frame(term_config, view, self._lane(view_name, term),
                                           f"{name} pass {view_name}".rstrip()).image[..., :channels]
            except PreviewError as error:  # e.g. a Shadow pass beside an AO render, in a scene without lights
                why = error
                if isinstance(error, NoLightError):
                    fix = "make one visible" if error.hidden else "add a light"
                    why = f"{error.why} ({fix}, or turn the {name} pass off)"
                warnings.append(f"the {name} pass is left black: {why}")
                images[name] = np.zeros((view.height, view.width, channels), np.float32)
        return images, warnings

    def _write(self, views: dict, first: RenderedView, background: np.ndarray | None) -> None:
        """Fill the RenderResult, every view's passes ({view name: RenderedView}; every view has the size
        and passes of the `first`), the Combined pass opaque over `background` unless None; Blender writes
        it (output path and format) and shows it."""
        view = first.view
        for name, channels, ids, *_ in PASSES:
            if name in first.images:
                self.engine.add_pass(name, channels, ids, layer=self.depsgraph.view_layer.name)
        # Blender calls render() once per view layer, each with its own depsgraph: fill that layer only
        layer_name = self.depsgraph.view_layer.name
        result = self.engine.begin_result(0, 0, view.width, view.height, layer=layer_name)
        layer = result.layers[0]
        for view_name, rendered in views.items():
            image = rendered.result.image
            combined = image if background is None else opaque(image, background)
            _pass(layer, "Combined", view_name).rect.foreach_set(to_rect(combined))
            for name, image in rendered.images.items():
                _pass(layer, name, view_name).rect.foreach_set(to_rect(image))
        self.engine.end_result(result)


def _pass(layer, name: str, view_name: str):
    """The render layer's pass `name` of view `view_name` ("": the one view without multiview)."""
    return layer.passes.find_by_name(name, view_name) if view_name else layer.passes[name]


def film_background(scene, depsgraph) -> np.ndarray | None:
    """The RGB the Combined pass shows where nothing is hit, None when Film > Transparent is on (alpha 0
    there). The world's viewport colour (World > Viewport Display), as Workbench renders it: the preview
    reads no shaders, the world's nodes included. Read from the evaluated world: a keyed colour is the
    frame's only there during an animation render. (A frame with holdouts stays transparent: Cycles keeps a
    holdout's pixels at alpha 0 over an opaque film, and the image does not tell them from the background's.)"""
    if scene.render.film_transparent:
        return None
    if scene.world is None:
        return np.zeros(3, np.float32)
    return np.array(scene.world.evaluated_get(depsgraph).color[:3], np.float32)


def opaque(image: np.ndarray, background: np.ndarray) -> np.ndarray:
    """The (H, W, 4) image (premultiplied, as Blender's render results) over `background`: alpha 1."""
    alpha = image[..., 3:4]
    out = np.empty_like(image)
    out[..., :3] = image[..., :3] + background * (1.0 - alpha)
    out[..., 3] = 1.0
    return out


def update_render_passes(engine, scene, view_layer) -> None:
    """Name the passes the compositor's Render Layers node offers for this engine."""
    engine.register_pass(scene, view_layer, "Combined", 4, "RGBA", "COLOR")
    for name, channels, ids, kind, _ in requested_passes(view_layer):
        engine.register_pass(scene, view_layer, name, channels, ids, kind)


def _say_compile_wait(status: str, said: str) -> str:
    """In a background render (blender -b, a bpy script) Blender shows no status line, so a frame that
    waits minutes for the kernels' first compile would look hung: print the wait once (a counting
    status such as "compiling kernels (first use) 12s" once, not every second). Returns what was said."""
    kind = re.sub(r"\d+s\b", "", status)
    if not bpy.app.background or kind == said or not waits_for_a_compile(status):
        return said
    print(f"KD Preview: {status} (once per installation)", flush=True)
    return kind


_uncompiled_noted = False  # the note below is said once a process


def _note_uncompiled() -> None:
    """A background render (blender -b, a script on the bpy module) starts no second warm-up stage: say
    once a process, while it is not cached, that its frames are slower until the compile command has run
    (compile_command.py). Blender's binary has a binary_path; the bpy module's is empty (unless a script
    sets it), and its command is the module's. Advice only: a cache folder it cannot read says nothing, and
    the render goes on."""
    global _uncompiled_noted
    if not bpy.app.background or _uncompiled_noted:
        return
    _uncompiled_noted = True
    try:
        note = compile_command.uncompiled_note(compile_command.COMMAND_ID if bpy.app.binary_path
                                               else "python -m kd_addon")
    except OSError:
        return
    if note:
        print(f"KD Preview: note: {note}", flush=True)
