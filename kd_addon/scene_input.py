"""The scene's camera and lights, converted to the plain keywords core.Camera and core.Light take.

The conversions are pure functions of numbers; `read_scene` only gathers them from bpy. Nothing here
imports core, so a scene can fail with a clear message before any kernel is compiled.

Blender's `lens`, `ortho_scale` and lens shift are along the *fitted* sensor axis (AUTO: the larger
one); core wants them along the larger image dimension, so they are rescaled by the image aspect, as
BKE_camera_params_compute_viewplane does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import bulk_instances
from .animation_curves import animated_paths
from .errors import NoLightError, PreviewError
from .extraction_warnings import hidden_light_warnings
from .render_visibility import RenderVisibility, entry_visible  # the meshes' visibility rules
from .light_nodes import NO_NODES, Emission, plain_emission


@dataclass(frozen=True)
class CameraInput:
    """Keywords for core.Camera, plus the world position the preview traces relative to."""

    matrix_world: np.ndarray  # (4, 4) float64, rotation columns normalized
    fov: float | None  # radians along the larger image dimension (perspective)
    ortho_scale: float | None  # extent along the larger image dimension (orthographic)
    clip_start: float
    clip_end: float
    shift: tuple[float, float] = (0.0, 0.0)  # lens shift in units of the larger image dimension
    pixel_aspect: float = 1.0  # a pixel's height over its width (core.Camera)

    @property
    def position(self) -> np.ndarray:
        return self.matrix_world[:3, 3].copy()

    def keywords(self) -> dict:
        return {
            "matrix_world": self.matrix_world,
            "fov": self.fov,
            "ortho_scale": self.ortho_scale,
            "clip_start": self.clip_start,
            "clip_end": self.clip_end,
            "shift": self.shift,
            "pixel_aspect": self.pixel_aspect,
        }


@dataclass(frozen=True)
class LightInput:
    """One light: `kind` names the core.Light constructor, `keywords` its arguments."""

    name: str
    kind: str  # "point", "sun", "spot" or "area"
    keywords: dict
    unapplied: tuple[str, ...] = ()  # the light's settings that change Cycles' image but not the preview's
    portal: bool = False  # a Cycles light portal: an area light that only guides the world's light, emitting none
    emits_nothing: str = ""  # why its nodes emit no light in Cycles (light_nodes.py), "" when they emit
    no_diffuse: str = ""  # why it lights no diffuse surface in Cycles (diffuse_switched_off), "" when it does


@dataclass
class SceneInputs:
    """What the renderer needs from the scene besides triangles."""

    camera: CameraInput
    lights: list[LightInput]
    width: int
    height: int
    warnings: list[str] = field(default_factory=list)
    hidden_lights: list[str] = field(default_factory=list)  # a warning per light hidden in the viewport


# --------------------------------------------------------------------------
# Pure conversions
# --------------------------------------------------------------------------


def fitted_axis(sensor_fit: str, width: float, height: float) -> str:
    """"x" or "y": the image axis Blender fits the sensor (or ortho scale) to."""
    if sensor_fit == "HORIZONTAL":
        return "x"
    if sensor_fit == "VERTICAL":
        return "y"
    return "x" if width >= height else "y"


def to_larger_dimension(extent: float, sensor_fit: str, width: float, height: float) -> float:
    """Rescale an extent along the fitted axis to the larger image dimension.

    Works for anything proportional to the image plane size: 2*tan(fov/2) or ortho_scale.
    """
    axis = fitted_axis(sensor_fit, width, height)
    larger = "x" if width >= height else "y"
    if axis == larger:
        return extent
    return extent * max(width, height) / min(width, height)


def shift_to_larger_dimension(shift: float, sensor_fit: str, width: float, height: float) -> float:
    """Rescale a lens shift from Blender's unit (the fitted axis's extent) to the larger dimension's.

    Blender moves the view plane by shift * (pixels along the fitted axis) (BKE_camera_params_compute_
    viewplane; Cycles' viewplane agrees): a fraction of the fitted extent, which is the larger extent
    divided by the rescaling of an extent.
    """
    return shift / to_larger_dimension(1.0, sensor_fit, width, height)


def perspective_fov(lens: float, sensor_width: float, sensor_height: float,
                    sensor_fit: str, width: float, height: float) -> float:
    """Field of view in radians along the larger image dimension."""
    sensor = sensor_height if sensor_fit == "VERTICAL" else sensor_width
    tan_half = to_larger_dimension(sensor / (2.0 * lens), sensor_fit, width, height)
    return 2.0 * math.atan(tan_half)


def orthographic_scale(ortho_scale: float, sensor_fit: str, width: float, height: float) -> float:
    """Orthographic view extent along the larger image dimension."""
    return to_larger_dimension(ortho_scale, sensor_fit, width, height)


def normalized_matrix(matrix) -> np.ndarray:
    """A float64 4x4 copy whose rotation columns are unit length: Blender ignores a camera's
    object scale when rendering, and so must the preview."""
    m = np.array(matrix, dtype=np.float64).reshape(4, 4)
    norms = np.linalg.norm(m[:3, :3], axis=0)
    if not np.all(np.isfinite(m)) or np.any(norms < 1e-12):
        raise PreviewError("the camera's transform is degenerate (zero scale or not finite)")
    m[:3, :3] /= norms
    return m


def camera_input(data, matrix_world, width: int, height: int,
                 pixel_aspect: float = 1.0) -> tuple[CameraInput, list[str]]:
    """CameraInput from a bpy Camera datablock (or anything with its attribute names). `pixel_aspect`:
    the scene's pixel_aspect_y / pixel_aspect_x. Blender fits the sensor to the image's extent in pixel
    widths, width by height * pixel_aspect (BKE_camera_params_compute_viewplane), so the conversions
    below take that extent."""
    warnings = []
    if data.type == "PANO":
        raise PreviewError("panoramic cameras are not supported: use a perspective or orthographic camera")
    if not data.clip_start < data.clip_end:  # Blender takes it; Cycles then renders an empty frame
        raise PreviewError(f"clip start {data.clip_start:g} is not below clip end {data.clip_end:g}, so the camera sees "
                           "nothing (a final render is empty): set Clip Start below Clip End")
    tall = height * pixel_aspect
    shift = tuple(shift_to_larger_dimension(float(v), data.sensor_fit, width, tall)
                  for v in (data.shift_x, data.shift_y))
    fov = ortho = None
    if data.type == "ORTHO":
        ortho = orthographic_scale(data.ortho_scale, data.sensor_fit, width, tall)
    else:
        fov = perspective_fov(data.lens, data.sensor_width, data.sensor_height, data.sensor_fit, width, tall)
    camera = CameraInput(normalized_matrix(matrix_world), fov, ortho, float(data.clip_start), float(data.clip_end),
                         shift, float(pixel_aspect))
    return camera, warnings


def light_direction(matrix_world) -> np.ndarray:
    """Unit direction the light travels: the object's local -Z in world space (the zero vector for a
    zero Z scale, which core.Light then names)."""
    m = np.array(matrix_world, dtype=np.float64).reshape(4, 4)
    d = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
    norm = np.linalg.norm(d)
    return d / norm if norm > 0.0 else d


def light_color(data, emission: Emission | None = NO_NODES) -> tuple[float, float, float]:
    """The light's colour as Cycles emits it, its largest channel at most 1: its Color times its nodes'
    Emission Color (`emission`, light_nodes.py; None: nodes the preview does not apply) times its
    blackbody Temperature's colour when *Temperature* is on (Blender 4.5+; Blender normalises that to
    luminance 1, so a channel reaches 2.5 at 2000 K: its largest channel is scaled to 1 here). A colour
    above 1 (an Emission Color or a Color typed above 1) is a power, which the preview does not weight:
    scaled down to 1 it keeps its hue, where S would otherwise clip to another hue when displayed
    (docs/choices.md#light-colour-normalised-to-its-largest-channel)."""
    color = np.array(data.color, np.float64)
    if emission is not None:
        color = color * emission.color
    if getattr(data, "use_temperature", False):  # the tint's largest channel 1: a hue, as Color is
        tint = np.array(data.temperature_color, np.float64)
        color = color * tint / tint.max() if tint.max() > 0.0 else color * 0.0
    peak = color.max()
    return tuple(float(c) for c in (color / peak if peak > 1.0 else color))


def light_input(name: str, data, matrix_world) -> LightInput | None:
    """LightInput from a bpy Light datablock; None for a type the preview does not know."""
    m = np.array(matrix_world, dtype=np.float64).reshape(4, 4)
    emission = plain_emission(data)
    position, color = m[:3, 3].copy(), light_color(data, emission)
    if data.type == "POINT":
        kw = dict(position=position, radius=float(data.shadow_soft_size), power=float(data.energy))
    elif data.type == "SUN":
        kw = dict(direction=light_direction(m), angle=float(data.angle), strength=float(data.energy))
    elif data.type == "SPOT":  # axes: a non-uniformly scaled spot's cone is elliptical in Cycles
        kw = dict(position=position, direction=light_direction(m), spot_size=float(data.spot_size),
                  spot_blend=float(data.spot_blend), radius=float(data.shadow_soft_size), power=float(data.energy),
                  axes=m[:3, :3].copy())
    elif data.type == "AREA":
        size_y = float(data.size_y) if data.shape in ("RECTANGLE", "ELLIPSE") else None
        kw = dict(matrix_world=m, shape=data.shape, size=float(data.size), size_y=size_y, power=float(data.energy),
                  spread=float(data.spread))
    else:
        return None
    kw["color"] = color
    kw["cast_shadow"] = bool(getattr(data, "use_shadow", True))
    portal = data.type == "AREA" and bool(getattr(getattr(data, "cycles", None), "is_portal", False))
    if emission is None:  # nodes the preview does not apply (light_nodes.py)
        return LightInput(name, data.type.lower(), kw, portal=portal,
                          unapplied=("its shader nodes (only an Emission node's own Color and Strength are applied)",))
    return LightInput(name, data.type.lower(), kw, portal=portal, emits_nothing=emission.nothing)


# --------------------------------------------------------------------------
# Reading the scene
# --------------------------------------------------------------------------


def read_camera(scene, depsgraph, width: int, height: int, camera_object=None) -> tuple[CameraInput, list[str]]:
    """The scene camera (or `camera_object`, a multiview render's camera of one view), evaluated (so
    animated lens or constraints count)."""
    ob = scene.camera if camera_object is None else camera_object
    if ob is None:
        raise PreviewError(f"scene '{scene.name}' has no active camera: add one and set it as the scene camera")
    if ob.type != "CAMERA":
        kind = ob.bl_rna.properties["type"].enum_items[ob.type].name.lower()  # as the UI
        raise PreviewError(f"the scene camera '{ob.name}' is {'an' if kind[0] in 'aeiou' else 'a'} {kind} "
                           "object, which the preview cannot look through: set a camera object as the scene camera")
    evaluated = ob.evaluated_get(depsgraph)
    try:
        camera, warnings = camera_input(evaluated.data, evaluated.matrix_world, width, height,
                                        scene.render.pixel_aspect_y / scene.render.pixel_aspect_x)
    except PreviewError as error:  # named: timeline markers may switch between several cameras
        raise PreviewError(f"scene camera '{ob.name}': {error}") from None
    if evaluated.data.dof.use_dof:  # Cycles blurs the silhouettes
        warnings.append(f"the depth of field of camera '{ob.name}' is ignored by the preview: it renders "
                        "a pinhole camera, everything in focus")
    return camera, warnings


def read_lights(depsgraph, visibility: RenderVisibility | None = None, instanced: set | None = None) -> list[LightInput]:
    """Render-visible scene lights, instanced ones too (a light in an instanced collection lights the
    scene in Cycles): the render-visibility rules of meshes (render_visibility.py), from object_instances.
    `visibility`: the view layer's visibility table when the caller has one. `instanced`: a set that
    gets the original pointers of the instanced lights the viewport made (hidden_light_warnings)."""
    visibility = RenderVisibility(depsgraph) if visibility is None else visibility
    lights = []
    for inst in bulk_instances.light_entries(depsgraph):
        ob = inst.object
        if ob.type != "LIGHT":
            continue
        parent = inst.parent if inst.is_instance else None
        if parent is not None and instanced is not None:
            instanced.add(ob.original.as_pointer())
        if not entry_visible(visibility, parent, ob):  # a light is no instancer: the collection rules and
            continue  # the vertex/face-instancing parent's
        name = ob.original.name if parent is None else f"{ob.original.name} (instanced by {parent.original.name})"
        light = light_input(name, ob.data, inst.matrix_world)
        if light is not None:
            lights.append(replace(light, unapplied=unapplied_light_settings(ob) + light.unapplied,
                                  no_diffuse=diffuse_switched_off(ob, parent)))
    return lights


def check_lights_present(inputs: SceneInputs, depsgraph, mode: str, scene_name: str) -> None:
    """A light mode needs a light: without one read, a PreviewError naming why, unless the view layer's
    lights are keyed off for renders (their Disable in Renders animated): an animation that turns its
    lights off renders those frames dark with a warning, as for lights keyed to emit nothing, rather than
    stopping. "auto" renders AO then."""
    if inputs.lights or mode == "auto":
        return
    switched_off = [] if inputs.hidden_lights else lights_keyed_off(depsgraph)
    if not switched_off:
        why = f"scene '{scene_name}' " + ("has no light the preview can see: " + "; ".join(inputs.hidden_lights)
                                          if inputs.hidden_lights else "has no render-visible light")
        remedy = "" if inputs.hidden_lights else ": add one or use mode 'ao'"
        raise NoLightError(f"mode '{mode}' needs a light, but {why}{remedy}", why, bool(inputs.hidden_lights))
    quoted = ", ".join(f"'{name}'" for name in switched_off)
    inputs.warnings.append(f"light {quoted} is not visible in renders on this frame (its Disable in Renders is "
                           "keyed)" if len(switched_off) == 1 else
                           f"lights {quoted} are not visible in renders on this frame (their Disable in Renders "
                           "is keyed)")


def lights_keyed_off(depsgraph) -> list[str]:
    """The view layer's lights disabled in renders on this frame by their animation (a collection's Disable
    in Renders is not animatable): the animation turned them off."""
    return sorted(ob.name for ob in depsgraph.view_layer.objects
                  if ob.type == "LIGHT" and ob.hide_render and "hide_render" in animated_paths(ob))


def unapplied_light_settings(ob) -> tuple[str, ...]:
    """What Cycles would apply and the preview does not, named so a warning can say so: the object's
    light and shadow linking (Blender 4.0+: which objects the light lights, which block it). The
    light's own shader nodes are named by light_input."""
    found = []
    linking = getattr(ob, "light_linking", None)
    for attribute, what in (("receiver_collection", "light linking"), ("blocker_collection", "shadow linking")):
        collection = getattr(linking, attribute, None)
        if collection is not None:
            found.append(f"{what} (collection '{collection.name}')")
    return tuple(found)


def diffuse_switched_off(ob, instancer=None) -> str:
    """Why the light lights no diffuse surface in Cycles, "" when it does: its Ray Visibility > Diffuse
    is off, or its instancer's (Cycles ANDs an instance's ray visibility with its instancer's). Diffuse
    surfaces are all the preview shades (N.L), so such a light is left out, as one that emits nothing
    is (docs/choices.md#lights-with-diffuse-ray-visibility-off-are-left-out)."""
    if not getattr(ob, "visible_diffuse", True):
        return "its Ray Visibility > Diffuse is off"
    if instancer is not None and not getattr(instancer, "visible_diffuse", True):  # evaluated, as `ob`: keyed
        return f"its instancer '{instancer.original.name}''s Ray Visibility > Diffuse is off"
    return ""


def read_scene(scene, depsgraph, width: int, height: int, lights: bool = True,
               camera: CameraInput | None = None) -> SceneInputs:
    """Camera and lights of the evaluated scene for a width x height preview (`lights` False: an AO
    frame, which needs none, so lights hidden in the viewport are not looked for). `camera`: the view
    a render engine set (its region or the viewport's), instead of the scene camera's whole frame.
    A render depsgraph holds the lights hidden in the viewport, so none is missed there."""
    warnings = []
    if scene.render.use_border and camera is None:  # a final render crops or blanks outside the region
        warnings.append("the Render Region (Output > Format) is ignored by the preview: it renders the whole frame")
    if scene.render.use_motion_blur:
        warnings.append("motion blur is ignored by the preview: it renders the frame's instant")
    camera, camera_warnings = read_camera(scene, depsgraph, width, height) if camera is None else (camera, [])
    visibility = RenderVisibility(depsgraph)  # one table for the lights read and the hidden ones
    instanced: set[int] = set()
    read = read_lights(depsgraph, visibility, instanced)
    viewport = lights and depsgraph.mode != "RENDER"
    return SceneInputs(camera, read, width, height, warnings + camera_warnings,
                       hidden_light_warnings(depsgraph, visibility, instanced) if viewport else [])
