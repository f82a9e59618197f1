"""Kernel timings leave out Numba compiles: a first call's build_ms is the build's, not the compile's."""
import threading
import time

import numpy as np
from numba import njit

import core
import core.build.builder as builder
from core.jit.compile_clock import _CompileSeconds, clock, compile_seconds
from tests.meshes import random_soup


def fresh_function(k):
    """A function Numba has not compiled in this process (not cached on disk: every test run compiles it)."""
    @njit(cache=False)
    def f(x):
        s = 0.0
        for i in range(x.shape[0]):
            s += np.sin(x[i] * k) + np.cos(x[i] + k)
        return s
    return f


def test_the_clock_stands_still_while_numba_compiles():
    f = fresh_function(3.0)
    wall, stopped, compiled = time.perf_counter(), clock(), compile_seconds()
    f(np.arange(4.0))  # compiles here
    wall, stopped = time.perf_counter() - wall, clock() - stopped
    spent = compile_seconds() - compiled
    assert 0.0 < spent <= wall
    assert abs((wall - stopped) - spent) < 1e-3  # the two clocks are read microseconds apart
    compiled = compile_seconds()
    f(np.arange(4.0))  # compiled already: nothing to add
    assert compile_seconds() == compiled


def test_a_reading_on_another_thread_never_goes_back_while_a_compile_runs():
    """The count includes the compile under way, so a thread timing its own work while another thread
    compiles sees the clock stand still, never jump back when the compile ends."""
    f = fresh_function(7.0)
    compiling = threading.Thread(target=f, args=(np.arange(4.0),))
    readings, before = [], compile_seconds()
    compiling.start()
    while compiling.is_alive():
        readings.append(clock())
    compiling.join()
    readings.append(clock())
    assert compile_seconds() > before
    assert min(np.diff(readings)) >= 0.0


def test_an_end_without_its_start_is_ignored():
    """A listener registered while a compile runs sees that compile's end only: no count, no negative depth."""
    listener = _CompileSeconds()
    listener.on_end(None)
    assert listener.reading()[1] == 0.0
    listener.on_start(None)
    listener.on_start(None)  # a callee compiling inside its caller's event
    listener.on_end(None)
    time.sleep(0.01)
    assert listener.reading()[1] >= 0.01  # the compile under way counts
    listener.on_end(None)
    done = listener.reading()[1]
    time.sleep(0.01)
    assert listener.reading()[1] == done >= 0.01


def test_build_ms_leaves_out_a_compile_inside_the_build(monkeypatch):
    tris = random_soup(np.random.default_rng(0), 200)
    core.build_kdtree(tris)  # the builder's own kernels are loaded
    compile_wall = []
    original = builder._initial_references

    def compiling_first(t):
        start = time.perf_counter()
        fresh_function(5.0)(np.arange(4.0))
        compile_wall.append(time.perf_counter() - start)
        return original(t)

    monkeypatch.setattr(builder, "_initial_references", compiling_first)
    start = time.perf_counter()
    tree = core.build_kdtree(tris)
    wall_ms = (time.perf_counter() - start) * 1e3
    stats = tree.stats()
    compile_ms = compile_wall[0] * 1e3
    assert 0.0 < stats["compile_ms"] <= compile_ms
    assert stats["compile_ms"] > 0.5 * compile_ms  # the compile is most of the wrapper's time
    assert stats["build_ms"] <= wall_ms - stats["compile_ms"] + 1e-3
    assert stats["prepare_ms"] <= stats["build_ms"]
