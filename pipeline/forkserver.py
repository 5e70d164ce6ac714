"""This process's forkserver (Python's `multiprocessing.forkserver`, one per process): whether one
runs, and stopping it.  Whoever starts one (a local cluster's `pipeline.fleet.fork_server`, the camera
detection pool) stops it when done, so that nothing else is later forked from a server it did not
prepare."""

from __future__ import annotations

import os
import signal


def running() -> bool:
    """A forkserver runs for this process (started by anyone)."""
    from multiprocessing import forkserver

    return getattr(forkserver._forkserver, "_forkserver_pid", None) is not None


def terminate() -> None:
    """Stop this process's forkserver, whoever started it (none: a no-op): SIGTERM (its default action:
    no interpreter teardown) and reap it.  Call only once no pool forks from it any more."""
    from multiprocessing import forkserver

    server = forkserver._forkserver  # the module's singleton (no public handle on it)
    pid = getattr(server, "_forkserver_pid", None)
    if pid is None:
        return
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        pass
    server._stop()  # closes our end of its liveness pipe and waits for it
