"""The encoder stream as robocal wrote it before the protobuf stream: JSON batches (`robocal.JointState`,
`schemas/joint_state.schema.json`), still read for archived recordings.

One pure function over the message bodies: each is parsed as JSON (orjson, correctly rounded;
the standard library for NaN/Infinity literals, which the finite check then names) and turned
into arrays per message (≈ 250 samples; no Python loop per sample).  A record that is not JSON,
lacks a field, has ragged or non-numeric rows, changes its joint names or holds NaN/inf is a
`RobocalError` naming file, channel and record.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError, where
from pipeline.recording.reader import decode


def decode_json_stream(raw: Sequence[bytes], path: Path | str, topic: str
                       ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], np.ndarray]:
    """(sample times (T,) ns, positions (T, n_joints) rad, joint names, message of each sample (T,))."""
    if not raw:
        raise RobocalError(f"{where(path, topic)}: channel missing or empty")
    ts, qs, names = [], [], None
    for i, body in enumerate(raw):
        def bad(why: str) -> RobocalError:
            return RobocalError(f"{where(path, topic, i)}: {why}")
        try:
            m = decode(body)
        except (ValueError, UnicodeDecodeError) as e:
            raise bad(f"message is not valid JSON ({e})") from None
        if not isinstance(m, dict):
            raise bad("message is not a JSON object")
        for key in ("joint_names", "timestamps_ns", "positions"):
            if key not in m:
                raise bad(f"field {key!r} missing")
        nm = m["joint_names"]
        if not isinstance(nm, list) or not nm or not all(isinstance(s, str) for s in nm):
            raise bad("'joint_names' is not a non-empty list of strings")
        if names is None:
            names = tuple(nm)
        elif tuple(nm) != names:
            raise bad("joint_names change within the recording")
        tl, ql = m["timestamps_ns"], m["positions"]
        t = np.asarray(tl) if isinstance(tl, list) and tl else np.zeros(0, np.int64)
        if not isinstance(tl, list) or t.ndim != 1 or t.dtype.kind not in "iu":
            raise bad("'timestamps_ns' is not a list of integers")
        if t.dtype.kind == "u" and t.size and t.max() >= 2**63:
            raise bad("'timestamps_ns' holds an integer out of range (int64)")
        t = t.astype(np.int64, copy=False)
        if not isinstance(ql, list):
            raise bad("'positions' is not a list of rows")
        try:
            q = np.asarray(ql) if ql else np.zeros((0, len(names)))
        except (ValueError, TypeError):
            raise bad("'positions' rows differ in length or are not numbers") from None
        if q.dtype.kind not in "iuf":  # strings, booleans, null or integers beyond 64 bits
            raise bad("'positions' holds values that are not numbers")
        q = q.astype(np.float64, copy=False)
        if q.ndim != 2 or q.shape != (t.size, len(names)):
            raise bad(f"'positions' has shape {q.shape}, expected ({t.size}, {len(names)})")
        if not np.all(np.isfinite(q)):
            raise bad("field 'positions' has NaN or inf")
        ts.append(t)
        qs.append(q)
    n = np.fromiter(map(len, ts), np.int64, len(ts))
    return np.concatenate(ts), np.concatenate(qs), names, np.repeat(np.arange(len(ts)), n)
