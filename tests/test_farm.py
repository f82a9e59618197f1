"""Rendering on a Dask cluster (kd_addon/farm/, docs/farm.md), on the loopback only: the frames equal the
in-process ones, the report is complete, a killed worker loses no frame, and each failure (no Dask, an
unreachable scheduler, a worker without bpy or without KD Preview, Ctrl-C) ends with its own message.

The cluster tests start `dask scheduler` and `dask worker` processes (or `--local-workers`) whose kernels
load from the session's Numba cache (tests/conftest.py), and render the demo at a few percent of its size.
"""

from __future__ import annotations

import io
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from tests.addon_support import PYTHON, REPO, run_python

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from kd_addon import cli, demo_scene, kernel_warmup  # noqa: E402
from kd_addon.farm import client as farm_client  # noqa: E402
from kd_addon.farm.progress import ProgressLine, format_seconds  # noqa: E402
from kd_addon.sequence import summarize, write_report  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402

SMALL = ["--resolution", "5", "--samples", "2"]  # the demo at 48x27
WORKER_ENV = {"PYTHONPATH": str(REPO), "NUMBA_NUM_THREADS": "1"}


# -- pieces, without a cluster -----------------------------------------------------------------------------


@pytest.mark.parametrize("dask", [None, "tcp://a:1"])
def test_a_run_on_local_workers_names_the_compile_command_while_the_cache_lacks_it(dask, capsys, monkeypatch):
    """Local workers share this machine's cache, so a --local-workers run says, as a run in one process
    does, that frames are slower until the compile command has run; a --dask run's workers may be other
    machines with their own caches (docs/farm.md), so it says nothing."""
    monkeypatch.setattr(kernel_warmup, "second_stage_cached", lambda: False)
    run = SimpleNamespace(args=SimpleNamespace(dask=dask, prog="python -m kd_addon", out="out"), scene_name="Scene",
                          config=SimpleNamespace(settings=SimpleNamespace(mode="ao", samples=2),
                                                 resolution_percentage=5),
                          frames=[1, 2], workers_at_start=2, chunks=[[1], [2]], chunk_size=1,
                          prepared=SimpleNamespace(keyed_note=None))
    farm_client.FarmRun._print_header(run)
    said = "`python -m kd_addon compile` has compiled every kernel once" in capsys.readouterr().out
    assert said == (dask is None)


def test_a_chunk_of_one_frame_is_named_as_one_frame():
    assert farm_client._span_text([16]) == "frame 16"
    assert farm_client._span_text([3, 5, 7]) == "frames 3-7"


def test_chunks_are_contiguous_and_cover_every_frame_once():
    frames = list(range(1, 25))
    chunks = farm_client.chunk_frames(frames, 5)
    assert [len(c) for c in chunks] == [5, 5, 5, 5, 4] and sum(chunks, []) == frames
    assert all(c == list(range(c[0], c[-1] + 1)) for c in chunks)
    assert farm_client.chunk_frames([1, 3, 5], 2) == [[1, 3], [5]]  # a stepped range keeps its order
    with pytest.raises(cli.PreviewError, match="--chunk-size must be 1 or more"):
        farm_client.chunk_frames(frames, 0)


@pytest.mark.parametrize("frames, workers, size", [(240, 2, 24), (240, 8, 10), (24, 2, 4), (24, 8, 2), (1, 4, 1),
                                                   (3, 1, 2), (40, 1, 14)])
def test_automatic_chunk_size(frames, workers, size):
    """About three chunks a worker, at least two frames (reuse) and at most 24 (a rerun's loss)."""
    assert farm_client.auto_chunk_size(frames, workers) == size


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_line_counts_frames_rate_and_time_left_on_a_terminal_only():
    now = [0.0]
    live = ProgressLine(10, stream=_Terminal(), clock=lambda: now[0])
    now[0] = 4.0
    live.update(2)
    assert live.text() == "2/10 frames, 0.50 fps, ETA 00:16"
    assert live.stream.getvalue().endswith("\r\033[K2/10 frames, 0.50 fps, ETA 00:16")
    live.clear()
    assert live.stream.getvalue().endswith("\r\033[K")
    quiet = ProgressLine(10, stream=io.StringIO(), clock=lambda: now[0])
    quiet.update(3)
    quiet.clear()
    assert quiet.stream.getvalue() == ""
    assert format_seconds(3725) == "1:02:05" and format_seconds(59.6) == "01:00"


