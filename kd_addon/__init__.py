"""KD Preview's Blender glue: scene extraction, settings, operators, panel and command line.

Only registration lives here; the logic lives in the modules beside it.
Nothing imported here touches core or numba (corelib imports them on the first
render), so enabling the add-on is instant; with Blender's UI it starts the kernels' first compile in
a separate process (kernel_warmup.py), shown in the status bar and the panel until it is done.
"""

import atexit
import sys

from . import early_interrupt

if sys.argv[:1] == ["-m"]:  # `python -m kd_addon`, while Python locates __main__ (documented for -m)
    early_interrupt.install()

import bpy  # noqa: E402

from . import (bulk_instances, cli, engine, image_keeping, kernel_warmup, live_update, operators, panel,  # noqa: E402
               properties, tree_cache, warmup_display)

# Registration order: settings before the operators, panels and render engine that use them.
MODULES = (properties, operators, panel, engine, live_update, image_keeping, cli, warmup_display)
_registered = False


def register():
    """Register the add-on; registering it again re-registers it (a script calling register() twice got
    Blender's "already registered" error)."""
    global _registered
    unregister()  # nothing when not registered
    _registered = True  # before the modules: unregister() then undoes a registration that failed halfway
    if compiles_at_enable():
        kernel_warmup.start(packed=True)  # before the modules: the display's timer runs only while a compile does
    for module in MODULES:
        module.register()
    if not bpy.app.binary_path:  # the bpy module (Blender itself unregisters at quit)
        atexit.unregister(_unregister_at_exit)  # once, however often the add-on is registered
        atexit.register(_unregister_at_exit)


def compiles_at_enable() -> bool:
    """Whether enabling starts the kernels' compile: with Blender's UI only. A background run (`blender
    -b`, the bpy module) may never render a preview, and a batch job's CPU is not taken for it; its first
    preview render starts the compile itself and waits for it (pipeline.FrameJob)."""
    return not bpy.app.background


def unregister():
    """Undo register(); a second call does nothing (Blender's own exit disables add-ons enabled with
    addon_utils after our exit hook already did)."""
    global _registered
    if not _registered:
        return
    for module in reversed(MODULES):
        module.unregister()
    tree_cache.clear()  # kept trees, images and instance rows go with the add-on
    bulk_instances.forget()
    _registered = False


def _unregister_at_exit():
    """A script that registers the add-on with the bpy module and exits without unregistering it made
    the bpy 4.2 module crash at exit (SIGSEGV, exit code 139, after the work was done): its teardown
    fails on classes holding Python functions (methods, update callbacks). Unregistering first avoids it."""
    unregister()
