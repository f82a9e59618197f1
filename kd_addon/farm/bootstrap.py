"""A chunk task's first step on a Dask worker, sent by value (cloudpickle.register_pickle_by_value) so it
runs where the project does not import: it names the worker and what it lacks (the bpy module, KD
Preview, or the client's version of core) before importing the worker side (tasks.py).

Only the standard library and distributed are imported here: the module's code travels with the task.
"""

import importlib
import os
import socket
import sys


def chunk_task():
    """The function to submit. A local function, so that pickle refuses it and Dask's pickler (cloudpickle)
    takes the whole task, sending this module's code by value: a module-level function inside Dask's
    task object went by reference, and a worker without the project failed to unpickle it."""
    def render_chunk_task(spec: dict, blend_bytes=None) -> dict:
        return run_chunk(spec, blend_bytes)

    return render_chunk_task


def run_chunk(spec: dict, blend_bytes=None) -> dict:
    """Render the chunk `spec` describes on this worker's bpy thread (bpy_thread), and wait for it."""
    from distributed import get_client, get_worker

    worker = get_worker()
    return bpy_thread(worker).submit(checked_chunk, spec, blend_bytes, worker.address, get_client()).result()


def bpy_thread(worker):
    """The one thread of this worker process that runs bpy. bpy works in the thread that imported it and
    crashes when another thread calls it (an operator from any other thread: SIGSEGV), so every chunk runs
    on the same thread, whichever task thread Dask gives it."""
    from concurrent.futures import ThreadPoolExecutor

    return worker.__dict__.setdefault("_kd_preview_bpy_thread",
                                      ThreadPoolExecutor(1, thread_name_prefix="kd-preview-bpy"))


def checked_chunk(spec: dict, blend_bytes, worker: str, client) -> dict:
    """Check this worker, then render (tasks.render_chunk); on the bpy thread."""
    from distributed import Queue

    forget_inherited_paths(spec["blender_paths"])
    problem = setup_problem(spec["package"], spec["digest"])
    if problem is not None:
        message = (f"worker {worker} (host {socket.gethostname()}, pid {os.getpid()}, Python {sys.executable}) "
                   f"cannot render: {problem}")
        Queue(spec["queue"], client=client).put({"kind": "setup-failed", "chunk": spec["chunk"], "worker": worker,
                                                 "error": message})
        raise RuntimeError(message)
    tasks = importlib.import_module(spec["package"] + ".farm.tasks")
    return tasks.render_chunk(spec, blend_bytes, worker, client)


def forget_inherited_paths(paths) -> None:
    """A LocalCluster's worker processes start with the client's sys.path (multiprocessing's spawn), which
    holds Blender's script folders once bpy is imported; `import bpy` there then finds Blender's Python
    package `bpy` instead of the module and fails ("No module named '_bpy'"). Before bpy is imported in
    this process, those folders go: the bpy module puts them back itself."""
    if "bpy" not in sys.modules:
        sys.path[:] = [p for p in sys.path if p not in set(paths)]


def setup_problem(package: str, digest: str):
    """What keeps this Python from rendering as the client does, or None."""
    try:
        import bpy  # noqa: F401
    except ImportError as error:
        return (f"the bpy module is not importable here ({error}); install it into the worker's Python "
                "(pip install -e \".[blender,farm]\" in a clone of KD Preview) and restart the worker")
    try:
        corelib = importlib.import_module(package + ".corelib")
    except ImportError as error:
        return (f"KD Preview ({package}) is not importable here ({error}); install it into the worker's Python "
                "(pip install -e \".[blender,farm]\" in a clone) or start the worker with PYTHONPATH set to one")
    mine = corelib.source_digest()
    if mine != digest:
        return (f"its KD Preview core ({corelib.CORE_FOLDER}, sources digest {mine}) is not the client's "
                f"(digest {digest}): its frames would differ; run the same version on every machine")
    return None
