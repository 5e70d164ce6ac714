"""Reprocess an archive: discover, skip what is done (input hash + version), run the rest on Dask
(a LocalCluster by default, or an existing scheduler), a process pool or in-process, and stream
each row to the results dataset as it completes."""

from __future__ import annotations

import json
import logging
import os
import threading
import uuid
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed as pool_completed
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from pipeline import __version__
from pipeline.errors import RobocalError
from pipeline.fleet import fork_server
from pipeline.fleet.dataset import ResultsWriter, done_keys
from pipeline.fleet.discover import DEFAULT_PATTERNS, Found, discover
from pipeline.fleet.fork_server import SINGLE_THREADED, warm_worker
from pipeline.fleet.rows import code_version, gate, lost_row, reprocess_one

ENGINES = ("dask", "processes", "serial")
# Dask's diagnostics that cost CPU a reprocess does not use: the workers' statistical profiler (a
# stack sample every 10 ms) and the GIL monitor; on a busy box they take CPU from the tasks.  Also
# glibc's default malloc: Dask sets MALLOC_TRIM_THRESHOLD_=65536 in workers, which turns off glibc's
# dynamic mmap threshold, so every numpy temporary over 128 KiB is a fresh mmap + page faults
# (measured: tasks 17 % slower than in a process pool).
QUIET = {"distributed.worker.profile.enabled": False, "distributed.admin.system-monitor.gil.enabled": False,
         "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
QUIET_ENV = {"DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
             "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__GIL__ENABLED": "False"}
# Dask's periodic housekeeping, relaxed for a batch of CPU-bound tasks.  With the defaults (a 20 ms
# event-loop tick, system and memory monitors every 0.5 and 0.1 s, work stealing every 0.1 s) an idle
# LocalCluster burns ≈ 19 ms of CPU per second in each worker and ≈ 28 ms/s in the client process
# (scheduler, nannies): ≈ 3 % of a 2-core box, taken from the tasks.  Relaxed: ≈ 3 and 5 ms/s.  The
# tick only measures event-loop latency; stealing has nothing to balance when the scheduler queues
# the tasks and hands each worker ⌈1.1 × threads⌉.
RELAXED = {"distributed.admin.tick.interval": "1s", "distributed.admin.system-monitor.interval": "1s",
           "distributed.worker.memory.monitor-interval": "1s", "distributed.scheduler.work-stealing": False}
# LocalCluster's workers are forked from a fork server that has imported distributed and robocal's
# stages once (`fork_server`, started in the background while the archive is hashed), not spawned as
# fresh interpreters that each import them: up + close 1.2 s instead of 2.4–3.0 s (2 workers, load 5,
# `bench_reprocess.py --startup`), and the stages' imports overlap the hashing.
FORK_SERVER = {"distributed.worker.multiprocessing-method": "forkserver"}


@dataclass
class Task:
    found: Found
    sha256: str | None  # None: never run before, the task hashes what it reads
    nbytes: int | None
    run_dir: Path

    def lost(self, config: str, reason: str) -> dict:
        """The row of this task when its worker died (after Dask's retries)."""
        from pipeline.stages.artefacts import sha256_file

        sha, nbytes = self.sha256, self.nbytes
        if sha is None:
            try:
                sha, nbytes = sha256_file(self.found.path), self.found.path.stat().st_size
            except OSError:
                sha, nbytes = "", 0
        return lost_row(str(self.found.path), self.found.rel, sha, nbytes, str(self.run_dir), config, reason)

    def args(self, stages: list[str] | None, robot_id: str | None, config: str) -> tuple:
        return (str(self.found.path.resolve()), self.found.rel, self.sha256, self.nbytes, str(self.run_dir),
                stages, robot_id, config)


@dataclass
class Outcome:
    rows: list[dict] = field(default_factory=list)      # rows computed by this run
    kept: list[dict] = field(default_factory=list)      # rows of a previous run, skipped (resume)
    skipped_paths: list[str] = field(default_factory=list)  # symlinks out of the archive, loops

    @property
    def all_rows(self) -> list[dict]:
        return sorted(self.rows + self.kept, key=lambda r: r["recording"])


def config_of(stages: list[str] | None, robot_id: str | None) -> str:
    return json.dumps({"stages": stages or "all", "robot_id": robot_id}, sort_keys=True)


def plan(archive: Path, out: Path, patterns=DEFAULT_PATTERNS, stages=None, robot_id=None,
         resume: bool = True, on_first_task: Callable[[], None] | None = None
         ) -> tuple[list[Task], list[dict], list[str]]:
    """(tasks to run, rows kept from a previous run, paths skipped by discovery); `on_first_task` is
    called once, as soon as the first recording that needs a run is known.

    Only a recording with a row in OUT that this version and these options could keep is hashed here
    (its input hash decides whether the row still stands); any other is a task at once and its task
    hashes the file before running it, so an archive of thousands is not read through serially
    before the first task starts."""
    from pipeline.stages.artefacts import sha256_file

    found, skipped = discover(archive, patterns)
    done = done_keys(out) if resume else {}
    config, code = config_of(stages, robot_id), code_version()
    done_rels = {key[0] for key in done if key[2:] == (__version__, code, config)}
    tasks, kept = [], []
    for f in found:
        run_dir = Path(out) / "runs" / f.run_name
        if f.rel not in done_rels:
            if on_first_task is not None and not tasks:
                on_first_task()
            tasks.append(Task(f, None, None, run_dir))
            continue
        try:
            sha, nbytes = sha256_file(f.path), f.path.stat().st_size
        except OSError as e:  # unreadable: its row says so, the others run
            row = lost_row(str(f.path), f.rel, "", 0, str(run_dir), config, f"{f.path}: cannot be read ({e.strerror})")
            kept.append(row | {"status": "error", "_regated": True})
            continue
        prev = done.get((f.rel, sha, __version__, code, config))
        if prev is not None:
            before = (prev["expected"], list(prev["regressions"] or []), prev["ok"])
            gate(prev, f.path)  # the expected figures may have changed since
            prev["_regated"] = before != (prev["expected"], prev["regressions"], prev["ok"])
            kept.append(prev)
        else:
            if on_first_task is not None and not tasks:
                on_first_task()
            tasks.append(Task(f, sha, nbytes, run_dir))
    return tasks, kept, skipped


@contextmanager
def dask_client(scheduler: str | None, workers: int | None, allowed_failures: int | None,
                stages: list[str] | None = None) -> Iterator:
    """A `distributed.Client`: to `scheduler` (tcp://HOST:PORT), else to a new LocalCluster of
    `workers` single-threaded worker processes (default: the CPU count) forked from robocal's fork
    server (`fork_server.start`)."""
    import dask
    from distributed import Client, LocalCluster

    cfg = {**QUIET, **RELAXED}
    if allowed_failures is not None:
        cfg["distributed.scheduler.allowed-failures"] = allowed_failures
    if not scheduler:
        fork_server.start(stages)
        cfg |= FORK_SERVER
    with dask.config.set(cfg):
        if scheduler:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as e:
                raise RobocalError(f"{scheduler}: no Dask scheduler answered ({e})") from None
            with client:
                try:
                    client.wait_for_workers(1, timeout=60)
                except TimeoutError:
                    raise RobocalError(f"{scheduler}: the Dask scheduler has no workers (waited 60 s)") from None
                client.run(warm_worker, stages)
                yield client
            return
        n = workers or os.cpu_count() or 1
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                          scheduler_port=0, silence_logs=logging.ERROR, env=SINGLE_THREADED | QUIET_ENV) as cluster, \
                Client(cluster) as client:
            client.run(warm_worker, stages)  # what the fork server lacks, at start-up, not on the first tasks
            yield client


