"""The ray memo: one visibility bit per ray of every pixel, kept from frame to frame.

Ray (s, use) of a pixel keeps its visibility in bit s * (1 + lights) + use of the pixel's row (when that
fits in render_kernels.MEMO_BITS). A continued pixel takes last frame's bit for every ray that cannot
meet a changed box (`known[i]`: bits last frame traced; pixel_reuse.py says which pixels continue), and a
light without extent (lights.DELTA) repeats sample 0's bit in later samples. The sampling kernel
(render_kernels.py) reads and writes the bits through these helpers.
"""
from typing import NamedTuple

import numpy as np
from numba import njit

from ..trace.layout import NO_HIT
from ..trace.array_views import unowned
from .pixel_reuse import segment_meets_any

TRACE = 1 << 62  # an answer no ray has (prims are >= -1 or suspended, < -1): the ray must be traced


class RayMemo(NamedTuple):
    """The ray memo (module docstring): `bits` (M, B) uint8, `known` (M,) int64, `boxes` (K, 6) the
    changed boxes, `reused` (M,) int64 rays whose bit was taken from last frame, `repeated` (M,) int64
    rays of lights without extent that took sample 0's bit (not counted in PixelSums.rays), `pretraced`
    (M, lights) int8 the visibility of light k's ray traced beforehand (1 occluded, 0 clear, -1 none), and
    `weights` (M, lights) float64 that ray's weight (0 where the pixel takes no ray; NaN where no ray of
    light k was made beforehand; (0, lights) when none was), and `alone` (M,) int64 rays of a chunk traced
    in packets that no packet answered, which the sampling loop traced alone (sample_packets.trace_use;
    counted in PixelSums.rays as well)."""

    bits: np.ndarray
    known: np.ndarray
    boxes: np.ndarray
    reused: np.ndarray
    repeated: np.ndarray
    pretraced: np.ndarray
    weights: np.ndarray
    alone: np.ndarray


@njit(cache=True, inline="always")
def reused_visibility(memo, i, bit, origin, direction, tmax):
    """Last frame's answer for pixel i's ray `bit` (origin, direction, tmax): the any-hit prim's sign (0
    occluded, -1 clear) when pixel i traced that ray last frame (bit < known[i]) and the ray cannot meet
    a changed box, counted in reused[i]; else TRACE."""
    if bit >= 8 * memo.bits.shape[1] or bit >= memo.known[i]:
        return TRACE
    if segment_meets_any(origin, direction, 0.0, tmax, memo.boxes):
        return TRACE
    memo.reused[i] += 1
    return 0 if memo_bit(memo.bits, i, bit) else -1


@njit(cache=True, inline="always")
def keep_traced(memo, i, bit, prim):
    """Keep a traced ray's answer (any-hit prim: >= 0 occluded, -1 clear; a suspended prim keeps
    nothing) in pixel i's `bit` for the next frame, when the bit fits."""
    if bit < 8 * memo.bits.shape[1] and prim >= NO_HIT:
        keep_memo_bit(memo.bits, i, bit, prim >= 0)


@njit(cache=True, inline="always")
def memo_bit(bits, i, bit):
    """Whether pixel i's memo holds `bit` set (the ray was occluded)."""
    return bits[i, bit >> 3] & (1 << (bit & 7)) != 0


@njit(cache=True, inline="always")
def keep_memo_bit(bits, i, bit, occluded):
    """Set or clear pixel i's memo `bit`."""
    mask = np.uint8(1 << (bit & 7))
    bits[i, bit >> 3] = bits[i, bit >> 3] | mask if occluded else bits[i, bit >> 3] & ~mask


@njit(cache=True, inline="always")
def unowned_memo(memo):
    """The RayMemo as unowned views (array_views.py)."""
    return RayMemo(unowned(memo.bits), unowned(memo.known), unowned(memo.boxes), unowned(memo.reused),
                   unowned(memo.repeated), unowned(memo.pretraced), unowned(memo.weights), unowned(memo.alone))
