"""One Numba cache folder for the test session and every process it starts.

Test modules import core directly, which decorates core's kernels with Numba's folder for them under
NUMBA_CACHE_DIR; the add-on's processes that tests start (`python -m kd_addon`, Blender's command line)
cache core's kernels in the add-on's folder, named by the sources' digest (kd_addon/corelib.py). A cold
run compiled every kernel into both: ~2 minutes of the CI run on two cores, once per Python version.
Pointing the process at the add-on's folder first makes both one (a child inherits the variable, and
corelib keeps a folder that already is the versioned one). The base is under the system temp folder
unless NUMBA_CACHE_DIR is set, so tests never write the add-on's cache in the home folder and later runs
start warm. conftest.py and the kernel warm-up beside pytest (warm_kernels.py) both call use_test_cache.
"""
import os
import tempfile


def use_test_cache() -> None:
    """Send this process's (and its children's) kernels to the test session's cache folder; must run
    before core is imported."""
    os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(tempfile.gettempdir(), "kd_preview_test_numba_cache"))
    os.environ["NUMBA_CACHE_DIR"] = os.path.abspath(os.environ["NUMBA_CACHE_DIR"])  # children run elsewhere

    from kd_addon import corelib

    corelib.configure_numba_cache(corelib.numba_cache_dir())
