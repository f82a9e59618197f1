"""What a frame's instances were, so the next frame can tell which parts of space changed.

A row of bytes per instance some ray can hit: a digest of its mesh's key and fingerprint, its matrix,
how its triangles were rounded (re-rounding moves a surface by an ulp, enough to put a kept ray start
behind it) and its ray visibility, with its world box minus `origin`. `changed_boxes`: the boxes of
rows present in only one of two frames; outside them both frames hold the same triangles.
"""
import hashlib
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .ray_visibility import stops_rays
from .two_level import transformed_boxes


class InstanceSignature(NamedTuple):
    """origin (3,) float64; rows (I,) void (digest + matrix bytes); boxes (I, 6) float64."""

    origin: np.ndarray
    rows: np.ndarray
    boxes: np.ndarray


def mesh_digest(key, fingerprint):
    """8 bytes naming a mesh's content: stable across frames, processes and builders."""
    return hashlib.blake2b(repr((key, fingerprint)).encode(), digest_size=8).digest()


def instance_signature(digests, bounds, mesh_of, o2w, origin, rounding, visibility):
    """The signature of a frame. digests: one 8-byte `mesh_digest` per mesh; bounds (M, 6) object-
    space boxes (inverted for a mesh with nothing to hit); mesh_of (I,); o2w (I, 4, 4) world matrices
    (before the origin shift); origin (3,); rounding (I, 4) float64: (0, 0, 0, 0) for an instance
    under its own tree, (1, anchor) for a soup member; visibility (I,) uint8 ray_visibility bits."""
    origin = np.asarray(origin, np.float64).copy()
    mesh_of = np.asarray(mesh_of, np.int64)
    visibility = np.asarray(visibility, np.uint8)
    # rows for what rays can meet: an empty mesh or an instance no ray meets changes nothing
    solid = (bounds[mesh_of, 0] <= bounds[mesh_of, 3]) & stops_rays(visibility) if len(mesh_of) else np.zeros(0, bool)
    rounding = np.asarray(rounding, np.float64).reshape(-1, 4)
    if not solid.all():  # (a million-row copy of every matrix otherwise)
        mesh_of, o2w, rounding, visibility = mesh_of[solid], o2w[solid], rounding[solid], visibility[solid]
    o2w, rounding = np.ascontiguousarray(o2w, np.float64), np.ascontiguousarray(rounding)
    visibility = visibility.reshape(-1, 1)
    table = np.frombuffer(b"".join(digests), np.uint8).reshape(len(digests), 8)  # read-only, even when empty
    raw = _row_bytes(table, mesh_of, o2w.reshape(len(o2w), 16).view(np.uint8), rounding.view(np.uint8),
                     visibility)
    rows = raw.view(np.dtype((np.void, raw.shape[1]))).reshape(-1)
    boxes = transformed_boxes(bounds[mesh_of], o2w, origin)
    return InstanceSignature(origin, rows, _with_soup_rounding(boxes, rounding, origin))


@njit(cache=True, parallel=True)
def _row_bytes(table, mesh_of, matrices, rounding, visibility):
    """(I, 8 + 128 + 32 + 1) uint8: each instance's mesh digest, matrix, rounding and visibility bytes
    side by side, written in one parallel pass (np.concatenate of the gathered parts made each a
    temporary of the instances' size)."""
    parts = (8, 8 + matrices.shape[1], 8 + matrices.shape[1] + rounding.shape[1])
    out = np.empty((len(mesh_of), parts[2] + 1), np.uint8)
    for i in prange(len(mesh_of)):
        out[i, :parts[0]] = table[mesh_of[i]]
        out[i, parts[0]:parts[1]] = matrices[i]
        out[i, parts[1]:parts[2]] = rounding[i]
        out[i, parts[2]] = visibility[i, 0]
    return out


def _with_soup_rounding(boxes, rounding, origin):
    """A soup member's triangles are stored in float32 relative to its soup's anchor, so its surface may
    lie up to half a float32 step of |vertex - anchor| outside its exact box: grown by a whole step
    (2^-23 of the farthest corner's distance from the anchor). pixel_reuse's own pad is relative to
    the camera and misses this for a small object far from the anchor but near the camera."""
    soup = rounding[:, 0] == 1.0
    if not soup.any():
        return boxes
    anchor = rounding[soup, 1:] - origin
    reach = np.maximum(np.abs(boxes[soup, :3] - anchor), np.abs(boxes[soup, 3:] - anchor)).max(axis=1)
    pad = (reach * 2.0 ** -23)[:, None]
    boxes = boxes.copy()
    boxes[soup] = np.concatenate([boxes[soup, :3] - pad, boxes[soup, 3:] + pad], axis=1)
    return boxes


def changed_boxes(before, after):
    """(K, 6) float64 boxes, in `after`'s coordinates, outside which both frames hold the same
    geometry; None when that cannot be said (a signature is missing or the origin moved)."""
    if before is None or after is None or not np.array_equal(before.origin, after.origin):
        return None
    gone = ~np.isin(before.rows, after.rows)
    new = ~np.isin(after.rows, before.rows)
    return np.concatenate([before.boxes[gone], after.boxes[new]])
