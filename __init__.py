"""KD Preview extension entry point: Blender imports this package and calls register().

The add-on itself is `kd_addon` (Blender glue) on top of `core` (the kd-tree
and renderer, numpy/Numba only), both imported relatively so they load as
`bl_ext.<repo>.kd_preview.kd_addon` / `.core` when installed.
"""

from . import kd_addon


def register():
    kd_addon.register()


def unregister():
    kd_addon.unregister()
