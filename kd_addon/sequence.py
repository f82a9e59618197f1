"""A frame range rendered to an image sequence plus `report.json`, one FrameJob per frame.

Shared by the Render Animation operator and the command line, so the files and the report are the
same however the sequence is started. The scene's frame is put back afterwards, on any outcome.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
import time
from pathlib import Path

from . import background, output
from .run_record import run_record
from .signals_held import signals_held
from .config import RenderConfig, make_config
from .errors import Cancelled, PreviewError
from .pipeline import FrameJob, FrameResult

REPORT_NAME = "report.json"
REPORT_INTERVAL = 1.0  # seconds: how often a running sequence rewrites its report at most
TOTAL_KEYS = ("triangles", "extract_ms", "build_ms", "trace_ms", "total_ms", "rays", "rays_saved", "rays_reused",
              "pixels_reused", "objects_rebuilt", "objects_reused", "compile_ms", "load_ms")
TIMINGS_NOTE = ("extract, build, trace and total times and Mrays/s leave out the kernels' compile and load "
                "(compile_ms, load_ms), which a process's first frame waits for")


def frame_filename(frame: int, extension: str) -> str:
    return f"frame_{frame:04d}{extension}"


def parse_frames(text: str) -> list[int]:
    """Frames from "7", "1-24", "1-24:2" or a comma list of those; raises PreviewError naming the problem."""
    parts = [p.strip() for p in str(text).split(",")]
    if not any(parts):
        raise PreviewError(f"bad frame range {text!r}: no frames")
    if not all(parts):  # "1,,2" or a trailing comma: a typo, not a request
        raise PreviewError(f"bad frame range {text!r}: an empty item in the comma list")
    frames: list[int] = []
    for part in parts:
        frames += _parse_range(part)
    return list(dict.fromkeys(frames))


_RANGE = re.compile(r"^(-?\d+)(?:-(-?\d+))?(?::(-?\d+))?$")  # a negative step is matched, then named
# Blender's frame limits (Scene.frame_current's hard range, MINAFRAME and MAXFRAME): frame_set clamps a
# frame beyond them silently, which would render the last frame again under the requested frame's name.
FIRST_FRAME, LAST_FRAME = -1048574, 1048574


def _parse_range(part: str) -> list[int]:
    match = _RANGE.match(part)
    if match is None:
        raise PreviewError(f"bad frame range {part!r}: use N, A-B or A-B:STEP, or a comma list of those")
    first = int(match.group(1))
    last = int(match.group(2)) if match.group(2) is not None else first
    stride = int(match.group(3) or 1)
    if last < first:
        raise PreviewError(f"bad frame range {part!r}: the end ({last}) is before the start ({first})")
    if stride < 1:
        raise PreviewError(f"bad frame range {part!r}: the step must be 1 or more, got {stride}")
    check_frames_in_range((first, last))
    return list(range(first, last + 1, stride))


def check_frames_in_range(frames) -> None:
    """PreviewError naming the first frame Blender cannot go to (beyond FIRST_FRAME..LAST_FRAME)."""
    for frame in frames:
        if not FIRST_FRAME <= frame <= LAST_FRAME:
            raise PreviewError(f"frame {frame} is outside Blender's frame range ({FIRST_FRAME} to {LAST_FRAME})")


def check_folder_path(folder: Path) -> list[Path]:
    """Check, without making anything, that `folder` is or can become a folder: its nearest existing
    ancestor must be one (the command line checks this before its first output line). Returns the
    missing folders, innermost first."""
    missing = []
    probe = folder
    while not probe.exists() and probe != probe.parent:
        missing.append(probe)
        probe = probe.parent
    if not probe.is_dir():  # mkdir would say "File exists"
        raise PreviewError(f"cannot write to the output folder {folder}: {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):  # a read-only disk or a folder of another user's
        raise PreviewError(f"cannot write to the output folder {folder}: {probe} is not writable")
    return missing


def prepare_folder(folder: Path) -> list[Path]:
    """Make `folder` (absolute and normalised; and missing parents) and check that files can be
    written there, before the first frame renders: a folder under a file, or on a read-only disk, was
    found only when frame 1 was written, after its render (minutes on a first run: the kernels
    compile). Returns the folders made, innermost first, for remove_empty_folders."""
    missing = check_folder_path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        remove_empty_folders(missing)
        raise PreviewError(f"cannot create the output folder {folder}: {error.strerror or error}") from None
    try:
        tempfile.TemporaryFile(dir=folder).close()
    except OSError as error:
        remove_empty_folders(missing)
        raise PreviewError(f"cannot write to the output folder {folder}: {error.strerror or error}") from None
    return missing


def remove_empty_folders(folders: list[Path]) -> None:
    """Remove these folders (innermost first) while empty: a sequence that wrote nothing leaves none."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


