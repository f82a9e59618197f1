"""Numba's on-disk kernel cache, invalidated by any change to core's sources, not just the kernel's file.

Numba stamps a cached kernel with its own source file only (numba 0.68), but core's kernels inline
functions from other files. `register` puts a locator before Numba's own (`CacheImpl._locator_classes`,
internal; numba is pinned) that adds the digest of all of core's sources, subpackages included, to the
stamp of every kernel in a registered folder or below, and wraps `IndexDataCacheFile.save` (read,
extend, rewrite the index) in a file lock (`locked_cache_folder`), since several processes may compile
into one cache. Numba re-reads NUMBA_CACHE_DIR before every compile, so a helper is told where this
process reads: CORE_CACHE_FOLDER_VARIABLE, JSON from each kernel folder relative to core to its cache
folder.
"""
import functools
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from numba.core import caching

from .sources_digest import sources_digest

CORE_FOLDER = Path(__file__).resolve().parent.parent
_sources_of = {}  # registered kernel folder (and its subfolders) -> the folder whose sources stamp its kernels
_core_cache_folders = {}  # core's kernel folder, relative to core ("render") -> its kernels' cache folder
_locked_folders = set()  # cache folders of registered kernels, whose index saves take the lock
LOCK_NAME = "kd_preview_index.lock"
CORE_CACHE_FOLDER_VARIABLE = "KD_PREVIEW_CORE_KERNEL_CACHE"  # a helper's cache folders for core's kernels


@functools.lru_cache(maxsize=None)
def folder_digest(folder: Path) -> str:
    """Read once a process: sources do not change under kernels a process has already loaded."""
    return sources_digest(folder)


class SourcesDigestLocator(caching._CacheLocator):
    """Numba's usual locator for the kernel's file, with the sources' digest added to its stamp."""

    def __init__(self, usual, sources: Path, folder=None):
        self._usual = usual
        self._py_file = usual._py_file  # Numba's warning that a kernel cannot be cached names it
        self._sources = sources
        self._folder = folder or usual.get_cache_path()
        _locked_folders.add(os.path.normpath(self._folder))

    def ensure_cache_path(self):
        if self._folder == self._usual.get_cache_path():
            self._usual.ensure_cache_path()
        else:  # as Numba's own: the folder must exist and take files
            os.makedirs(self._folder, exist_ok=True)
            tempfile.TemporaryFile(dir=self._folder).close()

    def get_cache_path(self):
        return self._folder

    def get_source_stamp(self):
        return self._usual.get_source_stamp(), folder_digest(self._sources)

    def get_disambiguator(self):
        return self._usual.get_disambiguator()

    @classmethod
    def from_function(cls, py_func, py_file):
        kernel_folder = Path(py_file).resolve().parent
        sources = _registered_sources(kernel_folder)
        if sources is None:
            return None
        in_core = kernel_folder == CORE_FOLDER or CORE_FOLDER in kernel_folder.parents
        relative = kernel_folder.relative_to(CORE_FOLDER).as_posix() if in_core else None
        folder = _helper_cache_folders().get(relative) if in_core else None
        for usual_class in caching.CacheImpl._locator_classes:
            if usual_class is not cls:
                usual = usual_class.from_function(py_func, py_file)
                if usual is not None:
                    locator = cls(usual, sources, folder)
                    if in_core:
                        _core_cache_folders[relative] = locator.get_cache_path()
                    return locator
        return None


def _registered_sources(kernel_folder: Path):
    """The sources that stamp the kernels of `kernel_folder`: those registered for it or for the nearest
    folder above it; None when neither it nor any folder above is registered."""
    for folder in (kernel_folder, *kernel_folder.parents):
        if folder in _sources_of:
            return _sources_of[folder]
    return None


def _helper_cache_folders() -> dict:
    """In a helper process, the cache folders its parent gave core's kernels (CORE_CACHE_FOLDER_VARIABLE);
    elsewhere empty, and each kernel goes where Numba would put it."""
    value = os.environ.get(CORE_CACHE_FOLDER_VARIABLE)
    return json.loads(value) if value else {}


@contextmanager
def locked_cache_folder(folder):
    """Hold an exclusive lock on `folder`/LOCK_NAME (blocking; released on exit or process death).
    Where the lock cannot be taken, it proceeds unlocked: Numba's own behaviour, not a failed compile."""
    try:
        handle = open(os.path.join(folder, LOCK_NAME), "a+b")
    except OSError:
        yield
        return
    with handle:
        try:
            _lock(handle, True)
        except OSError:
            yield
            return
        try:
            yield
        finally:
            _lock(handle, False)


def _lock(handle, take):
    if os.name == "nt":
        import msvcrt
        handle.seek(0)
        msvcrt.locking(handle.fileno(), msvcrt.LK_LOCK if take else msvcrt.LK_UNLCK, 1)
    else:
        import fcntl
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX if take else fcntl.LOCK_UN)


def _save_under_lock(numba_save):
    @functools.wraps(numba_save)
    def save(self, key, data):
        if os.path.normpath(self._cache_path) not in _locked_folders:
            return numba_save(self, key, data)
        with locked_cache_folder(self._cache_path):
            return numba_save(self, key, data)

    save.kd_preview_lock = True
    return save


def core_cache_folders() -> str:
    """The value of CORE_CACHE_FOLDER_VARIABLE for a helper: where this process caches the kernels of
    each of core's folders, as JSON."""
    return json.dumps(_core_cache_folders, sort_keys=True)


def cached_signatures(dispatcher) -> list:
    """The argument types of the versions of `dispatcher` (an njit(cache=True) function) that Numba's
    on-disk cache holds for this machine (its codegen's magic tuple) and for the current sources (the
    index's stamp, SourcesDigestLocator's) whose data file is written (Numba saves the index first); []
    when none. Reads Numba's index as Numba does (IndexDataCacheFile._load_index, internal; numba is
    pinned) without loading any code."""
    cache_file = getattr(dispatcher._cache, "_cache_file", None)  # a NullCache has none
    if cache_file is None:
        return []
    magic = dispatcher.targetctx.codegen().magic_tuple()
    return [key[0] for key, name in cache_file._load_index().items()
            if key[1] == magic and os.path.exists(cache_file._data_path(name))]


def holds_version(dispatcher, accept=None) -> bool:
    """Whether `dispatcher` has a version whose argument types `accept` takes (any version when None) that
    runs without a compile: loaded in this process, or in the on-disk cache (cached_signatures). A loaded
    one answers without reading the cache's index; an unreadable index reads as none."""
    accept = accept or (lambda signature: True)
    if any(accept(signature) for signature in dispatcher.signatures):
        return True
    try:
        return any(accept(signature) for signature in cached_signatures(dispatcher))
    except Exception:  # noqa: BLE001 (a broken or foreign index: Numba would recompile too)
        return False


def register(folder=CORE_FOLDER, sources=CORE_FOLDER) -> None:
    """Key the cached kernels of `folder` and its subfolders (core's, or e.g. a test's that inline
    core's functions) by the `*.py` files of `sources` (and its subfolders) too. Must run before the
    folder's kernels are decorated: Numba picks a kernel's locator when `njit(cache=True)` wraps it."""
    _sources_of[Path(folder).resolve()] = Path(sources).resolve()
    if SourcesDigestLocator not in caching.CacheImpl._locator_classes:
        caching.CacheImpl._locator_classes.insert(0, SourcesDigestLocator)
    if not getattr(caching.IndexDataCacheFile.save, "kd_preview_lock", False):
        caching.IndexDataCacheFile.save = _save_under_lock(caching.IndexDataCacheFile.save)


register()
