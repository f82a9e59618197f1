"""Per-sample shading pieces: robust ray offsets, cosine-weighted directions, light sampling."""
import numpy as np
from numba import njit

from .lights import AREA, AREA_TAN_HALF_SPREAD, SPOT, SPOT_INV_LEN_Z, SUN

TWO_PI = 2.0 * np.pi


OFFSET_RELATIVE = 2.0 ** -40  # ray start offset / the hit point's error scale: 8192 float64 roundings


@njit(cache=True, inline="always")
def offset_origin(p, n, error_scale):
    """A hit point p moved off its surface along the normal n by OFFSET_RELATIVE times its error scale
    (hit_frames._error_scale), as a tuple, after Wachter and Binder, "A Fast and Robust Method for
    Avoiding Self-Intersection" (Ray Tracing Gems, ch. 6): the offset scales with the point's error.
    Their 2^-15 bounds a float32 hit point; ours is float64 on float32 vertices, where that carried rays
    through thin roofs. 2^-40 clears the surface by 8192 float64 roundings at any magnitude; an absolute
    floor biased AO at small scales, and a bound from max |p_k| alone failed far from the origin."""
    step = error_scale * OFFSET_RELATIVE
    return p[0] + n[0] * step, p[1] + n[1] * step, p[2] + n[2] * step


LIGHT_END_RELATIVE = 2.0 ** -32  # how far short of a sampled light point a shadow ray ends, relative


@njit(cache=True, inline="always")
def short_of_light(p, direction, dist):
    """A shadow ray's tmax: the distance from p to the sampled light point, less a step off the light.
    A light lying on a surface (an area light flush with a ceiling) is reached at t = dist, where that
    surface is met too, within rounding, and would shadow everything. Cycles moves the light end off the
    light (ray_offset(ls->P, ls->Ng)); here the ray stops 2^-32 of (dist + the light point's largest
    coordinate) short: 2^21 float64 roundings, far more than the triangle test's t carries, far less
    than float32 geometry can place between a surface and the light. A sun's rays are unchanged."""
    if dist == np.inf:
        return dist
    largest = 0.0
    for k in range(3):
        largest = max(largest, abs(p[k] + direction[k] * dist))
    return max(0.0, dist - (dist + largest) * LIGHT_END_RELATIVE)


@njit(cache=True, inline="always")
def tangent_frame(n):
    """Two unit vectors completing n to an orthonormal basis (Duff et al. 2017, branchless ONB)."""
    sign = 1.0 if n[2] >= 0.0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]), (b, sign + n[1] * n[1] * a, -n[1])


@njit(cache=True, inline="always")
def cosine_direction(n, u1, u2, out):
    """A direction about unit normal n with density cos(theta)/pi (Malley's method)."""
    t, b = tangent_frame(n)
    r = np.sqrt(u1)
    phi = TWO_PI * u2
    x, y, z = r * np.cos(phi), r * np.sin(phi), np.sqrt(max(0.0, 1.0 - u1))
    for k in range(3):
        out[k] = x * t[k] + y * b[k] + z * n[k]


@njit(cache=True)
def sample_light(light, p, u1, u2):
    """(direction, distance, mask) from p to a sampled point of the light: the unit direction as a
    tuple, and the light's mask there (spot cone, area light's front side). The point p comes and the
    direction goes as tuples of floats: array arguments of a call pass seven words each and count
    references (docs/choices.md#the-light-sampler-on-tuples)."""
    kind = int(light[0])
    if kind == SUN:
        return _cone_direction(light, u1, u2), np.inf, 1.0
    q = _area_point(light, u1, u2) if kind == AREA else _disk_point(light, p, u1, u2)
    dx, dy, dz = q[0] - p[0], q[1] - p[1], q[2] - p[2]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    if dist == 0.0:
        return (dx, dy, dz), 0.0, 0.0
    to_light = (dx / dist, dy / dist, dz / dist)
    return to_light, dist, _light_mask(light, kind, to_light)


