"""The client side of a cluster run: chunks out, frames back, one report.

The frames are split into contiguous chunks, one task (future) a chunk, so each worker reuses trees and
pixels across its chunk as the in-process path does across the whole range. A task streams each frame,
once rendered, through a distributed.Queue (its encoded file and its report row); the future's own
result is only the chunk's timings. Queue items pass through the scheduler: simple, ordered with the
task's end (a task's puts are acknowledged before it returns), and a frame a few MB at most
(docs/choices.md "Frames stream back through a Dask queue"). Each frame is written once: a chunk rerun
after its worker died sends its frames again, and those already written are counted and dropped.
"""

from __future__ import annotations

import math
import os
import sys
import time
import uuid
from pathlib import Path
from types import SimpleNamespace

import bpy

from .. import cli, compile_command, corelib, output
from ..errors import Cancelled, PreviewError
from ..sequence import frame_filename, prepare_folder, remove_empty_folders, stop_reason, summarize, write_report
from ..signals_held import signals_held
from . import bootstrap, cluster
from .progress import ProgressLine

# Automatic chunk size (docs/choices.md "Chunks of contiguous frames"): each chunk's first frame is a fresh
# build, so chunks are long, yet a few a worker so the last ones balance out; reuse needs two frames, and a
# chunk rerun after its worker died repeats at most MAX_CHUNK frames.
CHUNKS_PER_WORKER = 3
MIN_CHUNK, MAX_CHUNK = 2, 24
POLL_SECONDS = 0.1  # wait between looks at an empty queue (and at the futures and the cancel flag)
REPORT_INTERVAL = 1.0  # seconds between rewrites of report.json while the run goes on


def auto_chunk_size(frames: int, workers: int) -> int:
    size = math.ceil(frames / (CHUNKS_PER_WORKER * max(1, workers)))
    return max(1, min(frames, max(MIN_CHUNK, min(MAX_CHUNK, size))))


def chunk_frames(frames: list[int], size: int) -> list[list[int]]:
    """Contiguous runs of `size` frames (the last may be shorter), in the order given."""
    if size < 1:
        raise PreviewError(f"--chunk-size must be 1 or more, got {size}")
    return [frames[i:i + size] for i in range(0, len(frames), size)]


def noted_first(results: list, note: str, order: list[int]) -> list:
    """The report's rows (in frame order) with `note` added to the warnings of the row written earliest in
    the run's order `order` (its frames as given), whichever came back first, as an in-process run says it
    on its first frame."""
    if not note or not results:
        return results
    rank = {frame: index for index, frame in enumerate(order)}
    first = min(range(len(results)), key=lambda i: rank[results[i].row["frame"]])
    row = results[first].row
    noted = RemoteFrame(dict(row, warnings=[*row.get("warnings", []), note]))
    return [noted if i == first else r for i, r in enumerate(results)]


class RemoteFrame:
    """A frame rendered on a worker: its report row, read as pipeline.FrameResult's fields are (so the
    in-process report writer, totals and table row take it)."""

    def __init__(self, row: dict):
        self.row = row

    def __getattr__(self, name):
        if name == "tree_stats":
            return self.row.get("tree", {})
        try:
            return self.row[name]
        except KeyError:
            raise AttributeError(name) from None

    def summary(self) -> dict:
        return dict(self.row)


def run(args, interrupted) -> int:
    """`render --dask ADDRESS` / `--local-workers N`: the exit code, as cli._run's; `interrupted`:
    cli.interrupt_flag's Event, polled between frames."""
    farm = None
    try:
        cluster.import_distributed()  # before a file is opened: say how to install it
        prepared = cli.prepare(args)
        with cluster.dask_client(args.dask, args.local_workers, args.connect_timeout) as client:
            cluster.wait_for_a_worker(client, args.dask, args.connect_timeout)
            farm = FarmRun(client, args, prepared)
            farm.run(interrupted.is_set)
    except PreviewError as error:
        _clear(farm)
        print(f"{args.prog}: error: {error}", file=sys.stderr)
        return 1
    except (Cancelled, KeyboardInterrupt):
        _clear(farm)
        written = len(farm.written) if farm is not None else 0
        print(cli.stopped_message(args.prog, written, interrupted), file=sys.stderr)
        return 130
    farm.print_totals()
    return 0


def _clear(farm) -> None:
    if farm is not None:
        farm.progress.clear()


