"""Install the built extension zip into a throwaway Blender user folder, enable it, render one small
frame through the operator and one through the render engine, disable, re-enable and uninstall it. Run in
its own process (by test_addon_extension.py) with BLENDER_USER_RESOURCES pointing at an empty temp folder:

    BLENDER_USER_RESOURCES=/tmp/u python tests/extension_smoke.py kd_preview-0.1.0-linux_x64-py311.zip

Prints one JSON line of facts for the test to check; any failed step raises (non-zero exit).

    --kernels-from DIR  before the render, copy the kernel files in DIR into the installed core's
                        Numba folders (kernels an earlier run of this script compiled: see
                        test_addon_extension.py); the kernels' background compile, which enabling
                        starts, is switched off until they are in place (KD_PREVIEW_WARMUP)
    --kernels-to DIR    after the render, copy the installed core's kernel files into DIR, one
                        subfolder per folder of core ("." for core itself, "render", ...)
"""

import argparse
import importlib
import json
import os
import shutil
import sys
from pathlib import Path

import bpy
import numpy as np

MODULE = "bl_ext.user_default.kd_preview"


def enabled() -> bool:
    return MODULE in {addon.module for addon in bpy.context.preferences.addons}


def install(zip_path: str) -> dict:
    assert bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True) == {"FINISHED"}
    assert enabled(), "not enabled after install"
    return {"numba_after_enable": "numba" in sys.modules, "core_after_enable": MODULE + ".core" in sys.modules,
            "warmup_after_enable": warmup().status().state}


def warmup():
    """The installed add-on's kernel_warmup module."""
    return importlib.import_module(MODULE + ".kd_addon.kernel_warmup")


def render_default_scene() -> dict:
    """The factory startup scene (cube, light, camera) at 5% of 1920x1080, through the operator."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 1920, 1080
    settings = scene.kd_preview
    settings.resolution_percentage, settings.samples = 5, 2
    assert settings.mode == "auto"  # the default: ao+shadow, since the scene has a light
    assert bpy.ops.kdpreview.render() == {"FINISHED"}
    image = bpy.data.images["KD Preview"]
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    alpha = pixels.reshape(-1, 4)[:, 3]
    import numba

    return {
        "size": list(image.size),
        "hit_fraction": float(alpha.mean()),
        "core_module": sys.modules[MODULE + ".core"].__name__,
        "numba_cache_dir": numba.config.CACHE_DIR,
        "last_run": json.loads(bpy.context.window_manager.kd_preview_state.last_run),
    }


def render_through_engine(folder: Path) -> dict:
    """The same scene through the KD_PREVIEW render engine (F12's operator), written as a PNG: Blender's
    own pipeline at the scene's resolution and % (5 % of 1920 x 1080)."""
    scene = bpy.context.scene
    scene.render.engine = "KD_PREVIEW"
    scene.render.resolution_percentage = 5
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(folder / "engine_still")
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    written = folder / "engine_still.png"
    image = bpy.data.images.load(str(written))
    return {"engine_file_written": written.is_file(), "engine_image_size": list(image.size)}


def engine_registered() -> bool:
    return bpy.types.RenderEngine.bl_rna_get_subclass_py("KD_PREVIEW") is not None


def installed_cache_folder() -> Path:
    """The installed add-on's versioned Numba cache folder (its corelib)."""
    return importlib.import_module(MODULE + ".kd_addon.corelib").numba_cache_dir()


def installed_kernel_folders() -> dict:
    """{folder of the installed core, relative to it ("." for core itself, "render", ...): the folder
    Numba caches its kernels in}: inside the add-on's cache folder, the subfolder Numba names after
    the kernels' source folder (its full path, which differs from run to run)."""
    from numba.core.caching import _CacheLocator  # internal; numba is pinned (core/jit/kernel_cache.py)

    core = Path(sys.modules[MODULE].__file__).parent / "core"
    sources = [core, *sorted(p for p in core.iterdir() if (p / "__init__.py").is_file())]
    return {folder.relative_to(core).as_posix(): installed_cache_folder()
            / _CacheLocator.get_suitable_cache_subpath(str(folder / "__init__.py")) for folder in sources}


def kernel_files(folder: Path) -> dict:
    """{relative path: [size, mtime_ns]} of the Numba cache files anywhere under `folder`: a kernel
    compiled or saved again (in any subfolder) adds or changes an entry."""
    return {str(path.relative_to(folder)): [path.stat().st_size, path.stat().st_mtime_ns]
            for path in sorted(folder.rglob("*.nb[ic]"))} if folder.is_dir() else {}


def copy_kernel_files(source: Path, target: Path) -> None:
    target.mkdir(parents=True, exist_ok=True)
    for path in source.glob("*.nb[ic]"):
        shutil.copy2(path, target / path.name)  # copy2: the times stay, so kernel_files can compare


def save_kernels(folders: dict, target: Path) -> None:
    """Every core folder's kernel files into target/<its relative path>."""
    for relative, folder in folders.items():
        copy_kernel_files(folder, target / relative)


def load_kernels(source: Path, folders: dict) -> None:
    """The kernel files save_kernels wrote under `source` into this install's Numba folders."""
    for relative, folder in folders.items():
        if (source / relative).is_dir():
            copy_kernel_files(source / relative, folder)


def toggle_and_uninstall() -> dict:
    bpy.ops.preferences.addon_disable(module=MODULE)
    assert not hasattr(bpy.types.Scene, "kd_preview") and not enabled() and not engine_registered()
    bpy.ops.preferences.addon_enable(module=MODULE)
    assert hasattr(bpy.types.Scene, "kd_preview") and enabled()
    repos = [repo.module for repo in bpy.context.preferences.extensions.repos]
    bpy.ops.extensions.package_uninstall(repo_index=repos.index("user_default"), pkg_id="kd_preview")
    installed = Path(os.environ["BLENDER_USER_RESOURCES"], "extensions", "user_default", "kd_preview")
    return {"enabled_after_uninstall": enabled(), "files_after_uninstall": installed.exists(),
            "scene_prop_after_uninstall": hasattr(bpy.types.Scene, "kd_preview")}


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("zip_path")
    parser.add_argument("--kernels-from", type=Path)
    parser.add_argument("--kernels-to", type=Path)
    args = parser.parse_args(argv)
    if args.kernels_from is not None:
        os.environ["KD_PREVIEW_WARMUP"] = "0"
    facts = install(args.zip_path)
    kernels = installed_kernel_folders()
    if args.kernels_from is not None:
        load_kernels(args.kernels_from, kernels)
        del os.environ["KD_PREVIEW_WARMUP"]  # the render starts it: it finds them
    facts["kernel_files_before"] = kernel_files(installed_cache_folder())
    facts.update(render_default_scene())
    facts["warmup_after_render"] = warmup().status().state
    facts.update(render_through_engine(Path(os.environ["BLENDER_USER_RESOURCES"])))
    facts["kernel_files_after"] = kernel_files(installed_cache_folder())
    if args.kernels_to is not None:
        save_kernels(kernels, args.kernels_to)
    facts.update(toggle_and_uninstall())
    print("FACTS " + json.dumps(facts))


if __name__ == "__main__":
    main(sys.argv[1:])
