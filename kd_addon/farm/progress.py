"""The live line of a cluster run: frames done / total, frames per second and the time left, redrawn in
place on a terminal; nothing when the output is not one (CI logs, pipes)."""

from __future__ import annotations

import sys
import time

CLEAR_LINE = "\r\033[K"


class ProgressLine:
    def __init__(self, total: int, stream=None, clock=time.perf_counter):
        self.total, self.stream, self.clock = total, stream or sys.stderr, clock
        self.live = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = clock()
        self.done = 0
        self._shown = False

    def text(self) -> str:
        elapsed = self.clock() - self.t0
        fps = self.done / elapsed if elapsed > 0 else 0.0
        eta = f"ETA {format_seconds((self.total - self.done) / fps)}" if fps > 0 else "ETA --:--"
        return f"{self.done}/{self.total} frames, {fps:.2f} fps, {eta}"

    def update(self, done: int) -> None:
        self.done = done
        if self.live:
            self.stream.write(CLEAR_LINE + self.text())
            self.stream.flush()
            self._shown = True

    def clear(self) -> None:
        """Take the line away, so another line can be printed in its place (update() draws it again)."""
        if self._shown:
            self.stream.write(CLEAR_LINE)
            self.stream.flush()
            self._shown = False


def format_seconds(seconds: float) -> str:
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60:02d}:{rest % 60:02d}"
