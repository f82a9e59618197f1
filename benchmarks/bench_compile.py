"""Where a first render's JIT compile time goes: per-kernel compile seconds, in every process, with an empty
Numba cache.

Usage: python benchmarks/bench_compile.py [--top 15] [--helper on|off|both] [--runs 1] [-- RENDER_ARGS ...]

Runs `python -m kd_addon render --demo --frames 1 --out TMP` (or RENDER_ARGS) in a fresh process whose
NUMBA_CACHE_DIR is an empty folder. The first frame waits for the kernel warm-up process
(kd_addon/kernel_warmup.py), which compiles while a helper process compiles the rendering kernels beside
it (core/jit/parallel_compile.py); the render's own process then mostly loads them. So every process
counts its own compiles: a `sitecustomize.py` in a temporary folder put first on PYTHONPATH (which the
add-on hands on to the processes it starts) registers a listener on Numba's "numba:compile" events in
each process and writes what it counted to a JSON file at exit. Each process is labelled by its role:
`main` (the render), `warm-up` (helper_program.py running first_frame.py's task) or `helper` (any other
helper_program.py task). A kernel's time is exclusive: the compiles of the functions it calls (each
compiled once, then reused) count for those, while code inlined into it (inline="always") counts for it,
which is what makes a large inlined callee at several call sites expensive. Cache loads are not compiles
and are not counted. Each time is counted twice: wall seconds, and CPU seconds of the compiling thread,
which stay comparable when the processes share the cores with each other or with other work.

Prints the first frame's figures from the render's report.json (its wait for the kernels' compile, their
load, the frame itself), each process's compile total, span and CPU seconds (the longest process is the
critical path), the total, and the top kernels labelled by process. `--helper off` runs with
KD_PREVIEW_COMPILE_HELPER=0 (the warm-up compiles alone); `--helper both` alternates the two `--runs`
times. Writes benchmarks/out/bench_compile.json (benchmarks/results.py).
"""
import argparse
import atexit
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HELPER_SWITCH = "KD_PREVIEW_COMPILE_HELPER"  # core/jit/parallel_compile.py's switch
WARMUP_TASK_MODULE = "jit.first_frame"  # kd_addon/kernel_warmup.py's TASK lives there
SITECUSTOMIZE = """\
import importlib.util
spec = importlib.util.spec_from_file_location("_bench_compile_listener", {path!r})
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
module.record_compiles({dumps!r})
"""


# -- in every process of a run (loaded by the sitecustomize) ------------------------------------------------

def compile_listener():
    """A Numba event listener summing each function's exclusive compile time into two dicts: wall seconds,
    and CPU seconds of the compiling thread (what the compile costs whatever else runs on the cores)."""
    from numba.core import event

    seconds, cpu_seconds = defaultdict(float), defaultdict(float)

    class Listener(event.Listener):
        def __init__(self):
            self.open = []  # one stack: Numba's compiler lock lets one thread compile at a time

        def on_start(self, ev):
            func = getattr(ev.data["dispatcher"], "py_func", None)
            name = f"{func.__module__}.{func.__qualname__}" if func is not None else repr(ev.data["dispatcher"])
            self.open.append((name, time.perf_counter(), time.thread_time()))

        def on_end(self, ev):
            name, start, cpu_start = self.open.pop()
            spent, cpu_spent = time.perf_counter() - start, time.thread_time() - cpu_start
            seconds[name] += spent
            cpu_seconds[name] += cpu_spent
            if self.open:  # a compile nested in another's: not the outer kernel's own time
                seconds[self.open[-1][0]] -= spent
                cpu_seconds[self.open[-1][0]] -= cpu_spent

    event.register("numba:compile", Listener())
    return seconds, cpu_seconds


def process_role(argv) -> tuple[str, str]:
    """(role, task) of a process from its argv: helper_program.py runs as `python -c CODE CORE FOLDER FLAG
    [TASK]`, the warm-up with first_frame.py's task, a render's helper with the default task."""
    if not argv or argv[0] != "-c":
        return "main", ""
    task = argv[4] if len(argv) > 4 else ""
    return ("warm-up" if task.startswith(WARMUP_TASK_MODULE + ":") else "helper"), task


def record_compiles(dumps: str) -> None:
    """Count this process's compiles and write them to DUMPS/<pid>.json at exit; a <pid>.started file
    marks a process that started, so one that ended without atexit (killed) is reported, not missed."""
    started, cpu_started = time.time(), time.process_time()
    Path(dumps, f"{os.getpid()}.started").write_text(json.dumps({"argv": sys.argv}))
    seconds, cpu_seconds = compile_listener()

    def dump():
        role, task = process_role(sys.argv)
        record = {"pid": os.getpid(), "parent": os.getppid(), "role": role, "task": task, "started": started,
                  "ended": time.time(), "cpu_s": time.process_time() - cpu_started, "seconds": dict(seconds),
                  "cpu_seconds": dict(cpu_seconds)}
        Path(dumps, f"{os.getpid()}.json").write_text(json.dumps(record))

    atexit.register(dump)


