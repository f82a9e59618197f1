"""Lights mirroring Blender's point, sun, spot and area lights, packed into rows for the kernels.

Soft shadows come from sampling the light's extent (a point or spot light's radius, a sun's angular
diameter, an area light's shape); cast_shadow=False lights every surface facing it without a shadow ray.
"""
import numpy as np

from ..inputs import as_number, as_real_array, without_negligible_components

POINT, SUN, SPOT, AREA = 0, 1, 2, 3
AREA_SHAPES = {"SQUARE": 0, "RECTANGLE": 1, "DISK": 2, "ELLIPSE": 3}

# Packed row: kind, position(3), direction(3) (spot: its cone's axis, _spot_frame's W), radius,
# cos_half_angle, spot_cos (area: tan of half its spread), spot_smooth, axis_u(3), axis_v(3) (area: half
# extents; spot: the first two rows of its axes' inverse), spot_inv_len_z, no_shadow, delta, shape, color(3)
ROW = 24
AREA_TAN_HALF_SPREAD, SPOT_INV_LEN_Z, NO_SHADOW, DELTA, COLOR = 9, 17, 18, 19, 21
COLOR_MAX = float(np.finfo(np.float32).max)  # a pixel is at most its lights' largest colour component
FULL_SPREAD = np.pi + 1e-6  # Blender's 180 degrees, a float32 pi, is a little above float64's


