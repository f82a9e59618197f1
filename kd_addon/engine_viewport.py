"""The 3D viewport's Rendered shading through the render engine: a progressive preview of what the view shows.

The work is the existing pipeline's FrameJob, for the view's camera (read from the region's matrices, so
perspective, orthographic and camera view with its lens, shift, zoom and offset all follow) at the panel's
Resolution % of the region's size. `ViewportSession` holds one job and the image shown; every draw ticks
the job for at most VIEWPORT_POLL_SECONDS (its kernels run on the background worker, so the UI never
waits on a build or a sample) and asks for another draw until the image has all its samples. A changed
view starts a new job, which continues from the trees kept in the viewport's group of tree_cache; an
edit (`depsgraph.updates`) does too, and the reuse rebuilds only the meshes whose geometry changed.
Nothing here needs a GPU; engine.py draws `ViewportSession.image` with the `gpu` module.
"""

from __future__ import annotations

import numpy as np

from .config import RenderConfig, frame_size
from .errors import PreviewError
from .pipeline import FrameJob, FrameResult, FrameView, job_running
from .scene_input import CameraInput, normalized_matrix

VIEWPORT_GROUP = "viewport"  # the viewport's own trees and image (tree_cache.state_for)
VIEWPORT_POLL_SECONDS = 0.005  # longest a draw waits for the worker
VIEWPORT_STEP_SECONDS = 0.25  # a sampling step's length: a navigation's new job waits for the cancelled one's
# Data-block types whose changes cannot change the preview's image: it shades no material or texture.
IGNORED_UPDATES = frozenset(("MATERIAL", "TEXTURE", "IMAGE", "WORKSPACE", "SCREEN", "WINDOWMANAGER", "BRUSH",
                             "PALETTE", "TEXT"))


def camera_from_matrices(view_matrix, window_matrix, width: int, height: int) -> CameraInput:
    """The camera whose width x height image is what a region with these matrices shows (Blender's
    RegionView3D.view_matrix, world to view, and window_matrix, the projection, OpenGL conventions).

    Perspective: the image plane at distance 1 spans 2/P00 by 2/P11, centred on (P02/P00, P12/P11);
    orthographic: 2/P00 by 2/P11 centred on (-P03/P00, -P13/P11). The clip distances come from the third
    row. A region's near plane may lie behind its viewpoint (orthographic views): the camera then moves
    back to it, so core's clip start is 0. The pixel aspect takes the image's rounding to whole pixels."""
    p = np.array(window_matrix, np.float64).reshape(4, 4)
    to_world = np.linalg.inv(np.array(view_matrix, np.float64).reshape(4, 4))
    perspective = p[3, 2] != 0.0
    half_x, half_y = 1.0 / p[0, 0], 1.0 / p[1, 1]
    if perspective:
        centre = (p[0, 2] / p[0, 0], p[1, 2] / p[1, 1])
        near, far = p[2, 3] / (p[2, 2] - 1.0), p[2, 3] / (p[2, 2] + 1.0)
    else:
        centre = (-p[0, 3] / p[0, 0], -p[1, 3] / p[1, 1])
        near, far = (p[2, 3] + 1.0) / p[2, 2], (p[2, 3] - 1.0) / p[2, 2]
    larger = 2.0 * max(half_x, half_y)
    matrix = normalized_matrix(to_world)
    if not perspective and near < 0.0:  # move back to the near plane: core's clip start is at least 0
        matrix[:3, 3] -= -near * -matrix[:3, 2]
        near, far = 0.0, far - near
    if not 0.0 <= near < far:
        raise PreviewError(f"the view's clip range {near:g} to {far:g} is empty (View > Clip Start and End)")
    return CameraInput(matrix, float(2.0 * np.arctan(larger / 2.0)) if perspective else None,
                       None if perspective else float(larger), float(near), float(far),
                       (float(centre[0] / larger), float(centre[1] / larger)),
                       float(half_y * width / (half_x * height)))


