"""KD Preview extension entry point: Blender imports this package and calls register().

The add-on itself is `kd_addon` (Blender glue) on top of `core` (the kd-tree
and renderer, numpy/Numba only), both imported relatively so they load as
`bl_ext.<repo>.kd_preview.kd_addon` / `.core` when installed.

Why the imports are inside the functions: importing this file must have no
side effects. pytest imports a root `__init__.py` while collecting the tests,
and in a checkout whose folder name is not a Python identifier (`kd-preview`)
it imports it as a plain module, where a relative import would fail.
"""


def register():
    from . import kd_addon

    kd_addon.register()


def unregister():
    from . import kd_addon

    kd_addon.unregister()
