"""The kernels' first compile, started in the background when the add-on is enabled.

A first render on a machine compiles Numba kernels for a minute or two on 2 idle cores. `start()`
(register() calls it) begins that at once in a separate process, which runs a made-up first and second frame
(core/jit/first_frame.py, with its own helper process for the rendering kernels: the same two-core
split as a first render, docs/choices.md#the-first-renders-compile-on-two-cores) into the add-on's
Numba cache; a render then waits for it and only loads the kernels. A process, not a thread: the
compile is Python code, and Python running beside Blender's depsgraph evaluation crashed the bpy
module (docs/choices.md#the-scene-is-read-only-between-kernel-calls); it also leaves Blender's UI
its own interpreter lock. Nothing here imports numba or core, so registering stays instant.

The process ends when Blender does (it watches its parent; atexit stops it too); Numba writes each
cache file under a temporary name and renames it, so an interrupted compile leaves no broken kernel.
Disabling the add-on lets a running compile finish: it only fills the cache. KD_PREVIEW_WARMUP=0
turns the warm-up off (then a first render compiles as before: pipeline.FrameJob).

Once those kernels are cached, a second process of lower priority compiles the camera and hard-shadow
packets' kernels, the sampling kernel's packed version (sample packets in batches of 8+ samples) and the
denoiser (core/jit/first_frame.compile_second_stage), which no render waits for: renders trace in packets
(pipeline.FrameJob) and step in batches that large (sampling_steps.py) only once they are cached, and a
denoised frame before then compiles the denoiser itself. Background runs and KD_PREVIEW_WARMUP=0 start no
second stage; `compile_both_stages` (`python -m kd_addon compile`) runs both and waits.

API for the UI and a render engine: start(), status() -> WarmupStatus (state, elapsed seconds,
message; `.text` is the line to show), wait(cancel=None, timeout=None).
"""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass

from . import corelib

NOT_STARTED, COMPILING, READY, FAILED = "not started", "compiling", "ready", "failed"
SWITCH = "KD_PREVIEW_WARMUP"  # "0": no background compile
TASK = "jit.first_frame:compile_first_frames"
PACKED_TASK = "jit.first_frame:compile_second_stage"
PACKED_NICE = 10  # the packed stage's niceness (POSIX): a render running meanwhile keeps the cores
POLL_SECONDS = 0.05


@dataclass(frozen=True)
class WarmupStatus:
    """state: NOT_STARTED, COMPILING, READY or FAILED; elapsed: seconds since the compile started (its
    length once it ended; 0 when the cache was already warm); message: why it failed."""

    state: str
    elapsed: float = 0.0
    message: str = ""

    @property
    def text(self) -> str:
        """What the panel, the status bar and a render's stats line show ("" when nothing to say)."""
        if self.state == COMPILING:
            return f"compiling kernels (first use) {self.elapsed:.0f}s"
        if self.state == FAILED:
            return f"kernel compile failed: {self.message}"
        return ""


class _Warmup:
    """The one warm-up of this process (module state: it outlives a disable and re-enable)."""

    def __init__(self):
        self.process: subprocess.Popen | None = None
        self.errors = None  # the process's stderr, for the failure message
        self.started_at = 0.0
        self.ended_at: float | None = None
        self.state, self.message = NOT_STARTED, ""
        self.packed: subprocess.Popen | None = None  # the packed stage (_start_packed_stage)
        self.packed_wanted = False  # start(packed=True) asked for it (Blender's UI)

    def observe(self) -> WarmupStatus:
        if self.state == COMPILING:
            code = self.process.poll()
            if code is not None:
                self.ended_at = time.perf_counter()
                self.state, self.message = (READY, "") if code == 0 else (FAILED, _failure(code, self.errors))
                if code == 0 and self.packed_wanted:
                    _start_packed_stage()
        end = time.perf_counter() if self.ended_at is None else self.ended_at
        return WarmupStatus(self.state, end - self.started_at if self.started_at else 0.0, self.message)


_warmup = _Warmup()
_packed_lock = threading.Lock()


