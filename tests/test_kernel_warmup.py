"""The kernels' background compile (kd_addon/kernel_warmup.py): its states and what they show, a
failure's message, the compile process as the add-on starts it, and a render waiting for it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from kd_addon import corelib, kernel_warmup

REAL_PROGRAM = corelib.CORE_FOLDER / "jit" / "helper_program.py"


@pytest.fixture
def warmup(monkeypatch):
    """kernel_warmup with a fresh state, the cache cold unless a test says otherwise, and the switch on."""
    monkeypatch.setattr(kernel_warmup, "_warmup", kernel_warmup._Warmup())
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: False)
    monkeypatch.delenv(kernel_warmup.SWITCH, raising=False)
    yield kernel_warmup
    kernel_warmup.stop()


def fake_compile(monkeypatch, code: str) -> None:
    """The compile process replaced by `python -c code`."""
    monkeypatch.setattr(kernel_warmup, "_spawn", lambda errors: subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=errors))


def test_a_warm_cache_is_ready_without_a_process(warmup, monkeypatch):
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: True)
    monkeypatch.setattr(kernel_warmup, "_spawn", lambda errors: pytest.fail("a process was started"))
    now = warmup.start()
    assert (now.state, now.elapsed, now.text) == (warmup.READY, 0.0, "")


@pytest.fixture
def packed_starts(monkeypatch):
    """The packed stage's starts, recorded instead of run (each a process that sleeps 60 s, ended after
    the test: a test that replaces the warm-up's state would leave one behind)."""
    started = []

    def spawn():
        started.append(subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]))
        return started[-1]
    monkeypatch.setattr(kernel_warmup, "_spawn_packed_stage", spawn)
    yield started
    for process in started:
        process.kill()
        process.wait()


def test_with_the_ui_a_warm_cache_starts_the_packed_stage_once(warmup, monkeypatch, packed_starts):
    """Blender's UI (start(packed=True)): the first frames' kernels cached, the sampling kernel's packed
    version not yet: only the packed stage starts, once, and the state is READY (no render waits for it)."""
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: True)
    monkeypatch.setattr(corelib, "packed_version_cached", lambda: False)
    monkeypatch.setattr(kernel_warmup, "_spawn", lambda errors: pytest.fail("the first stage was started"))
    started = packed_starts
    assert warmup.start(packed=True).state == warmup.READY
    assert warmup.start(packed=True).state == warmup.READY and len(started) == 1
    assert warmup.packed_stage_running() and warmup.status().text == ""
    warmup.stop()
    assert not warmup.packed_stage_running() and started[0].poll() is not None


def test_the_packed_stage_follows_a_successful_first_stage_only(warmup, monkeypatch, packed_starts):
    monkeypatch.setattr(corelib, "packed_version_cached", lambda: False)
    started = packed_starts
    fake_compile(monkeypatch, "import time; time.sleep(1)")
    warmup.start(packed=True)
    assert started == []  # not beside the first stage: the first render waits for that one
    assert warmup.wait().state == warmup.READY and len(started) == 1
    monkeypatch.setattr(kernel_warmup, "_warmup", kernel_warmup._Warmup())
    fake_compile(monkeypatch, "raise SystemExit('the compile broke')")
    warmup.start(packed=True)
    assert warmup.wait().state == warmup.FAILED and len(started) == 1


def test_without_the_ui_or_with_the_packed_version_cached_no_packed_stage(warmup, monkeypatch, packed_starts):
    """A render's own start() (a batch job, a test session: it would end the stage unfinished) and a cache
    that holds the packed version start no packed stage."""
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: True)
    monkeypatch.setattr(corelib, "packed_version_cached", lambda: False)
    started = packed_starts
    assert warmup.start().state == warmup.READY and started == []
    monkeypatch.setattr(corelib, "packed_version_cached", lambda: True)
    assert warmup.start(packed=True).state == warmup.READY and started == []


def test_a_packed_version_cached_without_the_denoiser_starts_the_stage_again(warmup, monkeypatch, packed_starts):
    """The stage compiles the denoiser after the packed version: a stage stopped in between (Blender
    quit) must run again, or the denoiser would never be warmed."""
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: kernel != corelib.DENOISE_KERNEL)
    monkeypatch.setattr(corelib, "packed_version_cached", lambda: True)
    assert warmup.start(packed=True).state == warmup.READY and len(packed_starts) == 1
    warmup.stop()