class Light:
    """One light. Use the constructors `point`, `sun`, `spot`, `area`."""

    def __init__(self, kind, color, power, cast_shadow=True, **params):
        rgb = _floats(color)
        if rgb.shape != (3,) or not np.isfinite(rgb).all() or (rgb < 0).any():
            raise ValueError(f"light color must be 3 finite non-negative numbers (r, g, b), got {color!r}")
        if (rgb > COLOR_MAX).any():  # the image is float32: a larger colour made inf pixels
            raise ValueError(f"light color components must be at most {COLOR_MAX:.4g} (the float32 image's "
                             f"range), got {color!r}")
        color = rgb
        if not (np.isfinite(as_number("light power", power)) and power >= 0):
            raise ValueError(f"light power must be finite and >= 0, got {power}")
        if not isinstance(cast_shadow, (bool, np.bool_)):
            raise ValueError(f"light cast_shadow must be True or False, got {cast_shadow!r}")
        self.kind, self.color, self.power, self.params = kind, color, float(power), params
        self.cast_shadow = bool(cast_shadow)

    @classmethod
    def point(cls, position, radius=0.0, power=1000.0, color=(1.0, 1.0, 1.0), cast_shadow=True):
        return cls(POINT, color, power, cast_shadow, position=_vector("point light position", position),
                   radius=_non_negative("point light radius", radius))

    @classmethod
    def sun(cls, direction, angle=0.0, strength=1.0, color=(1.0, 1.0, 1.0), cast_shadow=True):
        """`direction` is the direction the light travels (Blender: matrix_world @ (0, 0, -1))."""
        angle = _at_most_half_turn("sun angle", _non_negative("sun angle", angle))
        return cls(SUN, color, strength, cast_shadow, direction=_unit("sun direction", direction), angle=angle)

    @classmethod
    def spot(cls, position, direction, spot_size, spot_blend=0.15, radius=0.0, power=1000.0,
             color=(1.0, 1.0, 1.0), cast_shadow=True, axes=None):
        """axes: optional 3x3 matrix whose columns are the light object's X, Y, Z axes in world space,
        scale included (Blender's matrix_world.to_3x3()), with `direction` along minus its Z. The
        cone is then taken in the object's own frame, as Cycles does (spot_light_to_local): a
        non-uniform scale makes it elliptical."""
        spot_size = _at_most_half_turn("spot_size", _positive("spot_size", spot_size))
        if not 0.0 <= as_number("spot_blend", spot_blend) <= 1.0:
            raise ValueError(f"spot_blend must be in [0, 1], got {spot_blend}")
        direction = _unit("spot direction", direction)
        return cls(SPOT, color, power, cast_shadow, position=_vector("spot position", position),
                   direction=direction, spot_size=float(spot_size), spot_blend=float(spot_blend),
                   radius=_non_negative("spot radius", radius), frame=_spot_frame(direction, axes))

    @classmethod
    def area(cls, matrix_world, shape="SQUARE", size=1.0, size_y=None, power=1000.0, color=(1.0, 1.0, 1.0),
             cast_shadow=True, spread=np.pi):
        """An area light in its object's XY plane, emitting along its -Z (as in Blender). `spread`
        (radians, 0 to pi): Blender's Spread, the cone its light leaves each point in (see
        shading._light_mask)."""
        m = _floats(matrix_world)
        if m.shape != (4, 4) or not np.isfinite(m).all():
            raise ValueError(f"area light matrix_world must be a finite 4x4 matrix, got {matrix_world!r}")
        if not np.array_equal(m[3], (0.0, 0.0, 0.0, 1.0)):
            raise ValueError(f"area light matrix_world must be affine (bottom row 0 0 0 1), got {m[3].tolist()}")
        if not isinstance(shape, str) or shape not in AREA_SHAPES:
            raise ValueError(f"area light shape must be one of {sorted(AREA_SHAPES)}, got {shape!r}")
        for k, name in enumerate("XYZ"):  # X, Y span the light, -Z is where it emits
            if not np.linalg.norm(m[:3, k]) > 0.0:
                raise ValueError(f"area light matrix_world has a zero {name} axis (zero scale): it has no "
                                 "extent or no direction to emit in")
        if _collapsed(m[:3, :3]):
            raise ValueError("area light matrix_world has parallel axes (a sheared or collapsed scale): the "
                             "light has no area, or emits along its own plane")
        size = _positive("area light size", size)
        size_y = size if size_y is None or shape in ("SQUARE", "DISK") else _positive("area light size_y", size_y)
        spread = _at_most_half_turn("area light spread", _non_negative("area light spread", spread))
        return cls(AREA, color, power, cast_shadow, matrix_world=m, shape=shape, size=size, size_y=size_y,
                   spread=spread)

    def translated(self, offset):
        """The same light in a frame whose origin is at `offset` (3 finite numbers; the moved light must be
        finite too)."""
        offset = _vector("offset", offset)
        params = dict(self.params)
        with np.errstate(over="ignore"):  # an overflow to inf is named below
            if "position" in params:
                params["position"] = _vector("the translated light's position", params["position"] - offset)
            if "matrix_world" in params:
                params["matrix_world"] = params["matrix_world"].copy()
                params["matrix_world"][:3, 3] = _vector("the translated light's position",
                                                        params["matrix_world"][:3, 3] - offset)
        return Light(self.kind, self.color, self.power, self.cast_shadow, **params)

    def packed(self):
        """The light as one float64 row for the kernels (see ROW)."""
        row = np.zeros(ROW)
        p = self.params
        row[0] = self.kind
        row[COLOR:COLOR + 3] = self.color
        row[NO_SHADOW] = 0.0 if self.cast_shadow else 1.0
        if self.kind in (POINT, SPOT):
            row[1:4], row[7] = p["position"], p["radius"]
        if self.kind == SUN:
            row[4:7], row[8] = p["direction"], np.cos(p["angle"] / 2.0)
        if self.kind == SPOT:  # row[4:7]: the cone's axis in the object's frame (_spot_frame's W)
            row[9] = np.cos(p["spot_size"] / 2.0)
            row[10] = (1.0 - row[9]) * p["spot_blend"]  # Cycles' spot_smooth
            row[11:14], row[14:17], row[4:7], row[SPOT_INV_LEN_Z] = p["frame"]
        if self.kind == AREA:
            m = p["matrix_world"]
            row[1:4] = m[:3, 3]
            row[4:7] = -m[:3, 2] / np.linalg.norm(m[:3, 2])  # emits along -Z
            row[11:14] = m[:3, 0] * p["size"] / 2.0
            row[14:17] = m[:3, 1] * p["size_y"] / 2.0
            row[20] = AREA_SHAPES[p["shape"]]
            row[AREA_TAN_HALF_SPREAD] = np.inf if p["spread"] >= np.pi else np.tan(p["spread"] / 2.0)
        row[DELTA] = 1.0 if _has_no_extent(self.kind, row) else 0.0
        return row

    def __repr__(self):
        names = {POINT: "point", SUN: "sun", SPOT: "spot", AREA: "area"}
        return f"Light.{names[self.kind]}(power={self.power}, color={self.color.tolist()})"


def _has_no_extent(kind, row):
    """A point or spot light of radius 0, or a sun whose half angle's cosine rounds to 1: every sample of it
    is the same ray, so none are drawn and later samples repeat the first one's."""
    if kind in (POINT, SPOT):
        return row[7] <= 0.0
    return kind == SUN and row[8] == 1.0


