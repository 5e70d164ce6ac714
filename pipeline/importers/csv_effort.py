"""Joint position / velocity / effort logs in CSV → the encoder stream of a dynamics recording.

The logs come as one table (columns ``t`` and per joint ``J`` or ``J_position``, ``J_velocity``,
``J_effort``) or as separate position, velocity and effort tables sharing the time column (as
``ros2 topic echo --csv`` / FIGAROH export them, whose headers start with ``- ``: ``- J_position``).
A header matches joint J when, stripped of a leading ``- ``, it is ``J`` (position tables, or a velocity /
effort table of its own) or ``J_<kind>`` — or the one header equal to it but for case.  Times are seconds (any
origin), or, for tables without a time column, row i at i / `rate`; `rows` keeps data rows [a, b) (zero-based).
Position readings that are not joint angles (motor-side encoders, a coupled wrist) are converted by the
declaration `positions` (`joint_readings`) before the limits are checked.

Refused with one line naming file, row and column: a missing joint or effort column, a time column
that is not strictly increasing (or differs between the tables), empty / NaN / inf values (a burst is
named with its first and last row), positions or speeds beyond the URDF's limits (`joint_logs`).
Vectorised: one pass per column, no Python loop over rows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.importers.bounds import check_bound
from pipeline.importers.csv_text import numbers, read_columns
from pipeline.models.urdf import RobotDescription

KINDS = ("position", "velocity", "effort")


def _norm(h: str) -> str:
    h = h.strip()
    return h[1:].strip() if h.startswith("-") and not h[1:2].isdigit() else h


def _match(header: list[str], joint: str, kind: str, bare: bool = False) -> str | None:
    """The column of `joint`'s `kind` in `header`: ``J_<kind>`` (or ``J`` in a position table, or in a
    table of that kind alone: `bare`), a leading ``- `` ignored; exact names first, then the one column
    equal to it but for case (``Joint_1`` for ``joint_1``)."""
    want = {f"{joint}_{kind}"} | ({joint} if kind == "position" or bare else set())
    for h in header:
        if _norm(h) in want:
            return h
    low = {w.lower() for w in want}
    near = [h for h in header if _norm(h).lower() in low]
    return near[0] if len(near) == 1 else None


def _burst(path: Path, col: str, bad: np.ndarray, offset: int) -> RobocalError:
    """One line naming the first run of bad rows (file line numbers: header is line 1)."""
    brk = np.flatnonzero(np.diff(bad) != 1)
    i, j = int(bad[0]), int(bad[brk[0]] if brk.size else bad[-1])
    a, b = i + offset + 2, j + offset + 2
    rows = f"row {a}" if a == b else f"rows {a}–{b} ({b - a + 1} rows)"
    return RobocalError(f"{path}: {rows}: column {col!r} is empty, NaN or inf")


def _block(path: Path, header: list[str], cols: dict, joints: list[str], kind: str, rows: slice,
           offset: int, bare: bool = False) -> np.ndarray:
    names = [_match(header, j, kind, bare) for j in joints]
    missing = [j for j, c in zip(joints, names) if c is None]
    if missing:
        raise RobocalError(f"{path}: missing {kind} column(s) for {', '.join(missing)} (named JOINT_{kind} or "
                           f"'- JOINT_{kind}'; columns: {', '.join(header[:12])}{', …' if len(header) > 12 else ''})")
    out = np.stack([numbers(path, c, cols[c][rows], first_line=offset + 2) for c in names], axis=1)
    for k, c in enumerate(names):
        bad = np.flatnonzero(~np.isfinite(out[:, k]))
        if bad.size:
            raise _burst(path, c, bad, offset)
        check_bound(path, c, out[:, k], first_line=offset + 2, unit="SI units")
    return out


def _times(path: Path, header: list[str], cols: dict, time_col: str, rows: slice, offset: int,
           rate: float | None = None, n: int = 0) -> np.ndarray:
    if rate is not None:
        if time_col in header:
            raise RobocalError(f"{path}: has a time column {time_col!r}: --rate is for a table without one")
        return np.arange(n)[rows] / rate
    if time_col not in header:
        raise RobocalError(f"{path}: no time column {time_col!r} (seconds; --time-col names another, --rate HZ "
                           "gives the sample rate of a table without one)")
    t = numbers(path, time_col, cols[time_col][rows], first_line=offset + 2)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise _burst(path, time_col, bad, offset)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise RobocalError(f"{path}: row {i + offset + 2}: column {time_col!r}: {t[i]!r} s is not after the previous "
                           f"row's {t[i - 1]!r} s: times must increase strictly")
    return t


def read_logs(position: Path, desc: RobotDescription, velocity: Path | None = None, effort: Path | None = None,
              time_col: str = "t", rows: tuple[int, int | None] = (0, None), rate: float | None = None,
              positions: dict | None = None) -> dict[str, np.ndarray]:
    """{t_s (T,), q (T, J) rad / m, v (T, J) rad/s / m/s or absent, effort (T, J) raw} in the chain's
    joint order, rows [a, b) of the tables.  `rate` (Hz): tables without a time column, row i at i / rate
    s; `positions`: the raw position readings' conversion (`joint_readings.declaration`)."""
    from pipeline.importers import joint_logs, joint_readings

    if rate is not None and not (np.isfinite(rate) and rate > 0):
        raise RobocalError(f"--rate {rate!r}: expected the sample rate in Hz, > 0")
    joints = desc.movable
    names = [j.name for j in joints]
    a, b = rows
    sl = slice(a, b)
    files = {"position": Path(position), "velocity": velocity and Path(velocity), "effort": effort and Path(effort)}
    read: dict[Path, tuple] = {}
    for p in {f for f in files.values() if f}:
        header, cols, n = read_columns(p)
        if n == 0:
            raise RobocalError(f"{p}: no data rows")
        if a >= n or (b is not None and b > n):
            raise RobocalError(f"{p}: --rows {a}:{'' if b is None else b} is beyond its {n} data rows")
        read[p] = ([h.strip() for h in header], cols, n)
    out: dict[str, np.ndarray] = {}
    pos = files["position"]
    header, cols, n_pos = read[pos]
    for p, (_, _, n) in read.items():
        if n != n_pos and (rate is not None or b is None):  # rows paired by index: the lengths must agree
            raise RobocalError(f"{p}: {n} data rows, {pos} has {n_pos} (the tables must share one clock, row by row)")
    out["t_s"] = _times(pos, header, cols, time_col, sl, a, rate, n_pos)
    for kind in KINDS:
        p = files[kind] or (pos if kind == "position" or any(_match(header, j, kind) for j in names) else None)
        if p is None:
            if kind == "effort":
                raise RobocalError(f"{pos}: no effort columns (JOINT_effort) and no --effort-csv: a dynamics "
                                   "recording needs the drives' efforts")
            continue
        h, c, _ = read[p]
        if p != pos:
            t = _times(p, h, c, time_col, sl, a, rate, n_pos)
            off = np.flatnonzero(np.abs(t - out["t_s"]) > 1e-6)
            if off.size:
                i = int(off[0])
                raise RobocalError(f"{p}: row {i + a + 2}: time {t[i]!r} s differs from {pos}'s {out['t_s'][i]!r} s "
                                   "(the tables must share one clock, row by row)")
        out[{"position": "q", "velocity": "v", "effort": "effort"}[kind]] = _block(p, h, c, names, kind, sl, a,
                                                                                 bare=p != pos)
    out["q"], v = joint_readings.convert(positions, names, out["q"], out.get("v"))
    if v is not None:
        out["v"] = v
    row = lambda i: f"{pos}: row {i + a + 2}"  # noqa: E731
    joint_logs.check_limits(row, out["q"], desc, converted=bool(positions))
    joint_logs.check_speeds(row, out["t_s"], out["q"], desc)
    return out