# -- the benchmark -------------------------------------------------------------------------------------------

def write_sitecustomize(folder: Path, dumps: Path) -> None:
    """FOLDER/sitecustomize.py: loads this file by path in each process and counts its compiles into DUMPS."""
    (folder / "sitecustomize.py").write_text(SITECUSTOMIZE.format(path=str(Path(__file__).resolve()),
                                                                  dumps=str(dumps)))


def read_processes(dumps: Path, launched: float) -> list[dict]:
    """Every process's record, labelled (a second process of one role gets `#2`), its times from the
    run's launch; a process that started but wrote no record fails the run, named by role and task."""
    records = [json.loads(p.read_text()) for p in sorted(dumps.glob("*.json"))]
    unwritten = [p for p in dumps.glob("*.started") if not p.with_suffix(".json").exists()]
    if unwritten:
        argv = [process_role(json.loads(p.read_text())["argv"]) for p in unwritten]
        raise BenchmarkError(f"{len(unwritten)} process(es) ended without writing their compile record (killed?), "
                             f"so their compiles would be missing: (role, task) {argv}")
    if not any(r["role"] == "main" for r in records):
        raise BenchmarkError("no compile record from the render's own process: did the sitecustomize not load?")
    order = {"main": 0, "warm-up": 1, "helper": 2}
    records.sort(key=lambda r: (order.get(r["role"], 3), r["started"]))
    seen = defaultdict(int)
    for r in records:
        seen[r["role"]] += 1
        r["label"] = r["role"] + (f"#{seen[r['role']]}" if seen[r["role"]] > 1 else "")
        r["compile_s"], r["compile_cpu_s"] = sum(r["seconds"].values()), sum(r["cpu_seconds"].values())
        r["start_s"], r["end_s"] = r["started"] - launched, r["ended"] - launched
    return records


def top_kernels(processes: list[dict], top: int) -> list[dict]:
    """The `top` longest exclusive compiles over every process, each with its process's label."""
    rows = [{"process": p["label"], "name": name, "seconds": s, "cpu_seconds": p["cpu_seconds"][name]}
            for p in processes for name, s in p["seconds"].items()]
    return sorted(rows, key=lambda row: -row["seconds"])[:top]


class BenchmarkError(Exception):
    """A run's output lacks what the benchmark needs (says what, and shows the output)."""


def report_path(stdout: str) -> Path:
    """report.json's path from the CLI's `report: PATH` line."""
    lines = [line for line in stdout.splitlines() if line.startswith("report: ")]
    if not lines:
        raise BenchmarkError("the render printed no 'report: PATH' line (kd_addon/cli.py's totals), so its "
                             "report.json with the first frame's figures cannot be found")
    return Path(lines[-1][len("report: "):].strip())


def first_frame(report: dict) -> dict:
    """The first frame's figures from report.json, in seconds: its wait for the kernels' compile, their
    load, the frame itself (none of them includes another) and their sum, the first frame's wait."""
    frames = report.get("frames") or []
    if not frames:
        raise BenchmarkError("report.json holds no frame row, so there is no first frame to time")
    row = frames[0]
    missing = [key for key in ("frame", "total_ms", "compile_ms", "load_ms") if key not in row]
    if missing:
        raise BenchmarkError(f"report.json's first frame row lacks {', '.join(missing)} (it has {', '.join(row)})")
    out = {key[:-3] + "_s": row[key] / 1e3 for key in ("compile_ms", "load_ms", "total_ms")}
    out["wait_s"] = sum(out.values())
    out["frame"], out["compile_helper"] = row["frame"], row.get("compile_helper")
    return out


def frame_rows(stdout: str) -> list[str]:
    """The CLI's table header and what follows it up to the totals (frame rows, kernel lines), for the
    eye: the figures come from report.json."""
    lines = stdout.splitlines()
    start = next((i for i, line in enumerate(lines) if line.split()[:1] == ["frame"]), None)
    if start is None:
        return []
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("total: ")), len(lines))
    return lines[start:end]


