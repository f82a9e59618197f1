"""`python -m kd_addon compile` (kd_addon/compile_command.py, kernel_warmup.compile_both_stages): both
warm-up stages run in turn at normal priority and are waited for, a cached second stage is skipped, a
failed stage or one that cannot start is named, and an interrupted one is ended and said so. The stages'
processes are replaced by short Python processes (the real tasks are the warm-up's:
tests/test_kernel_warmup.py, tests/test_packets_once_cached.py)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading

import pytest

from kd_addon import cli, corelib, kernel_warmup


@pytest.fixture
def stages(monkeypatch):
    """The stages' processes recorded, each `python -c code[task]` (default: exit at once); the cache
    holds what `cached` names ("first", "second")."""
    run = {"code": {}, "spawned": [], "cached": set()}

    def spawn(errors, task=kernel_warmup.TASK, low_priority=False):
        run["spawned"].append((task, low_priority))
        code = run["code"].get(task, "pass")
        run["last"] = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL,
                                       stdout=subprocess.DEVNULL, stderr=errors)
        return run["last"]
    monkeypatch.setattr(kernel_warmup, "_spawn", spawn)
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: (
        "first" if kernel == corelib.WARM_KERNEL else "second") in run["cached"])
    monkeypatch.setattr(corelib, "packed_version_cached", lambda: "second" in run["cached"])
    return run


def test_compile_runs_both_stages_in_turn_and_skips_a_cached_second_one(stages, capsys):
    """The first stage always runs (what it cached only loads: a kernel cached midway through an
    interrupted first stage does not say it finished); the second unless its kernels are cached."""
    assert cli.execute(["compile"]) == 0
    assert stages["spawned"] == [(kernel_warmup.TASK, False), (kernel_warmup.PACKED_TASK, False)]
    out = capsys.readouterr().out
    assert str(corelib.numba_cache_dir()) in out and "every kernel compiled and cached" in out
    stages["spawned"].clear()
    stages["cached"].update(("first", "second"))
    assert cli.execute(["compile"]) == 0
    assert stages["spawned"] == [(kernel_warmup.TASK, False)]


def test_a_compile_process_that_cannot_start_is_named(stages, capsys, monkeypatch):
    def refuse(errors, task=kernel_warmup.TASK, low_priority=False):
        raise PermissionError(13, "Permission denied", "/cache")
    monkeypatch.setattr(kernel_warmup, "_spawn", refuse)
    assert cli.execute(["compile"]) == 1
    assert "error: the kernels' compile failed: could not start the compile process: [Errno 13]" in (
        capsys.readouterr().err)


def test_a_failed_stage_is_named_and_the_next_one_not_started(stages, capsys):
    stages["code"][kernel_warmup.TASK] = "import sys; sys.exit('LLVM ERROR: out of memory')"
    assert cli.execute(["compile"]) == 1
    assert stages["spawned"] == [(kernel_warmup.TASK, False)]
    assert "error: the kernels' compile failed: LLVM ERROR: out of memory" in capsys.readouterr().err


def test_an_interrupted_compile_ends_its_stage_and_says_what_is_kept(stages, capsys):
    """Ctrl-C (here a SIGINT sent once the stage runs) ends the stage's process and exits with 130."""
    stages["code"][kernel_warmup.TASK] = "import time; time.sleep(60)"
    timer = threading.Timer(1.0, lambda: signal.raise_signal(signal.SIGINT) if "last" in stages else None)
    timer.start()
    try:
        code = cli.execute(["compile"])
    finally:
        timer.cancel()
    assert code == 130 and stages["last"].poll() is not None  # ended, not left behind
    assert stages["spawned"] == [(kernel_warmup.TASK, False)]
    assert "interrupted; the kernels compiled so far are kept" in capsys.readouterr().err


@pytest.mark.parametrize("cached", [False, True])
def test_a_render_without_the_packet_kernels_says_how_to_compile_them(cached, tmp_path, capsys, monkeypatch):
    """A command-line render whose cache lacks the second stage's kernels says once that it runs without
    them and names the command that compiles them (as run: python -m kd_addon, or Blender's)."""
    monkeypatch.setattr(kernel_warmup, "second_stage_cached", lambda: cached)
    for prog, command in (("python -m kd_addon", "python -m kd_addon compile"),
                          (cli.COMMAND_ID, f"blender -b --command {cli.COMMAND_ID} compile")):
        assert cli.execute(["render", "--demo", "--frames", "1", "--resolution", "5", "--out", str(tmp_path)],
                           prog=prog) == 0
        out = capsys.readouterr().out
        assert (f"`{command}` has compiled every kernel once" in out) is not cached
