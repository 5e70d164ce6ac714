"""Decode robocal channels into numpy columns, checking every record on the way.

Each extractor raises `RobocalError` naming file, channel and record (message index on
its channel) for a missing field, a wrong shape, or a NaN/inf value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import RobocalError, where
from pipeline.ingest.legacy_json_stream import decode_json_stream
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import Recording

JOINT_STATE = "/robot/joint_state"
TOUCH_CONTACT = "/touch/contact"


@dataclass(frozen=True)
class JointStream:
    """The encoder stream: sample times (ns since epoch), positions (T, n_joints) rad; the optional
    drive state (T, n_joints), None when not logged: commanded positions rad / m, efforts N·m / N (or raw drive
    units the campaign converts), motor currents A; the optional logged velocities (T, n_joints) rad/s / m/s."""

    t_ns: np.ndarray
    q: np.ndarray
    names: tuple[str, ...]
    message_index: np.ndarray  # (T,) message each sample came from
    q_cmd: np.ndarray | None = None
    effort: np.ndarray | None = None
    current: np.ndarray | None = None
    velocity: np.ndarray | None = None

    def __len__(self) -> int:
        return self.t_ns.size


def _field(rec: Recording, topic: str, i: int, msg: dict, key: str):
    if key not in msg:
        raise RobocalError(f"{where(rec.path, topic, i)}: field {key!r} missing")
    return msg[key]


def _finite(rec: Recording, topic: str, i: int, key: str, a: np.ndarray) -> None:
    if not np.all(np.isfinite(a)):
        raise RobocalError(f"{where(rec.path, topic, i)}: field {key!r} has NaN or inf")


def joint_stream(rec: Recording) -> JointStream:
    """The batched `/robot/joint_state` messages as one stream, decoded by the channel's message
    encoding: ``protobuf`` (`robocal.JointStateBatch`, what robocal writes now) or
    ``json`` (archived recordings: `legacy_json_stream`).  A message that does not decode against
    its registered schema is a `RobocalError` naming file, channel and record."""
    raw = rec.messages.raw.get(JOINT_STATE)
    if not raw or rec.registration.get(JOINT_STATE):
        rec.require(JOINT_STATE)  # raises: missing, empty or registered with another schema
    if rec.encodings.get(JOINT_STATE) == JSB.ENCODING:
        try:
            b = JSB.decode(raw)
        except JSB.BatchError as e:
            raise RobocalError(f"{where(rec.path, JOINT_STATE, e.record)}: {e.why}") from None
        return JointStream(t_ns=b.t_ns, q=b.q, names=b.names, message_index=b.message_index, q_cmd=b.q_cmd,
                           effort=b.effort, current=b.current, velocity=b.velocity)
    t, q, names, index = decode_json_stream(raw, rec.path, JOINT_STATE)
    return JointStream(t_ns=t, q=q, names=names, message_index=index)


def contacts(rec: Recording) -> dict[str, np.ndarray]:
    """`/touch/contact` as columns: timestamp_ns, joint_positions (n, n_joints), face, axis (0/1/2),
    coordinate (m), record (message index)."""
    msgs = rec.require(TOUCH_CONTACT)
    axis_of = {"x": 0, "y": 1, "z": 2}
    n = len(msgs)
    q0 = _field(rec, TOUCH_CONTACT, 0, msgs[0], "joint_positions")
    out = {"timestamp_ns": np.empty(n, np.int64), "joint_positions": np.empty((n, len(q0))),
           "face": np.empty(n, object), "axis": np.empty(n, np.int64), "coordinate": np.empty(n),
           "record": np.arange(n)}
    for i, m in enumerate(msgs):
        q = np.asarray(_field(rec, TOUCH_CONTACT, i, m, "joint_positions"), dtype=float)
        if q.shape != (len(q0),):
            raise RobocalError(f"{where(rec.path, TOUCH_CONTACT, i)}: joint_positions has {q.size} values, expected {len(q0)}")
        _finite(rec, TOUCH_CONTACT, i, "joint_positions", q)
        ax = _field(rec, TOUCH_CONTACT, i, m, "axis")
        if ax not in axis_of:
            raise RobocalError(f"{where(rec.path, TOUCH_CONTACT, i)}: axis {ax!r} is not x, y or z")
        c = _field(rec, TOUCH_CONTACT, i, m, "coordinate")
        if not isinstance(c, (int, float)) or not np.isfinite(c):
            raise RobocalError(f"{where(rec.path, TOUCH_CONTACT, i)}: coordinate {c!r} is not a finite number")
        out["timestamp_ns"][i] = int(_field(rec, TOUCH_CONTACT, i, m, "timestamp_ns"))
        out["joint_positions"][i] = q
        out["face"][i] = str(_field(rec, TOUCH_CONTACT, i, m, "face"))
        out["axis"][i] = axis_of[ax]
        out["coordinate"][i] = float(c)
    return out
