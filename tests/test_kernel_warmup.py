"""The kernels' background compile (kd_addon/kernel_warmup.py): its states and what they show, a
failure's message, the compile process as the add-on starts it, and a render waiting for it."""

from __future__ import annotations

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
    """Every Numba dispatcher alive in this process and the argument types it holds compiled (or loaded)."""
    import gc

    from numba.core.registry import CPUDispatcher

    return {d: set(d.overloads) for d in gc.get_objects() if isinstance(d, CPUDispatcher)}


@pytest.mark.slow
def test_after_the_warm_up_the_factory_scenes_first_frame_compiles_nothing(monkeypatch):
    """The warm-up's made-up frames (core/jit/first_frame.py) run every kernel, with every argument type,
    that a first render of the factory scene (one cube, one point light, the default settings) runs:
    after them, in this process, Render adds no compiled version to any kernel, so in Blender the frame
    only loads kernels from the cache the warm-up filled."""
    import bpy

    import kd_addon
    from core.jit import first_frame, parallel_compile
    from tests import bpy_scenes

    monkeypatch.setenv(parallel_compile.HELPER_SWITCH, "0")  # the helper's side runs here too
    first_frame.compile_first_frames()
    before = compiled_versions()
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    kd_addon.register()
    try:
        bpy.context.scene.kd_preview.resolution_percentage = 5
        assert bpy.ops.kdpreview.render() == {"FINISHED"}
    finally:
        kd_addon.unregister()
        bpy_scenes.reset()
    after = compiled_versions()
    grown = sorted(f"{d.py_func.__module__}.{d.py_func.__qualname__}{sorted(map(str, after[d] - before.get(d, set())))}"
                   for d in after if after[d] - before.get(d, set()))
    assert grown == [], "compiled after the warm-up: " + "; ".join(grown)
