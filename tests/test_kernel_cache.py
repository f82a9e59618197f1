"""Cached kernels are keyed by every source file they may inline, not only their own
(core/jit/kernel_cache.py). CI once ran a `trace_rays` cached before a fix to the triangle test it inlines."""
import subprocess
import sys
import textwrap
from pathlib import Path

import core
from core.jit import kernel_cache
from core.trace.traversal import trace_rays

CALLER = """
from numba import njit
from .callee import value

@njit(cache=True)
def run():
    return value()
"""
CALLEE = """
from numba import njit

@njit(cache=True, inline="always")
def value():
    return {}
"""
RUN = """
import sys
sys.path.insert(0, {root!r})
from core.jit import kernel_cache
if {register}:
    kernel_cache.register({package!r}, sources={package!r})
from pkg.caller import run
print(run())
"""


def _run_cached(root: Path, register: bool, cache: Path) -> int:
    script = RUN.format(root=str(root), package=str(root / "pkg"), register=register)
    # No .pyc: Python checks one by its source's mtime in whole seconds and its size, so a callee
    # edited within the same second would run old bytecode whatever Numba does.
    env = {"NUMBA_CACHE_DIR": str(cache), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    out = subprocess.run([sys.executable, "-c", script], cwd=Path(core.__file__).parent.parent, env=env,
                         capture_output=True, text=True, check=True, timeout=300)
    return int(out.stdout.split()[-1])


def _package_returning(root: Path, value: int) -> None:
    (root / "pkg").mkdir(exist_ok=True)
    (root / "pkg" / "__init__.py").write_text("")
    (root / "pkg" / "caller.py").write_text(CALLER)
    (root / "pkg" / "callee.py").write_text(textwrap.dedent(CALLEE.format(value)))


def test_editing_an_inlined_callee_recompiles_its_caller(tmp_path):
    """The caller's own file is unchanged; only the callee's differs between the two processes."""
    _package_returning(tmp_path, 1)
    assert _run_cached(tmp_path, True, tmp_path / "cache") == 1
    _package_returning(tmp_path, 22)
    assert _run_cached(tmp_path, True, tmp_path / "cache") == 22


def test_without_registering_numba_runs_the_stale_callee(tmp_path):
    """The hazard the module exists for, in Numba as pinned: if this starts failing, Numba keys its
    cache by callees itself and kernel_cache can go."""
    _package_returning(tmp_path, 1)
    assert _run_cached(tmp_path, False, tmp_path / "cache") == 1
    _package_returning(tmp_path, 22)
    assert _run_cached(tmp_path, False, tmp_path / "cache") == 1


def test_core_kernels_are_stamped_with_all_of_core():
    locator = trace_rays._cache._impl.locator
    assert isinstance(locator, kernel_cache.SourcesDigestLocator)
    own_stamp, digest = locator.get_source_stamp()
    assert digest == kernel_cache.folder_digest(kernel_cache.CORE_FOLDER)


def test_kernels_in_every_subpackage_are_stamped_with_all_of_core():
    """Core's kernels live in subpackages (build, trace, scene, render); each is keyed by all of core."""
    from core.build.subtree import build_subtree
    from core.render.render_kernels import add_samples
    from core.scene.instance_traversal import trace_scene_rays

    digest = kernel_cache.folder_digest(kernel_cache.CORE_FOLDER)
    for kernel in (trace_rays, build_subtree, add_samples, trace_scene_rays):
        locator = kernel._cache._impl.locator
        assert isinstance(locator, kernel_cache.SourcesDigestLocator), kernel
        assert locator.get_source_stamp()[1] == digest


def test_the_digest_follows_files_in_subfolders(tmp_path):
    """An edit, a new file or a move inside a subfolder changes the digest of the folder above."""
    (tmp_path / "render").mkdir()
    (tmp_path / "trace").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "render" / "kernels.py").write_text("y = 1\n")
    before = kernel_cache.sources_digest(tmp_path)
    (tmp_path / "render" / "kernels.py").write_text("y = 2\n")
    edited = kernel_cache.sources_digest(tmp_path)
    (tmp_path / "render" / "kernels.py").rename(tmp_path / "trace" / "kernels.py")
    moved = kernel_cache.sources_digest(tmp_path)
    (tmp_path / "trace" / "new.py").write_text("")
    added = kernel_cache.sources_digest(tmp_path)
    assert len({before, edited, moved, added}) == 4