def test_the_packed_version_counts_as_cached_from_a_second_sampling_kernel_file(tmp_path, monkeypatch):
    monkeypatch.setattr(corelib, "numba_cache_dir", lambda package=None: tmp_path)
    python = f"py{sys.version_info[0]}{sys.version_info[1]}"
    kernel = tmp_path / "render"
    kernel.mkdir()
    (kernel / f"{corelib.WARM_KERNEL}-76.{python}.nbi").write_bytes(b"")
    (kernel / f"{corelib.WARM_KERNEL}-76.{python}.1.nbc").write_bytes(b"")
    (kernel / f"{corelib.WARM_KERNEL}-76.py10.2.nbc").write_bytes(b"")  # another Python's
    assert not corelib.packed_version_cached()
    other = tmp_path / "render_elsewhere"  # the same sources installed at another path: a folder of its own
    other.mkdir()
    (other / f"{corelib.WARM_KERNEL}-76.{python}.1.nbc").write_bytes(b"")
    assert not corelib.packed_version_cached()
    (kernel / f"{corelib.WARM_KERNEL}-76.{python}.2.nbc").write_bytes(b"")
    assert corelib.packed_version_cached()


@pytest.mark.skipif(not hasattr(os, "setpriority"), reason="POSIX niceness")
def test_the_packed_stage_runs_at_lower_priority(warmup, monkeypatch, tmp_path):
    """The real process: core/jit/helper_program.py running PACKED_TASK (here a stand-in that records its
    niceness), PACKED_NICE or the parent's if that is lower already."""
    core = tmp_path / "kd_stand_in" / "core"
    (core / "jit").mkdir(parents=True)
    for folder in (core, core / "jit"):
        (folder / "__init__.py").write_text("")
    (core / "jit" / "first_frame.py").write_text(
        "import os, sys\nfrom pathlib import Path\n\ndef compile_second_stage():\n"
        "    Path(sys.argv[2], 'nice.txt').write_text(str(os.nice(0)))\n")
    shutil.copy(REAL_PROGRAM, core / "jit" / "helper_program.py")
    monkeypatch.setattr(corelib, "CORE_FOLDER", core)
    monkeypatch.setattr(corelib, "core_module_name", lambda package=None: "kd_stand_in.core")
    monkeypatch.setattr(corelib, "numba_cache_dir", lambda package=None: tmp_path / "cache")
    process = kernel_warmup._spawn_packed_stage()
    try:
        assert process.wait(60) == 0
    finally:
        process.kill()
    assert int((core / "nice.txt").read_text()) == max(os.nice(0), warmup.PACKED_NICE)


