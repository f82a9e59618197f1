"""The cluster path's cost against the in-process command line, and the time on N machines.

Renders the demo's frames (kd_addon/demo_scene.py, 24 by default) with `python -m kd_addon render --demo` in
process and with `--local-workers 1` (one worker process given every core: the same compute, so the
difference is the cluster path's own cost: starting the worker process, its imports and kernel load, the
scene opened again for each chunk, each chunk's fresh first frame, and the frames' trip through the
scheduler), alternating, --runs times. Figures, medians:

- per-frame overhead: (cluster run's wall time - in-process run's) / frames, for whole processes, and for
  the render alone (report.json's wall_ms: from the first frame's start, after the cluster is up);
- the measured chunk times (scene opening + render, from report.json's "farm" section), scheduled in
  order onto N machines (each chunk to the first machine free, as the scheduler's queue does), each
  machine starting after the kernel load a new worker measured, plus the measured fixed cost of a run
  (processes, cluster start, client): the projected time for N = 1, 2, 4, 8, 16 machines, for the frames
  measured and for --shot frames (the measured chunks repeated). Transfers are taken as on the loopback.

    python benchmarks/bench_farm.py [--frames 24] [--runs 3] [--resolution 50] [--samples 16] [--chunk-size 3]
"""
from __future__ import annotations

import argparse
import heapq
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks import results  # noqa: E402

MACHINES = (1, 2, 4, 8, 16)


