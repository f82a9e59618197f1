"""The frame's memory limit: triangles, kd-tree and pixel buffers, estimated before any is allocated.

Checked right after extraction and before the world triangles, the tree or the renderer exist, so a
frame over the limit fails with a message naming the estimate, the limit and what to change instead
of the out-of-memory killer ending Blender during the build. The figures are core's (core/memory.py);
the world triangles the tree keeps are added to the build's working set, which bounds the peak.
"""

from __future__ import annotations

from . import corelib
from .errors import PreviewError

MIB = 1 << 20


class MemoryLimitError(PreviewError):
    """The frame's estimated peak memory is above the Memory Limit setting."""


def frame_bytes(n_triangles: int, width: int, height: int, builder: str,
                keeps_previous: bool = False) -> tuple[int, int]:
    """(bytes for the triangles and the kd-tree, bytes for the pixel buffers), estimated; keeps_previous:
    the last frame's pixels are held for pixel reuse."""
    memory = corelib.load_core().memory
    geometry = memory.build_bytes(n_triangles, builder) + int(memory.MARGIN * memory.TRIANGLE_BYTES * n_triangles)
    return geometry, memory.render_bytes(width, height, keeps_previous)


def check_frame(n_triangles: int, width: int, height: int, config, keeps_previous: bool = False,
                held: int = 0) -> None:
    """Raise MemoryLimitError when the frame would need more than config.memory_limit bytes
    (keeps_previous: the last frame's pixel state is held while this one renders; held: bytes other
    views' and passes' kept images hold meanwhile, tree_cache.held_bytes). With no limit set,
    only the pixel buffers are checked, against the machine's physical memory: their estimate is
    close, while the geometry's covers the worst scene and would refuse typical ones that fit
    (docs/choices.md#without-a-memory-limit-only-the-pixel-buffers-are-checked). With a limit, the
    renderer's kept blocks from earlier frames are let go first (core/buffer_pool.py)."""
    geometry, pixels = frame_bytes(n_triangles, width, height, config.settings.builder, keeps_previous)
    pixels += held
    kept = f", of which {held / MIB:,.0f} MiB other views' and passes' kept pixels" if held else ""
    limit = config.memory_limit
    if limit is not None:  # the estimate is what the frame adds: earlier frames' kept blocks go first
        corelib.load_core().buffer_pool.release()
    if limit is None:
        machine = corelib.load_core().memory.physical_memory()
        if machine is not None and pixels > machine:
            raise MemoryLimitError(
                f"this frame's {width}x{height} pixels need about {pixels / MIB:,.0f} MiB{kept}, above this "
                f"machine's memory of {machine / MIB:,.0f} MiB: lower the resolution")
        return
    if geometry + pixels > limit:
        raise MemoryLimitError(
            f"this frame needs about {(geometry + pixels) / MIB:,.0f} MiB ({n_triangles:,} triangles and their "
            f"kd-tree: {geometry / MIB:,.0f} MiB; {width}x{height} pixels: {pixels / MIB:,.0f} MiB{kept}), above "
            f"the memory limit of {limit / MIB:,.0f} MiB: lower the resolution, hide objects, or raise the memory "
            "limit (0 = no limit)")
