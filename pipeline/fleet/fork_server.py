"""The process a LocalCluster's workers are forked from (Python's forkserver), with distributed and
robocal's stage modules imported once and BLAS on one thread, so that no worker imports them again.

Its imports (≈ 1 s) are the longest part of a local cluster's start, so it is started as early as it
is known to be needed: by `robocal reprocess` before its own imports when OUT holds no results yet
(every recording then runs), else at the first recording that needs a run.  It is stopped by a
signal once the cluster is closed (or at exit): left to notice its parent's exit, it would tear down
an interpreter full of modules while still holding the caller's stdout and stderr (≈ 0.2–0.3 s in
which a pipe reader waits)."""

from __future__ import annotations

import atexit
import os
import threading
from pathlib import Path

from pipeline.forkserver import terminate

SINGLE_THREADED = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
# What a task imports on its first call beyond the stage and system modules: robocal's lazy imports and
# pyarrow's (a Parquet read imports pyarrow.dataset; converting Python objects, dateutil).  Left to the
# first task, they made it ≈ 0.1 s longer than the next ones on every worker.
TASK_IMPORTS = ("pipeline.stages.reprocess", "pipeline.stages.results", "pipeline.accuracy.prior",
                "pipeline.models.jig", "pipeline.models.dh_export", "pipeline.ros2.kind",
                "pyarrow.dataset", "dateutil.relativedelta", "pipeline.physics.compliance",
                "pipeline.physics.gravity", "pipeline.physics.summary", "pipeline.validate.plausibility",
                "pipeline.validate.outlier_fit",
                "threadpoolctl", "pipeline.identify.folds", "pipeline.identify.physics_choice",
                "pipeline.physics.encoder", "pipeline.identify.route", "pipeline.dynamics.stage")
_started = False  # this module started the forkserver running now
_lock = threading.Lock()


def warm_modules(stages: list[str] | None = None) -> list[str]:
    """The modules a task imports: the row's own, each of `stages`' (default: all) and every system's."""
    import pkgutil

    import pipeline.systems as systems
    from pipeline.stages.registry import STAGES

    mods = [s.module for s in STAGES if stages is None or s.name in stages]
    return ["pipeline.fleet.rows", "pipeline.stages.runner", *mods, *TASK_IMPORTS,
            *(f"pipeline.systems.{m.name}" for m in pkgutil.iter_modules(systems.__path__))]


def warm_worker(stages: list[str] | None = None) -> int:
    """Import the modules of `stages` (default: every stage) and of every system once, at a worker's
    start, so that no task pays the interpreter's imports (a spawned Dask worker is a fresh process;
    one forked from the fork server has them already).  Returns the number of modules imported."""
    import importlib

    n = 0
    for name in warm_modules(stages):
        try:
            importlib.import_module(name)
            n += 1
        except ImportError:  # an optional stage's module may be absent
            pass
    return n


def start(stages: list[str] | None = None) -> bool:
    """Start the fork server in the background, preloading distributed and the modules of `stages`
    (default: all).  Returns at once: True if this call started it (its caller stops it, `stop`);
    False if it runs already (its imports are those of the first call) or another part of the process
    started a forkserver of its own (left alone)."""
    import multiprocessing
    from multiprocessing import forkserver

    global _started
    with _lock:  # (and os.environ is shared: never set from two threads at once)
        if _started or forkserver._forkserver._forkserver_pid is not None:
            return False
        multiprocessing.get_context("forkserver").set_forkserver_preload(["distributed", *warm_modules(stages)])
        saved = {k: os.environ.get(k) for k in SINGLE_THREADED}
        os.environ.update(SINGLE_THREADED)  # BLAS reads them when numpy loads: in the server, before the fork
        try:
            forkserver.ensure_running()
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        _started = True
        return True


def start_if_fresh(out: Path, stages: list[str] | None = None) -> bool:
    """Start the fork server now if `out` holds no results yet (every recording will run); True if this
    call started it."""
    results = Path(out) / "results"
    if results.is_dir() and any(results.glob("part-*.parquet")):
        return False
    return start(stages)


def stop() -> None:
    """Stop the fork server this process started (none: a no-op), once no worker is forked from it any
    more: SIGTERM (its default action: no interpreter teardown) and reap it."""
    global _started
    with _lock:
        if not _started:
            return
        _started = False
        terminate()  # pipeline.forkserver


# At exit, after distributed's own handlers (registered later, when it is imported: atexit runs them
# last-in first-out) have closed any cluster still open.
atexit.register(stop)