class EarlyCluster:
    """`dask_client` for a LocalCluster, brought up in a background thread while the archive is
    discovered and hashed (its start and the client's import of distributed overlap them).  The
    thread also closes it (distributed's client context must be left in the context it was entered)."""

    def __init__(self, workers: int | None, allowed_failures: int | None, stages: list[str] | None) -> None:
        self._args = (workers, allowed_failures, stages)
        self._client, self._error, self._raised = None, None, False
        self._ready, self._done = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._hold, name="robocal-cluster", daemon=True)
        self._thread.start()

    def _hold(self) -> None:
        try:
            with dask_client(None, *self._args) as client:
                self._client = client
                self._ready.set()
                self._done.wait()
        except BaseException as e:  # noqa: BLE001 — raised in the caller's thread by `client` / `close`
            self._error = e
        finally:
            self._ready.set()

    def client(self):
        """The started client (waits for the start; its error, if any, is raised here)."""
        self._ready.wait()
        if self._error is not None:
            self._raised = True
            raise self._error
        return self._client

    def close(self) -> None:
        """Close the cluster (in its thread); an error of the start not yet raised, or of the close, is
        raised here, not lost."""
        self._done.set()
        self._thread.join()
        if self._error is not None and not self._raised:
            self._raised = True
            raise RobocalError(f"Dask LocalCluster: {type(self._error).__name__}: {self._error}") from self._error


