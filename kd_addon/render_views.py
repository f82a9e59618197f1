"""The views of a final render (Output > Views: Stereo 3D or Multi-View), each seen by its own camera.

Blender hands an engine one render() per view layer and leaves the views to it, as Cycles takes them
(BlenderSession::render): make a view active (RenderEngine.active_view_set), take that view's camera
(camera_override: in Multi-View the camera named with the view's suffix, else the scene camera), and
ask for its matrix and horizontal shift (camera_model_matrix, camera_shift_x), which carry the stereo
eye's offset, toe-in or off-axis shift. Without multiview there is one view, named "" here, seen by the
scene camera as read.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .scene_input import CameraInput, normalized_matrix, shift_to_larger_dimension

STEREO_VIEWS = ("left", "right")  # Blender's STEREO_LEFT_NAME, STEREO_RIGHT_NAME


@dataclass(frozen=True)
class Eye:
    """One view's camera as Blender places it: the camera object (its lens and clipping are read as the
    scene camera's), the world matrix, the horizontal lens shift (in Camera.shift_x's units) and the
    sensor fit that shift is measured by."""

    camera_object: object
    matrix_world: np.ndarray
    shift_x: float
    sensor_fit: str


def view_names(render) -> list[str]:
    """The views a final render makes, in Blender's order: [""] without multiview; in Stereo 3D the left
    and right views that are on; in Multi-View every view that is on (BKE_scene_multiview_is_render_view_active)."""
    if not render.use_multiview:
        return [""]
    names = [view.name for view in render.views if view.use]
    if render.views_format == "STEREO_3D":
        names = [name for name in names if name in STEREO_VIEWS]
    return names or [""]


def eye_of(engine, depsgraph, name: str) -> Eye | None:
    """View `name`'s camera from the engine (None for the one view without multiview, or when the view
    has no camera object, which read_camera then names). The matrix is the evaluated camera's, so its
    animation and constraints count."""
    if not name:
        return None
    engine.active_view_set(name)
    camera = engine.camera_override
    if camera is None or camera.type != "CAMERA":
        return None
    evaluated = camera.evaluated_get(depsgraph)
    matrix = np.array(engine.camera_model_matrix(evaluated, use_spherical_stereo=False), np.float64)
    shift_x = float(engine.camera_shift_x(evaluated, use_spherical_stereo=False))
    return Eye(camera, matrix.reshape(4, 4), shift_x, evaluated.data.sensor_fit)


def eye_camera(camera: CameraInput, eye: Eye | None, width: int, height: int) -> CameraInput:
    """`camera` (read for the eye's camera object at width x height) moved to the eye."""
    if eye is None:
        return camera
    shift_x = shift_to_larger_dimension(eye.shift_x, eye.sensor_fit, width, height * camera.pixel_aspect)
    return replace(camera, matrix_world=normalized_matrix(eye.matrix_world), shift=(shift_x, camera.shift[1]))


def lane_of(layer: str, name: str, term: str = "") -> str:
    """The tree_cache lane of view `name`'s image (each view keeps its own pixels across frames), or of
    its pass of `term` ("ao", "shadow"), in view layer `layer`; "" for the Combined image without views,
    which the panel's renders share. The others begin with final_lanes(layer)."""
    if not name and not term:
        return ""
    return f"{final_lanes(layer)}view:{name}|pass:{term}"


def final_lanes(layer: str) -> str:
    """How the lanes only view layer `layer`'s final renders use begin (tree_cache.keep_lanes drops those
    a frame of that layer no longer renders); the name's length first, so no layer's begins another's."""
    return f"layer:{len(layer)}:{layer}|"