def test_rows_from_workers_go_through_the_one_report_writer(tmp_path):
    """A worker's rows (RemoteFrame) give the same totals and report rows as the frames did, plus the
    worker and chunk, and the report's "farm" section."""
    from kd_addon.config import make_config

    rows = [{"frame": f, "width": 4, "height": 3, "triangles": 10, "objects": 1, "lights": 0, "extract_ms": 1.0,
             "build_ms": 2.0, "trace_ms": 3.0, "total_ms": 6.0, "rays": 100, "rays_saved": 0, "mrays_per_s": 0.03,
             "samples": 2, "first_run": f == 1, "objects_rebuilt": 1, "objects_reused": 0, "image_reused": False,
             "pixels_reused": 0, "rays_reused": 0, "compile_helper": None, "compile_ms": 0.0, "load_ms": 0.0,
             "mode": "ao", "tree": {"nodes": 3}, "warnings": [],
             "worker": "tcp://w:1", "chunk": 0} for f in (1, 2)]
    results = [farm_client.RemoteFrame(r) for r in rows]
    totals = summarize(results, 20.0)
    assert totals["frames"] == 2 and totals["rays"] == 200 and totals["mean_total_ms_after_first"] == 6.0
    files = [tmp_path / "frame_0001.png", tmp_path / "frame_0002.png"]
    path = write_report(tmp_path, "S", make_config(object()), results, files, totals, 3,
                        extra={"farm": {"chunks": []}})
    report = json.loads(path.read_text())
    assert report["complete"] is False and report["resolution"] == [4, 3] and report["farm"] == {"chunks": []}
    assert [(r["frame"], r["worker"], r["file"]) for r in report["frames"]] == [
        (1, "tcp://w:1", "frame_0001.png"), (2, "tcp://w:1", "frame_0002.png")]