def one_run(args, mode: str) -> dict:
    """One fresh render on an empty cache with every process's compiles counted."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cache, out, site, dumps = tmp / "cache", tmp / "out", tmp / "site", tmp / "dumps"
        for folder in (cache, site, dumps):
            folder.mkdir()
        write_sitecustomize(site, dumps)
        render_args = args.render_args or ["render", "--demo", "--frames", "1", "--out", str(out)]
        path = os.pathsep.join([str(site), str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=path, **{HELPER_SWITCH: "1" if mode == "on" else "0"})
        launched = time.time()
        proc = subprocess.run([sys.executable, "-m", "kd_addon", *render_args], cwd=ROOT, env=env,
                              capture_output=True, text=True)
        wall = time.time() - launched
        try:
            if proc.returncode != 0:
                raise BenchmarkError(f"the render exited with code {proc.returncode}")
            frame = first_frame(json.loads((ROOT / report_path(proc.stdout)).read_text()))
            processes = read_processes(dumps, launched)
        except BenchmarkError as error:
            raise BenchmarkError(f"{error}\n--- the render's output ---\n{proc.stdout}{proc.stderr}") from None
    return {"wall_s": wall, "first_frame": frame, "processes": processes, "rows": frame_rows(proc.stdout),
            "compile_s": sum(p["compile_s"] for p in processes)}


def print_run(run: dict, top: int) -> None:
    print("\n".join(run["rows"]))
    f = run["first_frame"]
    helper = f" (its compile helper: {f['compile_helper']})" if f["compile_helper"] else ""
    print(f"first frame ({f['frame']}): waited {f['wait_s']:.1f} s = kernels' compile {f['compile_s']:.1f} s "
          f"+ load {f['load_s']:.1f} s + the frame {f['total_s']:.2f} s{helper}")
    print("compile seconds by process (wall, and CPU of the compiling thread); the process's run and CPU:")
    for p in run["processes"]:
        print(f"  {p['label']:<9} {p['compile_s']:6.1f} s, CPU {p['compile_cpu_s']:6.1f} s, {len(p['seconds']):3d} "
              f"functions; ran {p['start_s']:5.1f}-{p['end_s']:5.1f} s, {p['cpu_s']:.1f} s CPU  {p['task']}")
    longest = max(run["processes"], key=lambda p: p["compile_s"])
    print(f"compile total {run['compile_s']:.1f} s (CPU {sum(p['compile_cpu_s'] for p in run['processes']):.1f} s); "
          f"the longest process: {longest['label']} ({longest['compile_s']:.1f} s); the render's process wall "
          f"{run['wall_s']:.1f} s (empty cache)")
    print("top kernels, exclusive compile seconds (wall, CPU):")
    for row in top_kernels(run["processes"], top):
        print(f"  {row['seconds']:7.1f} s {row['cpu_seconds']:7.1f} s  {row['process']:<9} {row['name']}")


def by_label(run: dict, label: str, key: str = "compile_s") -> float:
    """A run's compile seconds in the process of this label (0 when the run had none)."""
    return sum(p[key] for p in run["processes"] if p["label"] == label)


def summary(runs: list[dict], top: int) -> dict:
    """One mode's figures (results.figure: medians and every run) for benchmarks/out/."""
    import results as result_files  # benchmarks/ is on sys.path when run as a script

    labels = sorted({p["label"] for run in runs for p in run["processes"]})
    per_process = {label: result_files.figure([by_label(r, label) for r in runs]) for label in labels}
    per_process_cpu = {label: result_files.figure([by_label(r, label, "compile_cpu_s") for r in runs]) for label in labels}
    return {
        "first_frame_wait": result_files.figure([r["first_frame"]["wait_s"] for r in runs]),
        "kernels_compile_wait": result_files.figure([r["first_frame"]["compile_s"] for r in runs]),
        "kernels_load": result_files.figure([r["first_frame"]["load_s"] for r in runs]),
        "first_frame_total": result_files.figure([r["first_frame"]["total_s"] for r in runs]),
        "process_wall": result_files.figure([r["wall_s"] for r in runs]),
        "compile_total": result_files.figure([r["compile_s"] for r in runs]),
        "compile_by_process": per_process,
        "compile_cpu_by_process": per_process_cpu,
        "processes": [[{k: p[k] for k in ("label", "task", "compile_s", "compile_cpu_s", "cpu_s", "start_s", "end_s")}
                       for p in r["processes"]] for r in runs],
        "top_kernels": [top_kernels(r["processes"], top) for r in runs],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--helper", choices=["on", "off", "both"], default="on")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("render_args", nargs="*")
    args = ap.parse_args()
    modes = ["off", "on"] if args.helper == "both" else [args.helper]
    runs = {m: [] for m in modes}
    for run in range(args.runs):
        for mode in (modes if run % 2 == 0 else modes[::-1]):
            print(f"-- helper {mode}, run {run + 1}", flush=True)
            try:
                result = one_run(args, mode)
            except BenchmarkError as error:
                sys.exit(f"bench_compile.py: {error}")
            print_run(result, args.top)
            runs[mode].append(result)
    for mode in modes:
        rs = runs[mode]
        print(f"helper {mode}: first frame waited {statistics.median(r['first_frame']['wait_s'] for r in rs):.1f} s, "
              f"compile {statistics.median(r['compile_s'] for r in rs):.1f} s in all, process "
              f"{statistics.median(r['wall_s'] for r in rs):.1f} s (medians of {len(rs)}); compile by process: "
              + ", ".join(f"{label} {statistics.median(by_label(r, label) for r in rs):.1f} s"
                          for label in sorted({p["label"] for r in rs for p in r["processes"]})))
    import results as result_files

    jit = statistics.median(r["compile_s"] for rs in runs.values() for r in rs)
    result_files.write("bench_compile", {"runs": args.runs, "render_args": args.render_args or "demo, frame 1",
                                         "helper": {m: summary(runs[m], args.top) for m in modes}}, jit)


if __name__ == "__main__":
    main()
