"""The one place that imports `core` (lazily) and points Numba's cache somewhere writable first.

Lazily, because importing core imports numba and its kernels compile on first use: enabling the
add-on must not pay for that. The cache goes to Blender's per-extension user folder (or, outside an
extension, the platform's user cache folder; NUMBA_CACHE_DIR wins), since Numba's default
`__pycache__` inside the extension is wiped on update and may be read-only. One folder per digest of
core's sources keeps versions apart and lets `cache_is_warm` tell loading from compiling. Installed,
core is the sibling subpackage `bl_ext.<repo>.kd_preview.core`; in the repository, top-level `core`.
"""

from __future__ import annotations

import collections
import functools
import importlib
import importlib.util
import os
import sys
import time
from pathlib import Path

APP_NAME = "kd_preview"
CORE_FOLDER = Path(__file__).resolve().parent.parent / "core"


def extension_package(package: str | None = __package__) -> str | None:
    """The extension's 3-part package name ("bl_ext.<repo>.<id>"), or None outside one.

    extension_path_user rejects any other number of parts.
    """
    parts = (package or "").split(".")
    if len(parts) >= 3 and parts[0] == "bl_ext":
        return ".".join(parts[:3])
    return None


def core_module_name(package: str | None = __package__) -> str:
    """Absolute name of the core package that sits beside this add-on package."""
    parent = (package or "").rpartition(".")[0]
    return f"{parent}.core" if parent else "core"


def user_cache_dir() -> Path:
    """Per-user cache folder outside any extension (XDG / Windows / macOS conventions)."""
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / APP_NAME / "numba"


def numba_cache_dir(package: str | None = __package__) -> Path:
    """Where compiled kernels are cached: a folder named by the sources' digest inside
    NUMBA_CACHE_DIR if set, else the extension's user folder, else the user cache folder."""
    return _versioned(_cache_base(package))


def _cache_base(package: str | None) -> Path:
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    ext = extension_package(package)
    if ext is not None:
        try:
            import bpy

            return Path(bpy.utils.extension_path_user(ext, path="numba_cache", create=True))
        except (ImportError, ValueError, AttributeError):
            pass
    return user_cache_dir()


def _versioned(base: Path) -> Path:
    """base / "core-<digest>", unless base already is that folder (a child process inherits the
    configured NUMBA_CACHE_DIR)."""
    name = f"core-{source_digest()}"
    return base if base.name == name else base / name


def source_digest(folder: Path | None = None) -> str:
    """16 hex digits that change whenever any of core's source files (in `folder`, default: this
    installation's core) changes."""
    return _digest(Path(folder)) if folder is not None else _installed_digest()


@functools.lru_cache(maxsize=1)
def _installed_digest() -> str:
    """Read once a process: the status line asks for the cache folder on every tick until the
    kernels are ready, and the installed sources do not change under a running process."""
    return _digest(CORE_FOLDER)


def _digest(folder: Path) -> str:
    return _core_sources_digest_module().sources_digest(folder)


@functools.lru_cache(maxsize=1)
def _core_sources_digest_module():
    """core/jit/sources_digest.py loaded as a file: importing it as part of core would import numba and
    every kernel module, which enabling the add-on must not do (see above)."""
    path = CORE_FOLDER / "jit" / "sources_digest.py"
    spec = importlib.util.spec_from_file_location(f"{APP_NAME}_core_sources_digest", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def configure_numba_cache(path: Path) -> None:
    """Send Numba's cache to `path`. Must run before core's modules are imported, since
    Numba picks a function's cache location when the function is decorated.

    Both the environment and numba.config are set: Numba re-reads NUMBA_* variables at each
    compilation whenever any of them changed, which would otherwise undo the config value.
    """
    path.mkdir(parents=True, exist_ok=True)
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    import numba

    numba.config.CACHE_DIR = str(path)


def is_loaded() -> bool:
    """Whether core has been imported in this process (i.e. no import cost left)."""
    return core_module_name() in sys.modules


def compile_reading() -> tuple[float, float]:
    """(perf_counter(), seconds Numba has spent compiling in this process), read at one instant
    (core/jit/compile_clock.py counts every compile once core is imported; 0 before), so differences of
    the second are the compiles between two readings."""
    if not is_loaded():
        return time.perf_counter(), 0.0
    return importlib.import_module(core_module_name() + ".jit.compile_clock").reading()


def load_core():
    """Import and return the core package, configuring the Numba cache on first import."""
    name = core_module_name()
    if name not in sys.modules:
        configure_numba_cache(numba_cache_dir())
    return importlib.import_module(name)


WARM_KERNEL = "render_kernels.add_samples"  # the renderer's sampling kernel, the longest to compile
DENOISE_KERNEL = "denoise.atrous_pass"  # the denoiser's filter, compiled on Denoise's first use


def cache_is_warm(kernel: str = WARM_KERNEL) -> bool:
    """Whether the cache folder already holds `kernel` ("module.function") compiled for this Python
    (so the first run only loads kernels). Any index file is not enough: the first appears seconds
    into a compile of minutes."""
    return holds_kernel(numba_cache_dir(), kernel)


def packed_version_cached() -> bool:
    """Whether the cache folder holds a second version of the sampling kernel for this Python: the add-on
    compiles it in two, steps of one sample and the packed batches (kernel_warmup's packed stage). A file
    count, so that the check needs no numba; renders ask core itself (PreviewRender.batch_without_compile),
    so a wrong count only starts or skips that stage."""
    folder = numba_cache_dir()
    if not folder.is_dir():
        return False
    # per kernel folder: Numba keeps one a source path, and installations at several paths share `folder`
    counts = collections.Counter(path.parent for path in folder.rglob(f"{WARM_KERNEL}-*.{_python_tag()}.*.nbc"))
    return any(count >= 2 for count in counts.values())


def holds_kernel(folder: Path, kernel: str = WARM_KERNEL) -> bool:
    """Whether the Numba cache files in `folder` (or below) include `kernel` compiled for this Python."""
    return folder.is_dir() and any(folder.rglob(f"{kernel}-*.{_python_tag()}.nbi"))


def _python_tag() -> str:
    """This Python's tag in Numba's cache file names ("py311")."""
    return f"py{sys.version_info[0]}{sys.version_info[1]}"
