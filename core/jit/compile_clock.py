"""A clock that stands still while Numba compiles, so kernel timings (build_ms, trace_ms) leave out a first
call's compile: without it a script's first two-triangle tree reported minutes of build
(docs/choices.md#core-timings-without-the-compile).

Numba announces each compile as a "numba:compile" event (numba.core.event; loading from the cache, and
writing to it, are not in it). One listener, registered at import, adds up the outermost events' durations;
Numba compiles under one global lock, so the events of different threads never interleave. The count is
the process's: a compile on another thread stops the clock for every thread.
"""
import threading
from time import perf_counter

from numba.core import event


class _CompileSeconds(event.Listener):
    """Seconds this process has spent compiling since the listener was registered, the compile under way
    included, so clock() stands still during a compile instead of jumping back at its end. A lock keeps a
    reading on another thread from seeing a compile half ended."""

    def __init__(self):
        self._lock = threading.Lock()
        self._done = 0.0
        self._depth = 0
        self._start = 0.0

    def on_start(self, ev):
        with self._lock:
            if self._depth == 0:
                self._start = perf_counter()
            self._depth += 1  # a kernel's callees compile inside its own event

    def on_end(self, ev):
        with self._lock:
            if self._depth == 0:
                return  # registered while a compile was under way: its start was not seen
            self._depth -= 1
            if self._depth == 0:
                self._done += perf_counter() - self._start

    def reading(self):
        """(perf_counter(), seconds compiled so far) taken together under the lock: read one after the
        other, a thread switch between them during a compile would put the pair milliseconds apart."""
        with self._lock:
            now = perf_counter()
            return now, self._done + (now - self._start if self._depth else 0.0)


_COMPILES = _CompileSeconds()
event.register("numba:compile", _COMPILES)


def reading():
    """(perf_counter(), compile_seconds()) read at one instant."""
    return _COMPILES.reading()


def compile_seconds():
    """Seconds spent in Numba compiles in this process (any thread, any code) since core was imported."""
    return _COMPILES.reading()[1]


def clock():
    """perf_counter() less compile_seconds(): it stands still while Numba compiles, so the difference of
    two readings is the time between them without the compiles in between."""
    wall, compiled = _COMPILES.reading()
    return wall - compiled
