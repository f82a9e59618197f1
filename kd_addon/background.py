"""Kernel work on a worker thread, so the caller can stop waiting at any moment.

A Numba kernel cannot be interrupted and a build can take seconds, so every kernel call of a frame
runs here while the main thread polls it in short waits (`FrameJob.tick`) and sees a cancel within
one poll. A cancelled job stops polling; its worker runs to the end under `lock` (KERNEL_LOCK), so a
later job's kernels wait for it instead of running beside it. The thread is a daemon, and the
command lines end with os._exit while one still runs (exit_now_if_abandoned;
docs/choices.md#a-daemon-worker-and-an-immediate-exit-while-a-cancelled-build-runs).
"""

from __future__ import annotations

import os
import sys
import threading
import time
import weakref

_calls: weakref.WeakSet = weakref.WeakSet()  # every BackgroundCall not yet collected
# The bpy module can crash (SIGSEGV in evaluated_depsgraph_get) when the scene is evaluated while the
# worker runs a call's Python code, so the scene is read only while no kernel call runs: a job reads
# it in a tick that first finds no call running; Live Update's timer and frame handler, which must
# return at once, wait at most SCENE_READ_WAIT seconds, then try again later.
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
    cancelled kernel call still runs (that teardown can crash beside the worker)."""
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
