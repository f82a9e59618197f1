"""Checks and conversions for everything that enters the library, done once before any kernel runs.

Kernels assume finite float32 triangles and finite float64 rays in C order; these functions make that
true or raise a ValueError that names the first bad index.
"""
import numbers

import numpy as np
from numba import njit, prange

from .jit.threads import thread_count

MIN_DIRECTION = 1e-20  # largest direction component allowed below this is rejected (see as_rays)
NEGLIGIBLE_COMPONENT = 2.0 ** -600  # a direction component below this times the largest is made 0
BLOCK = 4096  # rays a parallel task of the ray checks and of the float32 outputs takes


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


def as_rays(origins, directions, threads=None):
    """Origins and directions as C-contiguous (R, 3) float64 arrays; directions must be finite and non-zero.
    The checks are one compiled pass, parallel on `threads` (None: all)."""
    o = _as_points("origins", origins)
    d = _as_points("directions", directions)
    if o.shape != d.shape:
        raise ValueError(f"origins and directions must have the same shape (R, 3), got {o.shape} and {d.shape}")
    faults = np.full((-(-len(o) // BLOCK), 5), -1, np.int64)
    with thread_count(threads):
        _ray_faults(o, d, faults)  # NumPy's row reductions cost more than tracing
    firsts = [faults[faults[:, k] >= 0, k] for k in range(4)]  # blocks in ray order: the first is the first
    if any(len(f) for f in firsts):
        _raise_ray_fault(o, d, [int(f[0]) if len(f) else -1 for f in firsts])
    return o, without_negligible_components(d) if (faults[:, 4] > 0).any() else d


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


@njit(cache=True, parallel=True)
def _ray_faults(o, d, faults):
    """Per block b of BLOCK rays, faults[b] = [its first ray with a non-finite origin, with a non-finite
    direction, with a zero direction, with a direction shorter than MIN_DIRECTION (-1: none), 1 if some
    direction has a negligible component (else -1)]."""
    for b in prange(faults.shape[0]):
        _block_faults(o, d, faults[b], b * BLOCK, min(o.shape[0], (b + 1) * BLOCK))


@njit(cache=True)
def _block_faults(o, d, faults, start, stop):
    """_ray_faults for rays start..stop-1: a ray passes one cheap test (x * 0 is 0 only for a finite x),
    and only a ray that fails it is told apart fault by fault."""
    for r in range(start, stop):
        ax, ay, az = abs(d[r, 0]), abs(d[r, 1]), abs(d[r, 2])
        largest = max(ax, ay, az)
        finite = (o[r, 0] * 0.0 + o[r, 1] * 0.0 + o[r, 2] * 0.0 + ax * 0.0 + ay * 0.0 + az * 0.0) == 0.0
        if finite and largest >= MIN_DIRECTION and min(ax, ay, az) >= NEGLIGIBLE_COMPONENT * largest:
            continue
        finite_o = np.isfinite(o[r, 0]) and np.isfinite(o[r, 1]) and np.isfinite(o[r, 2])
        finite_d = np.isfinite(d[r, 0]) and np.isfinite(d[r, 1]) and np.isfinite(d[r, 2])
        for k, fault in enumerate((not finite_o, not finite_d, finite_d and largest == 0.0,
                                   finite_d and 0.0 < largest < MIN_DIRECTION)):
            if fault and faults[k] < 0:
                faults[k] = r
        for k in range(3):
            if abs(d[r, k]) < NEGLIGIBLE_COMPONENT * largest:
                faults[4] = 1


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
    per ray (a light's distance, say) and an empty interval is a valid answer there, not an error.
    A scalar is checked once, before it fills its array (ray 0 is named for a bad one)."""
    lo = _as_limit("tmin", tmin, count)
    hi = _as_limit("tmax", tmax, count)
    if np.isnan(lo).any() or np.isnan(hi).any():
        which, arr = ("tmin", lo) if np.isnan(lo).any() else ("tmax", hi)
        raise ValueError(f"{which} of ray {_first(np.isnan(arr))} is NaN")
    if (lo < 0).any():
        raise ValueError(f"tmin must be >= 0; ray {_first(lo < 0)} has tmin < 0")
    if np.isinf(lo).any():
        raise ValueError(f"tmin must be finite; ray {_first(np.isinf(lo))} has tmin = inf")
    return tuple(np.full(count, float(x)) if x.ndim == 0 else x for x in (lo, hi))


def _first(bad):
    """The first True of a check's result (0 for a scalar's)."""
    return int(np.flatnonzero(bad)[0]) if bad.ndim else 0


def is_real_dtype(dtype):
    """Whether an array of this dtype holds real numbers (floats or integers; not bool, complex, str, object)."""
    return np.issubdtype(dtype, np.floating) or np.issubdtype(dtype, np.integer)


def as_real_array(name, value):
    """`value` as a float64 array, or a ValueError naming `name` when it does not hold real numbers: numpy
    would parse strings of digits, cut complex values to their real part with only a warning, take bools
    as 0 and 1, and word its own errors without the argument's name."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):  # ragged nesting
        raise ValueError(f"{name} must be an array of numbers, got {value!r:.80}") from None
    if not is_real_dtype(arr.dtype):
        got = f"{value!r:.80}" if arr.dtype == object else f"dtype {arr.dtype}"
        raise ValueError(f"{name} must be an array of numbers, got {got}")
    return arr.astype(np.float64)


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
        return arr
    if arr.shape != (count,):
        raise ValueError(f"{name} must be a scalar or have shape ({count},), got {arr.shape}")
    return np.ascontiguousarray(arr)


def hits_as_float32(t, prim, u, v, lo, hi, threads=None):
    """The float64 hit distances and barycentrics (R,) as the float32 `t`, `u`, `v` queries return, in
    one compiled pass, parallel on `threads`; lo, hi the rays' (R,) limits (as_ray_limits). A hit beyond
    float32's range raises ValueError naming the first such ray (inf would read as a miss). A positive t
    below float32's smallest subnormal becomes that subnormal, not 0, and a t that rounds onto or past
    the ray's tmin or tmax moves one float32 step back inside the open interval."""
    out = (np.empty(len(t), np.float32), np.empty(len(t), np.float32), np.empty(len(t), np.float32))
    first_beyond = np.full(-(-len(t) // BLOCK), -1, np.int64)
    with thread_count(threads):
        _hits_to_float32(t, prim, u, v, lo, hi, out, first_beyond)
    beyond = first_beyond[first_beyond >= 0]
    if len(beyond):
        r = int(beyond[0])
        raise ValueError(f"ray {r} hits at t = {t[r]:.6g}, beyond float32's range for t: scale its direction "
                         "(t is in units of the direction's length)")
    return out


@njit(cache=True, parallel=True)
def _hits_to_float32(t, prim, u, v, lo, hi, out, first_beyond):
    """hits_as_float32's pass by blocks of BLOCK rays; first_beyond[b] gets block b's first hit beyond
    float32's range (or stays -1)."""
    for b in prange(first_beyond.shape[0]):
        first_beyond[b] = _convert_block(t, prim, u, v, lo, hi, out, b * BLOCK, min(t.shape[0], (b + 1) * BLOCK))


@njit(cache=True)
def _convert_block(t, prim, u, v, lo, hi, out, start, stop):
    """Rays start..stop-1 of _hits_to_float32 (its own function: the parfor pass rejects a variable
    assigned twice in a prange body); returns the first hit beyond float32's range, or -1."""
    t32, u32, v32 = out
    first = -1
    for r in range(start, stop):
        u32[r], v32[r] = u[r], v[r]
        f = np.float32(t[r])
        if prim[r] >= 0:
            if f == np.inf:
                first = r if first < 0 else first
            elif f == 0.0 or np.float64(f) >= hi[r] or np.float64(f) <= lo[r]:
                f = _inside_limits(f, lo[r], hi[r])
        t32[r] = f
    return first


@njit(cache=True)
def _inside_limits(f, lo, hi):
    """A hit's finite float32 t moved as hits_as_float32 says."""
    if f == 0.0:
        f = _next_float32(f, True)
    if np.float64(f) >= hi:
        f = _next_float32(f, False)
    if np.float64(f) <= lo:
        f = _next_float32(f, True)
    return f


@njit(cache=True)
def _next_float32(f, up):
    """np.nextafter(f, +inf if up else -inf) for a float32 f >= 0 (f > 0 when down), by its bit pattern.
    Not clipping.next_float32: its inlined `view` of an argument assigned twice fails Numba's checks."""
    bits = np.float32(f).view(np.int32)
    return np.int32(bits + 1 if up else bits - 1).view(np.float32)
