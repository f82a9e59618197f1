"""Per-instance affine arithmetic in compiled parallel passes: inverses, the invertibility test and
world boxes.

A scattered scene has up to millions of instances; NumPy's stacked `linalg.inv`, `det` and the
eight-corner `einsum` ran per matrix or through temporaries of eight corners an instance, and took
longer than the top-level tree's build (docs/choices.md#instance-arithmetic-in-compiled-passes).
Each function here is one pass over the instances, one matrix at a time, with no temporaries.
"""
import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def affine_inverses(o2w):
    """(I, 3, 4) float64: the top three rows of each affine matrix's inverse. The 3x3 part is inverted
    by its adjugate over the determinant (exact for a 3x3 up to rounding, no pivoting needed: callers
    reject matrices the relative determinant test calls singular); the translation is -A^-1 t."""
    n = o2w.shape[0]
    out = np.empty((n, 3, 4))
    for i in prange(n):
        m = o2w[i]
        c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
        c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
        c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
        det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
        r = 1.0 / det
        inv = out[i]
        inv[0, 0], inv[1, 0], inv[2, 0] = c00 * r, c01 * r, c02 * r
        inv[0, 1] = (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) * r
        inv[1, 1] = (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) * r
        inv[2, 1] = (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) * r
        inv[0, 2] = (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) * r
        inv[1, 2] = (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) * r
        inv[2, 2] = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) * r
        for j in range(3):
            inv[j, 3] = -(inv[j, 0] * m[0, 3] + inv[j, 1] * m[1, 3] + inv[j, 2] * m[2, 3])
    return out


@njit(cache=True, parallel=True)
def relative_determinants(o2w):
    """(I,) float64: |det A| over the product of A's column lengths (A the 3x3 part), which is 1 for a
    rotation times any scale and 0 for a singular A (Hadamard's inequality bounds it by 1)."""
    n = o2w.shape[0]
    out = np.empty(n)
    for i in prange(n):
        m = o2w[i]
        det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) + m[0, 1] * (m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2])
               + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
        scale = 1.0
        for k in range(3):
            scale *= np.sqrt(m[0, k] * m[0, k] + m[1, k] * m[1, k] + m[2, k] * m[2, k])
        out[i] = abs(det) / scale if scale > 0.0 else 0.0
    return out


@njit(cache=True, parallel=True)
def affine_boxes(bounds, o2w, origin):
    """(K, 6) float64 boxes, relative to `origin` (3,), of object-space boxes `bounds` (K, 6) under
    `o2w` (K, 4, 4), as if each matrix's translation were shifted by -origin first: per
    world axis the translation plus, per object axis, the smaller / larger of the two box ends times
    the matrix entry (Arvo, "Transforming Axis-Aligned Bounding Boxes", Graphics Gems 1990), which is
    the min / max over the eight transformed corners. A box with a non-finite end gives NaN (an empty
    box to every comparison), as the corners' arithmetic did."""
    n = bounds.shape[0]
    out = np.empty((n, 6))
    for i in prange(n):
        b, m = bounds[i], o2w[i]
        finite = True
        for k in range(6):
            finite &= np.isfinite(b[k])
        for j in range(3):
            lo = hi = m[j, 3] - origin[j]
            for k in range(3):
                a, z = m[j, k] * b[k], m[j, k] * b[k + 3]
                lo += min(a, z)
                hi += max(a, z)
            out[i, j], out[i, j + 3] = (lo, hi) if finite else (np.nan, np.nan)
    return out
