"""Run folders robocal owns: a marker so that only folders robocal wrote are ever emptied, and
an exclusive lock so that two runs on one folder take turns.

`DIR/.robocal-run` marks a run folder (written when robocal creates it, or adopts an empty one, or
one that holds nothing but what an earlier robocal wrote: stage folders with their stage.json);
`DIR/<stage>/.robocal-stage` marks a stage folder.  A non-empty folder without the marker is the
user's: robocal refuses it with one line and touches nothing in it.  `DIR/.robocal-lock` is locked
with `fcntl.flock` (released by the kernel when the process dies, so a killed run never leaves a
stale lock); it holds the pid of the run that has it, for the message of the run that waits.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pipeline.errors import RobocalError

RUN_MARKER = ".robocal-run"
STAGE_MARKER = ".robocal-stage"
LOCK = ".robocal-lock"
_HELD: dict[str, int] = {}  # resolved run folder -> re-entry depth (this process)


def _oserror(path: Path, e: OSError) -> RobocalError:
    return RobocalError(f"{path}: cannot write ({type(e).__name__}: {e.strerror or e})")


def claim(run_dir: Path) -> None:
    """Make `run_dir` a robocal run folder: create it, or adopt it when it is empty; refuse a
    non-empty folder robocal did not mark."""
    run_dir = Path(run_dir)
    marker = run_dir / RUN_MARKER
    try:
        if marker.is_file():
            return
        refuse_foreign(run_dir)
        run_dir.mkdir(parents=True, exist_ok=True)
        marker.write_text("robocal run folder: robocal may replace the stage folders in here\n")
    except OSError as e:
        raise _oserror(run_dir, e) from None


_TOP_FILES = {"results.json", "report.html", "run.rrd", LOCK}


def _legacy_stage(d: Path) -> bool:
    """A stage folder a robocal from before the markers wrote (its stage.json is there)."""
    return d.is_dir() and (d / "stage.json").is_file()


def _legacy_run(run_dir: Path) -> bool:
    """A run folder a robocal from before the markers wrote: only its own files and stage folders."""
    entries = list(run_dir.iterdir())
    return any(_legacy_stage(e) for e in entries) and all(
        e.name in _TOP_FILES if e.is_file() else _legacy_stage(e) for e in entries)


def refuse_foreign(run_dir: Path) -> None:
    """One line, and nothing written, when `run_dir` is a non-empty folder robocal did not mark."""
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise RobocalError(f"{run_dir}: exists and is not a folder; choose another --out")
    try:
        foreign = (run_dir.is_dir() and not (run_dir / RUN_MARKER).is_file()
                   and any(p.name != LOCK for p in run_dir.iterdir()) and not _legacy_run(run_dir))
    except OSError as e:
        raise RobocalError(f"{run_dir}: cannot read ({type(e).__name__}: {e.strerror or e})") from None
    if foreign:
        raise RobocalError(f"{run_dir}: folder is not empty and was not written by robocal (no {RUN_MARKER}); "
                           "robocal will not write into it — choose a new or empty --out")


def is_run_folder(run_dir: Path) -> bool:
    return (Path(run_dir) / RUN_MARKER).is_file()


def fresh_stage_dir(run_dir: Path, name: str) -> Path:
    """An empty `run_dir/name`, removing the previous one only if robocal wrote it."""
    d = Path(run_dir) / name
    if d.exists():
        if not (d / STAGE_MARKER).is_file() and (not d.is_dir() or any(d.iterdir())) and not _legacy_stage(d):
            raise RobocalError(f"{d}: not written by robocal (no {STAGE_MARKER}); robocal will not replace it — "
                               "move it away or choose another --out")
        try:
            shutil.rmtree(d)
        except OSError as e:
            raise _oserror(d, e) from None
    try:
        d.mkdir(parents=True)
        (d / STAGE_MARKER).write_text("written by robocal\n")
    except OSError as e:
        raise _oserror(d, e) from None
    return d


def _holder(lock_path: Path) -> str:
    try:
        pid = lock_path.read_text().strip()
    except OSError:
        pid = ""
    return f"pid {pid}" if pid else "another process"


@contextmanager
def locked(run_dir: Path, timeout_s: float | None = None, log=None) -> Iterator[None]:
    """Hold the run folder's lock (re-entrant within this process).  A second run waits for it
    (saying which process holds it) up to `timeout_s` (ROBOCAL_LOCK_TIMEOUT_S, default 3600 s),
    then stops with one line."""
    run_dir = Path(run_dir)
    key = str(run_dir.resolve())
    if key in _HELD:
        _HELD[key] += 1
        try:
            yield
        finally:
            _HELD[key] -= 1
        return
    if timeout_s is None:
        timeout_s = float(os.environ.get("ROBOCAL_LOCK_TIMEOUT_S", "3600"))
    lock_path = run_dir / LOCK
    refuse_foreign(run_dir)
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise _oserror(run_dir, e) from None
    try:
        t0, said = time.monotonic(), False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() - t0 > timeout_s:
                    raise RobocalError(f"{run_dir}: in use by another robocal run ({_holder(lock_path)}) for over "
                                       f"{timeout_s:g} s; wait for it or choose another --out") from None
                if not said and log is not None:
                    log(f"lock: waiting for {run_dir} (held by {_holder(lock_path)})")
                    said = True
                time.sleep(0.1)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        _HELD[key] = 1
        try:
            yield
        finally:
            del _HELD[key]
            os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
