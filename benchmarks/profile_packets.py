"""Where the packet kernel's time goes, instruction by instruction: perf samples on Numba's compiled code.

Usage (a copy of core made as bench_packet_copies.py says, e.g. /tmp/pv/base; perf installed):
    perf record -e cpu-clock -F 4000 -o /tmp/pv/base.data -- \
        python benchmarks/profile_packets.py run /tmp/pv/base 12
    python benchmarks/profile_packets.py annotate /tmp/pv/base.data /tmp/pv/base

`run` compiles the copy's trace_packets (cached after the first time), traces suzanne-251k's 640 x 480
camera rays on one thread for the given seconds, then dumps the process's anonymous executable memory
(where LLVM put the compiled code) beside the copy. `annotate` maps perf's sampled addresses into those
dumps, disassembles each region holding at least 1% of the samples (objdump), writes
<copy>.<address>.annot with each instruction's sample count and share, and prints the share of every
128-byte stretch above 0.4%. A sample lands on the instruction after the one that stalled (a load that
missed, a mispredicted branch's first instructions on the right path). Numba's code has no symbols for
perf, so the stretches are read against the disassembly (node step: the axis load and `vcmpleps`; leaf
test: `vcvtss2sd` of the vertices, `vcmpltpd` of the edge values; pop: `vcvtps2pd` of a stacked t0).
"""
import collections
import ctypes
import importlib
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def run(copy, seconds):
    sys.path[:0] = [str(HERE), str(HERE.parent), str(Path(copy).resolve().parent)]
    import core
    from core.jit.threads import thread_count
    from scenes import load_scene
    from workload import camera_workload
    from bench_packet_copies import copy_arrays

    scene = load_scene("suzanne-251k")
    o, d = camera_workload(scene, 640, 480)
    n = len(o)
    tree = core.build_kdtree(scene.triangles)
    name = Path(copy).name
    packets = importlib.import_module(name + ".trace.packet_traversal")
    arrays = copy_arrays(importlib.import_module(name + ".trace.layout").TreeArrays, tree.arrays)
    rays = packets.PacketRays(o, d, np.zeros(n), np.full(n, np.inf), packets.packet_order(640, 480))
    out = packets.PacketOutputs(np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n), np.zeros(n, np.uint8))
    with thread_count(1):
        packets.trace_packets(arrays, rays, out)
        start, calls = time.perf_counter(), 0
        while time.perf_counter() - start < seconds:
            packets.trace_packets(arrays, rays, out)
            calls += 1
    print(f"{calls} calls, {(time.perf_counter() - start) / calls * 1e3:.1f} ms a call")
    regions = []
    for line in open("/proc/self/maps"):
        parts = line.split()
        lo, hi = (int(x, 16) for x in parts[0].split("-"))
        if "x" in parts[1] and (len(parts) < 6 or parts[5].startswith("[anon")) and hi - lo < 64 << 20:
            regions.append((lo, hi))
            Path(f"{copy}.{lo:x}.bin").write_bytes(ctypes.string_at(lo, hi - lo))
    Path(f"{copy}.regions.json").write_text(json.dumps(regions))


def annotate(data, copy):
    regions = json.loads(Path(f"{copy}.regions.json").read_text())
    script = subprocess.run(["perf", "script", "-i", data, "-F", "ip"], capture_output=True, text=True).stdout
    ips = [int(word, 16) for word in script.split()]
    print(f"{len(ips)} samples")
    for lo, hi in regions:
        inside = collections.Counter(ip - lo for ip in ips if lo <= ip < hi)
        total = sum(inside.values())
        if total < 0.01 * len(ips):
            continue
        print(f"region {lo:x}: {total} samples ({100 * total / len(ips):.1f}% of all)")
        listing = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64", f"{copy}.{lo:x}.bin"],
                                 capture_output=True, text=True).stdout
        stretches = collections.Counter()
        with open(f"{copy}.{lo:x}.annot", "w") as annot:
            for line in listing.splitlines():
                match = re.match(r"\s*([0-9a-f]+):", line)
                if match:
                    offset = int(match.group(1), 16)
                    count = inside.get(offset, 0)
                    stretches[offset // 128] += count
                    annot.write(f"{count:6d} {100 * count / total:5.2f}% {line}\n")
        for stretch in sorted(stretches):
            if stretches[stretch] > 0.004 * total:
                print(f"  {stretch * 128:6x}  {100 * stretches[stretch] / total:5.1f}%")


if __name__ == "__main__":
    if sys.argv[1] == "run":
        run(sys.argv[2], float(sys.argv[3]))
    else:
        annotate(sys.argv[2], sys.argv[3])
