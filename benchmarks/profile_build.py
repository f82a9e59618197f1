"""Default builds in a loop for `perf record`, with a perf map naming Numba's compiled functions.

Usage: perf record -F 2000 -o perf.data python benchmarks/profile_build.py [--seconds 15] [--threads 1]
       [--scene suzanne-251k] [--dump build_subtree.bin]
then   perf report -i perf.data --no-children --sort sym

Numba's machine code lives in anonymous memory, so perf shows bare addresses. This writes
/tmp/perf-<pid>.map (perf's format for JIT code: start, size, name) for every compiled function of the
core package, each sized up to the next one. `--dump` also writes build_subtree's code bytes (up to the
end of its mapping) and prints its address, so samples can be placed on instructions:
objdump -D -b binary -m i386:x86-64 --adjust-vma=ADDRESS build_subtree.bin
(docs/choices.md#where-the-default-builds-time-goes-by-machine-instruction). Two hot instructions in an
anonymous page outside every function are the atomic add of Numba's reference counting (NRT incref /
decref).
"""
import argparse
import ctypes
import os
import sys
import time
from pathlib import Path

import numba

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import core  # noqa: E402
from core.build.subtree import build_subtree  # noqa: E402
from scenes import load_scene  # noqa: E402


def compiled_functions():
    """(address, name) of every compiled overload of the core package's Numba functions."""
    found = set()
    for module_name, module in list(sys.modules.items()):
        if not module_name.startswith("core"):
            continue
        for name, obj in vars(module).items():
            if isinstance(obj, numba.core.dispatcher.Dispatcher):
                for cres in obj.overloads.values():
                    address = cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)
                    if address:
                        found.add((address, f"{module_name}.{name}"))
    return sorted(found)


def write_perf_map(functions):
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as out:
        for k, (address, name) in enumerate(functions):
            end = functions[k + 1][0] if k + 1 < len(functions) else address + 65536
            out.write(f"{address:x} {min(end - address, 1 << 20):x} {name}\n")


def dump_code(address, path):
    """Write the bytes from `address` to the end of its memory mapping (at most 1 MB)."""
    size = 1 << 20
    with open("/proc/self/maps") as maps:
        for line in maps:
            low, high = (int(v, 16) for v in line.split()[0].split("-"))
            if low <= address < high:
                size = min(size, high - address)
    with open(path, "wb") as out:
        out.write(ctypes.string_at(address, size))
    print(f"build_subtree at {address:#x}, {size} bytes in {path}")


def main():
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--scene", default="suzanne-251k")
    ap.add_argument("--dump", default=None)
    args = ap.parse_args()
    triangles = load_scene(args.scene).triangles
    core.build_kdtree(triangles, threads=args.threads)  # compiles or loads every kernel
    write_perf_map(compiled_functions())
    if args.dump:
        overload = next(iter(build_subtree.overloads.values()))
        dump_code(overload.library.get_pointer_to_function(overload.fndesc.llvm_func_name), args.dump)
    builds, start = 0, time.perf_counter()
    while time.perf_counter() - start < args.seconds:
        core.build_kdtree(triangles, threads=args.threads)
        builds += 1
    print(f"{builds} builds in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
