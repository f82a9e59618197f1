"""Getting a Dask client: connected to a running scheduler (--dask) or to a LocalCluster started for the
run (--local-workers), with errors that name the problem instead of a traceback or a hang."""

from __future__ import annotations

import logging
import os
import sys
from contextlib import contextmanager
from pathlib import Path

from ..errors import PreviewError

INSTALL_HINT = 'pip install -e ".[farm]"'
LOCAL_WORKER_SETUP = Path(__file__).with_name("local_worker.py")


def import_distributed():
    """The distributed package, or PreviewError saying how to install it."""
    try:
        import distributed
    except ImportError:
        raise PreviewError(f"--dask and --local-workers need Dask's distributed scheduler, which this Python "
                           f"({sys.executable}) does not have: {INSTALL_HINT} in the KD Preview clone "
                           f"(or pip install \"dask[distributed]\")") from None
    return distributed


def cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def local_worker_threads(workers: int) -> int:
    """Kernel threads a local worker gets, so that workers x threads fits the cores."""
    return max(1, cores() // workers)


@contextmanager
def dask_client(address: str | None, local_workers: int | None, connect_timeout: float):
    """A distributed.Client for the run, closed (and a local cluster shut down) afterwards."""
    distributed = import_distributed()
    # The run reports what goes wrong itself (a lost scheduler, a failed chunk): the client's own log
    # printed the same as tracebacks, again at every reconnection attempt.
    for name in ["distributed", *logging.root.manager.loggerDict]:  # Dask's config gives some their own level
        if name.split(".")[0] == "distributed":
            logging.getLogger(name).setLevel(logging.CRITICAL)
    if address is not None:
        client = _connect(distributed, address, connect_timeout)
        try:
            yield client
        finally:
            client.close(timeout=connect_timeout)
        return
    threads = local_worker_threads(local_workers)
    # One task at a time a process (bpy holds one open file); its kernels use `threads` threads (Numba's
    # pool is sized by NUMBA_NUM_THREADS when the worker process starts).
    cluster = distributed.LocalCluster(n_workers=local_workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=logging.ERROR,
                                       env={"NUMBA_NUM_THREADS": str(threads)}, preload=[str(LOCAL_WORKER_SETUP)])
    try:
        client = distributed.Client(cluster, timeout=connect_timeout)
        try:
            yield client
        finally:
            client.close(timeout=connect_timeout)
    finally:
        cluster.close(timeout=connect_timeout)


def wait_for_a_worker(client, address: str | None, timeout: float) -> None:
    """Return once the scheduler has a worker; a PreviewError after `timeout` seconds without one (the
    chunks would wait for one silently, which looks like a hung run)."""
    if address is None or client.scheduler_info()["workers"]:
        return
    print(f"KD Preview: no worker has joined the Dask scheduler at {address} yet; waiting up to {timeout:g} s "
          "(--connect-timeout)", flush=True)
    try:
        client.wait_for_workers(1, timeout=timeout)
    except TimeoutError:  # Dask's WorkerStartTimeoutError is one
        raise PreviewError(f"no worker joined the Dask scheduler at {address} within {timeout:g} s: start workers "
                           f"(dask worker {address}) or give them longer with --connect-timeout") from None
    except OSError as error:  # the scheduler went away meanwhile (distributed's CommClosedError is one)
        raise PreviewError(f"lost the Dask scheduler ({address}): {str(error) or type(error).__name__}") from None


def _connect(distributed, address: str, timeout: float):
    _check_address(address)
    try:
        return distributed.Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as error:
        raise PreviewError(f"cannot reach the Dask scheduler at {address} within {timeout:g} s ({error}); "
                           "is it running (dask scheduler) and is the address right?") from None
    except ValueError as error:  # an address Dask cannot parse
        raise PreviewError(f"bad Dask scheduler address {address!r}: {error}") from None


def _check_address(address: str) -> None:
    """Refuse an address Dask cannot parse before a Client is made: a Client that fails on it in its
    constructor is half made, and its finaliser then waits for a connection and prints a traceback."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, location = parse_address(address)
        get_backend(scheme)  # an unknown scheme
        if scheme in ("tcp", "tls"):
            parse_host_port(location)  # a missing or bad port
    except ValueError as error:
        raise PreviewError(f"bad Dask scheduler address {address!r}: {error}") from None
