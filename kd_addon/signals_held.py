"""Ctrl-C and SIGTERM held back while a frame's file is put in place and recorded.

The command line's first interrupt raises KeyboardInterrupt at once (cli.interrupt_flag), wherever the
main thread is. Landing between a frame's rename into place and the line that records it, it left a
frame on disk that report.json did not list. Inside `signals_held()` their Python handlers are swapped
for one that only notes the signal; after the block the handlers are put back and the first noted
signal is raised again, so the interrupt lands before the file is in place or after it is recorded.
"""
import signal
import threading
from contextlib import contextmanager

HELD = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def signals_held():
    """Run the block with SIGINT and SIGTERM noted, not handled, then handle the first noted one as it
    would have been. Outside the main thread (where Python runs no handler), and for a handler that is
    not Python's (Blender's own SIGINT handler, in C), nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted, previous = [], {}
    try:  # every handler swapped is put back, even if a signal comes while they are swapped
        for signum in HELD:
            handler = signal.getsignal(signum)
            if callable(handler):
                previous[signum] = handler
                signal.signal(signum, lambda number, frame: noted.append(number))
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if noted:
            signal.raise_signal(noted[0])
