"""A clock that stands still while Numba compiles, so kernel timings (build_ms, trace_ms) leave out a first
call's compile: without it a script's first two-triangle tree reported minutes of build
(docs/choices.md#core-timings-without-the-compile).

Numba announces each compile as a "numba:compile" event (numba.core.event; loading from the cache, and
writing to it, are not in it). One listener, registered at import, adds up the outermost events' durations;
Numba compiles under one global lock, so the events of different threads never interleave. The count is
the process's: a compile on another thread stops the clock for every thread.
"""
from time import perf_counter

from numba.core import event


class _CompileSeconds(event.Listener):
    """Seconds this process has spent compiling since the listener was registered, the compile under way
    included, so clock() stands still during a compile instead of jumping back at its end."""

    def __init__(self):
        self._done = 0.0
        self._depth = 0
        self._start = 0.0

    def on_start(self, ev):
        if self._depth == 0:
            self._start = perf_counter()
        self._depth += 1  # a kernel's callees compile inside its own event

    def on_end(self, ev):
        if self._depth == 0:
            return  # registered while a compile was under way: its start was not seen
        self._depth -= 1
        if self._depth == 0:
            self._done += perf_counter() - self._start

    @property
    def seconds(self):
        return self._done + (perf_counter() - self._start if self._depth else 0.0)


_COMPILES = _CompileSeconds()
event.register("numba:compile", _COMPILES)


def compile_seconds():
    """Seconds spent in Numba compiles in this process (any thread, any code) since core was imported."""
    return _COMPILES.seconds


def clock():
    """perf_counter() less compile_seconds(): it stands still while Numba compiles, so the difference of
    two readings is the time between them without the compiles in between."""
    return perf_counter() - _COMPILES.seconds
