"""Cameras in Blender's convention: camera-to-world matrix, looking down local -Z with +Y up."""
import functools

import numpy as np
from numba import njit, prange

from .. import buffer_pool
from ..inputs import as_number, as_real_array, check_image_size, without_negligible_components
from ..trace.packet_traversal import L, TILE_SHAPE, packet_order

TILE = 8  # tiled_pixels: 8 x 8 = 64 rays, one traversal task (traversal.RAYS_PER_TASK)


class Camera:
    """A perspective (`fov`) or orthographic (`ortho_scale`) camera, in Blender's terms.

    matrix_world: 4x4 camera-to-world matrix. fov: full field of view in radians along the larger image
    dimension (sensor fit AUTO). ortho_scale: the view's width along that dimension. clip_start, clip_end:
    distances along the view axis. shift: (x, y) lens shift in units of the larger dimension's view extent
    (the image plane moves, the camera stays put). pixel_aspect: a pixel's height over its width; the image
    spans width by height * pixel_aspect pixel widths, and "larger" compares those, as Blender's
    BKE_camera_params_compute_viewplane does."""

    def __init__(self, matrix_world, fov=None, *, ortho_scale=None, clip_start=0.0, clip_end=np.inf,
                 shift=(0.0, 0.0), pixel_aspect=1.0):
        m = as_real_array("camera matrix_world", matrix_world)
        if m.shape != (4, 4):
            raise ValueError(f"camera matrix_world must be a 4x4 matrix, got shape {m.shape}")
        if not np.isfinite(m).all():
            raise ValueError(f"camera matrix_world has a NaN or inf entry: {m.tolist()}")
        if (fov is None) == (ortho_scale is None):
            raise ValueError("camera needs exactly one of fov (perspective) or ortho_scale (orthographic)")
        if fov is not None and not 0.0 < as_number("camera fov", fov) < np.pi:
            raise ValueError(f"camera fov must be in (0, pi) radians, got {fov}")
        if ortho_scale is not None and not 0.0 < as_number("camera ortho_scale", ortho_scale) < np.inf:
            raise ValueError(f"camera ortho_scale must be finite and > 0, got {ortho_scale}")
        if not 0.0 <= as_number("camera clip_start", clip_start) < as_number("camera clip_end", clip_end):
            raise ValueError(f"camera clip range must satisfy 0 <= clip_start < clip_end, got {clip_start}, {clip_end}")
        axes = np.linalg.norm(m[:3, :3], axis=0)  # the scale is ignored, so only a relative test
        if not (axes > 0).all() or abs(np.linalg.det(m[:3, :3] / axes)) < 1e-9:
            raise ValueError("camera matrix_world is singular (zero scale or collapsed axes)")
        if not (m[3] == (0.0, 0.0, 0.0, 1.0)).all():
            raise ValueError(f"camera matrix_world must be affine (bottom row 0 0 0 1), got {m[3].tolist()}")
        shift = as_real_array("camera shift", shift)
        if shift.shape != (2,) or not (np.abs(shift) <= 1e6).all():
            raise ValueError(f"camera shift must be two numbers (x, y) within +-1e6, got {shift.tolist()}")
        self.shift = (float(shift[0]), float(shift[1]))
        if not 1e-3 <= as_number("camera pixel_aspect", pixel_aspect) <= 1e3:
            raise ValueError(f"camera pixel_aspect must be in [0.001, 1000] (Blender's pixel aspects are 1-200), "
                             f"got {pixel_aspect}")
        self.pixel_aspect = float(pixel_aspect)
        self.matrix_world = m
        self.fov = None if fov is None else float(fov)
        self.ortho_scale = None if ortho_scale is None else float(ortho_scale)
        self.clip_start, self.clip_end = float(clip_start), float(clip_end)

    @property
    def position(self):
        return self.matrix_world[:3, 3].copy()

    def translated(self, offset):
        """The same camera in a frame whose origin is at `offset` (positions minus offset)."""
        m = self.matrix_world.copy()
        offset = as_real_array("camera offset", offset)
        if offset.shape != (3,) or not np.isfinite(offset).all():
            raise ValueError(f"camera offset must be 3 finite numbers, got {offset.tolist()}")
        m[:3, 3] -= offset
        return Camera(m, self.fov, ortho_scale=self.ortho_scale, clip_start=self.clip_start,
                      clip_end=self.clip_end, shift=self.shift, pixel_aspect=self.pixel_aspect)

    def rays(self, width, height, pixels=None):
        """Rays through pixel centres, row 0 at the top: (origins, directions, tmin, tmax), (R, 3).
        `pixels`: the row-major pixel indices to make rays for, in that order (default: every pixel in
        row-major order; see tiled_pixels). Directions have unit length along the view axis, so
        tmin/tmax are the clip distances."""
        check_image_size(width, height)
        left, right, bottom, top = self.image_plane(width, height)
        x = left + (np.arange(width) + 0.5) / width * (right - left)
        y = top - (np.arange(height) + 0.5) / height * (top - bottom)
        rot = self.matrix_world[:3, :3] / np.linalg.norm(self.matrix_world[:3, :3], axis=0)
        rot = without_negligible_components(rot.T).T  # per axis, as for query rays (inputs.py says why)
        rot = np.ascontiguousarray(rot)  # one compiled _pixel_rays, whether or not the call above copied
        pixels = np.arange(width * height, dtype=np.int64) if pixels is None else _pixel_indices(pixels, width, height)
        pixels = pixels.view()
        pixels.setflags(write=False)  # as tiled_pixels' order, which comes uncopied: one compiled _pixel_rays
        n = len(pixels)
        origins, directions = buffer_pool.empty((n, 3)), buffer_pool.empty((n, 3))
        _pixel_rays(x, y, rot, self.matrix_world[:3, 3].copy(), self.fov is not None, pixels, origins, directions)
        return origins, directions, buffer_pool.full(n, self.clip_start), buffer_pool.full(n, self.clip_end)

    def image_plane(self, width, height):
        """(left, right, bottom, top) of the image in camera space: on the plane z = -1 (perspective) or
        in world units (orthographic); the shift moves it by shift times its larger extent."""
        half_w, half_h = self._half_extent(width, height)
        larger = 2.0 * max(half_w, half_h)
        cx, cy = self.shift[0] * larger, self.shift[1] * larger
        return cx - half_w, cx + half_w, cy - half_h, cy + half_h

    def _half_extent(self, width, height):
        """Half the image plane's size at distance 1 (perspective) or in world units (ortho)."""
        half = np.tan(self.fov / 2.0) if self.fov is not None else self.ortho_scale / 2.0
        tall = height * self.pixel_aspect  # the image's height in pixel widths
        if width >= tall:
            return half, half * tall / width
        return half * width / tall, half

    def __repr__(self):
        kind = f"fov={self.fov:.4f}" if self.fov is not None else f"ortho_scale={self.ortho_scale}"
        shift = f", shift={self.shift}" if any(self.shift) else ""
        aspect = f", pixel_aspect={self.pixel_aspect}" if self.pixel_aspect != 1.0 else ""
        return f"Camera(position={self.position.round(4).tolist()}, {kind}{shift}{aspect})"


