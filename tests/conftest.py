"""One Numba cache folder for the test session and every process it starts.

Runs before pytest imports any test module. Test modules import core directly, which decorates core's
kernels with Numba's folder for them under NUMBA_CACHE_DIR; the add-on's processes that tests start
(`python -m kd_addon`, Blender's command line) cache core's kernels in the add-on's folder, named by
the sources' digest (kd_addon/corelib.py). A cold run compiled every kernel into both: ~2 minutes of
the CI run on two cores, once per Python version. Pointing this process at the add-on's folder first
makes both one (a child inherits the variable, and corelib keeps a folder that already is the
versioned one). The base is under the system temp folder unless NUMBA_CACHE_DIR is set, so tests
never write the add-on's cache in the home folder and later runs start warm.
"""
import os
import tempfile

os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(tempfile.gettempdir(), "kd_preview_test_numba_cache"))
os.environ["NUMBA_CACHE_DIR"] = os.path.abspath(os.environ["NUMBA_CACHE_DIR"])  # children run elsewhere

from kd_addon import corelib  # noqa: E402  (after the variable: corelib reads it)

corelib.configure_numba_cache(corelib.numba_cache_dir())

import pytest  # noqa: E402


@pytest.fixture
def scene():
    """A fresh empty scene (bpy imported here, so tests of core alone never load Blender)."""
    from tests import bpy_scenes

    return bpy_scenes.reset()


@pytest.fixture
def addon(monkeypatch):
    """The add-on registered on a fresh empty scene; unregistered afterwards. Live Update's edit timer
    waits for the worker's kernel call as long as it takes (background.SCENE_READ_WAIT; at its 0.1 s a
    slow build would make the tests' direct timer calls retry instead of acting)."""
    import kd_addon
    from kd_addon import background
    from tests import bpy_scenes

    monkeypatch.setattr(background, "SCENE_READ_WAIT", 60.0)
    bpy_scenes.reset()
    kd_addon.register()
    try:
        yield kd_addon
    finally:
        try:
            kd_addon.unregister()
        finally:
            # A test that cancelled a run leaves its kernel call running; the next test's ticks would
            # wait for it. One that never ends would make every later test wait: stop the session.
            if not background.wait_for_work(120.0):
                pytest.exit("a cancelled kernel call still runs 120 s after its test ended", returncode=1)


BULK_READINGS: dict = {}  # how many extractions the bulk path took or gave up, over the session


@pytest.fixture(params=["walk", "bulk"])
def extraction_path(request, monkeypatch):
    """Runs a test on both ways of reading instances (kd_addon/bulk_instances.py): "walk" switches the bulk
    path off; "bulk" leaves it on and checks each bulk reading against the walk of the same depsgraph."""
    from kd_addon import bulk_instances
    from tests.extract_support import bulk_checked_against_walk

    if request.param == "walk":
        monkeypatch.setattr(bulk_instances, "ENABLED", False)
    else:
        monkeypatch.setattr(bulk_instances, "read_in_bulk",
                            bulk_checked_against_walk(bulk_instances.read_in_bulk, BULK_READINGS))
    return request.param


def pytest_terminal_summary(terminalreporter):
    if BULK_READINGS:
        terminalreporter.write_line(f"bulk instance readings: {BULK_READINGS.get('bulk', 0)} taken, "
                                    f"{BULK_READINGS.get('walk', 0)} left to the walk")
