"""Command line: one parser and one run function behind both entry points.

    blender -b scene.blend --command kdpreview render --frames 1-24 --out DIR [options]
    python -m kd_addon render [scene.blend] --frames 1-24 --out DIR [options]

The scene is the .blend given, else the file Blender has open, else (or with --demo) the built-in
demo. Settings are the scene's own KD Preview settings, each overridden by the option of the same
name. Writes DIR/frame_0001.png... and DIR/report.json. Exit codes: 0 done, 1 a problem with the
scene, files or settings, 2 bad usage, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM); the frames
written are kept and report.json says an interrupted run is incomplete. With --dask ADDRESS or
--local-workers N the frames render on a Dask cluster instead (farm/, docs/farm.md); this module only
parses those options and hands the run over. `compile` (compile_command.py) compiles every kernel and
waits: 0 done, 1 failed, 130/143 stopped.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from types import SimpleNamespace

import bpy

from . import background, compile_command, corelib, demo_scene, properties
from .compile_command import COMMAND_ID
from .config import DEFAULTS, OUTPUT_FORMATS, SETTING_NAMES, SettingsError, make_config, read_setting
from .errors import Cancelled, PreviewError
from .keyed_settings import keyed_settings_note, stored_setting_values
from .operators import depsgraph_source
from .pipeline import claim, release, run_job
from .render_visibility import render_view_layer
from .sequence import SequenceJob, check_folder_path, parse_frames

FORMAT_ALIASES = {"PNG": "PNG", "EXR": "OPEN_EXR", "OPEN_EXR": "OPEN_EXR"}
TABLE = ("{:>6} {:>10} {:>8} {:>11} {:>10} {:>10} {:>10} {:>12} {:>8} {:>10} {:>12} {:>10} {:>10} {:>8} {:>7} {:>6}"
         " {:>8} {:>9}")
HEADER = TABLE.format("frame", "triangles", "objects", "extract ms", "build ms", "trace ms", "total ms", "rays",
                      "Mrays/s", "rays saved", "rays reused", "px kept", "nodes", "rebuilt", "reused", "image",
                      "top ms", "top refs")
_handle = None  # register_cli_command's handle


class UsageError(Exception):
    """Bad command-line usage (argparse's complaint, raised instead of exiting the process)."""


class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of calling sys.exit, which would end Blender itself."""

    def error(self, message):
        raise UsageError(f"{self.format_usage()}{self.prog}: error: {message}")


def _output_format(text: str) -> str:
    try:
        return FORMAT_ALIASES[text.upper()]
    except KeyError:
        raise argparse.ArgumentTypeError(f"use one of {', '.join(OUTPUT_FORMATS)} (or EXR)") from None


def build_parser(prog: str = COMMAND_ID) -> argparse.ArgumentParser:
    """The one parser. Setting options default to SUPPRESS so absent ones take the scene's saved settings
    (saved_settings_with_overrides), which default to config.DEFAULTS."""
    parser = _Parser(prog=prog, description="KD Preview: ray-traced AO / shadow previews from the command line")
    parser.set_defaults(prog=prog)  # messages name the program as it was run
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    render = commands.add_parser("render", help="render frames to images and report.json",
                                 epilog="Options not given take the scene's own KD Preview settings (saved in the "
                                        ".blend from the panel), else the defaults shown.")
    render.add_argument("blend", nargs="?", help=".blend file to render (default: the open file, else the demo)")
    render.add_argument("--out", required=True,
                        help='output folder (created if missing; "//" starts it beside the .blend, as in Blender)')
    render.add_argument("--frames", help="N, A-B, A-B:STEP or a comma list, negative frames too (-3--1) "
                                         "(default: the scene's frame range)")
    render.add_argument("--demo", action="store_true", help="render the built-in animated demo scene")
    render.add_argument("--scene", help="the scene to render, by name (default: the file's current scene)")
    s = argparse.SUPPRESS
    render.add_argument("--mode", type=str.lower, default=s,  # any case, as --format
                        help=f"ao, shadow, ao+shadow or auto (ao+shadow when a light emits, else ao; "
                             f"default {DEFAULTS.mode})")
    render.add_argument("--samples", type=int, default=s, help=f"samples per pixel (default {DEFAULTS.samples})")
    render.add_argument("--ao-distance", dest="ao_distance", type=float, default=s,
                        help=f"AO ray length (default {DEFAULTS.ao_distance})")
    render.add_argument("--resolution", dest="resolution_percentage", type=int, default=s,
                        help=f"percent of the scene's base render resolution, resolution_x/y (the scene's own %% "
                             f"is not applied; default {DEFAULTS.resolution_percentage})")
    render.add_argument("--builder", type=str.lower, default=s,  # any case, as --mode
                        help=f"binned, exact or median (default {DEFAULTS.builder})")
    render.add_argument("--leaf-size", dest="leaf_size", type=int, default=s,
                        help=f"(default {DEFAULTS.leaf_size})")
    render.add_argument("--max-depth", dest="max_depth", type=int, default=s, help="0 = automatic (default)")
    render.add_argument("--bins", type=int, default=s, help=f"(default {DEFAULTS.bins})")
    render.add_argument("--threads", type=int, default=s, help="0 = all cores (default)")
    render.add_argument("--error-target", dest="error_target", type=float, default=s, help="0 = off (default)")
    on_off = argparse.BooleanOptionalAction  # --no-X turns off a setting the .blend saved on
    render.add_argument("--denoise", action=on_off, default=s,
                        help="filter each finished frame with the edge-avoiding à-trous denoiser (default off)")
    render.add_argument("--seed", type=int, default=s, help=f"(default {DEFAULTS.seed})")
    render.add_argument("--memory-limit", dest="memory_limit_mb", type=int, default=s,
                        help="MiB; refuse a frame estimated to need more (default 0 = no limit)")
    render.add_argument("--format", dest="output_format", type=_output_format, default=s,
                        help="PNG (default) or EXR")
    render.add_argument("--lazy", action=on_off, default=s,
                        help="build the kd-tree on demand, only where rays go (the same image; in the shadow "
                             "modes up to the last float32 bit, as one merged tree rounds some shadow rays "
                             "differently)")
    render.add_argument("--rebuild-all", dest="rebuild_all", action=on_off, default=s,
                        help="rebuild every kd-tree and re-trace every frame (no reuse of unchanged objects' "
                             "trees or of unchanged images)")
    _add_farm_options(render)
    commands.add_parser("compile", help="compile every kernel now (both warm-up stages), e.g. on a farm node, so "
                                        "background renders take packets from their first frame")
    return parser


# The cluster options' defaults: the parser's, and what _check_farm_options compares against.
FARM_DEFAULTS = {"chunk_size": 0, "retries": 2, "connect_timeout": 10.0, "ship_blend": False}


def _add_farm_options(render) -> None:
    """Rendering on a Dask cluster (kd_addon/farm/, docs/farm.md); without --dask or --local-workers the
    frames render in this process."""
    farm = render.add_argument_group("cluster (needs pip install -e \".[farm]\"; docs/farm.md)")
    where = farm.add_mutually_exclusive_group()
    where.add_argument("--dask", metavar="ADDRESS", help="render on the Dask cluster whose scheduler is at "
                                                         "ADDRESS, e.g. tcp://HOST:8786")
    where.add_argument("--local-workers", dest="local_workers", type=int, metavar="N",
                       help="start a Dask cluster of N worker processes on this machine for the run")
    farm.add_argument("--chunk-size", dest="chunk_size", type=int, default=FARM_DEFAULTS["chunk_size"],
                      metavar="FRAMES",
                      help="frames a task renders in a row, reusing trees and pixels (default 0 = automatic: "
                           "about three chunks a worker, 2 to 24 frames each)")
    farm.add_argument("--ship-blend", dest="ship_blend", action="store_true",
                      help="send the .blend's bytes to the workers (for workers without a shared filesystem)")
    farm.add_argument("--connect-timeout", dest="connect_timeout", type=float, default=FARM_DEFAULTS["connect_timeout"],
                      metavar="SECONDS",
                      help="give up on an unreachable scheduler after this long, and on one without workers "
                           "after this long again (default 10)")
    farm.add_argument("--retries", type=int, default=FARM_DEFAULTS["retries"],
                      help="times a chunk whose task failed is rerun (default 2; a chunk whose worker died is "
                           "rerun by the scheduler in any case)")


def load_scene(args) -> bpy.types.Scene:
    """Open the requested .blend, or keep the open file, or build the demo; return the scene."""
    if args.blend and args.demo:
        raise PreviewError(f"give a .blend file or --demo, not both (got {args.blend} and --demo)")
    if args.blend:
        path = Path(args.blend)
        if path.is_dir():
            raise PreviewError(f"{path} is a folder, not a .blend file")
        if not path.is_file():
            raise PreviewError(f"no such .blend file: {path}")
        _check_blend_header(path)
        try:
            bpy.ops.wm.open_mainfile(filepath=str(path.resolve()), load_ui=False)
        except RuntimeError as error:
            raise PreviewError(f"could not open {path}: {error}") from None
    elif args.demo or not bpy.data.filepath:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        demo_scene.build_demo_scene(bpy.context.scene)
    return bpy.context.scene


BLEND_MAGICS = (b"BLENDER", b"\x1f\x8b", b"\x28\xb5\x2f\xfd")  # plain, gzip and zstd-compressed .blend


def _check_blend_header(path: Path) -> None:
    """Name a file that is no .blend at all before Blender reads it: Blender's own refusal ("File format
    is not supported") goes to stdout, ahead of and apart from our message on stderr."""
    try:
        with path.open("rb") as file:
            head = file.read(len(BLEND_MAGICS[0]))
    except OSError as error:
        raise PreviewError(f"could not read {path}: {error.strerror or error}") from None
    if not head.startswith(BLEND_MAGICS):
        raise PreviewError(f"{path} is not a .blend file (it does not begin with Blender's file header)")


def pick_scene(current, name: str | None):
    """(scene, view layer name) to render: the file's current scene and view layer, or the scene named
    `name` through the view layer a render of it takes (render_visibility.render_view_layer)."""
    if name is None:
        return current, bpy.context.view_layer.name
    scene = bpy.data.scenes.get(name)
    if scene is None:
        names = ", ".join(f"'{s.name}'" for s in bpy.data.scenes)
        raise PreviewError(f"no scene named '{name}' in the file; its scenes: {names}")
    return scene, (bpy.context.view_layer if scene == current else render_view_layer(scene)).name


def saved_settings_with_overrides(scene, args) -> tuple[SimpleNamespace, dict]:
    """The scene's own KD Preview settings (saved in the .blend by the panel), each replaced by the
    command-line option of the same name where one was given: so `blender -b scene.blend --command
    kdpreview render` renders what the file's Render Animation would; and the values as stored
    (keyed_settings.stored_setting_values). Under `python -m kd_addon` the add-on is not registered, so
    its settings group is registered for the reading (Blender keeps a group's saved values as ID
    properties until a class claims them) and then removed again."""
    registered = hasattr(bpy.types.Scene, "kd_preview")
    if not registered:
        properties.register()
    try:
        saved = scene.kd_preview
        return SimpleNamespace(**{name: getattr(args, name) if hasattr(args, name) else read_setting(saved, name)
                                  for name in SETTING_NAMES}), stored_setting_values(saved)
    finally:
        if not registered:
            properties.unregister()


def _top_level(stats: dict) -> tuple[str, str]:
    """The top level's build time and references per instance, "-" without a top level over instances."""
    if not stats.get("instances"):
        return "-", "-"
    return f"{stats.get('top_build_ms', 0.0):.1f}", f"{stats.get('top_references', 0) / stats['instances']:.2f}"


def _print_row(prog, result, path) -> None:
    mark = "*" if result.first_run else ""
    print(TABLE.format(f"{mark}{result.frame}", f"{result.triangles:,}", result.objects, f"{result.extract_ms:.1f}",
                       f"{result.build_ms:.1f}", f"{result.trace_ms:.1f}", f"{result.total_ms:.1f}",
                       f"{result.rays:,}", f"{result.mrays_per_s:.2f}", f"{result.rays_saved:,}",
                       f"{result.rays_reused:,}", f"{result.pixels_reused:,}",
                       f"{result.tree_stats.get('nodes', 0):,}", result.objects_rebuilt, result.objects_reused,
                       "reused" if result.image_reused else "new", *_top_level(result.tree_stats)), flush=True)
    if result.compile_ms or result.load_ms:
        compiled = f"compiled in {result.compile_ms / 1e3:.1f} s (first use), " if result.compile_ms else ""
        loaded_in_frame = f", but frame {result.frame} (*) loaded more itself" if result.first_run else ""
        print(f"kernels: {compiled}loaded in {result.load_ms / 1e3:.1f} s; not in frame {result.frame}'s times or "
              f"Mrays/s{loaded_in_frame}", flush=True)
    for warning in result.warnings:  # e.g. an object left out for non-finite vertices
        print(f"{prog}: warning: frame {result.frame}: {warning}", file=sys.stderr, flush=True)


@contextmanager
def interrupt_flag():
    """An Event that Ctrl-C (SIGINT) or SIGTERM sets, for the job loop to poll, while the first such
    signal also raises KeyboardInterrupt at once; `signum` says which one it was (the exit code). The
    flag survives Blender printing and clearing an exception raised in a handler or driver during
    frame_set. Later signals are ignored, so a second Ctrl-C cannot break the cleanup that writes the
    report. SIGTERM is taken over only where Python's default is in place.

    Inside Blender SIGINT's handler is Blender's own, in C (Python sees None), which only prints a
    message; Python cannot put it back, so there SIGINT is ignored after the run, and a Ctrl-C into
    Blender's teardown cannot turn exit 130 into a kill. Outside the main thread, and in Blender's
    UI, the flag is never set."""
    flag = threading.Event()
    flag.signum = signal.SIGINT

    def on_signal(signum, frame):
        if not flag.is_set():
            flag.signum = signum
            flag.set()
            raise KeyboardInterrupt

    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or (previous is None and not bpy.app.background):
        yield flag  # (Blender's UI keeps its own handler: it does not exit after this call)
        return
    take_sigterm = signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    signal.signal(signal.SIGINT, on_signal)
    if take_sigterm:
        signal.signal(signal.SIGTERM, on_signal)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN if previous is None else previous)
        if take_sigterm:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)