def test_a_helper_gets_the_cache_folder_of_every_core_folder_with_kernels():
    """The helper process writes each of core's kernels where this process reads it
    (CORE_CACHE_FOLDER_VARIABLE): one folder per subpackage with kernels."""
    import json

    from core.render.render_kernels import add_samples

    folders = json.loads(kernel_cache.core_cache_folders())
    assert {"build", "trace", "scene", "render"} <= set(folders)
    assert folders["render"] == add_samples._cache._cache_path
    assert folders["trace"] == trace_rays._cache._cache_path


def test_the_digest_follows_every_source_file(tmp_path):
    for name in ("a.py", "b.py"):
        (tmp_path / name).write_text("x = 1\n")
    before = kernel_cache.sources_digest(tmp_path)
    (tmp_path / "b.py").write_text("x = 2\n")
    edited = kernel_cache.sources_digest(tmp_path)
    (tmp_path / "c.py").write_text("")
    added = kernel_cache.sources_digest(tmp_path)
    assert len({before, edited, added}) == 3


UNCACHABLE = """
import ctypes

from numba import njit

_initialized = ctypes.pythonapi.Py_IsInitialized
_initialized.argtypes, _initialized.restype = [], ctypes.c_int

@njit(cache=True)
def run():
    return _initialized()  # a ctypes function pointer: machine code Numba cannot cache
"""


def test_a_registered_kernel_that_cannot_be_cached_still_runs(tmp_path):
    """Numba warns and runs a kernel it cannot cache (its warning names the kernel's file, which it
    reads from the locator): the digest locator must answer that too. It raised AttributeError,
    found with NUMBA_OPT=0, under which core's triangle_boxes keeps a dynamic global."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "caller.py").write_text(UNCACHABLE)
    script = RUN.format(root=str(tmp_path), package=str(tmp_path / "pkg"), register=True)
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    out = subprocess.run([sys.executable, "-c", script], cwd=Path(core.__file__).parent.parent, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[-1] == "1"
    assert "Cannot cache compiled function" in out.stderr and "caller.py" in out.stderr


TWO_TYPES = """
from numba import njit

@njit(cache=True)
def twice(x):
    return 2 * x
"""
SIGNATURES = """
import sys
sys.path.insert(0, {root!r})
from core.jit import kernel_cache
kernel_cache.register({package!r}, sources={package!r})
from pkg.twice import twice
if {call}:
    twice(1), twice(1.5)
print(sorted(str(sig) for sig in kernel_cache.cached_signatures(twice)), sorted(map(str, twice.signatures)))
"""


def _signatures(root: Path, call: bool, cache: Path) -> str:
    script = SIGNATURES.format(root=str(root), package=str(root / "pkg"), call=call)
    env = {"NUMBA_CACHE_DIR": str(cache), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    out = subprocess.run([sys.executable, "-c", script], cwd=Path(core.__file__).parent.parent, env=env,
                         capture_output=True, text=True, check=True, timeout=300)
    return out.stdout.strip().splitlines()[-1]


def test_cached_signatures_lists_what_the_cache_holds_before_anything_loads(tmp_path):
    """What PreviewRender.batch_without_compile asks (through render_kernels.packed_version_ready): the
    versions another process compiled are listed without being loaded; none for an empty cache or once
    the sources changed (the index's stamp no longer matches)."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "twice.py").write_text(TWO_TYPES)
    cache = tmp_path / "cache"
    assert _signatures(tmp_path, False, cache) == "[] []"
    assert _signatures(tmp_path, True, cache) == "['(float64,)', '(int64,)'] ['(float64,)', '(int64,)']"
    assert _signatures(tmp_path, False, cache) == "['(float64,)', '(int64,)'] []"
    (tmp_path / "pkg" / "__init__.py").write_text("# edited\n")
    assert _signatures(tmp_path, False, cache) == "[] []"