class SequenceJob:
    """Renders `frames` of `scene` into `out_dir`; drive with tick(), then call close()."""

    def __init__(self, scene, config: RenderConfig, frames: list[int], out_dir: Path, depsgraph_for, on_frame=None,
                 note: str | None = None):
        """`depsgraph_for(scene)` returns the evaluated depsgraph after frame_set (e.g.
        operators.depsgraph_source(scene, view_layer)); `on_frame(result, path)` is called
        after each frame is written; `note`: the caller's own check of keyed settings (the command line's), said
        on the first frame ("" for none), in place of this job's."""
        if not frames:
            raise PreviewError("no frames to render")
        check_frames_in_range(frames)
        self.scene, self.config, self.frames = scene, config, list(frames)
        self._scene_name = scene.name  # the report's, should the scene be removed mid-run
        # Normalised: with "a/missing/../b" every part looks missing, and a first frame that failed
        # would remove the user's empty folder b.
        self.out_dir = Path(os.path.normpath(os.path.abspath(out_dir)))
        self.depsgraph_for, self.on_frame = depsgraph_for, on_frame
        self.results: list[FrameResult] = []
        self.files: list[Path] = []
        self.job: FrameJob | None = None
        self._made_folders: list[Path] | None = None  # at the first tick: once the job holds the claim
        self._start_frame = scene.frame_current
        self._t0 = time.perf_counter()
        self._started_at = time.time()  # report.json's start time
        self.report_path: Path | None = None
        self._reported = 0  # frames the last report written lists
        self._stopped: dict | None = None  # what stopped an unfinished sequence (close), for its report
        self._next_report = 0.0  # perf_counter time before which _report_progress writes none
        self.totals: dict = {}
        self._preview_before = output.preview_state()  # put back by close() when the run does not finish
        # the scene's KD Preview settings when the run's config was made (now: the current frame's); None
        # where the add-on's settings are not registered (the command line reads the .blend's itself)
        self._first_settings = _scene_settings(scene)
        # said once, on the first frame whose settings differ ("" once said, or when the caller checked)
        self._keyed_note: str | None = note

    @property
    def done(self) -> bool:
        return len(self.results) == len(self.frames)

    @property
    def progress(self) -> float:
        current = self.job.progress if self.job is not None else 0.0
        return (len(self.results) + current) / len(self.frames)

    @property
    def status(self) -> str:
        frame = self.frames[min(len(self.results), len(self.frames) - 1)]
        inner = self.job.status if self.job is not None else "Starting"
        return f"Frame {frame} ({len(self.results) + 1}/{len(self.frames)}): {inner}"

    def tick(self) -> bool:
        """Next short piece of work; True once every frame is written and the report saved. An error
        names the frame it stopped at, as the frames' warnings do."""
        frame = self.frames[min(len(self.results), len(self.frames) - 1)]
        if self._made_folders is None:
            self._made_folders = prepare_folder(self.out_dir)
        try:
            if self.job is None:  # the frame is set when the job reads the scene (see FrameJob)
                self.job = FrameJob(self.scene, lambda: self._evaluated_at(frame), self.config)
            if not self.job.tick():
                return False
            result = self.job.result()
            if self._keyed_note:
                result.warnings.append(self._keyed_note)
                self._keyed_note = ""  # said: "" never again
            path = self._write(result)
            self.job = None
        except PreviewError as error:
            raise PreviewError(f"frame {frame}: {error}") from None
        if self.done:
            self._write_report()  # its error is the sequence's, not the last frame's
        else:
            self._report_progress()
        if self.on_frame is not None:
            self.on_frame(result, path)
        return self.done

    def _report_progress(self) -> None:
        """The report of the frames written so far, marked incomplete, before the frame is announced, so
        the report follows the files on disk even when the run is killed outright. Best effort (the
        last frame's report or close() names a failure), at most every REPORT_INTERVAL seconds and
        never more than 1/20 of the time (a long report takes a noticeable time to write)."""
        start = time.perf_counter()
        if start < self._next_report:
            return
        try:
            self._write_report()
        except PreviewError:
            return
        self._next_report = time.perf_counter() + max(REPORT_INTERVAL, 20 * (time.perf_counter() - start))

    def _evaluated_at(self, frame: int):
        self.scene.frame_set(frame)
        self._note_keyed_settings()
        return self.depsgraph_for(self.scene)

    def _note_keyed_settings(self) -> None:
        """A sequence renders with the settings it started with (report.json records one set): the scene's
        settings keyed to differ from them are named once, in the first frame where they do."""
        now = _scene_settings(self.scene)
        if now is None or self._first_settings is None:
            return
        changed = sorted(k for k in now if now[k] != self._first_settings[k])
        if changed and self._keyed_note is None:
            self._keyed_note = (f"KD Preview settings keyed to change over the frames ({', '.join(changed)}) are not "
                                "followed: this run keeps the values it started with (report.json's settings); the "
                                "render engine's animation (Ctrl-F12) follows them frame by frame")

    def _write(self, result: FrameResult) -> Path:
        path = self.out_dir / frame_filename(self.frames[len(self.results)], self.config.file_extension)
        with signals_held():  # the file on disk and its report entry come together
            try:
                output.save_frame(result.image, path, self.config.settings.output_format)
            except (OSError, RuntimeError) as error:  # RuntimeError: Image.save's own failure
                raise PreviewError(f"could not write {path}: {error}") from None
            self.results.append(result)
            self.files.append(path)
        return path

    def close(self, stopped_by: BaseException | None = None) -> None:
        """Put the scene back on the frame it was on (call on success, cancel and failure), and when
        the sequence stopped early, put the preview image back as it was before the run and write
        report.json for the frames that were written, marked incomplete, with the frame it stopped at
        and why (`stopped_by`: the error or cancel that ended it). Best effort: the error that stopped
        it is the one to report."""
        if stopped_by is not None and len(self.results) < len(self.frames):
            self._stopped = {"frame": self.frames[len(self.results)], "reason": stop_reason(stopped_by)}
            try:  # the frames written stay on disk; the preview and the panel's figures stay the last run's
                output.put_back_preview(self._preview_before)
            except (ReferenceError, RuntimeError):
                pass
        # stopped early (the report on disk does not say so yet), or the last report failed
        if self.results and (self._stopped is not None or self._reported != len(self.results)):
            try:
                self._write_report()
            except PreviewError:
                pass
        if not self.results:
            remove_empty_folders(self._made_folders or [])
        try:
            if self.scene.frame_current == self._start_frame:
                return
        except ReferenceError:  # the scene was removed (or reloaded by an undo) during the run
            return
        if background.abandoned_work_running():
            # A cancelled frame's kernel call still runs: frame_set would evaluate the scene beside it
            # (background.SCENE_READ_WAIT). The frame alone is set; Blender evaluates it later: in the
            # UI at its next update, as after a timeline change (which it does beside running work,
            # and which runs the frame-change handlers: with Live Update on, the preview is rendered
            # again once the call has ended, its image reused when unchanged); in a script at the next
            # depsgraph read or frame_set.
            self.scene.frame_current = self._start_frame
        else:
            self.scene.frame_set(self._start_frame)

    def scene_name(self) -> str:
        """The scene's name now (it may have been renamed), or its last one if it was removed."""
        try:
            self._scene_name = self.scene.name
        except ReferenceError:
            pass
        return self._scene_name

    def _write_report(self) -> None:
        self.totals = summarize(self.results, (time.perf_counter() - self._t0) * 1e3)
        self.report_path = write_report(self.out_dir, self.scene_name(), self.config, self.results, self.files,
                                        self.totals, len(self.frames), self._stopped, started_at=self._started_at)
        self._reported = len(self.results)