def run(args) -> int:
    """Render args.frames of the chosen scene into args.out (in this process, or on a Dask cluster with
    --dask / --local-workers), or compile the kernels (`compile`); return the exit code."""
    with interrupt_flag() as interrupted:
        if args.command == "compile":
            code = compile_command.run(args.prog, interrupted)
        elif getattr(args, "dask", None) is not None or getattr(args, "local_workers", None) is not None:
            from .farm import client  # only here: dask is an optional extra, never imported otherwise

            code = client.run(args, interrupted)
        else:
            code = _run(args, interrupted)
    return 128 + signal.SIGTERM if code == 130 and interrupted.signum == signal.SIGTERM else code


@dataclass
class Prepared:
    """A run's scene, settings and frames, resolved from the command line."""
    scene: object
    layer_name: str
    settings: SimpleNamespace  # the scene's saved settings with the options given
    config: object  # config.RenderConfig
    frames: list
    keyed_note: str = ""  # settings keyed to change over the frames, not followed (keyed_settings.py)


def prepare(args) -> Prepared:
    """Check the options, open the scene and resolve its settings and frames (shared by the in-process
    and the cluster paths)."""
    _check_options(args)  # bad options fail before a file is opened
    if not args.out.strip():
        raise PreviewError("--out is empty: give the folder to write the frames to")
    args.out = _beside_the_blend(args)
    check_folder_path(Path(os.path.abspath(args.out)))  # before the scene loads and the table starts
    scene, layer_name = pick_scene(load_scene(args), args.scene)
    settings, stored = saved_settings_with_overrides(scene, args)
    config = make_config(settings)
    frames = parse_frames(args.frames if args.frames is not None  # --frames "" is an error, not the default
                          else f"{scene.frame_start}-{scene.frame_end}:{max(1, scene.frame_step)}")
    _note_frames_outside(args.prog, scene, frames)
    keyed = keyed_settings_note(scene, frames, given=[n for n in SETTING_NAMES if hasattr(args, n)], stored=stored)
    return Prepared(scene, layer_name, settings, config, frames, keyed)