def viewport_size(region_width: int, region_height: int, percentage: int) -> tuple[int, int]:
    """The preview's size: the panel's Resolution % of the region's (config.frame_size's rounding)."""
    return frame_size(max(1, region_width), max(1, region_height), percentage)


def view_key(view: FrameView) -> tuple:
    """A comparable digest of a FrameView (its camera holds an array)."""
    c = view.camera
    return (view.width, view.height, c.matrix_world.tobytes(), c.fov, c.ortho_scale, c.clip_start, c.clip_end,
            c.shift, c.pixel_aspect)


def changes_image(updates) -> bool:
    """Whether depsgraph updates, given as (id type, geometry updated, transform updated) rows, can change
    the preview: any geometry or transform change, or any change of a data-block that is not only a
    material, texture, image or UI one (a setting of the scene, a light, a camera, a collection)."""
    return any(geometry or transform or kind not in IGNORED_UPDATES for kind, geometry, transform in updates)


def update_rows(depsgraph) -> list[tuple[str, bool, bool]]:
    """changes_image's rows from a depsgraph's updates."""
    return [(getattr(u.id, "id_type", type(u.id).__name__.upper()), bool(u.is_updated_geometry),
             bool(u.is_updated_transform)) for u in depsgraph.updates]


class ViewportSession:
    """One viewport's preview: its job, the image to draw and the last finished frame."""

    def __init__(self, scene):
        self.scene = scene
        self.job: FrameJob | None = None
        self.image: np.ndarray | None = None  # (H, W, 4), row 0 at the top: what the viewport shows
        self.result: FrameResult | None = None  # the last finished frame
        self.error = ""
        self.samples_shown = 0
        self._depsgraph = None
        self._key = None  # (view_key, settings) of the job, or of the finished image
        self._dirty = True

    def scene_changed(self) -> None:
        """The scene changed in a way that can change the image: render it anew (trees kept where unchanged)."""
        self._dirty = True

    def advance(self, depsgraph, view: FrameView, config: RenderConfig) -> bool:
        """One short piece of work for a draw; True while more work remains (draw again soon)."""
        self._depsgraph = depsgraph  # valid during this draw only: a job reads it through a function
        key = (view_key(view), config.settings)
        if self._dirty or key != self._key:
            self._start(view, config, key)
        if self.job is None:
            return False
        if job_running():  # a panel run or a final render reads the scene and holds the kernels: wait for it
            return True
        try:
            done = self.job.tick()
        except PreviewError as error:
            self.error, self.job = str(error), None
            return False
        if done:
            self.result, self.job = self.job.result(), None
            self.image, self.samples_shown = self.result.image, self.result.samples
            return False
        self._show_progress()
        return True

    def _start(self, view: FrameView, config: RenderConfig, key) -> None:
        """A new job for this view and these settings; the one before is left to its worker call."""
        self._key, self._dirty, self.error, self.samples_shown = key, False, "", 0  # the old image stays meanwhile
        self.job = FrameJob(self.scene, lambda: self._depsgraph, config, view=view, group=VIEWPORT_GROUP,
                            poll_seconds=VIEWPORT_POLL_SECONDS, step_seconds=VIEWPORT_STEP_SECONDS)

    def _show_progress(self) -> None:
        """Take the job's image once it has more samples than the one shown."""
        renderer = self.job.renderer
        if renderer is None or renderer.samples_done <= self.samples_shown:
            return
        image = self.job.current_image()
        if image is not None and image.shape[:2] == (renderer.height, renderer.width):
            self.image, self.samples_shown = image, renderer.samples_done

    @property
    def status(self) -> str:
        if self.error:
            return f"KD Preview: {self.error}"
        if self.job is not None:
            return f"KD Preview | {self.job.status}"
        if self.result is not None:
            r = self.result
            return (f"KD Preview | {r.samples} samples | build {r.build_ms:.1f} ms | trace {r.trace_ms:.1f} ms | "
                    f"{r.mrays_per_s:.2f} Mrays/s")
        return "KD Preview"
