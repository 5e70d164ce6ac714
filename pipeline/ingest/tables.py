"""Arrow tables of a recording: raw channel tables and the measurement table with motion context."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa

from pipeline.ingest.context import motion_context
from pipeline.ingest.streams import JointStream
from pipeline.ingest.temperature import TemperatureStream, rise_at


def channel_table(messages: list[dict], log_times: list[int] | None = None) -> pa.Table:
    """One row per message with its raw fields (pyarrow's type inference), plus `record`
    (message index on the channel) and `log_time_ns`.  Lenient: a field whose values pyarrow
    cannot type consistently is stored as JSON text, so a bad record still reaches validation."""
    fields = list(dict.fromkeys(k for m in messages for k in m))
    cols: dict[str, pa.Array] = {"record": pa.array(np.arange(len(messages), dtype=np.int64))}
    if log_times is not None:
        cols["log_time_ns"] = pa.array(np.asarray(log_times, np.int64))
    for f in fields:
        values = [m.get(f) for m in messages]
        try:
            cols[f] = pa.array(values, from_pandas=False)
        except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
            cols[f] = pa.array([None if v is None else json.dumps(v) for v in values], pa.string())
    return pa.table(cols)


def encoder_table(stream: JointStream) -> dict[str, np.ndarray]:
    """`t_ns`, `q_<joint>` (rad) and `record` (the joint_state message of each sample); where the stream
    carries drive state also `cmd_<joint>` (commanded, rad / m), `effort_<joint>` (N·m / N), `current_<joint>` (A),
    and where it carries logged velocities `vel_<joint>` (rad/s / m/s)."""
    out = {"t_ns": stream.t_ns.astype(np.int64), "record": stream.message_index.astype(np.int64)}
    for j, name in enumerate(stream.names):
        out[f"q_{name}"] = stream.q[:, j]
    for prefix, v in (("cmd", stream.q_cmd), ("effort", stream.effort), ("current", stream.current),
                      ("vel", stream.velocity)):
        if v is not None:
            for j, name in enumerate(stream.names):
                out[f"{prefix}_{name}"] = v[:, j]
    return out


def measurement_table(table: dict[str, np.ndarray], stream: JointStream | None,
                      time_column: str = "timestamp_ns", window_s: float = 0.02,
                      temperature: TemperatureStream | None = None, path: object = "",
                      channel: str = "") -> dict[str, np.ndarray]:
    """The system's measurement table (from `system.load`) joined with the motion context
    of each measurement: `v_<joint>` (rad/s), `dir_<joint>` (−1/0/+1), `time_since_start_s`;
    with a temperature channel, `temperature_rise_K` (since its first reading, interpolated)."""
    n = len(next(iter(table.values())))
    out = dict(table)
    out.setdefault("record", np.arange(n, dtype=np.int64))
    if time_column in table:
        check_times(*times_in_order(table, np.asarray(out["record"]), time_column), path, channel, time_column)
    if temperature is not None and time_column in table:
        out["temperature_rise_K"] = rise_at(temperature, np.asarray(table[time_column], np.int64), path, channel,
                                            out["record"])
    if stream is None or time_column not in table or len(stream) < 2:
        return out
    ctx = motion_context(stream, np.asarray(table[time_column], np.int64), window_s)
    for j, name in enumerate(stream.names):
        out[f"v_{name}"] = ctx["joint_velocity"][:, j]
    for j, name in enumerate(stream.names):
        out[f"dir_{name}"] = ctx["last_motion_sign"][:, j].astype(np.int8)
    out["time_since_start_s"] = ctx["time_since_start_s"]
    return out


def times_in_order(table: dict, record: np.ndarray, column: str = "timestamp_ns") -> tuple[np.ndarray, np.ndarray]:
    """(times, records) whose order is checked: the measured rows only (rows derived from the campaign, ``kind``
    ≠ 0 — known distances — have no time of their own), and where several recordings were merged (``session``)
    each session's times shifted to start after the previous sessions' (in order within each, not across)."""
    t = np.asarray(table[column], np.int64).copy()
    rec = np.asarray(record)
    own = np.asarray(table["kind"]) == 0 if "kind" in table else np.ones(t.size, bool)
    if "session" in table:
        ses = np.asarray(table["session"])
        for s_ in range(1, int(ses.max()) + 1 if ses.size else 0):
            m, before = own & (ses == s_), own & (ses < s_)
            if m.any() and before.any():
                t[m] += max(0, int(t[before].max()) - int(t[m].min()) + 1)
    return t[own], rec[own]


def check_times(t_ns: np.ndarray, record: np.ndarray, path: object, channel: str, column: str) -> None:
    """Measurement times (ns since the Unix epoch) must not be negative nor run backwards in record
    order (rows of one record share its time): one line naming the record, before anything is fitted."""
    from pipeline.errors import RobocalError, where

    if (neg := np.flatnonzero(t_ns < 0)).size:
        raise RobocalError(f"{where(path, channel, int(record[neg[0]]))}: {column} {int(t_ns[neg[0]])} is negative "
                           "(before 1970): not a time of this recording")
    order = np.argsort(record, kind="stable")
    if (back := np.flatnonzero(np.diff(t_ns[order]) < 0)).size:
        k = order[back[0] + 1]
        raise RobocalError(f"{where(path, channel, int(record[k]))}: {column} {int(t_ns[k])} is earlier than the "
                           f"previous record's {int(t_ns[order[back[0]]])}: measurement times run backwards")


MODEL_EXCLUDE_PREFIXES = ("v_", "dir_")


def model_columns(table: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The columns of a measurement table that came from the system (motion context removed)."""
    return {k: v for k, v in table.items()
            if not k.startswith(MODEL_EXCLUDE_PREFIXES) and k not in ("time_since_start_s", "temperature_rise_K")}
