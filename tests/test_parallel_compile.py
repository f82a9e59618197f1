"""The first render's helper process (core/parallel_compile.py) and the lock that lets several processes
write one kernel cache (core/kernel_cache.py)."""
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from core import kernel_cache, parallel_compile

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
from numba import njit

@njit(cache=True)
def twice(x):
    return 2 * x
"""
COMPILE_PROBE = """
import sys, time
sys.path[:0] = [{root!r}, {folder!r}]
from core import kernel_cache
kernel_cache.register({folder!r}, sources={folder!r})
import probe
probe.twice(21)
print(time.time())
"""


@pytest.mark.skipif(os.name == "nt", reason="the lock is held here with fcntl")
def test_a_cache_index_save_waits_for_the_lock(tmp_path):
    """A process compiling a registered kernel writes its cache index only once the folder's lock is
    free: it returns after the holder released the lock, and its entry is then in the index."""
    folder = tmp_path / "src"
    folder.mkdir()
    (folder / "probe.py").write_text(PROBE)
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    script = COMPILE_PROBE.format(root=str(ROOT), folder=str(folder))
    # Where the child's cache files go: the same locator here, on the same file.
    probe_cache = _probe_cache_folder(folder, cache)
    probe_cache.mkdir(parents=True, exist_ok=True)
    with kernel_cache.locked_cache_folder(str(probe_cache)):
        child = subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE, text=True)
        time.sleep(15)  # the child imports numba and compiles in 2-5 s, then waits at the save
        assert child.poll() is None, "the child finished while the lock was held"
        assert not list(probe_cache.glob("*.nbi")), "the child wrote its index while the lock was held"
        released = time.time()
    out, _ = child.communicate(timeout=120)
    assert child.returncode == 0
    assert float(out.split()[-1]) >= released
    assert len(list(probe_cache.glob("*twice*.nbi"))) == 1 and len(list(probe_cache.glob("*twice*.nbc"))) == 1


def _probe_cache_folder(folder: Path, cache: Path) -> Path:
    """The folder Numba's cache locator picks for folder/probe.py under NUMBA_CACHE_DIR=cache,
    asked in a fresh process (the locator reads NUMBA_CACHE_DIR once)."""
    code = textwrap.dedent(f"""
        import sys
        sys.path[:0] = [{str(ROOT)!r}, {str(folder)!r}]
        from core import kernel_cache
        kernel_cache.register({str(folder)!r}, sources={str(folder)!r})
        import probe
        print(probe.twice._cache._cache_path)
    """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    return Path(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                               check=True).stdout.strip())


FAKE_CORE = """
import sys
from pathlib import Path

def compile_rendering_kernels():
    Path(sys.argv[2], "ran.txt").write_text(__name__)
"""


def test_the_helper_imports_core_under_an_extension_package_name(tmp_path):
    """Installed, core is `bl_ext.<repo>.<id>.core` and the add-on's __init__ imports bpy: the helper
    imports core under that name without running the parents' __init__ files."""
    core_folder = tmp_path / "bl_ext" / "user_default" / "kd_preview" / "core"
    core_folder.mkdir(parents=True)
    (core_folder / "__init__.py").write_text("")
    (core_folder / "parallel_compile.py").write_text(FAKE_CORE)
    for parent in core_folder.parents[:3]:
        (parent / "__init__.py").write_text("raise ImportError('a parent package ran')\n")
    name = "bl_ext.user_default.kd_preview.core"
    run = subprocess.run([sys.executable, "-c", parallel_compile._HELPER_CODE, name, str(core_folder)],
                         capture_output=True, text=True, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert (core_folder / "ran.txt").read_text() == f"{name}.parallel_compile"


def test_the_helper_renders_with_the_rendering_kernels_and_exits_cleanly():
    """The helper's program, started as the first render starts it (here on this run's cache, so it
    mostly loads kernels): it renders the hand-made tree and exits with status 0."""
    parallel_compile.compile_scene_wrapping()
    helper = parallel_compile.RenderingKernelsHelper()
    try:
        helper.wait(600)
    finally:
        helper.stop()
    assert helper.outcome == "finished"
    assert parallel_compile.rendering_kernels_cached()


def test_no_helper_when_the_kernels_are_cached_or_it_is_switched_off(monkeypatch):
    parallel_compile.compile_rendering_kernels()  # in this process: they are in the cache now
    with parallel_compile.rendering_kernels_alongside() as helper:
        assert helper is None
    monkeypatch.setattr(parallel_compile, "rendering_kernels_cached", lambda: False)
    monkeypatch.setenv(parallel_compile.HELPER_SWITCH, "0")
    with parallel_compile.rendering_kernels_alongside() as helper:
        assert helper is None


def test_a_failing_block_ends_the_helper_at_once(monkeypatch):
    """A build that raises must not leave a helper writing the cache while this process goes on."""
    monkeypatch.setattr(parallel_compile, "rendering_kernels_cached", lambda: False)
    monkeypatch.delenv(parallel_compile.HELPER_SWITCH, raising=False)
    with pytest.raises(ValueError, match="bad build"):
        with parallel_compile.rendering_kernels_alongside() as helper:
            assert helper is not None
            raise ValueError("bad build")
    assert helper.process.poll() is not None


def test_the_hand_made_tree_renders_like_a_built_one():
    """The helper's tree is a valid KdTree: its render equals one of a built tree over the same square."""
    import numpy as np

    import core

    tree = parallel_compile.hand_made_tree()
    built = core.build_kdtree(tree.triangles)
    camera = core.Camera(np.array([[1.0, 0, 0, 0.2], [0, 1, 0, 0.1], [0, 0, 1, 3], [0, 0, 0, 1]]), 0.9)
    args = dict(mode="ao+shadow", samples=4, lights=[core.Light.point((0.0, 0.0, 2.0))])
    a, b = core.render_preview(tree, camera, 16, 12, **args), core.render_preview(built, camera, 16, 12, **args)
    assert a[..., 3].sum() > 0 and (a[..., 3] == 0).any()  # the square and background both in view
    np.testing.assert_array_equal(a, b)
