"""A clock that stands still while Numba compiles, so kernel timings (build_ms, trace_ms) leave out a first
call's compile: without it a script's first two-triangle tree reported minutes of build
(docs/choices.md#core-timings-without-the-compile).

Numba announces each compile as a "numba:compile" event (numba.core.event; cache loads are not
compiles). One listener, registered at import, adds up the outermost events' durations; Numba compiles
under one global lock, so the events of different threads never interleave.
"""
from time import perf_counter

from numba.core import event


class _CompileSeconds(event.Listener):
    """Seconds this process has spent compiling since the listener was registered."""

    def __init__(self):
        self.seconds = 0.0
        self._depth = 0
        self._start = 0.0

    def on_start(self, ev):
        if self._depth == 0:
            self._start = perf_counter()
        self._depth += 1  # a kernel's callees compile inside its own event

    def on_end(self, ev):
        self._depth -= 1
        if self._depth == 0:
            self.seconds += perf_counter() - self._start


_COMPILES = _CompileSeconds()
event.register("numba:compile", _COMPILES)


def compile_seconds():
    """Seconds spent in Numba compiles since core was imported."""
    return _COMPILES.seconds


def clock():
    """perf_counter() less compile_seconds(): the difference of two readings is the time between them
    without the compiles in between."""
    return perf_counter() - _COMPILES.seconds
