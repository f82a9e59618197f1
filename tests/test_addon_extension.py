"""The extension as users get it: build the linux-x64 zip with tools/build_extension.py, then install,
enable, render and uninstall it in a separate bpy process with its own Blender user folder.

Slow by nature: the first run downloads ~60 MB of wheels into build/wheels_cache/, and the
installed copy of core compiles its kernels from scratch (its Numba cache lives in the fresh user
folder, as in a real install): 1-3.5 minutes on two cores, the suite's slowest test.

Once per Python version and version of core's sources: the kernels that compile keep Blender's module
name for core (`bl_ext.user_default.kd_preview.core`, which the test process's cache cannot serve), so
the test keeps them beside the tests' Numba cache (installed_kernels_folder) and a later run (the next
CI pass on the same Python, bpy 4.2.0; any local run) installs the extension with them in its cache,
as after a restart of Blender, and checks that it loads every kernel and compiles none. The first run
on a machine (CI's, on each Python) checks the compile from scratch and its helper process instead.
"""

from __future__ import annotations

import json
import os
import sys
import zipfile
from pathlib import Path

import numba

from tests.addon_support import REPO, run_python

from kd_addon import corelib  # noqa: E402

ZIP_NAME = "kd_preview-0.1.0-linux_x64.zip"


def build_zip(tmp_path):
    proc = run_python([str(REPO / "tools" / "build_extension.py"), "--platforms", "linux-x64",
                       "--out", str(tmp_path / "dist"), "--stage", str(tmp_path / "stage")])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return tmp_path / "dist" / ZIP_NAME


def test_extension_builds_installs_renders_and_uninstalls(tmp_path):
    if not sys.platform.startswith("linux"):
        import pytest

        pytest.skip("the test builds the linux-x64 zip only")
    path = build_zip(tmp_path)
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
    assert {"__init__.py", "blender_manifest.toml", "kd_addon/__init__.py", "kd_addon/corelib.py",
            "core/__init__.py", "core/render.py"} <= names
    assert not any(n.startswith(("tests/", "benchmarks/", "tools/", "scripts/")) for n in names)
    user = tmp_path / "user"
    env = {"BLENDER_USER_RESOURCES": str(user), "NUMBA_CACHE_DIR": None}  # None: the extension picks the folder
    kept = installed_kernels_folder()
    warm = kept_for_this_python(kept)
    proc = run_python([str(REPO / "tests" / "extension_smoke.py"), str(path),
                       "--kernels-from" if warm else "--kernels-to", str(kept)], env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    facts = json.loads(next(line for line in proc.stdout.splitlines() if line.startswith("FACTS "))[6:])
    assert facts["numba_after_enable"] is False and facts["core_after_enable"] is False
    assert facts["core_module"] == "bl_ext.user_default.kd_preview.core"
    user_folder = user / "extensions" / ".user" / "user_default" / "kd_preview"  # extension_path_user
    # one folder per version of core's sources (Numba does not see a changed callee in another file)
    assert facts["numba_cache_dir"] == str(user_folder / "numba_cache" / f"core-{corelib.source_digest()}")
    assert facts["size"] == [96, 54] and 0.02 < facts["hit_fraction"] < 0.6
    assert facts["last_run"]["triangles"] == 12 and facts["last_run"]["lights"] == 1
    if warm:  # every kernel loaded from the cache, none compiled or saved again, and no helper started
        assert facts["kernel_files_before"] and facts["kernel_files_after"] == facts["kernel_files_before"]
        assert facts["last_run"].get("compile_helper") is None
    else:
        # an empty cache: the rendering kernels compiled in a helper process that imported the installed
        # core under its extension name beside the build (core/parallel_compile.py), and it succeeded
        assert facts["kernel_files_before"] == {} and facts["last_run"]["compile_helper"] == "finished"
        assert kept_for_this_python(kept)
    assert facts["enabled_after_uninstall"] is False and facts["files_after_uninstall"] is False
    assert facts["scene_prop_after_uninstall"] is False


def installed_kernels_folder() -> Path:
    """Where the installed extension's compiled kernels are kept between runs: beside the tests' Numba
    cache (tests/conftest.py), named by core's sources and the Numba version, whose cache files a
    later Numba would reject and compile again."""
    return Path(os.environ["NUMBA_CACHE_DIR"]).parent / (
        f"installed-extension-core-{corelib.source_digest()}-numba-{numba.__version__}")


def kept_for_this_python(folder: Path) -> bool:
    """Whether `folder` holds the sampling kernel compiled for this Python (as corelib.cache_is_warm)."""
    python = f"py{sys.version_info[0]}{sys.version_info[1]}"
    return any(folder.glob(f"{corelib.WARM_KERNEL}-*.{python}.nbi"))
