"""Benchmark results as JSON under benchmarks/out/, the files benchmarks/report.py renders the docs from.

Every result file holds the figures of one benchmark run and the run's context: the command line, the
date (UTC), the host's CPU model and LLVM's name and vector extension for it, its core count, the Numba
thread count, the Python, numpy and Numba versions, and the JIT compile (or cache load) time, which no
figure includes.
"""
import json
import os
import platform
import shlex
import sys
import time
from pathlib import Path

import numpy as np

OUT_DIR = Path(__file__).resolve().parent / "out"


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (Linux), else what `platform` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cpu_target() -> str:
    """The CPU as LLVM compiles for it, e.g. "znver4, AVX-512": the vector width Numba's kernels get
    (core/trace/simd.py) sets the figures more than the model name, which may not tell two
    generations apart ("AMD EPYC")."""
    from llvmlite import binding
    from numba.core import config
    features = binding.get_host_cpu_features()  # empty when LLVM cannot tell
    simd = next((name for flag, name in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("neon", "NEON"))
                 if features.get(flag)), "no AVX2" if features else "vector extension unknown")
    if config.CPU_NAME:  # NUMBA_CPU_NAME: Numba compiles for that CPU, not the host's
        return f"{config.CPU_NAME} (NUMBA_CPU_NAME; host {binding.get_host_cpu_name()}, {simd})"
    return f"{binding.get_host_cpu_name()}, {simd}"


def host() -> dict:
    """The run's machine and software, recorded beside its figures."""
    import numba
    return {
        "cpu": cpu_model(),
        "cpu_target": cpu_target(),
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "platform": platform.platform(),
    }


def figure(runs, reference_runs=None, unit="s") -> dict:
    """One figure: the median of its runs and every run; with a reference measured in the same run,
    the reference's median and runs too."""
    runs = [float(r) for r in runs]
    out = {"unit": unit, "median": float(np.median(runs)), "runs": runs}
    if reference_runs is not None:
        ref = [float(r) for r in reference_runs]
        out["reference"] = {"median": float(np.median(ref)), "runs": ref}
    return out


def write(name: str, results: dict, jit_seconds: float, quick: bool = False, out_dir=None) -> Path:
    """Write benchmarks/out/NAME.json: the results with the run's context. `quick` marks a reduced run
    (fewer runs or a smaller workload) whose figures only check that the benchmark works."""
    payload = {
        "benchmark": name,
        "command": shlex.join([Path(sys.executable).name, *sys.argv]),  # quoted: an empty argument stays one
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "quick": bool(quick),
        "jit_seconds": round(float(jit_seconds), 2),
        "host": host(),
        "results": results,
    }
    path = Path(out_dir or OUT_DIR) / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(payload, indent=1) + "\n")
    print(f"wrote {path}")
    return path
