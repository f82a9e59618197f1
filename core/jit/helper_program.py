"""The program a helper process runs (`python -c <this file's text> CORE_NAME CORE_FOLDER FLAG [TASK]`):
import core under the module name its parent uses, with core's parent packages stubbed so an add-on's
bpy-importing `__init__` does not run (in Blender core is `bl_ext.<repo>.<id>.core`, and a cached
kernel's pickled environment names its module), then run one task. TASK is "module:function" relative
to core, called with FLAG == "1" when it takes an argument; the default is the rendering kernels of
parallel_compile.py, with FLAG saying whether to compile the denoiser. On POSIX a thread ends the
helper once its parent is gone (getppid changes, or KD_PREVIEW_HELPER_PARENT names a process that
ended). Plain Python: the add-on reads this file without importing core (kd_addon/kernel_warmup.py).
"""
import importlib
import inspect
import os
import sys
import threading
import time
import types
from pathlib import Path

DEFAULT_TASK = "jit.parallel_compile:compile_rendering_kernels"


def _end_when_orphaned(parent_pid):
    while os.getppid() == parent_pid:
        time.sleep(0.5)
    os._exit(1)


def _stub_parents(name, folder):
    parts, parent = name.split("."), Path(folder).parent
    for depth in range(len(parts) - 1, 0, -1):
        stub = types.ModuleType(".".join(parts[:depth]))
        stub.__path__ = [str(parent)]
        sys.modules.setdefault(stub.__name__, stub)
        parent = parent.parent


def main(argv):
    if os.name != "nt":  # a parent that ended without stopping the helper (os._exit after Ctrl-C, a crash)
        parent_pid = int(os.environ.get("KD_PREVIEW_HELPER_PARENT", os.getppid()))
        threading.Thread(target=_end_when_orphaned, args=(parent_pid,), daemon=True).start()
    name, folder, flag = argv[1], argv[2], argv[3]
    module, function = (argv[4] if len(argv) > 4 else DEFAULT_TASK).split(":")
    _stub_parents(name, folder)
    task = getattr(importlib.import_module(f"{name}.{module}"), function)
    task(flag == "1") if inspect.signature(task).parameters else task()


if __name__ == "__main__":
    main(sys.argv)
