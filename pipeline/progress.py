"""Progress of long work, readable both on a terminal and in a log file or CI job.

`Ticker(label, total)` counts steps.  On a terminal it redraws one status line in place
("report: 3/9 figures, 12 s"); elsewhere (stderr redirected, CI) it writes a full line at most every
`every_s` seconds, and one at the end if any was written — a short job stays silent, a long one
shows it is alive and how far it got.  It only writes to the given stream (stderr by default).
"""

from __future__ import annotations

import sys
import time
from typing import IO


def _clock(s: float) -> str:
    s = int(round(s))
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s} s"


class Ticker:
    """Counts of one long stage (see module docstring)."""

    def __init__(self, label: str, total: int | None = None, unit: str = "", every_s: float = 10.0,
                 stream: IO[str] | None = None, tty: bool | None = None):
        self.label, self.total, self.unit, self.every_s = label, total, unit, every_s
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)()) if tty is None else tty
        self.n = 0
        self.t0 = time.monotonic()
        self.last = self.t0
        self.wrote = False

    def line(self, note: str = "") -> str:
        """The status line: "label: n/total unit note, elapsed, ETA"."""
        el = time.monotonic() - self.t0
        count = f"{self.n}/{self.total}" if self.total else str(self.n)
        text = f"{self.label}: {count}{' ' + self.unit if self.unit else ''}"
        if note:
            text += f" — {note}"
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
            self.stream.write(self.line(note) + "\n")
            self.stream.flush()
            self.last, self.wrote = now, True

    def done(self, note: str = "done") -> None:
        """End the status: a final line where anything was written (the terminal's line kept)."""
        if self.wrote:
            self.stream.write(("\r\033[K" if self.tty else "") + self.line(note) + "\n")
            self.stream.flush()
