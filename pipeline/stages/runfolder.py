"""Run folders robocal owns: a marker so that only folders robocal wrote are ever emptied, and
an exclusive lock so that two runs on one folder take turns.

`DIR/.robocal-run` marks a run folder (written when robocal creates it, or adopts an empty one, or
one that holds nothing but what an earlier robocal wrote: stage folders with their stage.json);
`DIR/<stage>/.robocal-stage` marks a stage folder and, once the stage has ended (done or stopped),
lists the files robocal wrote in it (its manifest; `stage.json`'s `outputs` list them too).
Replacing a stage folder removes only those files: anything else in it (a user's file, in a folder
robocal wrote or one a robocal from before the markers wrote) makes robocal refuse with one line
naming it.  A non-empty folder without the run marker is the user's: robocal refuses it with one
line and touches nothing in it.  `DIR/.robocal-lock` is locked
with `fcntl.flock` (released by the kernel when the process dies, so a killed run never leaves a
stale lock); it holds the pid of the run that has it, for the message of the run that waits.
"""

from __future__ import annotations

import fcntl
import json
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
    """A stage folder a robocal from before the markers wrote: its stage.json and nothing else than
    the files that stage.json lists."""
    return d.is_dir() and (d / "stage.json").is_file() and _foreign_file(d) is None


def record_manifest(d: Path) -> None:
    """Write into the stage folder's marker the files robocal wrote there (every file present
    now: the folder was emptied when the stage began)."""
    d = Path(d)
    files = sorted(p.relative_to(d).as_posix() for p in d.rglob("*") if (p.is_file() or p.is_symlink())
                   and p.name != STAGE_MARKER)
    (d / STAGE_MARKER).write_text(json.dumps({"written_by": "robocal", "files": files}, indent=0) + "\n")


def _owned(d: Path) -> set[str] | None:
    """The files of stage folder `d` robocal wrote (relative to `d`), or None when it cannot tell
    (a stage that was killed before it ended: its marker lists nothing and there is no stage.json)."""
    owned: set[str] = {STAGE_MARKER}
    known = False
    try:
        doc = json.loads((d / STAGE_MARKER).read_text())
        owned |= set(doc["files"])
        known = True
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        pass
    try:
        stage = json.loads((d / "stage.json").read_text())
        prefix = d.name + "/"
        owned |= {"stage.json"} | {k[len(prefix):] for k in stage.get("outputs", {}) if k.startswith(prefix)}
        known = True
    except (OSError, ValueError, AttributeError, TypeError, RecursionError):
        pass
    return owned if known else None


def _foreign_file(d: Path) -> Path | None:
    """The first file (or link) in stage folder `d` that robocal did not write there, if any."""
    owned = _owned(d)
    if owned is None:
        return None
    for p in sorted(d.rglob("*")):
        if (p.is_file() or p.is_symlink() or not p.is_dir()) and p.relative_to(d).as_posix() not in owned:
            return p
    return None


def _remove_owned(d: Path) -> None:
    """Remove stage folder `d`, which holds only what robocal wrote (checked by the caller)."""
    if _owned(d) is None:  # a stage killed before it ended: everything in it is that run's
        shutil.rmtree(d)
        return
    for p in sorted(d.rglob("*"), key=lambda p: len(p.parts), reverse=True):
        if p.is_symlink() or not p.is_dir():
            p.unlink()
        else:
            p.rmdir()
    d.rmdir()


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
        if not d.is_dir() or d.is_symlink() or (not (d / STAGE_MARKER).is_file() and any(d.iterdir())
                                                 and not (d / "stage.json").is_file()):
            raise RobocalError(f"{d}: not written by robocal (no {STAGE_MARKER}); robocal will not replace it — "
                               "move it away or choose another --out")
        if (foreign := _foreign_file(d)) is not None:
            raise RobocalError(f"{foreign}: not written by robocal; robocal will not delete it — move it out of "
                               f"{d} or choose another --out")
        try:
            _remove_owned(d)
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
