"""Ctrl-C from the first line of `python -m kd_addon`: importing bpy swallows a KeyboardInterrupt raised
while it runs (the render would then run to the end),
and raising one inside the imports it makes (numpy's) leaves them half done. So `install` sets a SIGINT
handler that only records the interrupt, before the package imports bpy; __main__ checks `interrupted`
after the import and then puts Python's own handler back. Never installed inside Blender.
"""

import signal
import threading

interrupted = threading.Event()


def _on_sigint(signum, frame):
    interrupted.set()


def install():
    signal.signal(signal.SIGINT, _on_sigint)


def uninstall():
    signal.signal(signal.SIGINT, signal.default_int_handler)