def status() -> WarmupStatus:
    """Where the warm-up stands now (cheap: polls the process, never blocks)."""
    return _warmup.observe()


def start(packed: bool = False) -> WarmupStatus:
    """Begin compiling the kernels in the background unless they are cached, a compile already runs or
    ran, or KD_PREVIEW_WARMUP is "0"; returns status(). Never raises: a warm-up that cannot start is
    FAILED, and a render then compiles in its own process as it would without one. `packed`: then
    the packed stage too, once they are ready (with Blender's UI only: a batch job or a test session
    would end it unfinished, and a render never waits for it)."""
    if os.environ.get(SWITCH, "1") == "0":
        return status()
    _warmup.packed_wanted = _warmup.packed_wanted or packed
    if _warmup.state == READY and _warmup.packed_wanted:
        _start_packed_stage()
    if _warmup.state in (COMPILING, READY):
        return status()
    try:
        if corelib.cache_is_warm():
            _warmup.state, _warmup.message = READY, ""
            if _warmup.packed_wanted:
                _start_packed_stage()
            return status()
        _warmup.errors = tempfile.TemporaryFile()
        _warmup.process = _spawn(_warmup.errors)
    except (OSError, ValueError, subprocess.SubprocessError) as error:
        _warmup.state, _warmup.message = FAILED, f"could not start the compile process: {error}"
        return status()
    _warmup.started_at, _warmup.ended_at, _warmup.state = time.perf_counter(), None, COMPILING
    return status()


def _spawn(errors, task=TASK, low_priority=False) -> subprocess.Popen:
    """The compile process: core/jit/helper_program.py running `task`, writing where this process's
    kernels will be read (corelib.numba_cache_dir), with this process's module path (Blender's
    extension site-packages hold the bundled numba). `low_priority`: below normal priority (Windows) or
    PACKED_NICE (POSIX, set before the process starts its threads and helper, which inherit it)."""
    cache = corelib.numba_cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), KD_PREVIEW_HELPER_PARENT=str(os.getpid()),
               PYTHONPATH=os.pathsep.join(p for p in sys.path if p and os.path.isdir(p)))
    program = (corelib.CORE_FOLDER / "jit" / "helper_program.py").read_text(encoding="utf-8")
    flags = getattr(subprocess, "CREATE_NO_WINDOW", 0)
    if low_priority:
        flags |= getattr(subprocess, "BELOW_NORMAL_PRIORITY_CLASS", 0)
    process = subprocess.Popen([sys.executable, "-c", program, corelib.core_module_name(), str(corelib.CORE_FOLDER),
                                "0", task], env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                               stderr=errors, creationflags=flags)
    if low_priority and hasattr(os, "setpriority"):
        try:  # never above this process's own niceness (lowering it would raise the compile's priority)
            os.setpriority(os.PRIO_PROCESS, process.pid, max(PACKED_NICE, os.getpriority(os.PRIO_PROCESS, 0)))
        except OSError:
            pass  # it ran or ended already: it only compiles at normal priority
    return process


def _start_packed_stage() -> None:
    """Start the packed stage once the first frames' kernels are cached, unless it ran in this process
    or the cache already holds what it compiles (second_stage_cached: a stage stopped part-way runs
    again). Never raises: without it, renders trace camera rays singly and keep their batches under
    8 samples (core PreviewRender's compile_packets and batch_without_compile)."""
    with _packed_lock:  # status() on the UI's timer and start() on a render's thread may both get here
        if _warmup.packed is not None or second_stage_cached():
            return
        try:
            _warmup.packed = _spawn_packed_stage()
        except (OSError, ValueError, subprocess.SubprocessError):
            pass


def _spawn_packed_stage() -> subprocess.Popen:
    return _spawn(subprocess.DEVNULL, PACKED_TASK, low_priority=True)


def packed_stage_running() -> bool:
    """Whether the packed stage's process runs now."""
    return _warmup.packed is not None and _warmup.packed.poll() is None


