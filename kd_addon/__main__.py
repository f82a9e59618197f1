"""`python -m kd_addon render [scene.blend] --frames 1-24 --out DIR [...]` with the bpy module (see cli.py)."""

import sys

from . import background, early_interrupt

try:
    from .cli import main

    early_interrupt.uninstall()
    if early_interrupt.interrupted.is_set():  # Ctrl-C while the package imported bpy
        raise KeyboardInterrupt
    code = main()
except KeyboardInterrupt:
    print("python -m kd_addon: interrupted", file=sys.stderr)
    code = 130
background.exit_now_if_abandoned(code)
sys.exit(code)
