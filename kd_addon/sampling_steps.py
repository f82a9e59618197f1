"""How many samples a FrameJob's next sampling step adds: batches growing toward a step time.

One sample first, then as many as the last step's rate fits in the step time, at most STEP_GROWTH times
its samples, and never so many that the sampling kernel's packed version would compile (core
PreviewRender.batch_without_compile: it waits until the warm-up's packed stage cached it,
kernel_warmup.py). Batches do not change the image; fewer kernel calls are faster, and batches of 8 or
more take the sample packets (docs/choices.md#the-add-on-steps-in-growing-batches).
"""

from __future__ import annotations

STEP_SECONDS = 1.0  # what a step's batch grows toward: a cancelled run's step runs on (holding the kernel
# lock the next run waits for), so the viewport asks for shorter ones (engine_viewport.py)
STEP_GROWTH = 16  # a batch at most this many times the last one's samples (a rate measured on few samples)


def next_batch(renderer, last_step: tuple[int, float] | None, step_seconds: float) -> int:
    """The next step's samples for `renderer` (a core.PreviewRender), given the last step's (samples,
    milliseconds), or None before the first step."""
    if last_step is None:
        return 1
    samples, ms = last_step
    left = renderer.target_samples - renderer.samples_done
    fit = int(step_seconds * 1e3 * samples / max(ms, 1e-3))
    return renderer.batch_without_compile(max(1, min(left, STEP_GROWTH * samples, fit)))
