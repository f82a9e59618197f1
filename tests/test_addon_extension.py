"""The extension as users get it: build the linux-x64 zip with tools/build_extension.py, then install,
enable, render and uninstall it in a separate bpy process with its own Blender user folder.

Slow the first time: it downloads ~60 MB of wheels into build/wheels_cache/, and the installed copy
of core compiles its kernels from scratch (its Numba cache lives in the fresh user folder, as in a
real install): 1-3.5 minutes on two cores, the suite's slowest test.

The kernels that compile are kept for later runs: they carry Blender's module name for core
(`bl_ext.user_default.kd_preview.core`), which the test process's own cache cannot serve. After a cold
run passes, the test keeps them beside the tests' Numba cache (installed_kernels_folder, named by the
zip's contents, this test's smoke script, the Numba and numpy major versions and the Python), and a
later run with the same name (the bpy 4.2.0 CI pass, on the main pass's Python 3.11; a local rerun)
installs the extension with them in its cache, as after a restart of Blender, and checks that it
loads every kernel and compiles none (~10 s). A first run on a machine (CI's, on each Python) checks
the compile from scratch and its helper process instead. To force that: delete the folder.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import zipfile
from pathlib import Path

import numba
import numpy as np
import pytest

from tests.addon_support import REPO, run_python

from kd_addon import corelib  # noqa: E402

PYTHON = f"{sys.version_info[0]}.{sys.version_info[1]}"
ZIP_NAME = f"kd_preview-0.1.0-linux_x64-py{sys.version_info[0]}{sys.version_info[1]}.zip"  # this Python's zip
SMOKE = REPO / "tests" / "extension_smoke.py"
ZIP_CODE = ("core/", "kd_addon/", "wheels/", "__init__.py", "blender_manifest.toml")  # what decides the kernels


def build_zip(tmp_path):
    proc = run_python([str(REPO / "tools" / "build_extension.py"), "--platforms", "linux-x64", "--pythons", PYTHON,
                       "--out", str(tmp_path / "dist"), "--stage", str(tmp_path / "stage")])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return tmp_path / "dist" / ZIP_NAME


@pytest.mark.slow
def test_extension_builds_installs_renders_and_uninstalls(tmp_path):
    if not sys.platform.startswith("linux"):
        import pytest

        pytest.skip("the test builds the linux-x64 zip only")
    path = build_zip(tmp_path)
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
    assert {"__init__.py", "blender_manifest.toml", "kd_addon/__init__.py", "kd_addon/corelib.py",
            "core/__init__.py", "core/render/preview_render.py"} <= names
    assert not any(n.startswith(("tests/", "benchmarks/", "tools/", "scripts/", "docs/")) for n in names)
    user = tmp_path / "user"
    env = {"BLENDER_USER_RESOURCES": str(user), "NUMBA_CACHE_DIR": None}  # None: the extension picks the folder
    kept, compiled = installed_kernels_folder(path), tmp_path / "compiled_kernels"
    warm = corelib.holds_kernel(kept)
    proc = run_python([str(SMOKE), str(path), *(["--kernels-from", str(kept)] if warm else
                                                ["--kernels-to", str(compiled)])], env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    facts = json.loads(next(line for line in proc.stdout.splitlines() if line.startswith("FACTS "))[6:])
    assert facts["numba_after_enable"] is False and facts["core_after_enable"] is False
    assert facts["warmup_after_render"] == "ready" and facts["last_run"]["mode"] == "ao+shadow"  # "auto", a light
    wheels = sorted("-".join(Path(n).name.split("-")[0:3:2]) for n in names if n.endswith(".whl"))
    tag = "cp" + PYTHON.replace(".", "")
    assert wheels == [f"llvmlite-{tag}", f"numba-{tag}"]  # this Python's only
    assert facts["core_module"] == "bl_ext.user_default.kd_preview.core"
    user_folder = user / "extensions" / ".user" / "user_default" / "kd_preview"  # extension_path_user
    # one folder per version of core's sources (Numba does not see a changed callee in another file)
    assert facts["numba_cache_dir"] == str(user_folder / "numba_cache" / f"core-{corelib.source_digest()}")
    assert facts["size"] == [96, 54] and 0.02 < facts["hit_fraction"] < 0.6
    assert facts["engine_file_written"] and facts["engine_image_size"] == [96, 54]
    assert facts["last_run"]["triangles"] == 12 and facts["last_run"]["lights"] == 1
    if warm:  # every kernel loaded from the cache, none compiled or saved again, and no helper started
        assert facts["kernel_files_before"], f"nothing was copied from {kept}"
        assert facts["kernel_files_after"] == facts["kernel_files_before"], (
            f"the installed extension compiled kernels the ones kept in {kept} should have served")
        assert facts["last_run"].get("compile_helper") is None and facts["last_run"]["compile_ms"] == 0
    else:
        # an empty cache: the kernels compiled in a process that imported the installed
        # core under its extension name (kernel_warmup.py, core/jit/first_frame.py); the render waited for
        # it, then loaded them: the frame compiled nothing itself (no helper of its own)
        # (the bpy module runs in background mode: the render, not enabling, started the compile)
        assert facts["kernel_files_before"] == {} and facts["warmup_after_enable"] == "not started"
        assert facts["last_run"]["compile_ms"] > 0 and facts["last_run"].get("compile_helper") is None
        assert facts["last_run"]["first_run"] is False
    assert facts["enabled_after_uninstall"] is False and facts["files_after_uninstall"] is False
    assert facts["scene_prop_after_uninstall"] is False
    if not warm:  # only after a run that passed, and only a set the next run will take as warm
        assert corelib.holds_kernel(compiled), f"the sampling kernel is not among {sorted(compiled.iterdir())}"
        keep_kernels(compiled, kept)


def installed_kernels_folder(zip_path: Path) -> Path:
    """Where the installed extension's compiled kernels are kept between runs: beside the tests' Numba
    cache (tests/conftest.py), named by what decides which kernels compile and whether Numba accepts
    them: the zip's code (core, the add-on that calls it, the manifest, the bundled wheels; not a
    stray file in the checkout, which the zip would carry too), the smoke script (the settings it
    renders with), the Numba version (a later one rejects the files), the numpy major version
    (Numba's typing differs between numpy 1 and 2) and the Python."""
    digest = hashlib.sha256(SMOKE.read_bytes())
    with zipfile.ZipFile(zip_path) as zf:
        for info in sorted(zf.infolist(), key=lambda entry: entry.filename):
            if info.filename.startswith(ZIP_CODE):
                digest.update(info.filename.encode() + b"\0" + zf.read(info))
    numpy_major = np.__version__.split(".")[0]
    return Path(os.environ["NUMBA_CACHE_DIR"]).parent / (
        f"installed-extension-{digest.hexdigest()[:16]}-numba{numba.__version__}-numpy{numpy_major}-{python_tag()}")


def python_tag() -> str:
    return f"py{sys.version_info[0]}{sys.version_info[1]}"


def keep_kernels(compiled: Path, kept: Path, keep_builds: int = 3) -> None:
    """Put `compiled` in place as `kept` in one rename, so an interrupted copy never leaves a folder that
    looks complete; then remove all but the `keep_builds` newest kept folders of the same Numba, numpy
    and Python (other checkouts' builds stay warm too), and partial copies whose run has ended."""
    partial = kept.with_name(f"{kept.name}.partial-{os.getpid()}")
    shutil.rmtree(partial, ignore_errors=True)
    shutil.copytree(compiled, partial)
    shutil.rmtree(kept, ignore_errors=True)  # an incomplete one (a cold run found no sampling kernel in it)
    os.utime(partial)  # now: copytree gave it the compiled folder's time, and the pruning sorts by it
    try:
        os.replace(partial, kept)
    except OSError:  # another run put the same build's kernels in place first
        shutil.rmtree(partial, ignore_errors=True)
        if not corelib.holds_kernel(kept):
            raise
    suffix = kept.name.split("-", 3)[3]  # "numba…-numpy…-py…" after "installed-extension-<digest>-"
    builds = sorted(kept.parent.glob(f"installed-extension-*-{suffix}"), key=lambda path: path.stat().st_mtime)
    for older in builds[:-keep_builds]:
        shutil.rmtree(older, ignore_errors=True)
    for leftover in kept.parent.glob("installed-extension-*.partial-*"):
        if not process_alive(int(leftover.name.rsplit("-", 1)[1])):
            shutil.rmtree(leftover, ignore_errors=True)


def process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # it exists but belongs to someone else
        return True
    return True