def _spot_frame(direction, axes):
    """(U, V, W, |r2|): the rows r0, r1 of the inverse of the spot's object axes and W = -r2 / |r2|,
    so that for a direction t towards the light, (t.U, t.V, -(t.W) |r2|) are its coordinates in the
    object's frame (shading._light_mask), as Cycles' spot_light_to_local takes them: only the inverse
    puts a sheared spot's cone where Cycles does. Without axes, any orthonormal frame (a round cone)."""
    if axes is None:
        u = np.cross(direction, (1.0, 0.0, 0.0) if abs(direction[0]) < 0.9 else (0.0, 1.0, 0.0))
        u /= np.linalg.norm(u)
        return u, np.cross(direction, u), direction, 1.0
    a = _floats(axes)
    if a.shape != (3, 3) or not np.isfinite(a).all():
        got = f"shape {a.shape}" if a.size else repr(axes)  # empty: not numbers (_floats)
        raise ValueError(f"spot axes must be a finite 3x3 matrix (columns X, Y, Z), got {got}")
    lengths = np.linalg.norm(a, axis=0)
    if not (lengths > 0.0).all():
        raise ValueError("spot axes have a zero-length axis (zero scale): the cone is undefined")
    if _collapsed(a):
        raise ValueError("spot axes are parallel (a sheared or collapsed scale): the cone is undefined")
    if np.dot(-a[:, 2] / lengths[2], direction) < 1.0 - 1e-6:
        raise ValueError("spot direction must be minus the Z axis of its axes (Blender: the light's local -Z)")
    inverse = np.linalg.inv(a)
    r2 = np.linalg.norm(inverse[2])
    return inverse[0], inverse[1], -inverse[2] / r2, r2


def pack_lights(lights):
    """The lights that emit as an (L, ROW) float64 array. The shadow term is their mean
    (docs/architecture.md), so a light of power 0 or a black colour, which emits nothing, is left out
    rather than counted; when none emits, the first one's row, black, makes the term 0."""
    if isinstance(lights, Light):
        raise ValueError("lights must be a list of core.Light, got one Light: pass [light]")
    try:
        lights = list(lights)
    except TypeError:
        raise ValueError(f"lights must be a list of core.Light, got {lights!r}") from None
    for i, light in enumerate(lights):
        if not isinstance(light, Light):
            raise ValueError(f"lights[{i}] is not a core.Light: {light!r}")
    if not lights:
        return np.zeros((0, ROW))
    emitting = [light.packed() for light in lights if light.power > 0.0 and light.color.max() > 0.0]
    if emitting:
        return np.stack(emitting)
    row = lights[0].packed()
    row[COLOR:COLOR + 3] = 0.0  # power 0 is as dark as black
    return row[None]


def _floats(value):
    """`value` as a float64 array, or an empty one when it is not real numbers (inputs.as_real_array): the
    caller's shape check then names the argument with its own words."""
    try:
        return as_real_array("", value)
    except ValueError:
        return np.full(0, np.nan)


def _vector(name, v):
    arr = _floats(v).reshape(-1)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {arr.tolist() if arr.size else repr(v)}")
    return arr


def _collapsed(axes):
    """Whether the columns of a 3x3 matrix (a light's X, Y, Z axes) are (nearly) linearly dependent:
    the determinant of the unit columns, the volume they span, is ~0."""
    unit = axes / np.linalg.norm(axes, axis=0)
    return abs(np.linalg.det(unit)) < 1e-9


def _unit(name, v):
    v = _vector(name, v)
    largest = np.abs(v).max()
    if largest == 0:
        raise ValueError(f"{name} must not be the zero vector")
    v = v / largest  # first, so the norm cannot overflow (1e300 components)
    return without_negligible_components(v / np.linalg.norm(v))  # a shadow ray's direction (inputs.py)


def _non_negative(name, x):
    if not (np.isfinite(as_number(name, x)) and x >= 0):
        raise ValueError(f"{name} must be finite and >= 0, got {x}")
    return float(x)


def _at_most_half_turn(name, angle):
    """`angle` (radians) checked against Blender's limit of 180 degrees and clamped to np.pi: Blender
    stores 180 degrees as float32 pi, a hair above float64's, so its largest spot size, sun angle or
    spread must not be refused."""
    if angle > FULL_SPREAD:
        raise ValueError(f"{name} must be at most pi (180 degrees), got {angle}")
    return min(angle, np.pi)


def _positive(name, x):
    if not (np.isfinite(as_number(name, x)) and x > 0):
        raise ValueError(f"{name} must be finite and > 0, got {x}")
    return float(x)
