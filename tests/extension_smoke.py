"""Install the built extension zip into a throwaway Blender user folder, enable it, render one small
frame through the operator, disable, re-enable and uninstall it. Run in its own process (by
test_addon_extension.py) with BLENDER_USER_RESOURCES pointing at an empty temp folder:

    BLENDER_USER_RESOURCES=/tmp/u python tests/extension_smoke.py kd_preview-0.1.0-linux_x64.zip

Prints one JSON line of facts for the test to check; any failed step raises (non-zero exit).
"""

import json
import os
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
    return {"numba_after_enable": "numba" in sys.modules, "core_after_enable": MODULE + ".core" in sys.modules}


def render_default_scene() -> dict:
    """The factory startup scene (cube, light, camera) at 5% of 1920x1080, through the operator."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 1920, 1080
    settings = scene.kd_preview
    settings.resolution_percentage, settings.samples, settings.mode = 5, 2, "ao+shadow"
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


def toggle_and_uninstall() -> dict:
    bpy.ops.preferences.addon_disable(module=MODULE)
    assert not hasattr(bpy.types.Scene, "kd_preview") and not enabled()
    bpy.ops.preferences.addon_enable(module=MODULE)
    assert hasattr(bpy.types.Scene, "kd_preview") and enabled()
    repos = [repo.module for repo in bpy.context.preferences.extensions.repos]
    bpy.ops.extensions.package_uninstall(repo_index=repos.index("user_default"), pkg_id="kd_preview")
    installed = Path(os.environ["BLENDER_USER_RESOURCES"], "extensions", "user_default", "kd_preview")
    return {"enabled_after_uninstall": enabled(), "files_after_uninstall": installed.exists(),
            "scene_prop_after_uninstall": hasattr(bpy.types.Scene, "kd_preview")}


def main(zip_path: str) -> None:
    facts = install(zip_path)
    facts.update(render_default_scene())
    facts.update(toggle_and_uninstall())
    print("FACTS " + json.dumps(facts))


if __name__ == "__main__":
    main(sys.argv[1])
