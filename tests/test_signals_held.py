"""Ctrl-C and SIGTERM held back while a frame's file is put in place and recorded (kd_addon/signals_held.py):
an interrupt during the block is handled right after it, and a farm run's frame that reached the disk is
in the run's record (report.json lists it) even when the interrupt lands while it is written."""
import signal
import threading
from types import SimpleNamespace

import pytest

from kd_addon.farm import client
from kd_addon.signals_held import signals_held


def test_ctrl_c_inside_the_block_raises_after_it():
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with signals_held():
            signal.raise_signal(signal.SIGINT)
            steps.append("after the signal, inside")
        steps.append("after the block")  # never: the interrupt comes at the block's end
    assert steps == ["after the signal, inside"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_sigterm_is_handled_once_after_the_block_by_its_own_handler():
    handled = []

    def on_term(signum, frame):
        handled.append(signum)

    before = signal.signal(signal.SIGTERM, on_term)
    try:
        with signals_held():
            signal.raise_signal(signal.SIGTERM)
            assert handled == []
        assert handled == [signal.SIGTERM]
        assert signal.getsignal(signal.SIGTERM) is on_term
    finally:
        signal.signal(signal.SIGTERM, before)


def test_outside_the_main_thread_nothing_changes():
    seen = []

    def worker():
        with signals_held():
            seen.append(signal.getsignal(signal.SIGINT))

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert seen == [signal.default_int_handler]


def test_a_farm_frame_written_when_ctrl_c_lands_is_recorded(tmp_path, monkeypatch):
    """FarmRun._on_frame with Ctrl-C arriving just after the file is renamed into place (the CI failure:
    the frame's file on disk, not in report.json): the interrupt comes after the frame is recorded."""
    written_files = []

    def write_then_interrupt(path, data):
        path.write_bytes(data)
        written_files.append(path.name)
        signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(client, "_write_file", write_then_interrupt)
    farm = object.__new__(client.FarmRun)
    farm.out_dir, farm.config = tmp_path, SimpleNamespace(file_extension=".png")
    farm.attempts = {0: [{"attempt": 1, "frames_sent": 0}]}
    farm.written, farm.files, farm.duplicates = {}, {}, 0
    message = {"chunk": 0, "attempt": 1, "frame": 7, "row": {"frame": 7}, "data": b"png", "worker": "w"}
    with pytest.raises(KeyboardInterrupt):
        farm._on_frame(message)
    assert written_files == ["frame_0007.png"]
    assert list(farm.written) == [7] and farm.files[7].name == "frame_0007.png"


def test_a_farm_run_stopped_after_its_last_frame_was_recorded_reports_it_complete():
    """The interrupt held back until the last frame was recorded: every frame is written when the run
    stops, and the report is written as complete (no frame left to name as where it stopped)."""
    farm = object.__new__(client.FarmRun)
    farm.client, farm.futures = SimpleNamespace(status="closed"), {}
    farm.frames, farm.written = [7, 8], {7: object(), 8: object()}
    farm._t0, farm.attempts = 0.0, {0: [{"outcome": "done"}], 1: [{"outcome": "running"}]}
    reports = []
    farm._write_report = lambda stopped=None: reports.append(stopped)
    farm._stop(KeyboardInterrupt())
    assert reports == [None]
    outcomes = [(a["outcome"], a.get("reason")) for attempts in farm.attempts.values() for a in attempts]
    assert outcomes == [("done", None), ("cancelled", "cancelled")]  # none left "running" in the report
    del farm.written[8]
    farm._stop(KeyboardInterrupt())
    assert reports[1]["frame"] == 8
