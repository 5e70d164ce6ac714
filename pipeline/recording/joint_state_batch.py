"""`robocal.JointStateBatch`: the encoder stream's protobuf message (`schemas/joint_state_batch.proto`).

The message class is built at import from a FileDescriptorSet assembled here (`descriptor_pb2`), not
from committed generated code: nothing to regenerate, no protoc at run time, and no coupling between
a generated `_pb2.py` and the installed protobuf runtime (generated code refuses runtimes older than
its protoc).  The serialized set (`FILE_DESCRIPTOR_SET`) is the schema data every recording registers
(schema encoding ``protobuf``, name ``robocal.JointStateBatch``; channel message encoding
``protobuf``), so any MCAP tool decodes the stream with its usual protobuf decoder;
tests/test_binary_stream.py checks it against the .proto text compiled by protoc.

Core functions are pure: `encode` (arrays → one message), `decode` (all messages → arrays, each
message checked; a bad one raises `BatchError` with its index), `descriptor_problem`.
Units: times ns since the Unix epoch, positions rad (row-major, sample × joint).

Optional per-sample joint velocities (`velocities`, rad/s; m/s for a prismatic joint: what the controller
logged, field 10) and drive state (commanded positions, efforts, motor currents), same (sample, joint) layout
as `positions`, empty when not logged:
`commanded_positions` (rad / m, what the controller commanded) and `efforts` (the drive's measured
torque on the link along the joint axis, N·m; force N for a prismatic joint — ROS JointState.effort's
convention; raw drive units where the campaign declares an effort → torque conversion, `pipeline.dynamics.effort`),
and `motor_currents` (A; a torque only once multiplied by the joint's torque constant,
which `pipeline.ingest.drive` does where the campaign states one).  A registered schema written
before these fields (fields 1–6 only) is still robocal's.  A dynamics identification reads position, velocity
and effort from this one stream (`pipeline.dynamics`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from google.protobuf import descriptor_pb2 as D
from google.protobuf.descriptor_pool import DescriptorPool
from google.protobuf.message import DecodeError
from google.protobuf.message_factory import GetMessageClass
from google.protobuf.unknown_fields import UnknownFieldSet

SCHEMA_NAME = "robocal.JointStateBatch"
ENCODING = "protobuf"  # both the channel's message encoding and the schema encoding
FILE_NAME = "joint_state_batch.proto"  # as protoc names it with schemas/ as the include root

_F = D.FieldDescriptorProto
_NS = _F.TYPE_SFIXED64  # an epoch time: fixed 8 bytes (a varint would take 9)
# the optional drive state's field names (7, 8, 9), the one spelling every module imports
COMMANDED_POSITIONS, EFFORTS, MOTOR_CURRENTS = "commanded_positions", "efforts", "motor_currents"
VELOCITIES = "velocities"  # field 10: logged joint velocities, rad/s (m/s prismatic)
# (name, number, type, label): the message's fields, in .proto order.  Sample times are offsets from
# `timestamp_ns` (varints of ~4·10⁶ ns): absolute times cost 1 MB more after zstd on the bundled campaign
FIELDS: tuple[tuple[str, int, int, int], ...] = (
    ("timestamp_ns", 1, _NS, _F.LABEL_OPTIONAL),
    ("joint_names", 2, _F.TYPE_STRING, _F.LABEL_REPEATED),
    ("sample_offsets_ns", 3, _F.TYPE_INT64, _F.LABEL_REPEATED),
    ("positions", 4, _F.TYPE_DOUBLE, _F.LABEL_REPEATED),
    ("device_timestamps_ns", 5, _NS, _F.LABEL_REPEATED),
    ("host_receive_times_ns", 6, _NS, _F.LABEL_REPEATED),
    (COMMANDED_POSITIONS, 7, _F.TYPE_DOUBLE, _F.LABEL_REPEATED),
    (EFFORTS, 8, _F.TYPE_DOUBLE, _F.LABEL_REPEATED),
    (MOTOR_CURRENTS, 9, _F.TYPE_DOUBLE, _F.LABEL_REPEATED),
    (VELOCITIES, 10, _F.TYPE_DOUBLE, _F.LABEL_REPEATED),
)
OPTIONAL_TIMES = ("device_timestamps_ns", "host_receive_times_ns")  # empty or one per sample
OPTIONAL_SAMPLES = (COMMANDED_POSITIONS, EFFORTS, MOTOR_CURRENTS)  # drive state: empty or samples × joints
STREAM_SAMPLES = (*OPTIONAL_SAMPLES, VELOCITIES)  # every optional samples × joints field, in `Batches` order
ADDED_LATER = frozenset({7, 8, 9, 10})  # fields a registered schema of an older robocal may lack


def _json_name(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(p.capitalize() for p in rest)


def file_descriptor() -> D.FileDescriptorProto:
    """The .proto file as a FileDescriptorProto (what protoc would emit for it)."""
    fd = D.FileDescriptorProto(name=FILE_NAME, package="robocal", syntax="proto3")
    msg = fd.message_type.add(name="JointStateBatch")
    for name, number, kind, label in FIELDS:
        msg.field.add(name=name, number=number, type=kind, label=label, json_name=_json_name(name))
    return fd


FILE_DESCRIPTOR_SET: bytes = D.FileDescriptorSet(file=[file_descriptor()]).SerializeToString(deterministic=True)
_POOL = DescriptorPool()
_POOL.Add(file_descriptor())
JointStateBatch = GetMessageClass(_POOL.FindMessageTypeByName(SCHEMA_NAME))


class BatchError(ValueError):
    """Message `record` (index on its channel) does not match robocal.JointStateBatch."""

    def __init__(self, record: int, why: str) -> None:
        super().__init__(f"record {record}: {why}")
        self.record, self.why = record, why


@dataclass(frozen=True)
class Batches:
    """The decoded stream: sample times (T,) ns, positions (T, n_joints) rad, joint names, the
    message of each sample (T,), the optional raw device / host receive times (T,) ns, and the
    optional drive state (T, n_joints): commanded positions rad / m, efforts N·m / N, motor currents A, and
    the optional logged velocities (T, n_joints) rad/s / m/s."""

    t_ns: np.ndarray
    q: np.ndarray
    names: tuple[str, ...]
    message_index: np.ndarray
    device_t_ns: np.ndarray | None = None
    host_t_ns: np.ndarray | None = None
    q_cmd: np.ndarray | None = None
    effort: np.ndarray | None = None
    current: np.ndarray | None = None
    velocity: np.ndarray | None = None


def encode(t_ns: np.ndarray, q: np.ndarray, names: Sequence[str], device_t_ns: np.ndarray | None = None,
           host_t_ns: np.ndarray | None = None, q_cmd: np.ndarray | None = None,
           effort: np.ndarray | None = None, current: np.ndarray | None = None,
           velocity: np.ndarray | None = None) -> bytes:
    """One message: samples at `t_ns` (n,) ns since the epoch (stored as `timestamp_ns` = t[0] and
    offsets t − t[0]), positions `q` (n, len(names)) rad; optional raw device times and host
    receive times (n,) ns; optional commanded positions (rad / m), efforts (N·m / N), motor currents (A) and
    velocities (rad/s / m/s), (n, len(names))."""
    t = np.asarray(t_ns, np.int64)
    q = np.asarray(q, np.float64)
    if t.ndim != 1 or not t.size or q.shape != (t.size, len(names)):
        raise ValueError(f"positions of shape {q.shape} for {t.size} samples of {len(names)} joints")
    m = JointStateBatch(timestamp_ns=int(t[0]), joint_names=list(names), sample_offsets_ns=(t - t[0]).tolist(),
                        positions=q.ravel().tolist())
    for key, v in zip(OPTIONAL_TIMES, (device_t_ns, host_t_ns)):
        if v is not None:
            v = np.asarray(v, np.int64)
            if v.shape != t.shape:
                raise ValueError(f"{key} has {v.size} values for {t.size} samples")
            getattr(m, key).extend(v.tolist())
    for key, v in zip(STREAM_SAMPLES, (q_cmd, effort, current, velocity)):
        if v is not None:
            v = np.asarray(v, np.float64)
            if v.shape != q.shape:
                raise ValueError(f"{key} of shape {v.shape} for positions of shape {q.shape}")
            getattr(m, key).extend(v.ravel().tolist())
    return m.SerializeToString()


def from_dict(msg: dict) -> bytes:
    """A JSON-form batch (the legacy `robocal.JointState` body) as one protobuf message."""
    q = np.asarray(msg["positions"], np.float64)
    names = msg["joint_names"]
    q = q.reshape(-1, len(names)) if q.size == 0 else q
    drive = [None if msg.get(k) is None else np.asarray(msg[k], np.float64).reshape(q.shape) for k in STREAM_SAMPLES]
    return encode(np.asarray(msg["timestamps_ns"], np.int64), q, names,
                  *(msg.get(k) for k in OPTIONAL_TIMES), *drive)


def _parse(record: int, body: bytes):
    m = JointStateBatch()
    try:
        m.ParseFromString(body)
    except DecodeError as e:
        raise BatchError(record, f"does not decode as {SCHEMA_NAME} ({e})") from None
    if len(UnknownFieldSet(m)):
        nums = sorted({f.field_number for f in UnknownFieldSet(m)})
        raise BatchError(record, f"holds fields {nums} that {SCHEMA_NAME} does not define (or of another type)")
    return m


def _join(msgs: list, key: str, dtype: type) -> np.ndarray:
    """One repeated field of every message, concatenated (numpy reads each packed field in C)."""
    return np.concatenate([np.array(getattr(m, key), dtype) for m in msgs])


def decode(raw: Sequence[bytes]) -> Batches:
    """Every message of the stream as arrays.  Each is parsed against the schema and checked: no
    unknown fields, joint names present and the same as the first message's, len(positions) =
    samples × joints, optional times empty or one per sample, positions finite.  Raises
    `BatchError` for the first that is not.  Python loops run per message, never per sample."""
    if not raw:
        raise BatchError(0, "no messages")
    msgs = [_parse(i, b) for i, b in enumerate(raw)]
    names = tuple(msgs[0].joint_names)
    nj = len(names)
    if not nj:
        raise BatchError(0, "joint_names is empty")
    n = np.fromiter((len(m.sample_offsets_ns) for m in msgs), np.int64, len(msgs))
    n_q = np.fromiter((len(m.positions) for m in msgs), np.int64, len(msgs))
    for i, m in enumerate(msgs):
        if tuple(m.joint_names) != names:
            raise BatchError(i, f"joint_names {list(m.joint_names)} differ from the first message's {list(names)}")
        if n[i] == 0:
            raise BatchError(i, "sample_offsets_ns is empty")
        if n_q[i] != n[i] * nj:
            raise BatchError(i, f"positions has {n_q[i]} values, expected {n[i]} samples × {nj} joints")
    total = int(n.sum())
    index = np.repeat(np.arange(len(msgs)), n)
    t0 = np.fromiter((m.timestamp_ns for m in msgs), np.int64, len(msgs))
    t = t0[index] + _join(msgs, "sample_offsets_ns", np.int64)
    q = _join(msgs, "positions", np.float64).reshape(total, nj)
    with np.errstate(over="ignore", invalid="ignore"):
        total_q = q.sum()
    if not np.isfinite(total_q):  # one pass; NaN/inf (or an overflowing sum) located below
        bad = ~np.isfinite(q).all(axis=1)
        if bad.any():
            raise BatchError(int(index[np.argmax(bad)]), "positions hold NaN or inf")
    extra = []
    for key in OPTIONAL_TIMES:
        k = np.fromiter((len(getattr(m, key)) for m in msgs), np.int64, len(msgs))
        if not k.any():
            extra.append(None)
            continue
        wrong = np.flatnonzero(k != n)
        if wrong.size:
            i = int(wrong[0])
            raise BatchError(i, f"{key} has {k[i]} values for {n[i]} samples")
        extra.append(_join(msgs, key, np.int64))
    for key in STREAM_SAMPLES:
        extra.append(_drive(msgs, key, n * nj, index, total, nj))
    return Batches(t, q, names, index, *extra)


def _drive(msgs: list, key: str, want: np.ndarray, index: np.ndarray, total: int, nj: int) -> np.ndarray | None:
    """One optional drive-state field of every message as (T, nj), None when no message has it;
    a message whose field is neither empty nor samples × joints, or holds NaN/inf, is a `BatchError`."""
    k = np.fromiter((len(getattr(m, key)) for m in msgs), np.int64, len(msgs))
    if not k.any():
        return None
    wrong = np.flatnonzero(k != want)
    if wrong.size:
        i = int(wrong[0])
        raise BatchError(i, f"{key} has {k[i]} values, expected {want[i] // nj} samples × {nj} joints "
                            "(or none in every message)")
    v = _join(msgs, key, np.float64).reshape(total, nj)
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise BatchError(int(index[np.argmax(bad)]), f"{key} hold NaN or inf")
    return v


def to_dict(body: bytes, record: int = 0) -> dict:
    """One message in the legacy JSON form (positions as rows), for code that reads bodies as dicts."""
    m = _parse(record, body)
    nj = max(len(m.joint_names), 1)
    q = np.asarray(m.positions, np.float64)
    t = np.asarray(m.sample_offsets_ns, np.int64) + np.int64(m.timestamp_ns)
    out = {"timestamp_ns": int(m.timestamp_ns), "timestamps_ns": t.tolist(),
           "joint_names": list(m.joint_names),
           "positions": q.reshape(-1, nj).tolist() if q.size % nj == 0 else q.tolist()}
    for key in OPTIONAL_TIMES:
        if len(getattr(m, key)):
            out[key] = list(getattr(m, key))
    for key in STREAM_SAMPLES:
        v = np.asarray(getattr(m, key), np.float64)
        if v.size:
            out[key] = v.reshape(-1, nj).tolist() if v.size % nj == 0 else v.tolist()
    return out


def _describe(f: tuple | None) -> str:
    if f is None:
        return "missing"
    label = "repeated " if f[3] == _F.LABEL_REPEATED else ""
    return f"{label}{_F.Type.Name(f[2]).removeprefix('TYPE_').lower()} {f[0]} = {f[1]}"


def descriptor_problem(schema_name: str, schema_encoding: str, data: bytes) -> str:
    """'' when a channel's registered schema is robocal.JointStateBatch as robocal defines it
    (a FileDescriptorSet whose message has exactly `FIELDS`, or lacks only the fields added later,
    `ADDED_LATER`: a recording written before them), else what differs."""
    if schema_encoding != ENCODING or schema_name != SCHEMA_NAME:
        return f"registered schema is {schema_name!r} ({schema_encoding}), expected {SCHEMA_NAME!r} ({ENCODING})"
    try:
        fds = D.FileDescriptorSet.FromString(bytes(data))
    except DecodeError:
        return "registered schema data is not a serialized FileDescriptorSet"
    for fd in fds.file:
        if fd.package != "robocal":
            continue
        for msg in fd.message_type:
            if msg.name == "JointStateBatch":
                got = {f.number: (f.name, f.number, f.type, f.label) for f in msg.field}
                for want in FIELDS:
                    have = got.pop(want[1], None)
                    if have is None and want[1] in ADDED_LATER:
                        continue
                    if have != want:
                        return (f"registered {SCHEMA_NAME}: field {want[1]} is {_describe(have)}, robocal reads "
                                f"{_describe(want)}")
                if got:
                    return f"registered {SCHEMA_NAME} has fields robocal does not read: {_describe(min(got.items())[1])}"
                return ""
    return f"registered FileDescriptorSet does not define {SCHEMA_NAME}"


def bad_records(raw: Sequence[bytes]) -> list[tuple[int, str]]:
    """Every message that does not match the schema, as (record, why): what `decode` checks, but
    each message on its own (joint names compared with the first message that parses), so the
    validate stage can name them all."""
    out, names = [], None
    for i, body in enumerate(raw):
        try:
            m = _parse(i, body)
        except BatchError as e:
            out.append((i, e.why))
            continue
        nm, n, nq = tuple(m.joint_names), len(m.sample_offsets_ns), len(m.positions)
        names = nm if names is None else names
        why = ("joint_names is empty" if not nm else
               f"joint_names {list(nm)} differ from the first message's {list(names)}" if nm != names else
               "sample_offsets_ns is empty" if not n else
               f"positions has {nq} values, expected {n} samples × {len(nm)} joints" if nq != n * len(nm) else
               next((f"{k} has {len(getattr(m, k))} values for {n} samples" for k in OPTIONAL_TIMES
                     if len(getattr(m, k)) not in (0, n)), "") or
               next((f"{k} has {len(getattr(m, k))} values, expected {n} samples × {len(nm)} joints"
                     for k in STREAM_SAMPLES if len(getattr(m, k)) not in (0, nq)), "") or
               next((f"{k} hold NaN or inf" for k in ("positions", *STREAM_SAMPLES)
                     if not np.isfinite(np.asarray(getattr(m, k), np.float64)).all()), ""))
        if why:
            out.append((i, why))
    return out
