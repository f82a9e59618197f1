"""Checks of denoise_pixels' inputs, so that a bad array gets a ValueError naming it rather than NaN
pixels, a pixel written twice or numpy's own wording (the same rule as core/inputs.py)."""
import numbers

import numpy as np

from ..inputs import as_number, as_real_array, check_image_size

MAX_ITERATIONS = 15  # taps 2^14 pixels apart already span the largest image (32,768 pixels)


def checked_denoise_inputs(width, height, pixels, arrays, variance_decay, settings):
    """(pixels as int64, the five arrays as float64, variance_decay as float) or a ValueError naming the
    first bad argument. arrays: points, normals, sums (M, 3), sq_sums, counts (M,), in that order."""
    check_image_size(width, height)
    pixels = _checked_indices(width * height, pixels)
    m = len(pixels)
    checked = []
    for name, a, tail in zip(("points", "normals", "sums", "sq_sums", "counts"), arrays,
                             ((3,), (3,), (3,), (), ())):
        checked.append(_checked_rows(name, a, (m, *tail)))
    for name, a, what in (("sq_sums", checked[3], "sums of squares"), ("counts", checked[4], "samples taken")):
        if m and a.min() < 0:
            raise ValueError(f"{name} must be >= 0 ({what} per pixel), got {a.min()} at row {int(np.argmin(a))}")
    decay = as_number("variance_decay", variance_decay)
    if not 0.0 <= decay <= 1.0:
        raise ValueError(f"variance_decay must be in [0, 1] (0 for independent samples), got {decay}")
    _check_settings(settings)
    return pixels, checked, decay


def _checked_indices(n, pixels):
    """The pixel indices as int64: integers in [0, n), each once (a negative one would wrap round to
    another pixel, a repeated one would keep only its last row)."""
    pixels = np.asarray(pixels)
    if pixels.ndim != 1 or (pixels.size and pixels.dtype.kind not in "iu"):
        raise ValueError(f"pixels must be a 1-D array of integer pixel indices, got shape {pixels.shape}, "
                         f"dtype {pixels.dtype}")
    if pixels.size and (pixels.min() < 0 or pixels.max() >= n):
        raise ValueError(f"pixels must be in [0, {n}) (width x height), got {pixels.min()} to {pixels.max()}")
    pixels = pixels.astype(np.int64, copy=False)
    seen = np.zeros(n, np.bool_)  # a byte a pixel (counts would take eight)
    seen[pixels] = True
    if np.count_nonzero(seen) != len(pixels):
        ordered = np.sort(pixels)
        twice = int(ordered[np.flatnonzero(ordered[1:] == ordered[:-1])[0]])
        raise ValueError(f"pixels must name each pixel once, got pixel {twice} "
                         f"{int(np.count_nonzero(pixels == twice))} times")
    return pixels


def _checked_rows(name, values, shape):
    """`values` as a float64 array of `shape` with finite entries, or a ValueError naming the first bad row."""
    if np.shape(values) != shape:
        raise ValueError(f"{name} must have shape {shape} (one row per pixel), got {np.shape(values)}")
    arr = as_real_array(name, values)
    finite = np.isfinite(arr) if arr.ndim == 1 else np.isfinite(arr).all(axis=1)
    if not finite.all():
        row = int(np.argmin(finite))
        raise ValueError(f"{name} must be finite, got {arr[row].tolist()} at row {row}")
    return arr


def _check_settings(settings):
    """FilterSettings' four fields: iterations an integer in [0, MAX_ITERATIONS], the sigmas positive."""
    if not isinstance(settings, tuple) or len(settings) != 4:
        raise ValueError(f"settings must be a FilterSettings (iterations and three sigmas), got {settings!r}")
    iterations = settings[0]
    if isinstance(iterations, (bool, np.bool_)) or not isinstance(iterations, numbers.Integral) \
            or not 0 <= iterations <= MAX_ITERATIONS:
        raise ValueError(f"settings.iterations must be an integer in [0, {MAX_ITERATIONS}], got {iterations!r}")
    for field, value in zip(("sigma_luminance", "sigma_normal", "sigma_plane"), settings[1:]):
        v = as_number(f"settings.{field}", value)
        if not 0.0 < v < float("inf"):
            raise ValueError(f"settings.{field} must be a positive number, got {v}")