def _scene_settings(scene) -> dict | None:
    """The scene's KD Preview settings (RenderConfig.as_dict), None without the add-on's properties."""
    settings = getattr(scene, "kd_preview", None)
    return None if settings is None else make_config(settings).as_dict()


def stop_reason(error: BaseException) -> str:
    """report.json's words for what ended a sequence early."""
    if isinstance(error, (Cancelled, KeyboardInterrupt)):
        return "cancelled"
    return str(error) or type(error).__name__


def summarize(results: list[FrameResult], wall_ms: float) -> dict:
    """Sums over the frames, the throughput, and the mean time of the frames after the first
    (the first includes Numba's compile or cache load when it ran in a fresh process)."""
    out = {key: sum(getattr(r, key) for r in results) for key in TOTAL_KEYS}
    out["frames"] = len(results)
    out["images_reused"] = sum(bool(r.image_reused) for r in results)
    out["wall_ms"] = wall_ms
    out["mrays_per_s"] = out["rays"] / (out["trace_ms"] * 1e3) if out["trace_ms"] else 0.0
    warm = results[1:] or results
    out["mean_total_ms_after_first"] = sum(r.total_ms for r in warm) / len(warm)
    return out


def write_report(out_dir: Path, scene_name: str, config: RenderConfig, results: list[FrameResult],
                 files: list[Path], totals: dict, frames_requested: int, stopped: dict | None = None, *,
                 started_at: float | None = None, extra: dict | None = None) -> Path:
    """Write `report.json` (the run: input file, versions, threads, CPU, start; the settings; one row
    per frame; totals) and return its path. `complete` is False when fewer frames than requested were
    written (a cancelled or failed sequence, or one still running); `stopped` ({"frame", "reason"}),
    when given, says where and why it ended; `started_at`: the run's start, time.time() (default: now);
    `extra`: more top-level sections (a cluster run's "farm": workers, chunks, retries)."""
    first = results[0]
    report = {
        "scene": scene_name,
        "complete": len(results) == frames_requested,
        **({"stopped": stopped} if stopped is not None else {}),
        "frames_requested": frames_requested,
        "resolution": [first.width, first.height],
        "run": run_record(time.time() if started_at is None else started_at, config.settings.threads),
        "settings": config.report_settings(),
        "timings": TIMINGS_NOTE,
        "frames": [dict(r.summary(), file=p.name) for r, p in zip(results, files)],
        "totals": totals,
        **(extra or {}),
    }
    path = Path(out_dir) / REPORT_NAME
    partial = output.partial_path(path)  # renamed over the report: never half a file
    try:
        partial.write_text(json.dumps(report, indent=2), encoding="utf-8")
        output.replace_file(partial, path)
    except OSError as error:
        raise PreviewError(f"could not write {path}: {error}") from None
    finally:
        output.remove_partial(partial)
    return path
