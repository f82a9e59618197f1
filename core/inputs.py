"""Checks and conversions for everything that enters the library, done once before any kernel runs.

Kernels assume finite float32 triangles and finite float64 rays in C order; these functions make that
true or raise a ValueError that names the first bad index.
"""
import numbers

import numpy as np
from numba import njit

MIN_DIRECTION = 1e-20  # largest direction component allowed below this is rejected (see as_rays)
NEGLIGIBLE_COMPONENT = 2.0 ** -600  # a direction component below this times the largest is made 0


def as_number(name, value):
    """`value` as a float, or a ValueError naming `name` when it is not one real number (a string, an
    array of several values, None or a bool): comparing those would raise TypeError or numpy's
    "truth value of an array is ambiguous", which name nothing."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return float(value)


def check_image_size(width, height):
    """Width and height must be integers in [1, 32768] (bools are not sizes)."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not 1 <= v <= 1 << 15:
            raise ValueError(f"{name} must be an integer in [1, 32768], got {v!r}")


FLOAT32_MAX = float(np.finfo(np.float32).max)


def first_row_beyond_float32(rows):
    """Index of the first row of the finite (N, k) array `rows` holding a value beyond float32's range, or
    -1. Checked before the cast to float32, which would make such a value inf (with a numpy warning)."""
    if rows.dtype == np.float32 or rows.size == 0:
        return -1
    beyond = (np.abs(rows) > FLOAT32_MAX).any(axis=1)
    return int(np.argmax(beyond)) if beyond.any() else -1


def as_triangles(triangles):
    """Triangles as a C-contiguous (N, 3, 3) float32 array of finite vertex positions."""
    try:
        arr = np.asarray(triangles)
    except ValueError as error:  # ragged nested lists: numpy's message names no argument
        raise ValueError(f"triangles must be an (N, 3, 3) array of numbers (N triangles, 3 vertices, xyz): "
                         f"{error}") from None
    if arr.ndim != 3 or arr.shape[1:] != (3, 3):
        raise ValueError(f"triangles must have shape (N, 3, 3) (N triangles, 3 vertices, xyz), got {arr.shape}")
    if not is_real_dtype(arr.dtype):
        raise ValueError(f"triangles must be real numbers (float32 or float64; integers are taken too), got dtype "
                         f"{arr.dtype}")
    if len(arr) and not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr).reshape(len(arr), 9).all(axis=1))[0])
        raise ValueError(f"triangle {bad} has a non-finite vertex coordinate (NaN or inf): {arr[bad].tolist()}")
    bad = first_row_beyond_float32(arr.reshape(len(arr), 9))
    if bad >= 0:
        raise ValueError(f"triangle {bad} has a vertex coordinate beyond float32's range (+-{FLOAT32_MAX:.4g}), "
                         f"in which triangles are stored: {arr[bad].tolist()}")
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    return arr


def as_rays(origins, directions):
    """Origins and directions as C-contiguous (R, 3) float64 arrays; directions must be finite and non-zero."""
    o = _as_points("origins", origins)
    d = _as_points("directions", directions)
    if o.shape != d.shape:
        raise ValueError(f"origins and directions must have the same shape (R, 3), got {o.shape} and {d.shape}")
    faults = _ray_faults(o, d)  # one compiled pass: NumPy's row reductions cost more than tracing
    if faults[:4].max() >= 0:
        _raise_ray_fault(o, d, faults)
    return o, without_negligible_components(d) if faults[4] else d


def _raise_ray_fault(o, d, faults):
    """The error for the first fault _ray_faults found, in the order the checks are made."""
    bad_origin, bad_direction, zero, short = (int(f) for f in faults[:4])
    if bad_origin >= 0:
        raise ValueError(f"origin of ray {bad_origin} is not finite (NaN or inf): {o[bad_origin].tolist()}")
    if bad_direction >= 0:
        raise ValueError(f"direction of ray {bad_direction} is not finite (NaN or inf): {d[bad_direction].tolist()}")
    if zero >= 0:
        raise ValueError(f"ray {zero} has a zero direction vector")
    # t is in units of the direction and returned as float32: a direction this short would put
    # hits at t beyond float32's range (subnormal directions).
    raise ValueError(f"ray {short} has a direction too short to trace ({d[short].tolist()}, every component "
                     f"below {MIN_DIRECTION:g}): normalise it")