def _beside_the_blend(args) -> str:
    """--out with Blender's "//" (the .blend's folder) resolved against the .blend given, else the file
    Blender has open; the demo has no folder, so "//" there is an error, not the filesystem's root."""
    if not args.out.startswith("//"):
        return args.out
    blend = args.blend or (None if args.demo else bpy.data.filepath)
    if not blend:
        raise PreviewError(f"--out {args.out} is relative to the .blend file (Blender's //), but this run has none "
                           "(the demo): give a folder path")
    return os.path.join(os.path.dirname(os.path.realpath(blend)), args.out[2:])  # load_scene opens it resolved


def stopped_message(prog: str, written: int, interrupted, kept: str = "") -> str:
    """The line a run that Ctrl-C or SIGTERM stopped ends with; `interrupted`: interrupt_flag's Event;
    `kept`: what the run keeps, if not frames."""
    how = "terminated (SIGTERM)" if interrupted.signum == signal.SIGTERM else "interrupted"
    kept = kept or (f"the {written} frame(s) already written are kept" if written else "no frame was written")
    return f"{prog}: {how}; {kept}"


def _run(args, interrupted) -> int:
    """The in-process run; `interrupted`: interrupt_flag's Event, polled between steps."""
    cancelled = interrupted.is_set
    job = None
    try:
        prepared = prepare(args)
        scene, config, frames = prepared.scene, prepared.config, prepared.frames
        _note_threads_beyond(args.prog, int(prepared.settings.threads))  # a cluster's workers have their own
        job = SequenceJob(scene, config, frames, Path(args.out),
                          depsgraph_source(scene, scene.view_layers[prepared.layer_name]),
                          on_frame=partial(_print_row, args.prog), note=prepared.keyed_note)
        print(f"KD Preview: scene '{scene.name}', {len(frames)} frame(s), mode {config.settings.mode}, "
              f"{config.settings.samples} samples, {config.resolution_percentage}% resolution -> {args.out}")
        if not corelib.cache_is_warm():  # else a first run looks hung for minutes
            print("First run with these sources and this Python: compiling the kernels (first use) takes a minute or "
                  "two on 2 idle cores (longer on a busy machine) before frame 1; its time is printed apart from "
                  f"the frame's (kept in {corelib.numba_cache_dir()})", flush=True)
        note = compile_command.uncompiled_note(args.prog)
        if note:
            print(f"Note: {note}", flush=True)
        print(HEADER, flush=True)  # piped, it would wait for the first frame: minutes on a first run
        _run_claimed(job, cancelled)
    except PreviewError as error:
        print(f"{args.prog}: error: {error}", file=sys.stderr)
        return 1
    except (Cancelled, KeyboardInterrupt):
        print(stopped_message(args.prog, len(job.results) if job is not None else 0, interrupted), file=sys.stderr)
        return 130
    _print_totals(job, any(r.first_run for r in job.results))
    return 0