def test_two_threads_start_one_packed_stage(warmup, monkeypatch, packed_starts):
    """A render's thread (start) and the UI's timer (status) may both find the first stage ready."""
    import threading

    monkeypatch.setattr(corelib, "packed_version_cached", lambda: False)
    spawn = kernel_warmup._spawn_packed_stage
    monkeypatch.setattr(kernel_warmup, "_spawn_packed_stage", lambda: time.sleep(0.2) or spawn())
    monkeypatch.setattr(kernel_warmup._warmup, "state", warmup.READY)
    monkeypatch.setattr(kernel_warmup._warmup, "packed_wanted", True)
    threads = [threading.Thread(target=warmup.start, kwargs={"packed": True}) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(packed_starts) == 1


def test_switched_off_it_starts_nothing(warmup, monkeypatch):
    monkeypatch.setenv(warmup.SWITCH, "0")
    monkeypatch.setattr(kernel_warmup, "_spawn", lambda errors: pytest.fail("a process was started"))
    assert warmup.start().state == warmup.NOT_STARTED and warmup.status().text == ""


def test_compiling_shows_the_seconds_until_ready(warmup, monkeypatch):
    fake_compile(monkeypatch, "import time; time.sleep(1.5)")
    first = warmup.start()
    assert first.state == warmup.COMPILING and first.text == "compiling kernels (first use) 0s"
    assert warmup.start().state == warmup.COMPILING  # a second start joins the running compile
    done = warmup.wait()
    assert done.state == warmup.READY and done.elapsed >= 1.5 and done.text == ""
    assert warmup.status().elapsed == done.elapsed  # the compile's length, no longer growing


def test_wait_returns_on_cancel_and_on_timeout(warmup, monkeypatch):
    fake_compile(monkeypatch, "import time; time.sleep(60)")
    warmup.start()
    t0 = time.perf_counter()
    assert warmup.wait(cancel=lambda: True).state == warmup.COMPILING
    assert warmup.wait(timeout=0.2).state == warmup.COMPILING
    assert time.perf_counter() - t0 < 5.0
    warmup.stop()
    assert warmup.status().state == warmup.FAILED and warmup.status().message == "stopped"


def test_a_failed_compile_says_why(warmup, monkeypatch):
    fake_compile(monkeypatch, "raise SystemExit('the compile broke')")
    warmup.start()
    failed = warmup.wait()
    assert failed.state == warmup.FAILED and failed.text == "kernel compile failed: the compile broke"


def test_missing_numba_names_the_zip_to_install(warmup, monkeypatch):
    """A zip for another Blender's Python installs no numba for this one (tools/build_extension.py)."""
    fake_compile(monkeypatch, "raise ModuleNotFoundError(\"No module named 'numba'\")")
    warmup.start()
    python = f"{sys.version_info[0]}.{sys.version_info[1]}"
    assert warmup.wait().message == (f"numba is not installed for this Blender's Python {python}: install the KD "
                                     f"Preview zip built for Python {python} (README, Install)")


FAKE_FIRST_FRAME = """
import os, sys
from pathlib import Path

def compile_first_frames():
    Path(sys.argv[2], "ran.txt").write_text(f"{__name__} {os.environ['NUMBA_CACHE_DIR']}")
"""


def test_the_compile_process_runs_core_under_the_add_ons_module_name(warmup, monkeypatch, tmp_path):
    """Installed, core is `bl_ext.<repo>.<id>.core` and the add-on's __init__ imports bpy: the process
    imports core under that name without running the parents' __init__ files, and writes the cache
    this process will read."""
    core = tmp_path / "bl_ext" / "user_default" / "kd_preview" / "core"
    (core / "jit").mkdir(parents=True)
    for folder in (core, core / "jit"):
        (folder / "__init__.py").write_text("")
    for parent in core.parents[:3]:
        (parent / "__init__.py").write_text("raise ImportError('a parent package ran')\n")
    (core / "jit" / "first_frame.py").write_text(FAKE_FIRST_FRAME)
    shutil.copy(REAL_PROGRAM, core / "jit" / "helper_program.py")
    monkeypatch.setattr(corelib, "CORE_FOLDER", core)
    monkeypatch.setattr(corelib, "core_module_name", lambda package=None: "bl_ext.user_default.kd_preview.core")
    monkeypatch.setattr(corelib, "numba_cache_dir", lambda package=None: tmp_path / "cache" / "core-x")
    warmup.start()
    assert warmup.wait(timeout=60).state == warmup.READY, warmup.status().message
    assert (core / "ran.txt").read_text() == (f"bl_ext.user_default.kd_preview.core.jit.first_frame "
                                              f"{tmp_path / 'cache' / 'core-x'}")


def test_registering_in_background_mode_starts_nothing(warmup, monkeypatch):
    """A background run (`blender -b`, this bpy module) may never render a preview: no compile at enable."""
    import kd_addon

    monkeypatch.setattr(kernel_warmup, "_spawn", lambda errors: pytest.fail("a process was started"))
    kd_addon.register()
    try:
        assert warmup.status().state == warmup.NOT_STARTED
    finally:
        kd_addon.unregister()


def test_registering_with_the_ui_starts_it_and_stays_quick(warmup, monkeypatch):
    """With Blender's UI, enabling the add-on starts the compile and does not wait for it."""
    import kd_addon

    monkeypatch.setattr(kd_addon, "compiles_at_enable", lambda: True)
    fake_compile(monkeypatch, "import time; time.sleep(30)")
    t0 = time.perf_counter()
    kd_addon.register()
    try:
        assert time.perf_counter() - t0 < 2.0 and warmup.status().state == warmup.COMPILING
    finally:
        kd_addon.unregister()
    assert warmup.status().state == warmup.COMPILING  # disabling lets it finish: it only fills the cache


@pytest.mark.slow
def test_a_render_started_meanwhile_waits_visibly_and_keeps_the_compile_apart(warmup, monkeypatch, addon):
    """A render started during the compile says so, waits, loads the kernels and reports the wait apart
    from its own times (the first frame's figures are a warm frame's)."""
    import bpy

    from kd_addon import pipeline
    from kd_addon.config import make_config
    from tests.addon_support import half_plane_scene

    monkeypatch.setattr(pipeline, "_kernels_ready", False)
    fake_compile(monkeypatch, "import time; time.sleep(2)")
    warmup.start()
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: True)  # the tests' cache is
    scene = half_plane_scene()
    job = pipeline.FrameJob(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))
    seen = []
    pipeline.run_job(job, progress=lambda fraction, status: seen.append(status))
    result = job.result()
    assert seen[0].startswith("compiling kernels (first use) ")
    assert seen[0].endswith(": the render starts when they are ready")
    assert result.compile_ms >= 1000.0 and result.load_ms > 0 and result.first_run is False
    assert result.summary()["compile_ms"] == result.compile_ms