def render(out: Path, args, farm: bool) -> tuple[float, dict]:
    """(process wall seconds, report.json) of one run."""
    command = [sys.executable, "-m", "kd_addon", "render", "--demo", "--frames", f"1-{args.frames}", "--out",
               str(out), "--resolution", str(args.resolution), "--samples", str(args.samples)]
    if farm:
        command += ["--local-workers", "1", "--chunk-size", str(args.chunk_size)]
    t0 = time.perf_counter()
    proc = subprocess.run(command, cwd=REPO, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"{' '.join(command)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return wall, json.loads((out / "report.json").read_text())


def makespan(chunk_seconds: list[float], machines: int, startup: float = 0.0) -> float:
    """Chunks taken in order, each by the first machine to be free; every machine starts `startup`
    seconds late (its kernels loading)."""
    free = [startup] * machines
    for seconds in chunk_seconds:
        heapq.heappush(free, heapq.heappop(free) + seconds)
    return max(free)


def chunk_seconds(report: dict) -> list[float]:
    return [(c["load_ms"] + c["render_ms"]) / 1e3 for c in report["farm"]["chunks"]]


def kernel_load_seconds(report: dict) -> float:
    """The worker's first frame against the other chunks' first frames (fresh builds too, with the
    kernels already loaded): what loading the compiled kernels from Numba's cache costs a new worker."""
    firsts = {c["frames"][0] for c in report["farm"]["chunks"]}
    rows = [r for r in report["frames"] if r["frame"] in firsts]
    later = [r["total_ms"] for r in rows if not r["first_run"]]
    first = [r["total_ms"] for r in rows if r["first_run"]]
    return (statistics.median(first) - statistics.median(later)) / 1e3 if first and later else float("nan")


def boundary_seconds(report: dict) -> float:
    """What the chunks' fresh first frames cost beyond a frame that reused the one before (the first
    chunk's left out: the in-process run builds its first frame fresh too)."""
    firsts = {c["frames"][0] for c in report["farm"]["chunks"]}
    reused = statistics.median(r["total_ms"] for r in report["frames"] if r["frame"] not in firsts)
    later_firsts = [r["total_ms"] for r in report["frames"] if r["frame"] in firsts and not r["first_run"]]
    return sum(t - reused for t in later_firsts) / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--resolution", type=int, default=50)
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--chunk-size", dest="chunk_size", type=int, default=3)
    parser.add_argument("--shot", type=int, default=240, help="frames of the longer shot projected")
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="bench_farm_"))
    t0 = time.perf_counter()
    render(scratch / "warm", args, farm=False)  # compiles the kernels if the cache is cold
    jit_seconds = time.perf_counter() - t0
    frames = args.frames
    walls = {"in_process": [], "cluster": []}
    render_walls = {"in_process": [], "cluster": []}
    chunks, fixed, loads, boundaries = [], [], [], []
    for run in range(args.runs):
        for mode in ("in_process", "cluster") if run % 2 == 0 else ("cluster", "in_process"):
            wall, report = render(scratch / f"{mode}{run}", args, farm=mode == "cluster")
            walls[mode].append(wall)
            render_walls[mode].append(report["totals"]["wall_ms"] / 1e3)
            if mode == "cluster":
                chunks.append(chunk_seconds(report))
                loads.append(kernel_load_seconds(report))
                boundaries.append(boundary_seconds(report) / frames)
                fixed.append(wall - sum(chunk_seconds(report)))  # process, cluster start, client, transfers
    overhead = [(c - i) / frames for c, i in zip(walls["cluster"], walls["in_process"])]
    render_overhead = [(c - i) / frames for c, i in zip(render_walls["cluster"], render_walls["in_process"])]
    median_chunks = [statistics.median(column) for column in zip(*chunks)]
    fixed_s, load_s = statistics.median(fixed), statistics.median(loads)
    warm_chunks = [median_chunks[0] - load_s, *median_chunks[1:]]  # every machine pays the load: startup
    repeats = -(-args.shot // frames)
    projected = {n: {"frames": fixed_s + makespan(warm_chunks, n, load_s),
                     "shot": fixed_s + load_s + (makespan(warm_chunks * repeats, n) * args.shot / (frames * repeats))}
                 for n in MACHINES}
    print(f"demo, {frames} frames at {args.resolution}% and {args.samples} samples, chunks of {args.chunk_size}, "
          f"{args.runs} paired runs (medians):")
    print(f"  in process:            {statistics.median(walls['in_process']):7.2f} s a run "
          f"({statistics.median(render_walls['in_process']):.2f} s rendering)")
    print(f"  cluster, 1 local worker: {statistics.median(walls['cluster']):7.2f} s a run "
          f"({statistics.median(render_walls['cluster']):.2f} s from the first chunk's submission)")
    print(f"  overhead a frame:      {statistics.median(overhead) * 1e3:7.1f} ms (whole processes), "
          f"{statistics.median(render_overhead) * 1e3:.1f} ms (rendering only)")
    print(f"  of which chunk boundaries (fresh first frames beyond a reused frame): "
          f"{statistics.median(boundaries) * 1e3:.1f} ms a frame")
    print(f"  chunk times (open + render): {', '.join(f'{s:.2f}' for s in median_chunks)} s; fixed cost "
          f"{fixed_s:.2f} s")
    print(f"  a new worker's kernel load from the cache (its first frame against later chunks' first frames): "
          f"{statistics.median(loads):.2f} s")
    for n in MACHINES:
        print(f"  projected on {n:2d} machine(s): {projected[n]['frames']:7.2f} s for {frames} frames, "
              f"{projected[n]['shot']:8.1f} s for {args.shot}")
    results.write("bench_farm", {
        "frames": frames, "resolution": args.resolution, "samples": args.samples, "chunk_size": args.chunk_size,
        "in_process_run": results.figure(walls["in_process"]),
        "cluster_run": results.figure(walls["cluster"], walls["in_process"]),
        "in_process_render": results.figure(render_walls["in_process"]),
        "cluster_render": results.figure(render_walls["cluster"], render_walls["in_process"]),
        "overhead_per_frame": results.figure(overhead),
        "render_overhead_per_frame": results.figure(render_overhead),
        "chunk_boundary_per_frame": results.figure(boundaries),
        "chunk_seconds": median_chunks, "fixed_seconds": fixed_s,
        "worker_kernel_load": results.figure(loads),
        "projected_seconds": {str(n): v for n, v in projected.items()}, "shot_frames": args.shot,
    }, jit_seconds, quick=args.runs < 3)


if __name__ == "__main__":
    main()
