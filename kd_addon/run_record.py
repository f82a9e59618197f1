"""What report.json says about the run itself: the input file, the versions, the machine, the start.

So that two reports can be compared (or a slow one explained) without asking where they came from.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import time
import tomllib
from pathlib import Path

MANIFEST = Path(__file__).resolve().parent.parent / "blender_manifest.toml"


def run_record(started_at: float, threads_setting: int) -> dict:
    """The run's block of report.json. `started_at`: time.time() at the start; `threads_setting`: the
    Threads setting (0 = every thread Numba was started with)."""
    import bpy
    import numba

    available = int(numba.config.NUMBA_NUM_THREADS)
    return {
        "blend_file": bpy.data.filepath or None,  # None: an unsaved file or the built-in demo
        "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(started_at)),
        "versions": {"kd_preview": kd_preview_version(), "blender": bpy.app.version_string,
                     "python": platform.python_version(), "numba": numba.__version__,
                     "numpy": sys.modules["numpy"].__version__},
        "threads": min(threads_setting, available) if threads_setting else available,
        "cpu": {"name": cpu_name(), "logical_cores": os.cpu_count()},
        "platform": platform.platform(),
    }


def kd_preview_version() -> str | None:
    """The extension's version from its manifest (None when the file is missing or unreadable)."""
    try:
        with MANIFEST.open("rb") as file:
            return tomllib.load(file).get("version")
    except (OSError, tomllib.TOMLDecodeError):
        return None


def cpu_name() -> str:
    """The processor's model name as the system reports it, else platform.processor() (may be "")."""
    try:
        if sys.platform.startswith("linux"):
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as file:
                for line in file:
                    if line.startswith("model name"):
                        return line.split(":", 1)[1].strip()
        elif sys.platform == "darwin":
            return subprocess.run(["sysctl", "-n", "machdep.cpu.brand_string"], capture_output=True, text=True,
                                  timeout=5).stdout.strip()
        elif sys.platform == "win32":
            return os.environ.get("PROCESSOR_IDENTIFIER", "") or platform.processor()
    except (OSError, subprocess.SubprocessError):
        pass
    return platform.processor()
