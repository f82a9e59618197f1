"""KD Preview's Blender glue: scene extraction, settings, operators, panel and command line.

Only registration lives here; the logic lives in the modules beside it.
Nothing imported here touches core or numba (corelib imports them on the first
render), so enabling the add-on is instant.
"""

import sys

from . import early_interrupt

if sys.argv[:1] == ["-m"]:  # `python -m kd_addon`, while Python locates __main__ (documented for -m)
    early_interrupt.install()

from . import cli, image_keeping, live_update, operators, panel, properties, tree_cache  # noqa: E402

# Registration order: settings before the operators and panel that use them.
MODULES = (properties, operators, panel, live_update, image_keeping, cli)


def register():
    for module in MODULES:
        module.register()


def unregister():
    for module in reversed(MODULES):
        module.unregister()
    tree_cache.clear()  # kept trees and images go with the add-on
