"""Reading and writing stage artefacts: measurement tables ↔ Parquet, deterministic JSON.

A measurement table (``dict[str, np.ndarray]``, one row per measurement) may hold k-vector
columns (e.g. ``joint_positions`` (n, 6)).  On disk they become ``<name>_<i>`` columns;
the Parquet schema metadata ``robocal.vectors`` ({name: k}) lets `read_table` restore them.
Object (string) columns become Arrow strings.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.recording.writer import jsonable

VECTORS_KEY = b"robocal.vectors"
STAGE_FILE = "stage.json"  # DIR/<stage>/stage.json: the stage's record (key, inputs, outputs, summary)


def _jsonable(o: Any) -> Any:
    if isinstance(o, Path):
        return str(o)
    return jsonable(o)


def dumps(doc: Any) -> str:
    """Deterministic JSON (sorted keys where the dict is built in a fixed order anyway; NaN → null)."""
    return json.dumps(_nan_to_none(doc), indent=1, default=_jsonable, allow_nan=False) + "\n"


def _nan_to_none(o: Any) -> Any:
    if isinstance(o, float) and not np.isfinite(o):
        return None
    if isinstance(o, np.ndarray):
        return _nan_to_none(o.tolist())
    if isinstance(o, dict):
        return {k: _nan_to_none(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_nan_to_none(v) for v in o]
    if isinstance(o, np.floating):
        return _nan_to_none(float(o))
    return o


def write_json(path: Path, doc: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dumps(doc))


def read_json(path: Path) -> Any:
    return json.loads(Path(path).read_text())


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def to_arrow(table: Mapping[str, np.ndarray]) -> pa.Table:
    """Flatten a measurement table into an Arrow table (see module docstring)."""
    cols: dict[str, pa.Array] = {}
    vectors: dict[str, int] = {}
    for name, v in table.items():
        a = np.asarray(v)
        if a.ndim == 2:
            vectors[name] = a.shape[1]
            for i in range(a.shape[1]):
                cols[f"{name}_{i}"] = pa.array(a[:, i])
        elif a.ndim == 1 and a.dtype == object:
            cols[name] = pa.array([None if s is None else str(s) for s in a], pa.string())
        elif a.ndim == 1:
            cols[name] = pa.array(a)
        else:
            raise ValueError(f"column {name!r} has {a.ndim} dimensions; only 1 or 2 are stored")
    t = pa.table(cols)
    return t.replace_schema_metadata({VECTORS_KEY: json.dumps(vectors).encode()})


def from_arrow(t: pa.Table) -> dict[str, np.ndarray]:
    """Inverse of `to_arrow`: k-vector columns restacked, strings as object arrays."""
    meta = t.schema.metadata or {}
    vectors: dict[str, int] = json.loads(meta.get(VECTORS_KEY, b"{}"))
    member = {f"{n}_{i}": n for n, k in vectors.items() for i in range(k)}
    out: dict[str, np.ndarray] = {}
    for name in t.column_names:
        if name in member:
            base = member[name]
            if base not in out:
                k = vectors[base]
                out[base] = np.stack([t.column(f"{base}_{i}").to_numpy() for i in range(k)], axis=1)
            continue
        col = t.column(name)
        if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
            out[name] = np.array(col.to_pylist(), dtype=object)
        else:
            out[name] = col.to_numpy()
    return out


def write_table(path: Path, table: Mapping[str, np.ndarray] | pa.Table) -> None:
    """Parquet (zstd); bit-identical for identical content."""
    path.parent.mkdir(parents=True, exist_ok=True)
    t = table if isinstance(table, pa.Table) else to_arrow(table)
    pq.write_table(t, path, compression="zstd")


def read_table(path: Path) -> dict[str, np.ndarray]:
    return from_arrow(pq.read_table(path))


def read_stage(run_dir: Path, name: str) -> dict | None:
    """The record DIR/<name>/stage.json of a stage that ran, or None (absent or unreadable)."""
    p = Path(run_dir) / name / STAGE_FILE
    if not p.is_file():
        return None
    try:
        return read_json(p)
    except (ValueError, RecursionError):  # not JSON, or nested past the recursion limit
        return None
