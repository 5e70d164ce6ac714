"""Strict reading of CSV text tables (measurement tables, compensation targets).

A table is UTF-8 text (an optional byte-order mark is skipped), comma-separated, with a header row
(or the column names given).  Only the columns asked for are kept, row by row, so memory grows with
rows × kept columns whatever the width of the file.  Refused with one line naming the file (and the
line or column): bytes that are not UTF-8, a header naming a column twice, a row with more fields
than the header, more than `MAX_COLUMNS` columns, a field over `MAX_FIELD_CHARS` characters.

Numbers are decimal literals as written by spreadsheets and numpy (``-1.5``, ``2e-3``, ``.5``,
``nan``, ``inf``); Python's other float spellings (``0_5``, ``١٢``) are not numbers here, and a
finite value beyond `pipeline.importers.bounds.BOUND` (m, rad, after unit conversion by the caller)
is damage, not a measurement.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError

MAX_COLUMNS = 100_000  # columns of a header; a wider file is refused before any row is read
MAX_FIELD_CHARS = 1 << 16  # characters of one field
_NUMBER = re.compile(r"\s*[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf|infinity)\s*",
                     re.IGNORECASE | re.ASCII)


def read_columns(path: Path, keep: Iterable[str] | None = None,
                 names: Iterable[str] = ()) -> tuple[list[str], dict[str, list[str]], int]:
    """(header, {column: field texts} for the columns in `keep` (all when None), data rows) of the
    CSV file `path`; `names` is the header of a file without one."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise RobocalError(f"{path}: no such file") from None
    except OSError as e:
        raise RobocalError(f"{path}: cannot read ({type(e).__name__}: {e})") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        raise RobocalError(f"{path}: line {line}: byte 0x{raw[e.start]:02x} is not UTF-8 text "
                           "(save the table as UTF-8)") from None
    del raw
    csv.field_size_limit(MAX_FIELD_CHARS)
    rows = csv.reader(io.StringIO(text, newline=""))
    line = 0
    try:
        header = list(names)
        if not header:
            line = 1
            header = [h.strip() for h in next(rows, [])]
        if len(header) > MAX_COLUMNS:
            raise RobocalError(f"{path}: {len(header)} columns, more than robocal reads ({MAX_COLUMNS})")
        seen: dict[str, int] = {}
        for k, h in enumerate(header):
            if h in seen:
                raise RobocalError(f"{path}: column {h!r} appears twice in the header (columns {seen[h] + 1} "
                                   f"and {k + 1})")
            seen[h] = k
        kept = None if keep is None else set(keep)
        wanted = [(k, h) for k, h in enumerate(header) if kept is None or h in kept]
        out: dict[str, list[str]] = {h: [] for _, h in wanted}
        n = 0
        for row in rows:
            line = rows.line_num
            if not row or (len(row) == 1 and not row[0].strip()):
                continue  # blank line
            if len(row) > len(header):
                raise RobocalError(f"{path}: line {line}: {len(row)} fields, the header has {len(header)}")
            for k, h in wanted:
                out[h].append(row[k] if k < len(row) else "")
            n += 1
    except csv.Error as e:
        raise RobocalError(f"{path}: line {line + 1}: not CSV ({e})") from None
    return header, out, n


def is_number(text: str) -> bool:
    """`text` is a decimal literal as `numbers` reads it."""
    return _NUMBER.fullmatch(text) is not None


def numbers(path: Path, column: str, texts: list[str], first_line: int = 2, where=None) -> np.ndarray:
    """The column's values as floats; one line naming file, row (line) and column for a field that
    is not a decimal number (`where(i)`: the caller's own words for data row i, 0-based).  Empty
    fields, NaN and inf are returned as NaN / inf for the caller."""
    try:
        return np.array([float(s) if _NUMBER.fullmatch(s) else _bad(s) for s in texts], float)
    except _NotANumber as e:
        i = texts.index(e.text)
        at = where(i) if where is not None else f"row {i + first_line}: column {column!r}"
        raise RobocalError(f"{path}: {at}: {e.text!r} is not a number") from None


class _NotANumber(Exception):
    def __init__(self, text: str) -> None:
        self.text = text


def _bad(s: str) -> float:
    if not s.strip():
        return float("nan")
    raise _NotANumber(s)
