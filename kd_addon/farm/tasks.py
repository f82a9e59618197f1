"""The worker side of a cluster run: one task renders one chunk of contiguous frames.

The chunk renders through sequence.SequenceJob in a scratch folder, as `python -m kd_addon render` does
in process, so trees and pixels are reused across the chunk's frames and its first frame is a fresh
build. Each frame, once written, goes to the client through the run's distributed.Queue (its encoded
file's bytes and its report row) and its file is deleted; the task returns the chunk's timings. The
client dedups frames by number, so a chunk rerun after a worker died may send its frames again.
bpy holds one open file per process, so chunks on one worker process take turns, however
many task threads the worker has: every chunk runs on the process's one bpy thread.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import socket
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from types import SimpleNamespace

from .. import cli, tree_cache
from ..config import make_config
from ..errors import PreviewError
from ..operators import depsgraph_source
from ..sequence import SequenceJob

def render_chunk(spec: dict, blend_bytes: bytes | None, worker: str, client) -> dict:
    """Render spec["frames"] and stream them to spec["queue"]; return the chunk's timings. On the worker
    process's bpy thread (bootstrap.bpy_thread); `client`: the worker's Dask client."""
    from distributed import Event, Queue

    _skip_teardown_at_exit()
    queue, cancel = Queue(spec["queue"], client=client), Event(spec["cancel"], client=client)
    here = {"chunk": spec["chunk"], "attempt": uuid.uuid4().hex[:8], "worker": worker}
    queue.put({"kind": "start", **here, "host": socket.gethostname(), "pid": os.getpid()})
    started = time.perf_counter()
    try:
        load_ms, frames = _render(spec, blend_bytes, lambda message: queue.put({**here, **message}), cancel.is_set)
    except BaseException as error:  # noqa: B036  (the client names why an attempt ended)
        queue.put({"kind": "failed", **here, "error": str(error) or type(error).__name__})
        raise
    return {**here, "frames": frames, "load_ms": load_ms,
            "render_ms": (time.perf_counter() - started) * 1e3 - load_ms}


_exit_hooked = False


def _skip_teardown_at_exit() -> None:
    """With bpy imported outside the main thread, the interpreter's teardown crashes (SIGSEGV after every
    exit handler ran; docs/choices.md "bpy on one worker thread"). A worker process that rendered ends
    at its last exit handler instead: os._exit, registered after bpy's, so run before it."""
    global _exit_hooked
    if not _exit_hooked:
        atexit.register(_exit_now)
        _exit_hooked = True


def _exit_now() -> None:
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _render(spec: dict, blend_bytes, send, cancelled) -> tuple[float, int]:
    """(ms spent opening the scene, frames sent). `cancelled()` is asked after each frame."""
    t0 = time.perf_counter()
    tree_cache.clear()  # every chunk starts from a fresh build, wherever the worker's last chunk was
    blend = _local_blend(spec, blend_bytes)
    try:
        scene, layer_name = cli.pick_scene(cli.load_scene(SimpleNamespace(blend=blend, demo=spec["demo"])),
                                           spec["scene"])
    except PreviewError as error:
        hint = "" if blend_bytes is not None or blend is None else " (without a shared filesystem, use --ship-blend)"
        raise PreviewError(f"{error}{hint}") from None
    config = make_config(SimpleNamespace(**spec["settings"]))
    load_ms = (time.perf_counter() - t0) * 1e3
    stop = threading.Event()
    with tempfile.TemporaryDirectory(prefix="kd_preview_chunk_") as scratch:
        def on_frame(result, path):
            send({"kind": "frame", "frame": result.frame, "row": result.summary(), "data": path.read_bytes()})
            path.unlink()
            if cancelled():
                stop.set()

        job = SequenceJob(scene, config, spec["frames"], Path(scratch),
                          depsgraph_source(scene, scene.view_layers[layer_name]), on_frame=on_frame)
        cli._run_claimed(job, stop.is_set)  # as in process: the claim, and close() on any outcome
    return load_ms, len(job.results)


def _local_blend(spec: dict, blend_bytes: bytes | None) -> str | None:
    """The .blend to open here: the shared path, or the shipped bytes saved once per worker machine
    under the temp folder, named by their digest."""
    if blend_bytes is None:
        return spec["blend"]
    digest = hashlib.sha256(blend_bytes).hexdigest()[:20]
    folder = Path(tempfile.gettempdir()) / "kd_preview_farm"
    path = folder / f"{digest}.blend"
    if not path.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        partial = folder / f".{digest}.{os.getpid()}.partial"
        partial.write_bytes(blend_bytes)
        os.replace(partial, path)
    return str(path)