def _failure(code: int, errors) -> str:
    """The failed process's last line of stderr, with the fix when numba is missing (a zip built for
    another Blender's Python: tools/build_extension.py builds one a Python)."""
    errors.seek(0)
    lines = errors.read().decode(errors="replace").strip().splitlines()
    last = lines[-1] if lines else f"exit code {code}"
    if "No module named 'numba'" in last or "No module named 'llvmlite'" in last:
        python = f"{sys.version_info[0]}.{sys.version_info[1]}"
        return (f"numba is not installed for this Blender's Python {python}: install the KD Preview zip built "
                f"for Python {python} (README, Install)")
    return last


def wait(cancel=None, timeout: float | None = None) -> WarmupStatus:
    """Wait while the warm-up compiles: until it ends, `cancel()` returns True (polled every
    POLL_SECONDS) or `timeout` seconds pass; returns status() then."""
    deadline = None if timeout is None else time.perf_counter() + timeout
    while True:
        now = status()
        if now.state != COMPILING or (cancel is not None and cancel()):
            return now
        if deadline is not None and time.perf_counter() >= deadline:
            return now
        try:
            _warmup.process.wait(POLL_SECONDS if deadline is None else
                                 max(0.0, min(POLL_SECONDS, deadline - time.perf_counter())))
        except subprocess.TimeoutExpired:
            pass


def compile_both_stages(cancel=None) -> WarmupStatus:
    """Compile both stages now and wait for them (the command line's `compile`: a farm node's set-up, a
    batch job's first run), the second at normal priority: background renders, which start no second
    stage, then take packets and packed batches from their first frame. The first stage always runs (a
    kernel cached midway through an interrupted one does not say it finished; cached kernels only load);
    the second unless second_stage_cached(). READY, or FAILED with the failing stage's message;
    NOT_STARTED when `cancel()` turned True (the running stage is ended: what it saved stays valid).
    KD_PREVIEW_WARMUP does not apply: this compile is asked for."""
    started = time.perf_counter()
    for task in (TASK, PACKED_TASK):
        if task == PACKED_TASK and second_stage_cached():
            break
        errors = None
        try:
            errors = tempfile.TemporaryFile()
            process = _spawn(errors, task)
        except (OSError, ValueError, subprocess.SubprocessError) as error:
            if errors is not None:
                errors.close()
            return WarmupStatus(FAILED, time.perf_counter() - started, f"could not start the compile process: {error}")
        with errors:
            code = _run_to_end(process, cancel)
            if code is None:
                return WarmupStatus(NOT_STARTED, time.perf_counter() - started)
            if code != 0:
                return WarmupStatus(FAILED, time.perf_counter() - started, _failure(code, errors))
    return WarmupStatus(READY, time.perf_counter() - started)


def _run_to_end(process: subprocess.Popen, cancel) -> int | None:
    """Wait for `process`; its exit code, or None when `cancel()` turned True first. It never outlives
    this call (ended on a cancel or an exception, e.g. Ctrl-C's KeyboardInterrupt)."""
    try:
        while process.poll() is None:
            if cancel is not None and cancel():
                return None
            try:
                process.wait(POLL_SECONDS)
            except subprocess.TimeoutExpired:
                pass
        return process.returncode
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def second_stage_cached() -> bool:
    """Whether the cache holds what the second stage compiles: the packet kernels and the packed version,
    compiled after them (corelib.packed_version_cached: only that stage compiles it for the add-on, whose
    renders keep their batches under its size until then), and the denoiser, compiled last."""
    return corelib.packed_version_cached() and corelib.cache_is_warm(corelib.DENOISE_KERNEL)


def stop() -> None:
    """End a running compile, either stage (this process is exiting); what it saved stays valid."""
    process = _warmup.process
    if process is not None and process.poll() is None:
        process.kill()
        process.wait()
        _warmup.state, _warmup.message, _warmup.ended_at = FAILED, "stopped", time.perf_counter()
    if packed_stage_running():
        _warmup.packed.kill()
        _warmup.packed.wait()


atexit.register(stop)