@njit(cache=True)
def _ray_faults(o, d):
    """[first ray with a non-finite origin, with a non-finite direction, with a zero direction, with a
    direction shorter than MIN_DIRECTION (-1: none), 1 if some direction has a negligible component]."""
    faults = np.full(5, -1, np.int64)
    faults[4] = 0
    for r in range(o.shape[0]):
        largest = max(abs(d[r, 0]), abs(d[r, 1]), abs(d[r, 2]))
        finite_o = np.isfinite(o[r, 0]) and np.isfinite(o[r, 1]) and np.isfinite(o[r, 2])
        finite_d = np.isfinite(d[r, 0]) and np.isfinite(d[r, 1]) and np.isfinite(d[r, 2])
        for k, fault in enumerate((not finite_o, not finite_d, finite_d and largest == 0.0,
                                   finite_d and 0.0 < largest < MIN_DIRECTION)):
            if fault and faults[k] < 0:
                faults[k] = r
        for k in range(3):
            if abs(d[r, k]) < NEGLIGIBLE_COMPONENT * largest:
                faults[4] = 1
    return faults


def without_negligible_components(d):
    """Directions (..., 3) with every component below NEGLIGIBLE_COMPONENT times the largest set to 0.
    Such a component turns the ray by under 1e-180 radians, but its reciprocal overflows (0 * inf in a
    plane test) and the triangle test's shear term underflows on one triangle and not its neighbour,
    so a ray starting on a split plane could slip through a closed mesh. A zero component is a case
    every step handles."""
    negligible = np.abs(d) < NEGLIGIBLE_COMPONENT * np.abs(d).max(axis=-1, keepdims=True)
    return np.where(negligible, 0.0, d) if negligible.any() else d


def as_ray_limits(tmin, tmax, count):
    """tmin and tmax (scalars or (R,) arrays) as (R,) float64 arrays: tmin finite and >= 0, neither NaN.
    A ray whose interval is empty (tmax <= tmin, tmax = -inf included) misses: callers compute tmax
    per ray (a light's distance, say) and an empty interval is a valid answer there, not an error."""
    lo = _as_limit("tmin", tmin, count)
    hi = _as_limit("tmax", tmax, count)
    if np.isnan(lo).any() or np.isnan(hi).any():
        which, arr = ("tmin", lo) if np.isnan(lo).any() else ("tmax", hi)
        raise ValueError(f"{which} of ray {int(np.flatnonzero(np.isnan(arr))[0])} is NaN")
    if (lo < 0).any():
        raise ValueError(f"tmin must be >= 0; ray {int(np.flatnonzero(lo < 0)[0])} has tmin < 0")
    if np.isinf(lo).any():
        raise ValueError(f"tmin must be finite; ray {int(np.flatnonzero(np.isinf(lo))[0])} has tmin = inf")
    return lo, hi


def is_real_dtype(dtype):
    """Whether an array of this dtype holds real numbers (floats or integers; not bool, complex, str, object)."""
    return np.issubdtype(dtype, np.floating) or np.issubdtype(dtype, np.integer)


def _as_points(name, values):
    arr = np.asarray(values)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (R, 3), got {arr.shape}")
    if not is_real_dtype(arr.dtype):
        raise ValueError(f"{name} must be a float array, got dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _as_limit(name, value, count):
    try:
        arr = np.asarray(value)
        if not is_real_dtype(arr.dtype):
            raise TypeError
        arr = arr.astype(np.float64)
    except (TypeError, ValueError):  # None or a string would become NaN or a silently parsed number
        raise ValueError(f"{name} must be a number or an array of numbers, got {value!r}") from None
    if arr.ndim == 0:
        return np.full(count, float(arr))
    if arr.shape != (count,):
        raise ValueError(f"{name} must be a scalar or have shape ({count},), got {arr.shape}")
    return np.ascontiguousarray(arr)


def hit_distances_as_float32(t, prim, tmin=0.0, tmax=np.inf):
    """The float64 hit distances as the float32 `t` queries return. A hit beyond float32's range raises
    ValueError naming the first such ray (inf would read as a miss). A positive t below float32's smallest
    subnormal becomes that subnormal, not 0, and a t that rounds onto or past the ray's tmin or tmax
    (scalars or (R,) arrays) moves one float32 step back inside the open interval."""
    with np.errstate(over="ignore"):
        out = t.astype(np.float32)
    hit = prim >= 0
    bad = hit & (out == np.inf)
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise ValueError(f"ray {r} hits at t = {t[r]:.6g}, beyond float32's range for t: scale its direction "
                         "(t is in units of the direction's length)")
    out[hit & (out == 0.0)] = np.nextafter(np.float32(0), np.float32(1))
    lo, hi = (np.broadcast_to(np.asarray(x, np.float64), out.shape) for x in (tmin, tmax))
    past = hit & (out >= hi)
    out[past] = np.nextafter(out[past], np.float32(-np.inf))
    before = hit & (out <= lo)
    out[before] = np.nextafter(out[before], np.float32(np.inf))
    return out
