"""The reprocess results as a Parquet dataset (`OUT/results/part-*.parquet`), written while the run
goes on: rows are buffered and flushed to a new part at most `flush_s` seconds after they arrive
(or at once when `flush_rows` are buffered), each part written to a temporary name and renamed, so a reader — or a resumed run — only
ever sees complete parts.  A later row of the same recording supersedes an earlier one."""

from __future__ import annotations

import os
import threading
import time
import uuid
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.errors import RobocalError
from pipeline.fleet.rows import FAILED, SCHEMA

RESULTS = "results"


def results_dir(out: Path) -> Path:
    return Path(out) / RESULTS


class ResultsWriter:
    """Append rows; parts appear as `part-<ns>-<uuid>.parquet`: a row is on disk at most `flush_s`
    after it was added (a timer flushes what is buffered), or at once when `flush_rows` are buffered."""

    def __init__(self, out: Path, flush_s: float = 2.0, flush_rows: int = 200) -> None:
        self.dir = results_dir(out)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.flush_s, self.flush_rows = flush_s, flush_rows
        self._rows: list[dict] = []
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        self.parts = 0

    def add(self, row: dict) -> None:
        with self._lock:
            self._rows.append(row)
            full = len(self._rows) >= self.flush_rows
            if not full and self._timer is None:
                self._timer = threading.Timer(self.flush_s, self.flush)
                self._timer.daemon = True
                self._timer.start()
        if full:
            self.flush()

    def flush(self) -> None:
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            if not self._rows:
                return
            table = pa.Table.from_pylist(self._rows, schema=SCHEMA)
            name = f"part-{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet"
            tmp = self.dir / f".{name}.tmp"
            pq.write_table(table, tmp)
            os.replace(tmp, self.dir / name)
            self._rows.clear()
            self.parts += 1

    def __enter__(self) -> "ResultsWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.flush()


def read_results(out_or_dir: Path, latest: bool = True) -> pa.Table:
    """Every row of a results dataset (`OUT` or `OUT/results`, or a single Parquet file); with
    `latest`, only the newest row of each recording.  Unreadable parts are reported, not skipped."""
    p = Path(out_or_dir)
    if p.is_dir() and (p / RESULTS).is_dir():
        p = p / RESULTS
    if p.is_file():
        parts = [p]
    elif p.is_dir():
        parts = sorted(q for q in p.glob("part-*.parquet"))
    else:
        raise RobocalError(f"{out_or_dir}: no such results dataset (a reprocess --out folder or its results/)")
    tables = []
    for q in parts:
        try:
            t = pq.read_table(q)
        except (OSError, pa.ArrowInvalid) as e:
            raise RobocalError(f"{q}: not a readable Parquet part ({str(e).splitlines()[0]})") from None
        missing = [f.name for f in SCHEMA if f.name not in t.column_names]
        if missing:
            raise RobocalError(f"{q}: not a robocal reprocess dataset (missing columns {', '.join(missing[:4])})")
        tables.append(t.select(SCHEMA.names).cast(SCHEMA))
    table = pa.concat_tables(tables) if tables else SCHEMA.empty_table()
    if not latest or table.num_rows == 0:
        return table
    recs = table.column("recording").to_pylist()
    last = {r: i for i, r in enumerate(recs)}  # parts are in time order: the last row wins
    return table.take(sorted(last.values()))


def done_keys(out: Path) -> dict[tuple[str, str, str, str, str], dict]:
    """(recording, input hash, version, code version, config) → row, for rows a resume may keep: every
    finished row except `lost` ones (a worker died: worth another try)."""
    if not results_dir(out).is_dir():
        return {}
    keep = {}
    for r in read_results(out).to_pylist():
        if r["status"] == "lost":
            continue
        keep[(r["recording"], r["input_sha256"], r["robocal_version"], r["code_version"], r["config"])] = r
    return keep


def is_failed(row: dict) -> bool:
    return row.get("status") in FAILED
