"""benchmarks/bench_compile.py's counting and reading, on tiny kernels (never the add-on's: compiling them
takes minutes): every process started with its sitecustomize counts its own exclusive compile seconds and
is labelled by its role; the first frame's figures come from report.json, and what is missing is named."""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.benchmark_modules import load_benchmark


MAIN_SCRIPT = """
import json, sys, time
from numba import njit

@njit
def callee(x):
    return x * 2.0 + 1.0

@njit
def caller(x):
    return callee(x) + callee(x + 1.0)

start = time.perf_counter()
caller(1.0)  # compiles caller, and callee inside caller's compile
json.dump({"first_call_s": time.perf_counter() - start}, open(sys.argv[1], "w"))
"""

HELPER_CODE = """
from numba import njit
njit(lambda x: x + 1)(1)
"""


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("bench_compile")


def test_every_process_counts_its_own_exclusive_compiles_under_its_role(bench, tmp_path):
    site, dumps = tmp_path / "site", tmp_path / "dumps"
    site.mkdir(), dumps.mkdir()
    bench.write_sitecustomize(site, dumps)
    script, timing = tmp_path / "main_script.py", tmp_path / "timing.json"
    script.write_text(MAIN_SCRIPT)
    env = dict(os.environ, PYTHONPATH=str(site), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    launched = time.time()
    commands = [[sys.executable, str(script), str(timing)],  # argv as helper_program.py's: CORE FOLDER FLAG TASK
                [sys.executable, "-c", HELPER_CODE, "core", "folder", "0", "jit.first_frame:compile_first_frames"],
                [sys.executable, "-c", HELPER_CODE, "core", "folder", "1"]]
    for process in [subprocess.Popen(c, env=env, cwd=tmp_path) for c in commands]:
        assert process.wait(120) == 0
    processes = bench.read_processes(dumps, launched)
    assert [p["label"] for p in processes] == ["main", "warm-up", "helper"]
    main = processes[0]["seconds"]
    caller, callee = main["__main__.caller"], main["__main__.callee"]
    first_call = json.loads(timing.read_text())["first_call_s"]
    # exclusive: the callee's compile, nested in the caller's, is not counted twice
    assert 0 < caller and 0 < callee and caller + callee <= first_call
    cpu = processes[0]["cpu_seconds"]  # the compiling thread's CPU seconds, exclusive the same way
    assert 0 < cpu["__main__.caller"] and 0 < cpu["__main__.callee"]
    assert cpu["__main__.caller"] + cpu["__main__.callee"] <= first_call
    assert all(len(p["seconds"]) == 1 and p["compile_s"] > 0 for p in processes[1:])
    top = bench.top_kernels(processes, 2)
    assert [row["seconds"] for row in top] == sorted((s for p in processes for s in p["seconds"].values()),
                                                     reverse=True)[:2]


def test_a_process_that_wrote_no_record_fails_the_run_by_name(bench, tmp_path):
    (tmp_path / "7.started").write_text(json.dumps({"argv": ["-c", "core", "folder", "0", "jit.x:task"]}))
    with pytest.raises(bench.BenchmarkError, match=r"ended without writing.*helper.*jit\.x:task"):
        bench.read_processes(tmp_path, time.time())


def test_the_first_frame_comes_from_report_json_and_a_missing_row_is_named(bench):
    stdout = " frame  triangles\n     1     12,345\ntotal: 1 frames\nreport: /tmp/x/report.json\n"
    assert bench.report_path(stdout) == Path("/tmp/x/report.json")
    assert bench.frame_rows(stdout) == [" frame  triangles", "     1     12,345"]
    row = {"frame": 1, "total_ms": 500.0, "compile_ms": 90000.0, "load_ms": 2500.0, "compile_helper": "finished"}
    frame = bench.first_frame({"frames": [row]})
    assert frame["wait_s"] == pytest.approx(93.0) and frame["compile_s"] == 90.0 and frame["total_s"] == 0.5
    with pytest.raises(bench.BenchmarkError, match="report: PATH"):
        bench.report_path(" frame  triangles\n")
    with pytest.raises(bench.BenchmarkError, match="no frame row"):
        bench.first_frame({"frames": []})
    with pytest.raises(bench.BenchmarkError, match="lacks compile_ms"):
        bench.first_frame({"frames": [{"frame": 1, "total_ms": 1.0, "load_ms": 0.0}]})