def run_tasks(tasks: list[Task], stages, robot_id, config: str, engine: str = "dask", workers: int | None = None,
              scheduler: str | None = None, allowed_failures: int | None = None,
              on_start: Callable[[object], None] | None = None, early: EarlyCluster | None = None) -> Iterator[dict]:
    """Yield each task's row as it completes (any order)."""
    if not tasks:
        return
    if engine == "serial":
        for t in tasks:
            yield reprocess_one(*t.args(stages, robot_id, config))
        return
    if engine == "processes":
        n = max(1, min(len(tasks), workers or os.cpu_count() or 1))
        with ProcessPoolExecutor(max_workers=n) as pool:
            futs = {pool.submit(reprocess_one, *t.args(stages, robot_id, config)): t for t in tasks}
            for fut in pool_completed(futs):
                t = futs[fut]
                try:
                    yield fut.result()
                except Exception as e:  # noqa: BLE001 — a dead pool process: the row says so
                    yield t.lost(config, f"worker process died: {type(e).__name__}: {e}")
        return
    if engine != "dask":
        raise RobocalError(f"unknown engine {engine!r} (one of {', '.join(ENGINES)})")
    from distributed import as_completed

    run_id = uuid.uuid4().hex[:12]  # keys unique per run: runs sharing a scheduler must not share results

    with (_started(early) if early is not None else dask_client(scheduler, workers, allowed_failures, stages)) as client:
        if on_start:
            on_start(client)
        futs, by_key = [], {}
        for i, t in enumerate(tasks):
            fut = client.submit(reprocess_one, *t.args(stages, robot_id, config), pure=False,
                                key=f"robocal-reprocess-{run_id}-{i}")
            futs.append(fut)
            by_key[fut.key] = t
        for fut in as_completed(futs):
            t = by_key[fut.key]
            try:
                row = fut.result()
            except Exception as e:  # noqa: BLE001 — KilledWorker after Dask's retries, or a lost task
                reason = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}".rstrip(": ")
                row = t.lost(config, f"worker died: {reason}")
            fut.release()
            yield row


@contextmanager
def _started(early: EarlyCluster) -> Iterator:
    try:
        yield early.client()
    except BaseException:
        try:
            early.close()
        except Exception:  # noqa: BLE001 — the run's own error is the one to report, not the close's
            pass
        raise
    early.close()


def reprocess_archive(archive: Path, out: Path, *, patterns=DEFAULT_PATTERNS, stages: list[str] | None = None,
                      robot_id: str | None = None, engine: str = "dask", workers: int | None = None,
                      scheduler: str | None = None, allowed_failures: int | None = None, resume: bool = True,
                      flush_s: float = 2.0, on_plan: Callable[[int, int], None] | None = None,
                      on_row: Callable[[dict], None] | None = None,
                      on_start: Callable[[object], None] | None = None) -> Outcome:
    """The whole run: rows written to `out/results/` as they complete; returns them all."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    early: list[EarlyCluster] = []
    owned: list[bool] = []  # this run started the fork server (the CLI may have started it already)

    def bring_up() -> None:  # at the first recording to run (none on a fully resumed archive)
        owned.append(fork_server.start(stages))  # its imports overlap the rest of the discovery and hashing
        early.append(EarlyCluster(workers, allowed_failures, stages))  # and so does the cluster's start

    failed = True
    try:
        res = _run(archive, out, patterns, stages, robot_id, engine, workers, scheduler, allowed_failures, resume,
                   flush_s, on_plan, on_row, on_start, early, bring_up if engine == "dask" and not scheduler else None)
        failed = False
        return res
    finally:
        try:
            for e in early:
                try:
                    e.close()
                except Exception:
                    if not failed:  # else the run's own error is the one to report, not the cluster's close
                        raise
        finally:
            if any(owned):
                fork_server.stop()  # no worker is forked from it any more


def _run(archive, out, patterns, stages, robot_id, engine, workers, scheduler, allowed_failures, resume, flush_s,
         on_plan, on_row, on_start, early, bring_up) -> Outcome:
    tasks, kept, skipped = plan(archive, out, patterns, stages, robot_id, resume, on_first_task=bring_up)
    if on_plan:
        on_plan(len(tasks), len(kept))
    res = Outcome(kept=kept, skipped_paths=skipped)
    config = config_of(stages, robot_id)
    with ResultsWriter(out, flush_s=flush_s) as w:
        for row in kept:
            if row.pop("_regated"):
                w.add(row)  # a new verdict on an old result: the dataset says so too
        for row in run_tasks(tasks, stages, robot_id, config, engine, workers, scheduler, allowed_failures,
                             on_start, early[0] if early else None):
            w.add(row)
            res.rows.append(row)
            if on_row:
                on_row(row)
    return res
