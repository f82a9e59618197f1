"""`python -m kd_addon compile` (`blender -b --command kdpreview compile`): compile every kernel now.

Background renders (the command line, `blender -b`, farm workers) start no second warm-up stage, so
until it is cached (by this command, or for the installed extension by a Blender session with its UI)
they trace camera rays singly and keep their sampling batches under 8 samples (kernel_warmup.py). This
command runs both stages and waits for them: a farm node's set-up, or a long batch job's first step.
"""

from __future__ import annotations

import sys

from . import corelib, kernel_warmup

COMMAND_ID = "kdpreview"  # Blender's command-line command: blender -b --command kdpreview ...


def uncompiled_note(prog: str) -> str | None:
    """What a background run (the command line, `blender -b`, a script on the bpy module) says when the
    cache lacks the second stage, which such runs never start: its images are the same, only slower, until
    this module's command has run, named as `prog` runs it (COMMAND_ID: Blender's command line; else the
    program, e.g. "python -m kd_addon"); None once it is cached."""
    if kernel_warmup.second_stage_cached():
        return None
    command = f"blender -b --command {COMMAND_ID}" if prog == COMMAND_ID else prog
    return (f"camera rays go one by one and samples in small batches (the same images, slower) until `{command} "
            "compile` has compiled every kernel once")


def run(prog: str, interrupted) -> int:
    """Compile both stages into this installation's cache; the exit code (0, 1 failed, 130 stopped)."""
    print(f"KD Preview: compiling every kernel into {corelib.numba_cache_dir()} (a few minutes on 2 idle cores; "
          "what is cached already only loads)", flush=True)
    try:
        status = kernel_warmup.compile_both_stages(cancel=interrupted.is_set)
    except KeyboardInterrupt:
        status = kernel_warmup.WarmupStatus(kernel_warmup.NOT_STARTED)
    if status.state == kernel_warmup.READY:
        print(f"KD Preview: every kernel compiled and cached ({status.elapsed:.0f} s): renders load them from now on")
        return 0
    if status.state == kernel_warmup.FAILED:
        print(f"{prog}: error: the kernels' compile failed: {status.message}", file=sys.stderr)
        return 1
    from .cli import stopped_message  # cli imports this module

    print(stopped_message(prog, 0, interrupted, kept="the kernels compiled so far are kept"), file=sys.stderr)
    return 130