class Layout:
    """A stand-in for a panel's or the status bar's layout: the labels drawn."""

    def __init__(self):
        self.labels = []

    def label(self, text, icon="NONE"):
        self.labels.append((text, icon))


def test_the_status_bar_and_panel_show_the_compile_until_ready(warmup, monkeypatch):
    from kd_addon import warmup_display

    drawn = Layout()
    warmup_display.draw_status(drawn)
    assert drawn.labels == []  # nothing started: nothing to say
    fake_compile(monkeypatch, "import time; time.sleep(1)")
    warmup.start()
    warmup_display.draw_status(drawn)
    assert drawn.labels == [("compiling kernels (first use) 0s", "TIME")]
    assert warmup_display._redraw() == warmup_display.REDRAW_SECONDS  # keeps the seconds moving
    warmup.wait()
    assert warmup_display._redraw() is None  # the timer ends with the compile
    drawn = Layout()
    warmup_display.draw_status(drawn)
    assert drawn.labels == []


def compiled_versions() -> dict:
    """Every Numba dispatcher alive in this process and the argument types it holds compiled (or loaded).
    By the object's own type: isinstance would ask a weak proxy among gc's objects for its referent's
    class, which raises once the referent is gone."""
    import gc

    from numba.core.registry import CPUDispatcher

    return {d: set(d.overloads) for d in gc.get_objects() if issubclass(type(d), CPUDispatcher)}


@pytest.mark.slow
@pytest.mark.parametrize("stages", ["first", "both"])
def test_after_the_warm_up_the_factory_scenes_first_frame_compiles_nothing(monkeypatch, stages):
    """The warm-up's made-up frames (core/jit/first_frame.py) run every kernel, with every argument type,
    that a first render of the factory scene (one cube, one point light, the default settings) runs:
    after them, in this process, Render adds no compiled version to any kernel, so in Blender the frame
    only loads kernels from the cache the warm-up filled. After the first stage alone (the second's
    kernels neither loaded nor cached: the render traces singly, in small batches), and after both
    stages, when a denoised frame compiles nothing either (the second stage runs the denoiser)."""
    import bpy

    import kd_addon
    from core.jit import first_frame, parallel_compile
    from core.render import preview_render
    from tests import bpy_scenes

    monkeypatch.setenv(parallel_compile.HELPER_SWITCH, "0")  # the helper's side runs here too
    if stages == "first":  # what a render finds before the second stage has run
        monkeypatch.setattr(preview_render, "_packet_kernels_ready", lambda: False)
        monkeypatch.setattr(preview_render, "packed_version_ready", lambda: False)
    first_frame.compile_first_frames()
    if stages == "both":
        first_frame.compile_second_stage()  # packets, packed samples (a render's larger batches), denoiser
    before = compiled_versions()
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    kd_addon.register()
    try:
        bpy.context.scene.kd_preview.resolution_percentage = 5
        assert bpy.ops.kdpreview.render() == {"FINISHED"}
        if stages == "both":
            bpy.context.scene.kd_preview.denoise = True
            assert bpy.ops.kdpreview.render() == {"FINISHED"}
    finally:
        kd_addon.unregister()
        bpy_scenes.reset()
    after = compiled_versions()
    grown = sorted(f"{d.py_func.__module__}.{d.py_func.__qualname__}{sorted(map(str, after[d] - before.get(d, set())))}"
                   for d in after if after[d] - before.get(d, set()))
    assert grown == [], "compiled after the warm-up: " + "; ".join(grown)