def _note_frames_outside(prog, scene, frames: list[int]) -> None:
    """Frames beyond the scene's range render as Blender would go to them; a note catches a typo."""
    outside = [f for f in frames if not scene.frame_start <= f <= scene.frame_end]
    if outside:
        print(f"{prog}: note: {len(outside)} of the frames ({outside[0]}"
              + (f" ... {outside[-1]}" if len(outside) > 1 else "")
              + f") are outside the frame range {scene.frame_start}-{scene.frame_end} of scene '{scene.name}'; "
              "rendering them anyway", file=sys.stderr, flush=True)


def _note_threads_beyond(prog, threads: int) -> None:
    """More threads than Numba was started with run as that many (report.json's run.threads); say so."""
    import numba  # core's dependency, imported by the render anyway

    available = int(numba.config.NUMBA_NUM_THREADS)
    if threads > available:
        print(f"{prog}: note: threads {threads} is more than Numba's {available} threads in this process; using "
              f"{available}", file=sys.stderr, flush=True)


# Options whose flag is not the setting's name with dashes (build_parser's dest=).
FLAG_OF_SETTING = {"resolution_percentage": "--resolution", "memory_limit_mb": "--memory-limit",
                   "output_format": "--format"}


def _check_options(args) -> None:
    """The command line's own values (absent ones take the defaults here), checked before a file is
    opened; an error names the flag typed, not only the setting behind it."""
    try:
        make_config(args)
    except SettingsError as error:
        if error.setting is None:
            raise
        flag = FLAG_OF_SETTING.get(error.setting, "--" + error.setting.replace("_", "-"))
        raise PreviewError(f"{flag}: {error}") from None
    _check_farm_options(args)
    if getattr(args, "frames", None) is not None:  # a typo must not cost the load of a large .blend
        parse_frames(args.frames)  # (prepare parses them again, with the scene's range as the default)