@njit(cache=True, inline="always")
def _light_mask(light, kind, to_light):
    """Spot cone with Cycles' smoothstep blend, in the light object's frame (lights._spot_frame). Area
    lights emit to their front (-Z) only, and with a Spread below 180 degrees into a cone weighted as
    Cycles' area_light_spread_attenuation (tan(spread/2) - tan(a) at angle a from the normal), divided by
    its value along the normal to stay in [0, 1]; a Spread of 0 keeps directions within 0.05 degrees."""
    cos_a = -(to_light[0] * light[4] + to_light[1] * light[5] + to_light[2] * light[6])
    if kind == SPOT:
        x = to_light[0] * light[11] + to_light[1] * light[12] + to_light[2] * light[13]
        y = to_light[0] * light[14] + to_light[1] * light[15] + to_light[2] * light[16]
        z = cos_a * light[SPOT_INV_LEN_Z]
        norm = np.sqrt(x * x + y * y + z * z)
        cos_a = z / norm if norm > 0.0 else 0.0
        if cos_a <= light[9]:
            return 0.0
        t = cos_a - light[9]
        if light[10] > 0.0 and t < light[10]:
            x = t / light[10]
            return x * x * (3.0 - 2.0 * x)
        return 1.0
    if kind == AREA:
        return _spread_mask(cos_a, light[AREA_TAN_HALF_SPREAD])
    return 1.0


@njit(cache=True, inline="always")
def _spread_mask(cos_a, tan_half_spread):
    """The area light's mask for light leaving it at angle a from its normal (_light_mask)."""
    if cos_a <= 0.0:
        return 0.0
    if tan_half_spread == np.inf:
        return 1.0
    if tan_half_spread == 0.0:
        return 1.0 if cos_a > 0.9999997 else 0.0
    tan_a = np.sqrt(max(0.0, 1.0 - cos_a * cos_a)) / cos_a
    return max(0.0, 1.0 - tan_a / tan_half_spread)


@njit(cache=True, inline="always")
def _cone_direction(light, u1, u2):
    """Towards the sun: uniform in the cone of half-angle angle/2 around minus its direction."""
    cos_max = light[8]
    cos_t = 1.0 - u1 * (1.0 - cos_max)
    sin_t = np.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    phi = TWO_PI * u2
    axis = (-light[4], -light[5], -light[6])
    t, b = tangent_frame(axis)
    c, s = np.cos(phi), np.sin(phi)
    return (sin_t * c * t[0] + sin_t * s * b[0] + cos_t * axis[0],
            sin_t * c * t[1] + sin_t * s * b[1] + cos_t * axis[1],
            sin_t * c * t[2] + sin_t * s * b[2] + cos_t * axis[2])


@njit(cache=True, inline="always")
def _disk_point(light, p, u1, u2):
    """A point on the disk of the light's radius facing p (a sphere light seen from p)."""
    radius = light[7]
    centre = (light[1], light[2], light[3])
    if radius <= 0.0:
        return centre
    ax, ay, az = p[0] - light[1], p[1] - light[2], p[2] - light[3]
    norm = np.sqrt(ax * ax + ay * ay + az * az)
    if norm == 0.0:
        return centre
    t, b = tangent_frame((ax / norm, ay / norm, az / norm))
    r = radius * np.sqrt(u1)
    phi = TWO_PI * u2
    c, s = np.cos(phi), np.sin(phi)
    return (centre[0] + r * (c * t[0] + s * b[0]), centre[1] + r * (c * t[1] + s * b[1]),
            centre[2] + r * (c * t[2] + s * b[2]))


@njit(cache=True, inline="always")
def _area_point(light, u1, u2):
    """A uniformly distributed point on the area light's square, rectangle, disk or ellipse."""
    if light[20] >= 2:  # disk or ellipse: concentric-free polar mapping, uniform in area
        r = np.sqrt(u1)
        phi = TWO_PI * u2
        su, sv = r * np.cos(phi), r * np.sin(phi)
    else:
        su, sv = 2.0 * u1 - 1.0, 2.0 * u2 - 1.0
    return (light[1] + su * light[11] + sv * light[14], light[2] + su * light[12] + sv * light[15],
            light[3] + su * light[13] + sv * light[16])
