"""Kernel work on a worker thread, so the caller can stop waiting at any moment.

Why: a Numba kernel cannot be interrupted, and a kd-tree build over a few
million triangles (or one trace step at a large resolution) takes seconds.
If the main thread ran it, ESC, a cancel callback or Ctrl-C would only be
seen once it returned. Instead every kernel call of a frame runs here and
the main thread polls it in short waits (`FrameJob.tick`), checking for
cancel in between, so a cancel returns within one poll interval (~50 ms).

A cancelled job simply stops polling: its worker runs to the end and writes
only into that job's own tree and renderer, which nobody reads any more.
The worker holds `lock` (the pipeline's KERNEL_LOCK) while it runs, so a
later job's kernels wait for the abandoned ones instead of running beside
them: Numba's workqueue threading layer aborts the process when two threads
launch parallel kernels at once.

The thread is a daemon, so a process that ends after a cancel (Ctrl-C on the
command line) ends at once instead of waiting for the abandoned build.
Measured: exiting while a daemon worker was inside a 1M-triangle build ended
cleanly with the intended exit code in 5 of 5 runs, with Numba's workqueue
layer and with the tbb layer bpy brings, with the bpy 5.0 module; the bpy 4.2
module's interpreter teardown crashes beside the running worker (SIGSEGV
instead of exit code 130), and so did a real Blender 5.2 exiting during a first
run's compile (LLVM), so both command lines end with os._exit then
(exit_now_if_abandoned).
"""

from __future__ import annotations

import os
import sys
import threading
import time
import weakref

_calls: weakref.WeakSet = weakref.WeakSet()  # every BackgroundCall not yet collected
# The bpy module crashed (SIGSEGV in the main thread's evaluated_depsgraph_get, about 1 run in 10 of
# test_addon_modal.py, CI once) when the scene was evaluated while the worker ran a call's Python code
# (not a kernel); the cause inside Blender was not found, so the add-on reads the scene only while no
# kernel call runs: ticks run on the main thread, so none starts before the reader returns. A job
# (pipeline.FrameJob, sequence.SequenceJob) evaluates its depsgraph and sets frames in a tick that first
# finds no call running (earlier ticks just wait: a Render clicked during a cancelled run's long build
# reads the scene after it). Live Update's timer and frame handler, which must return at once, wait at
# most SCENE_READ_WAIT seconds, then try again later.
SCENE_READ_WAIT = 0.1


def abandoned_work_running(besides: BackgroundCall | None = None) -> bool:
    """True while a worker still runs a kernel call nobody waits for any more (after a cancel).
    `besides`: the call a job does wait for, not counted (one job runs at a time, so any other
    unfinished call is an abandoned one, holding the lock that call waits for)."""
    return any(call is not besides and not call.finished for call in list(_calls))


def wait_for_work(timeout: float) -> bool:
    """Wait at most `timeout` seconds for every kernel call still on a worker (a running job's or an
    abandoned one); True once none is. See SCENE_READ_WAIT for why."""
    deadline = time.perf_counter() + timeout
    for call in list(_calls):
        if not call.wait(max(0.0, deadline - time.perf_counter())):
            return False
    return True


def exit_now_if_abandoned(code: int) -> None:
    """End the process with `code` at once, skipping the interpreter's (and Blender's) teardown, if a
    cancelled kernel call still runs: the bpy 4.2 module crashed in that teardown beside the worker,
    and Blender 5.2 itself crashed in LLVM when it exited during a first run's compile."""
    if abandoned_work_running():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


class BackgroundCall:
    """`fn(*args)` running on its own thread under `lock`; poll with wait(), collect with result()."""

    def __init__(self, lock: threading.Lock, fn, *args):
        self._finished = threading.Event()
        self._value = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(lock, fn, args), name="kd-preview-kernels",
                                        daemon=True)
        _calls.add(self)
        self._thread.start()

    def _run(self, lock, fn, args) -> None:
        try:
            with lock:
                self._value = fn(*args)
        except BaseException as error:  # handed to the polling thread by result()
            self._error = error
        finally:
            self._finished.set()

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    def wait(self, timeout: float) -> bool:
        """Wait at most `timeout` seconds; True once the call has finished."""
        return self._finished.wait(timeout)

    def result(self):
        """The call's return value, or its exception re-raised here; call only once finished."""
        if not self.finished:
            raise RuntimeError("BackgroundCall.result() called before the call finished")
        if self._error is not None:
            raise self._error
        return self._value
