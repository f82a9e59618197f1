"""`python -m kd_addon render [scene.blend] --frames 1-24 --out DIR [...]` with the bpy module (see cli.py)."""

import os
import signal
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
# The run has ended with `code` (its report written); a Ctrl-C now, in bpy's teardown, would make Python
# die by SIGINT and a finished run look interrupted to the script or farm waiting for it.
signal.signal(signal.SIGINT, signal.SIG_IGN)
background.exit_now_if_abandoned(code)
if code in (130, 143):
    # Interrupted (SIGINT) or terminated (SIGTERM): the run's report is written; end with that code now.
    # A KeyboardInterrupt that landed while Blender ran Python itself (it prints and clears it) can leave
    # the interpreter's "unhandled KeyboardInterrupt" flag set, and Python's teardown then turns the exit
    # into a SIGINT kill (-2).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
sys.exit(code)
