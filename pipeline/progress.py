"""Progress of long work, readable both on a terminal and in a log file or CI job.

`Ticker(label, total)` counts steps.  On a terminal it redraws one status line in place
("report: 3/9 figures, 12 s"); elsewhere (stderr redirected, CI) it writes a full line at most every
`every_s` seconds (default 10 s, or the environment's ``ROBOCAL_PROGRESS_EVERY_S``), and one at the end if
any was written — a short job stays silent, a long one shows it is alive and how far it got.  It writes to
the given stream (stderr by default) and, off a terminal, the same lines to `log` (a file in the run folder)
when given.

Code deep in a computation reports without being handed the ticker: inside `reporting(tick)`, `step(note)`
passes a note ("signatures: joint 3 of 16 (torso_j2)") to it; outside, `step` does nothing.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import sys
import time
from pathlib import Path
from typing import IO, Callable, Iterator

_REPORTER: contextvars.ContextVar[Callable[..., None] | None] = contextvars.ContextVar("robocal_progress", default=None)


def default_every_s() -> float:
    """Seconds between two progress lines off a terminal: ``ROBOCAL_PROGRESS_EVERY_S``, else 10."""
    try:
        return max(0.0, float(os.environ.get("ROBOCAL_PROGRESS_EVERY_S", "10")))
    except ValueError:
        return 10.0


def _clock(s: float) -> str:
    s = int(round(s))
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s} s"


class Ticker:
    """Counts of one long stage (see module docstring)."""

    def __init__(self, label: str, total: int | None = None, unit: str = "", every_s: float | None = None,
                 stream: IO[str] | None = None, tty: bool | None = None, log: Path | None = None,
                 count: bool = True):
        self.label, self.total, self.unit, self.count = label, total, unit, count
        self.every_s = default_every_s() if every_s is None else every_s
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)()) if tty is None else tty
        self.log = None if self.tty or log is None else Path(log)
        self.n = 0
        self.t0 = time.monotonic()
        self.last = self.t0
        self.wrote = False

    def line(self, note: str = "") -> str:
        """The status line: "label: n/total unit — note, elapsed, ETA" (`count` False: "label: note, elapsed")."""
        el = time.monotonic() - self.t0
        if self.count:  # "label: n/total unit — note"; without the count, "label: note"
            count = f"{self.n}/{self.total}" if self.total else str(self.n)
            text = f"{self.label}: {count}{' ' + self.unit if self.unit else ''}"
            if note:
                text += f" — {note}"
        else:
            text = f"{self.label}: {note}"
        text += f", {_clock(el)}"
        if self.total and 0 < self.n < self.total:
            text += f", ETA {_clock(el / self.n * (self.total - self.n))}"
        return text

    def __call__(self, note: str = "", advance: int = 1) -> None:
        """Count `advance` steps done (`note`: what was just done or comes next)."""
        self.n += advance
        now = time.monotonic()
        if self.tty:
            self.stream.write("\r\033[K" + self.line(note))
            self.stream.flush()
            self.wrote = True
        elif now - self.last >= self.every_s:
            self._write(self.line(note))
            self.last, self.wrote = now, True

    def _write(self, text: str) -> None:
        """One full line to the stream and, off a terminal, to the log file."""
        self.stream.write(text + "\n")
        self.stream.flush()
        if self.log is not None:
            with open(self.log, "a", encoding="utf-8") as fh:
                fh.write(text + "\n")

    def done(self, note: str = "done") -> None:
        """End the status: a final line where anything was written (the terminal's line kept)."""
        if self.wrote:
            if self.tty:
                self.stream.write("\r\033[K" + self.line(note) + "\n")
                self.stream.flush()
            else:
                self._write(self.line(note))


@contextlib.contextmanager
def reporting(tick: Callable[..., None]) -> Iterator[None]:
    """Within the block, `step(note, advance)` calls `tick(note, advance)` (a `Ticker`)."""
    token = _REPORTER.set(tick)
    try:
        yield
    finally:
        _REPORTER.reset(token)


def step(note: str, advance: int = 0) -> None:
    """Report `note` (what is under way; `advance` steps done) to the `reporting` ticker, if any."""
    tick = _REPORTER.get()
    if tick is not None:
        tick(note, advance)