def test_dask_missing_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # `import distributed` raises ImportError
    code = cli.execute(["render", "--demo", "--out", str(tmp_path / "x"), "--dask", "tcp://127.0.0.1:8786"])
    assert code == 1
    err = capsys.readouterr().err
    assert 'pip install -e ".[farm]"' in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_registering_the_add_on_imports_no_dask():
    """The extension never needs Dask: registering it (and parsing a farm option) imports none of it."""
    code = ("import sys, kd_addon; kd_addon.register(); from kd_addon import cli; "
            "cli.build_parser().parse_args(['render', '--out', 'x', '--local-workers', '2']); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed', 'kd_addon.farm'))); "
            "kd_addon.unregister()")
    proc = run_python(code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[]"


def test_farm_options_exclude_each_other_and_are_checked(tmp_path, capsys):
    out = str(tmp_path / "x")
    assert cli.execute(["render", "--demo", "--out", out, "--dask", "tcp://a:1", "--local-workers", "2"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err
    assert cli.execute(["render", "--demo", "--out", out, "--local-workers", "0"]) == 1
    assert "--local-workers must be 1 or more, got 0" in capsys.readouterr().err


def test_cluster_options_without_a_cluster_are_noted(tmp_path, capsys):
    """Checked as with a cluster (bad values are errors: test_addon_cli), and a note says they change
    nothing: the frames render here."""
    out = tmp_path / "x"
    assert cli.execute(["render", "--demo", "--frames", "1", "--resolution", "5", "--samples", "1", "--out", str(out),
                        "--chunk-size", "3", "--ship-blend"]) == 0
    assert ("note: --chunk-size, --ship-blend apply only with --dask or --local-workers"
            in capsys.readouterr().err)
    assert (out / "frame_0001.png").is_file()
    assert cli.execute(["render", "--demo", "--frames", "1", "--resolution", "5", "--samples", "1", "--out", str(out),
                        "--retries", "5"]) == 0
    assert "note: --retries applies only with --dask or --local-workers" in capsys.readouterr().err


@pytest.mark.parametrize("address, problem", [("notanaddress", "missing port number"),
                                              ("foo://host:1", "unknown address scheme 'foo'")])
def test_a_bad_scheduler_address_is_named_at_once(tmp_path, address, problem):
    """No Client is made for an address Dask cannot parse: a half-made one waited in its finaliser and
    printed a traceback after the error."""
    proc = run_python(["-m", "kd_addon", "render", "--demo", "--out", str(tmp_path / "x"), "--dask", address,
                       "--connect-timeout", "30"], timeout=120)
    assert proc.returncode == 1
    assert f"bad Dask scheduler address {address!r}: " in proc.stderr and problem in proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr
    assert not (tmp_path / "x").exists()


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_unreachable_scheduler_is_named_within_the_timeout(tmp_path):
    address = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    t0 = time.perf_counter()
    proc = run_python(["-m", "kd_addon", "render", "--demo", "--out", str(tmp_path / "x"), "--dask", address,
                       "--connect-timeout", "2"], timeout=120)
    assert proc.returncode == 1
    assert f"cannot reach the Dask scheduler at {address} within 2 s" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert time.perf_counter() - t0 < 60  # the process's own start (bpy, the demo) is most of it


# -- a scheduler and workers started here --------------------------------------------------------------------


class Cluster:
    """`dask scheduler` on the loopback and the `dask worker` processes a test starts (no nanny: a
    killed worker stays dead); everything is stopped by close()."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.file = folder / "scheduler.json"
        self.procs: list[subprocess.Popen] = []
        self.file.unlink(missing_ok=True)  # a folder used before: not the last scheduler's address
        self._spawn("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                  "--scheduler-file", str(self.file)])
        deadline = time.time() + 60
        while not self.file.is_file():
            assert time.time() < deadline, (folder / "scheduler.log").read_text()
            time.sleep(0.1)
        time.sleep(0.2)  # written whole
        self.address = json.loads(self.file.read_text())["address"]

    def _spawn(self, name: str, args: list[str], env=None) -> subprocess.Popen:
        log = open(self.folder / f"{name}.log", "w")  # noqa: SIM115  (closed with the process)
        proc = subprocess.Popen([PYTHON, "-m", "dask", *args], cwd=self.folder, stdout=log, stderr=subprocess.STDOUT,
                                env=dict(os.environ, **(env or {})))
        self.procs.append(proc)
        return proc

    def add_workers(self, count: int, preload: str | None = None) -> list[subprocess.Popen]:
        extra = ["--preload", preload] if preload else []
        before = set(self.workers())
        procs = [self._spawn(f"worker{len(self.procs)}", ["worker", "--scheduler-file", str(self.file),
                                                          "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                                          "--host", "127.0.0.1", *extra], env=WORKER_ENV)
                 for _ in range(count)]
        self.wait_for_new_workers(before, count)
        return procs

    def workers(self) -> list[str]:
        from distributed import Client

        with Client(self.address, timeout=30) as client:
            return list(client.scheduler_info()["workers"])

    def wait_for_new_workers(self, before: set, count: int) -> None:
        """Until `count` workers not in `before` have registered. Counted as new names, not as a total: a
        worker an earlier test killed can still be listed when `before` is read and leave meanwhile."""
        deadline = time.time() + 120
        while len(set(self.workers()) - before) < count:
            assert time.time() < deadline, f"{count} new workers never registered"
            time.sleep(0.2)

    def close(self) -> None:
        for proc in reversed(self.procs):
            proc.kill()
            proc.wait()


def test_a_scheduler_without_workers_is_named_within_the_timeout(tmp_path):
    """Chunks would wait for a worker silently, like a hung run: the run says it waits, then stops."""
    empty = Cluster(tmp_path)
    t0 = time.perf_counter()
    try:
        proc = run_python(["-m", "kd_addon", "render", "--demo", "--out", str(tmp_path / "x"), "--dask",
                           empty.address, "--connect-timeout", "2"], timeout=120)
    finally:
        empty.close()
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert f"no worker has joined the Dask scheduler at {empty.address} yet; waiting up to 2 s" in proc.stdout
    assert f"no worker joined the Dask scheduler at {empty.address} within 2 s: start workers" in proc.stderr
    assert time.perf_counter() - t0 < 60  # the process's own start (bpy, the demo) is most of it


def test_the_keyed_settings_note_goes_on_the_runs_first_frame_whatever_came_back_first():
    """Rows are in frame order; the run's first frame (5 of --frames 5,2,3) gets the note, once."""
    rows = [farm_client.RemoteFrame({"frame": f, "warnings": ["w"] if f == 3 else []}) for f in (2, 3, 5)]
    noted = farm_client.noted_first(rows, "keyed", [5, 2, 3])
    assert [r.row["warnings"] for r in noted] == [[], ["w"], ["keyed"]] and rows[2].row["warnings"] == []
    assert [r.row["warnings"] for r in farm_client.noted_first(rows, "keyed", [2, 3, 5])] == [["keyed"], ["w"], []]
    assert farm_client.noted_first(rows, "", [2, 3, 5]) is rows


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    running = Cluster(tmp_path_factory.mktemp("dask"))
    try:
        yield running
    finally:
        running.close()


def render_cli(args: list[str], **popen) -> subprocess.Popen:
    return subprocess.Popen([PYTHON, "-m", "kd_addon", "render", *args], cwd=REPO, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=dict(os.environ, PYTHONPATH=str(REPO)), **popen)


def finish(proc: subprocess.Popen, timeout=600) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        proc.kill()
    return proc.returncode, out, err


def demo_blend(folder: Path) -> Path:
    scenes.reset()
    demo_scene.build_demo_scene(bpy.context.scene)
    path = folder / "demo.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    scenes.reset()
    return path


def pixels(path: Path) -> np.ndarray:
    image = bpy.data.images.load(str(path))
    try:
        return np.array(image.pixels[:], dtype=np.float32).reshape(-1, 4)
    finally:
        bpy.data.images.remove(image)


def assert_same_pictures(reference: Path, farm: Path, chunk_firsts: set[int]) -> None:
    """Each frame equals the in-process one bit for bit, except a chunk's first frame (a fresh build where
    the in-process run reused the frame before): within one 16-bit level, and the same alpha."""
    report = json.loads((farm / "report.json").read_text())
    for row in report["frames"]:
        ours, theirs = pixels(farm / row["file"]), pixels(reference / row["file"])
        if row["frame"] in chunk_firsts:
            levels = np.abs(np.round(ours * 65535) - np.round(theirs * 65535))
            assert levels.max() <= 1, (row["frame"], levels.max())
            np.testing.assert_array_equal(ours[:, 3], theirs[:, 3])
        else:
            assert (farm / row["file"]).read_bytes() == (reference / row["file"]).read_bytes(), row["frame"]


def assert_complete_report(out: Path, frames: list[int], chunk_size: int) -> dict:
    report = json.loads((out / "report.json").read_text())
    assert report["complete"] is True and [r["frame"] for r in report["frames"]] == frames
    assert sorted(p.name for p in out.glob("frame_*")) == [f"frame_{f:04d}.png" for f in frames]
    assert not list(out.glob(".*partial*"))
    farm = report["farm"]
    assert farm["chunk_size"] == chunk_size and len(farm["chunks"]) == -(-len(frames) // chunk_size)
    for chunk in farm["chunks"]:
        assert chunk["worker"] in farm["workers"] and chunk["render_ms"] > 0 and chunk["attempts"][-1]["outcome"] == "done"
    assert all(r["worker"] in farm["workers"] for r in report["frames"])
    return report


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The demo's frames 1-6 rendered in this process: the reference."""
    out = tmp_path_factory.mktemp("in_process")
    assert cli.execute(["render", "--demo", "--frames", "1-6", "--out", str(out), *SMALL]) == 0
    return out


@pytest.mark.slow
def test_workers_started_here_render_the_in_process_frames(cluster, in_process, tmp_path):
    """A scheduler and two workers: the shipped .blend (as for workers without a shared filesystem)
    renders the in-process frames, and the report says which worker rendered which chunk."""
    cluster.add_workers(2)
    blend = demo_blend(tmp_path)
    out = tmp_path / "farm"
    code, printed, err = finish(render_cli([str(blend), "--frames", "1-6", "--out", str(out), *SMALL,
                                            "--dask", cluster.address, "--chunk-size", "3", "--ship-blend"]))
    assert code == 0, err
    assert "Traceback" not in err and "\r" not in err  # no progress line when not on a terminal
    report = assert_complete_report(out, list(range(1, 7)), 3)
    assert report["farm"]["blend_shipped"] and report["farm"]["retries"] == []
    assert_same_pictures(in_process, out, chunk_firsts={1, 4})
    assert "report:" in printed and printed.count("started on tcp://127.0.0.1") == 2


@pytest.mark.slow
def test_local_workers_render_the_in_process_frames(in_process, tmp_path):
    out = tmp_path / "local"
    code, printed, err = finish(render_cli(["--demo", "--frames", "1-6", "--out", str(out), *SMALL,
                                            "--local-workers", "2", "--chunk-size", "2"]))
    assert code == 0, err
    report = assert_complete_report(out, list(range(1, 7)), 2)
    assert report["farm"]["scheduler"] == "local cluster of 2 worker(s)"
    assert_same_pictures(in_process, out, chunk_firsts={1, 3, 5})


PRELOAD_WITHOUT = """import sys
sys.modules[{name!r}] = None  # `import {name}` raises ImportError in this worker, as where it is not installed
"""


@pytest.mark.slow
@pytest.mark.parametrize("missing, message", [
    ("bpy", "cannot render: the bpy module is not importable here"),
    ("kd_addon", "cannot render: KD Preview (kd_addon) is not importable here")])
def test_a_worker_without_bpy_or_the_project_fails_its_first_task_saying_which(tmp_path, missing, message):
    preload = tmp_path / f"without_{missing}.py"
    preload.write_text(PRELOAD_WITHOUT.format(name=missing))
    broken = Cluster(tmp_path)
    try:
        broken.add_workers(1, preload=str(preload))
        code, _, err = finish(render_cli(["--demo", "--frames", "1-4", "--out", str(tmp_path / "x"), *SMALL,
                                          "--dask", broken.address]), timeout=300)
    finally:
        broken.close()
    assert code == 1 and message in err and "worker tcp://127.0.0.1:" in err, err
    assert "Traceback" not in err


@pytest.mark.slow
def test_ctrl_c_cancels_the_chunks_and_reports_what_finished(cluster, tmp_path):
    if len(cluster.workers()) < 1:
        cluster.add_workers(1)
    out = tmp_path / "cancelled"
    proc = render_cli(["--demo", "--frames", "1-40", "--out", str(out), *SMALL, "--dask", cluster.address,
                       "--chunk-size", "20"])
    try:
        for line in proc.stdout:  # the first frame row
            if re.match(r"^\s*\*?\d+\s+[\d,]+\s", line):
                break
        proc.send_signal(signal.SIGINT)
        code, _, err = finish(proc, timeout=60)
    finally:
        proc.kill()
    assert code == 130 and "interrupted; the" in err, err
    report = json.loads((out / "report.json").read_text())
    assert report["complete"] is False and report["stopped"]["reason"] == "cancelled"
    written = sorted(p.name for p in out.glob("frame_*"))
    assert written == [r["file"] for r in report["frames"]] and 1 <= len(written) < 40
    outcomes = [a["outcome"] for chunk in report["farm"]["chunks"] for a in chunk["attempts"]]
    assert "running" not in outcomes and "cancelled" in outcomes, outcomes  # none left "running"


@pytest.mark.slow
def test_ctrl_c_in_a_terminal_stops_the_local_cluster_quietly(tmp_path):
    """A terminal's Ctrl-C reaches the whole process group, the local workers too: exit 130 with the
    report, and no worker's traceback."""
    out = tmp_path / "local_cancelled"
    proc = render_cli(["--demo", "--frames", "1-24", "--out", str(out), *SMALL, "--local-workers", "2",
                       "--chunk-size", "12"], start_new_session=True)
    try:
        for line in proc.stdout:
            if re.match(r"^\s*\*?\d+\s+[\d,]+\s", line):
                break
        os.killpg(proc.pid, signal.SIGINT)
        code, _, err = finish(proc, timeout=60)
    finally:
        proc.kill()
    assert code == 130 and "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert json.loads((out / "report.json").read_text())["stopped"]["reason"] == "cancelled"


@pytest.mark.slow
def test_a_worker_killed_mid_chunk_loses_no_frame(cluster, tmp_path):
    """SIGKILL to the worker rendering a chunk, after it sent a frame: the scheduler reruns the chunk on
    the other worker; every frame is written once, and the report names the rerun."""
    missing = 2 - len(cluster.workers())
    if missing > 0:
        cluster.add_workers(missing)
    pids = {}
    out = tmp_path / "killed"
    proc = render_cli(["--demo", "--frames", "1-12", "--out", str(out), "--resolution", "20", "--samples", "8",
                       "--dask", cluster.address, "--chunk-size", "4"])
    killed = None
    try:
        for line in proc.stdout:
            started = re.search(r"^chunk (\d+) .* started on (\S+) \(host .*, pid (\d+)\)", line)
            if started:
                pids[int(started.group(1))] = int(started.group(3))
            row = re.match(r"^\s*\*?(\d+)\s+[\d,]+\s", line)
            if row and killed is None:
                chunk = (int(row.group(1)) - 1) // 4
                if (int(row.group(1)) - 1) % 4 < 3:  # frames of the chunk still to come
                    killed = pids[chunk]
                    os.kill(killed, signal.SIGKILL)
                    break
        code, printed, err = finish(proc)
    finally:
        proc.kill()
    assert killed is not None and code == 0, err
    report = assert_complete_report(out, list(range(1, 13)), 4)
    retries = report["farm"]["retries"]
    assert len(retries) == 1 and retries[0]["reason"] == "worker lost", retries
    assert retries[0]["frames_sent_before"] >= 1
    assert report["farm"]["duplicate_frames_dropped"] == retries[0]["frames_sent_before"]
    assert "rerun on" in printed


@pytest.mark.slow
def test_a_lost_scheduler_ends_the_run_with_its_address_and_the_report(tmp_path):
    lost = Cluster(tmp_path)
    out = tmp_path / "lost"
    try:
        lost.add_workers(1)
        proc = render_cli(["--demo", "--frames", "1-24", "--out", str(out), *SMALL, "--dask", lost.address,
                           "--chunk-size", "24"])
        for line in proc.stdout:
            if re.match(r"^\s*\*?\d+\s+[\d,]+\s", line):
                break
        lost.procs[0].kill()  # the scheduler
        code, _, err = finish(proc, timeout=120)
    finally:
        lost.close()
    assert code == 1 and f"error: lost the Dask scheduler ({lost.address})" in err and "Traceback" not in err, err
    report = json.loads((out / "report.json").read_text())
    assert report["complete"] is False and len(report["frames"]) == len(list(out.glob("frame_*"))) >= 1