def _check_farm_options(args) -> None:
    """The cluster options' values, checked with or without a cluster (a bad one is never silently
    taken); given without --dask or --local-workers they change nothing, which a note on stderr says."""
    local_workers = getattr(args, "local_workers", None)
    given = {name: getattr(args, name, default) for name, default in FARM_DEFAULTS.items()}
    chunk_size, retries, timeout = given["chunk_size"], given["retries"], given["connect_timeout"]
    if local_workers is not None and local_workers < 1:
        raise PreviewError(f"--local-workers must be 1 or more, got {local_workers}")
    if chunk_size < 0:
        raise PreviewError(f"--chunk-size must be 1 or more (0: automatic), got {chunk_size}")
    if retries < 0:
        raise PreviewError(f"--retries must be 0 or more, got {retries}")
    if not 0.0 < timeout < float("inf"):
        raise PreviewError(f"--connect-timeout must be above 0 seconds, got {timeout:g}")
    if getattr(args, "dask", None) is None and local_workers is None:
        changed = ["--" + name.replace("_", "-") for name, value in given.items() if value != FARM_DEFAULTS[name]]
        if changed:
            prog = getattr(args, "prog", "kd_addon")
            verb = "applies" if len(changed) == 1 else "apply"
            print(f"{prog}: note: {', '.join(changed)} {verb} only with --dask or --local-workers; the frames render "
                  "in this process", file=sys.stderr, flush=True)


