"""Keeping last frame's pixels whose rays cannot meet anything that changed.

With the last frame's camera, lights and settings, a pixel's samples are last frame's unless one of its
rays can reach a changed box (instance_signature.py): sample k of pixel p depends only on (p, k, seed)
and what its rays hit. Conservatively: the camera ray is the segment from clip start to the hit; AO
rays lie within ao_distance of the ray start; shadow rays end within the light's radius (point, spot)
or half-diagonal (area) of its centre, so the segment to the centre against the grown box covers them;
a sun's rays stay within D sin(angle/2) of its axis at distance D. Other pixels restart from sample 0,
so the image is the full render's. Changed boxes merge into at most MAX_BOXES unions.
"""
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .lights import AREA, NO_SHADOW, SUN

MAX_BOXES = 64
RELATIVE_PAD = 1e-6  # boxes grow by this times their size and distance from the origin: float32 rounding


class PixelState(NamedTuple):
    """A finished render's per-pixel state, enough to continue the next frame (PreviewRender.pixel_state).

    settings: everything besides geometry that the pixels depend on (bytes); signature: the scene's
    InstanceSignature (None: no reuse); the rest are the renderer's per-hit-pixel arrays (`checked`: the
    sample variance at each error-target check passed, convergence.py)."""

    settings: bytes
    signature: object
    pixels: np.ndarray
    depths: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    starts: np.ndarray
    sums: np.ndarray
    sq_sums: np.ndarray
    counts: np.ndarray
    ray_counts: np.ndarray
    memo: np.ndarray
    checked: np.ndarray


def settings_key(camera, width, height, mode, samples, ao_distance, lights, seed, sampler, error_target,
                 min_samples, ambient):
    """Bytes that differ whenever a setting that affects pixels differs (lights: packed rows)."""
    cam = np.concatenate([camera.matrix_world.ravel(), [camera.fov or 0.0, camera.ortho_scale or 0.0,
                                                         camera.clip_start, camera.clip_end, *camera.shift,
                                                         camera.pixel_aspect]])
    head = repr((width, height, mode, samples, ao_distance, seed, sampler, error_target, min_samples, ambient))
    return head.encode() + cam.tobytes() + np.ascontiguousarray(lights, np.float64).tobytes()


def prepared_boxes(boxes):
    """Changed boxes padded for rounding and merged down to MAX_BOXES: (K, 6) float64."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 6)
    boxes = boxes[(boxes[:, :3] <= boxes[:, 3:]).all(axis=1)]
    if len(boxes) > MAX_BOXES:
        boxes = _merged(boxes)
    size = boxes[:, 3:] - boxes[:, :3]
    reach = np.maximum(np.abs(boxes[:, :3]), np.abs(boxes[:, 3:]))
    pad = RELATIVE_PAD * (size + reach).max(axis=1, keepdims=True) + 1e-12
    return np.concatenate([boxes[:, :3] - pad, boxes[:, 3:] + pad], axis=1)


def _merged(boxes):
    """MAX_BOXES unions of runs of boxes sorted by centre along the widest axis."""
    centres = (boxes[:, :3] + boxes[:, 3:]) / 2
    axis = int(np.argmax(centres.max(axis=0) - centres.min(axis=0)))
    groups = np.array_split(boxes[np.argsort(centres[:, axis], kind="stable")], MAX_BOXES)
    return np.array([np.concatenate([g[:, :3].min(axis=0), g[:, 3:].max(axis=0)]) for g in groups])


@njit(cache=True, parallel=True)
def segments_touch(origins, directions, t0, t1, boxes):
    """(R,) bool: the segment origin + t * direction, t in [t0, t1], meets one of the boxes."""
    out = np.zeros(origins.shape[0], np.bool_)
    for r in prange(origins.shape[0]):
        out[r] = segment_meets_any(origins[r], directions[r], t0[r], t1[r], boxes)
    return out


@njit(cache=True, inline="always")
def segment_meets_any(o, d, t0, t1, boxes):
    """o + t d, t in [t0, t1], meets one of the boxes (K, 6)."""
    for k in range(boxes.shape[0]):
        if _segment_meets_box(o, d, t0, t1, boxes, k, 0.0):
            return True
    return False


@njit(cache=True, parallel=True)
def surface_rays_touch(starts, ao_radius, lights, boxes):
    """(P,) bool: some AO ray (ao_radius > 0: within that distance) or shadow ray to one of the lights
    (packed rows, lights.py) from the pixels' ray starts (hit_frames.surface_frames) can meet one
    of the boxes."""
    out = np.zeros(starts.shape[0], np.bool_)
    for p in prange(starts.shape[0]):
        o, d = starts[p], np.empty(3)
        for k in range(boxes.shape[0]):
            if _rays_meet_box(o, ao_radius, lights, boxes, k, d):
                out[p] = True
                break
    return out


@njit(cache=True)
def _rays_meet_box(o, ao_radius, lights, boxes, b, d):
    """Some AO or shadow ray from o can meet box b (d: scratch for a direction)."""
    if ao_radius > 0.0 and _distance_to_box(o, boxes, b) <= ao_radius:
        return True
    for i in range(lights.shape[0]):
        light = lights[i]
        kind = int(light[0])
        if light[NO_SHADOW] != 0.0:
            continue  # traces no shadow rays
        if kind == SUN:
            far = _farthest_corner(o, boxes, b)
            grow = far * np.sqrt(max(0.0, 1.0 - light[8] * light[8]))
            for k in range(3):
                d[k] = -light[4 + k]
            if _segment_meets_box(o, d, 0.0, far, boxes, b, grow):
                return True
            continue
        grow = light[7]
        if kind == AREA:
            grow = np.sqrt(light[11] ** 2 + light[12] ** 2 + light[13] ** 2) + \
                np.sqrt(light[14] ** 2 + light[15] ** 2 + light[16] ** 2)
        for k in range(3):
            d[k] = light[1 + k] - o[k]
        if _segment_meets_box(o, d, 0.0, 1.0, boxes, b, grow):
            return True
    return False


@njit(cache=True, inline="always")
def _segment_meets_box(o, d, t0, t1, boxes, i, grow):
    """Slab test of o + t d, t in [t0, t1], against box i grown by `grow`; a zero direction component
    tests the origin against that slab instead of dividing by zero. (Boxes by index: a row slice
    would update the array's shared reference count on every ray.)"""
    lo, hi = t0, t1
    for k in range(3):
        a, b = boxes[i, k] - grow, boxes[i, 3 + k] + grow
        if d[k] == 0.0:
            if o[k] < a or o[k] > b:
                return False
            continue
        ta, tb = (a - o[k]) / d[k], (b - o[k]) / d[k]
        if ta > tb:
            ta, tb = tb, ta
        lo, hi = max(lo, ta), min(hi, tb)
        if lo > hi:
            return False
    return True


@njit(cache=True, inline="always")
def _distance_to_box(o, boxes, i):
    s = 0.0
    for k in range(3):
        e = max(boxes[i, k] - o[k], 0.0, o[k] - boxes[i, 3 + k])
        s += e * e
    return np.sqrt(s)


@njit(cache=True, inline="always")
def _farthest_corner(o, boxes, i):
    s = 0.0
    for k in range(3):
        e = max(abs(boxes[i, k] - o[k]), abs(boxes[i, 3 + k] - o[k]))
        s += e * e
    return np.sqrt(s)
