"""Runs `kdpreview` as Blender's `--command` does, with SIGINT handled as inside a real Blender: by a
C handler Python did not install (Python's signal.getsignal returns None) that does not raise. Here
the C-level action is "ignore", which, like Blender's own handler, never stops the render by itself.
Usage: python tests/blender_sigint_like.py render --out DIR ... (the kdpreview arguments)."""

import ctypes
import signal
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: kd_addon need not be installed

libc = ctypes.CDLL(None)
libc.signal.argtypes, libc.signal.restype = [ctypes.c_int, ctypes.c_void_p], ctypes.c_void_p
libc.signal(signal.SIGINT, 1)  # SIG_IGN, set behind Python's back
_python_getsignal = signal.getsignal
signal.getsignal = lambda signum: None if signum == signal.SIGINT else _python_getsignal(signum)

import bpy  # noqa: E402,F401

from kd_addon import cli  # noqa: E402

sys.exit(cli.blender_command(sys.argv[1:]))
