"""`python -m kd_addon render [scene.blend] --frames 1-24 --out DIR [...]` with the bpy module (see cli.py)."""

import os
import sys

from . import background, early_interrupt

try:
    from .cli import main

    early_interrupt.uninstall()
    if early_interrupt.interrupted.is_set():  # Ctrl-C while the package imported bpy
        raise KeyboardInterrupt
    code = main()
except KeyboardInterrupt:
    print("kdpreview: interrupted", file=sys.stderr)
    code = 130
if background.abandoned_work_running():
    sys.stdout.flush()  # a cancelled kernel call still runs: skip the interpreter's teardown, which the
    sys.stderr.flush()  # bpy 4.2 module crashes in beside it (background.py)
    os._exit(code)
sys.exit(code)