class FarmRun:
    """One run on a cluster: submit the chunks, take the frames back, write them and the report."""

    def __init__(self, client, args, prepared):
        from distributed import Event, Queue

        self.client, self.args, self.prepared = client, args, prepared
        self.config, self.frames = prepared.config, prepared.frames
        self.scene_name = prepared.scene.name
        self.out_dir = Path(os.path.normpath(os.path.abspath(args.out)))
        self.workers_at_start = len(client.scheduler_info()["workers"])
        self.chunk_size = args.chunk_size or auto_chunk_size(len(self.frames), self.workers_at_start)
        self.chunks = chunk_frames(self.frames, self.chunk_size)
        run_id = uuid.uuid4().hex[:12]
        self.queue = Queue(f"kd-preview-frames-{run_id}", client=client)
        self.cancel_event = Event(f"kd-preview-cancel-{run_id}", client=client)
        self.run_id = run_id
        self.futures: dict = {}  # future -> chunk index, while it runs
        self.attempts: dict[int, list[dict]] = {i: [] for i in range(len(self.chunks))}
        self.timings: dict[int, dict] = {}  # chunk -> its task's result
        self.retries: list[dict] = []
        self.written: dict[int, RemoteFrame] = {}
        self.files: dict[int, Path] = {}
        self.duplicates = 0
        self.progress = ProgressLine(len(self.frames))
        self.report_path: Path | None = None
        self.totals: dict = {}
        self._t0 = time.perf_counter()
        self._started_at = time.time()  # report.json's start time
        self._next_report = 0.0

    # -- the run -------------------------------------------------------------

    def run(self, cancelled) -> None:
        made = prepare_folder(self.out_dir)
        self._print_header()
        try:
            try:
                self._submit()
                while self.futures:
                    if cancelled():
                        raise Cancelled("cancelled")
                    self._step()
            except OSError as error:  # the scheduler went away (distributed's CommClosedError is one)
                raise PreviewError(f"lost the Dask scheduler ({self.args.dask or 'the local cluster'}): "
                                   f"{str(error) or type(error).__name__}") from None
        except BaseException as error:  # noqa: B036  (a cancel too: the report says what finished)
            self._stop(error)
            if not self.written:
                remove_empty_folders(made)
            raise
        self._write_report()

    def _submit(self) -> None:
        import cloudpickle

        cloudpickle.register_pickle_by_value(bootstrap)  # runs where the project does not import
        blend, blend_arg = self._blend_source()
        task = bootstrap.chunk_task()
        for index, frames in enumerate(self.chunks):
            spec = {"run": self.run_id, "chunk": index, "frames": frames, "blend": blend,
                    "demo": blend is None, "scene": self.args.scene, "settings": vars(self.prepared.settings),
                    "queue": self.queue.name, "cancel": self.cancel_event.name,
                    "package": __package__.rpartition(".")[0], "digest": corelib.source_digest(),
                    "blender_paths": blender_script_paths()}
            future = self.client.submit(task, spec, blend_arg, retries=self.args.retries,
                                        key=f"kd-preview-chunk-{index}-{self.run_id}", pure=False)
            self.futures[future] = index

    def _blend_source(self):
        """(the .blend's path as the workers open it, or None for the demo; the scattered bytes or None)."""
        path = self.args.blend or bpy.data.filepath or None
        if path is None:
            return None, None  # the built-in demo: each worker builds it
        path = str(Path(path).resolve())
        if not self.args.ship_blend:
            return path, None
        data = Path(path).read_bytes()
        return path, self.client.scatter(data, broadcast=True, hash=False)

    def _step(self) -> None:
        """Take the frames that arrived; then finish the chunks whose futures are done (their frames were
        all queued before the task ended, so a second look at the queue has them)."""
        self._receive(POLL_SECONDS)
        done = [future for future in self.futures if future.done()]
        if done:
            self._receive(0)
            for future in done:
                self._finish(future)
        self._report_progress()

    def _receive(self, wait: float) -> None:
        """Handle what the queue holds; with nothing there, wait `wait` seconds first. (A get with a
        timeout would do, but its timing out is logged as an error by the scheduler.)"""
        messages = self.queue.get(batch=True)
        if not messages and wait > 0:
            time.sleep(wait)
            messages = self.queue.get(batch=True)
        for message in messages:
            getattr(self, "_on_" + message["kind"].replace("-", "_"))(message)

    # -- messages from the workers ------------------------------------------

    def _on_setup_failed(self, message: dict) -> None:
        raise PreviewError(message["error"])

    def _on_start(self, message: dict) -> None:
        index = message["chunk"]
        earlier = [a for a in self.attempts[index] if a["outcome"] == "running"]
        for attempt in earlier:  # no result and no error from it: its worker died or left
            attempt["outcome"] = "worker lost"
        attempts = self.attempts[index]
        if attempts:
            last = attempts[-1]
            self.retries.append({"chunk": index, "frames": _span(self.chunks[index]), "failed_on": last["worker"],
                                 "rerun_on": message["worker"], "reason": last.get("error", last["outcome"]),
                                 "frames_sent_before": last["frames_sent"]})
            self._print(f"chunk {index} ({_span_text(self.chunks[index])}): rerun on {message['worker']} "
                        f"after {last['worker']}: {self.retries[-1]['reason']}")
        attempts.append({"attempt": message["attempt"], "worker": message["worker"], "host": message["host"],
                         "pid": message["pid"], "started_s": round(time.perf_counter() - self._t0, 3),
                         "frames_sent": 0, "outcome": "running"})
        self._print(f"chunk {index} ({_span_text(self.chunks[index])}) started on {message['worker']} "
                    f"(host {message['host']}, pid {message['pid']})")

    def _on_failed(self, message: dict) -> None:
        attempt = self._attempt(message)
        attempt["outcome"], attempt["error"] = "failed", message["error"]

    def _on_frame(self, message: dict) -> None:
        attempt = self._attempt(message)
        attempt["frames_sent"] += 1
        frame = message["frame"]
        if frame in self.written:  # a rerun chunk's frame, already written from the attempt before
            self.duplicates += 1
            return
        path = self.out_dir / frame_filename(frame, self.config.file_extension)
        row = dict(message["row"], file=path.name, worker=message["worker"], chunk=message["chunk"],
                   attempt=message["attempt"])
        result = RemoteFrame(row)
        with signals_held():  # the file on disk and its report entry come together
            _write_file(path, message["data"])
            self.written[frame], self.files[frame] = result, path
        self.progress.clear()
        cli._print_row(self.args.prog, result, path)
        self.progress.update(len(self.written))

    def _attempt(self, message: dict) -> dict:
        return next(a for a in self.attempts[message["chunk"]] if a["attempt"] == message["attempt"])

    # -- chunks ending ----------------------------------------------------------

    def _finish(self, future) -> None:
        index = self.futures.pop(future)
        frames = self.chunks[index]
        if future.status != "finished":
            error = future.exception() if future.status == "error" else future.status
            raise PreviewError(f"chunk {index} ({_span_text(frames)}) failed: {error}")
        timing = future.result()
        self.timings[index] = timing
        self._attempt(timing).update(outcome="done", ended_s=round(time.perf_counter() - self._t0, 3))
        missing = [f for f in frames if f not in self.written]
        if missing:
            raise PreviewError(f"chunk {index} ended on {timing['worker']} without sending frame(s) "
                               + ", ".join(map(str, missing)))

    def _stop(self, error: BaseException) -> None:
        """Cancel what still runs (a worker stops its chunk after the frame it is on) and write the report
        of what finished. Best effort: the error that stopped the run is the one to report."""
        if self.client.status == "running":  # else the scheduler is gone: each call would wait for it
            try:
                self.cancel_event.set()
                self.client.cancel(list(self.futures), force=True)
            except Exception:  # noqa: BLE001  (the error that stopped the run is the one to report)
                pass
        ended = round(time.perf_counter() - self._t0, 3)
        how = "cancelled" if isinstance(error, (Cancelled, KeyboardInterrupt)) else "stopped"
        for attempt in (a for attempts in self.attempts.values() for a in attempts if a["outcome"] == "running"):
            attempt.update(outcome=how, reason=stop_reason(error), ended_s=ended)  # not left "running"
        if self.written:
            missing = next((f for f in self.frames if f not in self.written), None)
            try:  # every frame written (an interrupt held back until the last one was recorded): complete
                self._write_report(None if missing is None else {"frame": missing, "reason": stop_reason(error)})
            except PreviewError:
                pass

    # -- report and printing ----------------------------------------------------

    def _report_progress(self) -> None:
        now = time.perf_counter()
        if self.written and now >= self._next_report and len(self.written) < len(self.frames):
            try:
                self._write_report()
            except PreviewError:
                return
            self._next_report = now + REPORT_INTERVAL

    def _write_report(self, stopped: dict | None = None) -> None:
        order = sorted(self.written)
        results = noted_first([self.written[f] for f in order], self.prepared.keyed_note, self.frames)
        self.totals = summarize(results, (time.perf_counter() - self._t0) * 1e3)
        self.report_path = write_report(self.out_dir, self.scene_name, self.config, results,
                                        [self.files[f] for f in order], self.totals, len(self.frames), stopped,
                                        started_at=self._started_at, extra={"farm": self.farm_section()})

    def farm_section(self) -> dict:
        """report.json's "farm": where it ran, each chunk's workers and times, and the reruns."""
        chunks = []
        for index, frames in enumerate(self.chunks):
            timing = self.timings.get(index, {})
            chunks.append({"chunk": index, "frames": _span(frames), "count": len(frames),
                           "worker": timing.get("worker"), "load_ms": timing.get("load_ms"),
                           "render_ms": timing.get("render_ms"),
                           "attempts": self.attempts[index]})
        return {"scheduler": self.args.dask or f"local cluster of {self.args.local_workers} worker(s)",
                "workers_at_start": self.workers_at_start,
                "workers": sorted({a["worker"] for attempts in self.attempts.values() for a in attempts}),
                "chunk_size": self.chunk_size, "retries_allowed": self.args.retries,
                "blend_shipped": bool(self.args.ship_blend), "chunks": chunks, "retries": self.retries,
                "duplicate_frames_dropped": self.duplicates}

    def _print_header(self) -> None:
        where = self.args.dask or "a local cluster"
        settings = self.config.settings
        print(f"KD Preview: scene '{self.scene_name}', {len(self.frames)} frame(s), mode {settings.mode}, "
              f"{settings.samples} samples, {self.config.resolution_percentage}% resolution -> {self.args.out}; "
              f"on {where} with {self.workers_at_start} worker(s), {len(self.chunks)} chunk(s) of up to "
              f"{self.chunk_size} frames", flush=True)
        if self.prepared.keyed_note:  # known before any chunk runs; the report puts it on the run's first frame
            print(f"{self.args.prog}: warning: {self.prepared.keyed_note}", file=sys.stderr, flush=True)
        note = None if self.args.dask else compile_command.uncompiled_note(self.args.prog)  # local workers: this cache
        if note:
            print(f"Note: {note}", flush=True)
        print(cli.HEADER, flush=True)

    def _print(self, line: str) -> None:
        self.progress.clear()
        print(line, flush=True)
        self.progress.update(len(self.written))

    def print_totals(self) -> None:
        self.progress.clear()
        if self.retries:
            print(f"reruns: {len(self.retries)} chunk(s) rerun ("
                  + "; ".join(f"chunk {r['chunk']} after {r['failed_on']}: {r['reason']}" for r in self.retries)
                  + f"); {self.duplicates} frame(s) sent twice were dropped")
        cli._print_totals(SimpleNamespace(totals=self.totals, config=self.config, report_path=self.report_path),
                          any(r.first_run for r in self.written.values()))


def blender_script_paths() -> list[str]:
    """The entries of sys.path that importing bpy added (Blender's script folders), for
    bootstrap.forget_inherited_paths."""
    roots = [os.path.normpath(bpy.utils.resource_path(kind)) for kind in ("LOCAL", "USER", "SYSTEM")
             if bpy.utils.resource_path(kind)]
    return [p for p in sys.path if any(os.path.normpath(p) == r or os.path.normpath(p).startswith(r + os.sep)
                                       for r in roots)]


def _write_file(path: Path, data: bytes) -> None:
    """Written beside, then renamed over (output.save_frame's rule: never a truncated frame)."""
    partial = output.partial_path(path)
    try:
        partial.write_bytes(data)
        output.replace_file(partial, path)
    except OSError as error:
        raise PreviewError(f"could not write {path}: {error.strerror or error}") from None
    finally:
        output.remove_partial(partial)


def _span(frames: list[int]) -> list[int]:
    return [frames[0], frames[-1]]


def _span_text(frames: list[int]) -> str:
    """"frames 3-7", or "frame 3" for a chunk of one frame."""
    return f"frames {frames[0]}-{frames[-1]}" if len(frames) > 1 else f"frame {frames[0]}"
