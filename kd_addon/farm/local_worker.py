"""Preloaded (as a file, not through the package) into each worker process --local-workers starts.

A terminal's Ctrl-C goes to the whole process group: the client cancels the run, writes its report and
shuts the cluster down, while the workers, left to Python's handler, each printed a KeyboardInterrupt
traceback. They ignore SIGINT instead; the client ends them.
"""

import signal


def dask_setup(worker):
    signal.signal(signal.SIGINT, signal.SIG_IGN)