def _run_claimed(job, cancelled) -> None:
    claim(job)
    stopped_by = None
    try:
        run_job(job, cancelled)
    except BaseException as error:  # noqa: B036  (a cancel too: the report says where and why it stopped)
        stopped_by = error
        raise
    finally:
        release(job)
        job.close(stopped_by)


def _print_totals(job, starred: bool) -> None:
    """The run's totals; `starred`: some frame's row is marked "*" (so the legend is printed)."""
    t = job.totals
    print(f"total: {t['frames']} frames, {t['triangles']:,} triangles, extract {t['extract_ms']:.0f} ms, "
          f"build {t['build_ms']:.0f} ms, trace {t['trace_ms']:.0f} ms, {t['mrays_per_s']:.2f} Mrays/s; "
          + (f"mean frame after the first {t['mean_total_ms_after_first']:.0f} ms" if t['frames'] > 1 else
             f"frame {t['mean_total_ms_after_first']:.0f} ms")
          + ("  (* = includes loading kernels)" if starred else ""))
    print(f"reuse: {t['objects_rebuilt']} kd-trees built, {t['objects_reused']} kept, {t['images_reused']} of "
          f"{t['frames']} images reused" + (" (--rebuild-all)" if job.config.settings.rebuild_all else ""))
    print(f"report: {job.report_path}")


def execute(argv: list[str], prog: str = COMMAND_ID) -> int:
    """Parse argv (the words after the command id) and run; never raises SystemExit."""
    try:
        args = build_parser(prog).parse_args(_frames_joined(argv))
    except UsageError as error:
        print(error, file=sys.stderr)
        return 2
    except SystemExit as done:  # --help
        return int(done.code or 0)
    return run(args)


def _frames_joined(argv: list[str]) -> list[str]:
    """`--frames -2-1` as `--frames=-2-1`: argparse takes a value starting with "-" (Blender's negative
    frames) that is not a plain number for an option and refuses it. So for the abbreviations argparse
    takes (`--fr`, ..., `--frame`: `--f` is ambiguous with `--format`)."""
    joined, words = [], iter(argv)
    for word in words:
        value = next(words, None) if word.startswith("--fr") and "--frames".startswith(word) else None
        if value is not None and value[:1] == "-" and value[1:2].isdigit():
            joined.append(f"--frames={value}")
        else:
            joined += [word] if value is None else [word, value]
    return joined


def main(argv: list[str] | None = None) -> int:
    """`python -m kd_addon` entry point."""
    return execute(sys.argv[1:] if argv is None else argv, prog="python -m kd_addon")


def blender_command(argv: list[str]) -> int:
    """`blender -b [scene.blend] --command kdpreview ...`: execute, then end at once if a cancelled
    kernel call still runs (background.exit_now_if_abandoned)."""
    code = execute(argv)
    background.exit_now_if_abandoned(code)
    return code


def register():
    global _handle
    unregister()
    _handle = bpy.utils.register_cli_command(COMMAND_ID, blender_command)


def unregister():
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