def _pixel_indices(pixels, width, height):
    """`pixels` as int64 indices, checked: the ray kernel reads the image coordinates without bounds checks."""
    given = np.asarray(pixels)
    if given.ndim != 1 or not (np.issubdtype(given.dtype, np.integer) or given.size == 0):
        raise ValueError(f"camera pixels must be a 1-D array of integer pixel indices, got {given.dtype} {given.shape}")
    if given.size and (given.min() < 0 or given.max() >= width * height):
        raise ValueError(f"camera pixels must lie in [0, {width * height}) for {width} x {height}, "
                         f"got {given.min()} .. {given.max()}")
    return np.ascontiguousarray(given, np.int64)  # no copy of an int64 order such as tiled_pixels


@functools.lru_cache(maxsize=8)
def tiled_pixels(width, height, tile=TILE):
    """Every row-major pixel index once, tile by tile (tile x tile squares, row-major across tiles; edge
    tiles are cut short), and inside a tile packet block by packet block (TILE_SHAPE, a packet's pixels:
    row-major across blocks and within one). Read-only and kept per size: every frame asks for the same
    order. Rays in this order are coherent within each traversal task (one 8 x 8 tile), so they walk
    the same nodes while those are in cache (docs/choices.md#pixels-traced-in-8-x-8-tiles), and the hits'
    later rays taken L at a time in this order leave a packet's compact block of pixels, not two rows
    (docs/choices.md#hits-listed-packet-block-by-packet-block)."""
    bw, bh = TILE_SHAPE
    ys, xs = np.divmod(np.arange(width * height, dtype=np.int64), width)
    tile_index = (ys // tile) * -(-width // tile) + xs // tile
    y, x = ys % tile, xs % tile  # inside the tile
    block = (y // bh) * -(-tile // bw) + x // bw
    key = (tile_index * (-(-tile // bw) * -(-tile // bh)) + block) * (bw * bh) + (y % bh) * bw + x % bw
    order = np.argsort(key, kind="stable")
    order.setflags(write=False)
    return order


@functools.lru_cache(maxsize=8)
def tiled_packets(width, height):
    """The camera rays of tiled_pixels(width, height) (positions in that order) grouped into packets of
    neighbouring pixels (packet_traversal.packet_order; -1 fills lanes off the image), the packets in
    the order of their tiles, so a task's packets share a tile's nodes in cache. Read-only, kept per size."""
    position = np.empty(width * height, np.int64)
    position[tiled_pixels(width, height)] = np.arange(width * height)
    packets = packet_order(width, height).reshape(-1, L)
    grouped = np.where(packets >= 0, position[np.maximum(packets, 0)], -1)
    first = np.where(grouped >= 0, grouped, width * height).min(axis=1)
    order = grouped[np.argsort(first, kind="stable")].ravel()
    order.setflags(write=False)
    return order


@njit(cache=True, parallel=True)
def _pixel_rays(x, y, rot, position, perspective, pixels, origins, directions):
    """Rays for row-major pixel indices `pixels`, from the image-plane coordinates x (W,) and y (H,). A
    kernel because numpy's meshgrid, stack and matrix product took a tenth of a preview's time to image."""
    width = x.shape[0]
    for r in prange(pixels.shape[0]):
        i, j = pixels[r] // width, pixels[r] % width
        for k in range(3):
            spread = x[j] * rot[k, 0] + y[i] * rot[k, 1]
            if perspective:
                origins[r, k] = position[k]
                directions[r, k] = spread - rot[k, 2]
            else:
                origins[r, k] = spread + position[k]
                directions[r, k] = -rot[k, 2]
