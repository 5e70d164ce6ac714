"""Decode robocal channels into numpy columns, checking every record on the way.

Each extractor raises `RobocalError` naming file, channel and record (message index on
its channel) for a missing field, a wrong shape, or a NaN/inf value.
"""

from __future__ import annotations

import io
import re
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import orjson
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pa_csv
import pyarrow.json as pa_json

from pipeline.errors import RobocalError, where
from pipeline.recording.reader import Recording

JOINT_STATE = "/robot/joint_state"
TOUCH_CONTACT = "/touch/contact"


@dataclass(frozen=True)
class JointStream:
    """The encoder stream: sample times (ns since epoch), positions (T, n_joints) rad."""

    t_ns: np.ndarray
    q: np.ndarray
    names: tuple[str, ...]
    message_index: np.ndarray  # (T,) message each sample came from

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
    """Concatenate the batched `/robot/joint_state` messages.

    Three paths, the first that succeeds wins, all giving the same arrays:
    1. canonical: every message is the compact JSON robocal writes (`_canonical_pattern`; checked
       in one pass by RE2, which proves each message valid JSON of exactly that shape: the same
       joint names, rows of n_joints numbers, no NaN/inf literal); its numbers are then parsed by
       pyarrow's CSV reader (correctly rounded, like any JSON parser) with no Python per sample;
    2. any JSON: pyarrow's JSON reader over all message bodies, flattened without Python loops;
    3. checked: message by message, naming the first bad record (file, channel, record) for a
       parse error, a missing field, ragged rows, NaN/inf or changing joint names.
    A path that finds anything irregular hands over to the next.
    """
    raw = rec.messages.raw.get(JOINT_STATE) or rec.require(JOINT_STATE)
    for path in (_joint_stream_canonical, _joint_stream_arrow):
        try:
            fast = path(raw)
        except (pa.ArrowInvalid, ValueError, KeyError, TypeError, IndexError):
            fast = None
        if fast is not None:
            return fast
    return _joint_stream_checked(rec)


_INT = r"-?(?:0|[1-9][0-9]{0,18})"
# a JSON number that cannot overflow a double (≤ 16 integer digits, 2 exponent digits): no inf
_NUM = r"-?(?:0|[1-9][0-9]{0,15})(?:\.[0-9]+)?(?:[eE][+-]?[0-9]{1,2})?"
_INTS = rf"\[{_INT}(?:,{_INT})*\]"
_TS_KEY, _Q_KEY = b'"timestamps_ns":[', b'"positions":[['
_TO_LINES = bytes.maketrans(b",", b"\n")
_PLAIN_NAME = re.compile(r"[A-Za-z0-9_.\-]+")  # a joint name that reads the same in JSON and (escaped) in RE2


def _canonical_pattern(names: list[str]) -> str:
    """RE2 pattern of one canonical `/robot/joint_state` body (`recording.writer`, `acquire.session`):
    keys in the writer's order, no whitespace, these joint names, rows of len(names) numbers, and the
    acquisition's optional device / host time lists.  Anything else goes to the general paths."""
    name_list = ",".join(f'"{re.escape(nm)}"' for nm in names)
    row = rf"\[{_NUM}(?:,{_NUM}){{{len(names) - 1}}}\]"
    return (rf'^\{{"timestamp_ns":{_INT},"timestamps_ns":{_INTS},"joint_names":\[{name_list}\],'
            rf'"positions":\[{row}(?:,{row})*\](?:,"device_timestamps_ns":{_INTS})?'
            rf'(?:,"host_receive_times_ns":{_INTS})?\}}$')


def _joint_stream_canonical(raw: list[bytes]) -> JointStream | None:
    names = orjson.loads(raw[0])["joint_names"]
    if not (isinstance(names, list) and names and all(isinstance(nm, str) and _PLAIN_NAME.fullmatch(nm)
                                                      for nm in names)):
        return None
    # RE2 proves the bodies canonical (C++, without the GIL) while the numbers are parsed here; the
    # parse is kept only when the proof holds (on other input it may fail or read nonsense: discarded)
    with ThreadPoolExecutor(1) as pool:
        proof = pool.submit(lambda: pc.all(pc.match_substring_regex(pa.array(raw, pa.binary()),
                                                                    _canonical_pattern(names))).as_py())
        try:
            out = _parse_canonical(raw, names)
        except Exception:
            if proof.result():
                raise
            return None
        return out if proof.result() else None


def _parse_canonical(raw: list[bytes], names: list[str]) -> JointStream | None:
    """The numbers of bodies in `_canonical_pattern`'s form (trusted here, proved by the caller)."""
    nj = len(names)
    ts, qs = [], []
    n_t, n_q = np.empty(len(raw), np.int64), np.empty(len(raw), np.int64)
    for i, m in enumerate(raw):  # per message (≈ 250 samples), not per sample: slices of the validated bodies
        a = m.index(_TS_KEY) + len(_TS_KEY)
        b = m.index(b"]", a)
        c = m.index(_Q_KEY, b) + len(_Q_KEY)
        d = m.rindex(b"]]")  # what follows the positions holds no nested list
        n_t[i] = m.count(b",", a, b) + 1
        n_q[i] = (m.count(b",", c, d) + 1) // nj  # rows of exactly nj numbers (the pattern)
        ts.append(m[a:b])
        qs.append(m[c:d].translate(_TO_LINES, b"[]"))  # one number per line
    if not np.array_equal(n_t, n_q):
        return None
    t = _csv_column(b"\n".join(ts).translate(_TO_LINES), pa.int64())
    q = _csv_column(b"\n".join(qs), pa.float64()).reshape(-1, nj)
    if t.size != n_t.sum() or q.shape[0] != t.size or not np.all(np.isfinite(q)):
        return None
    return JointStream(t_ns=t, q=q, names=tuple(names), message_index=np.repeat(np.arange(len(raw)), n_t))


def _csv_column(lines: bytes, kind: pa.DataType) -> np.ndarray:
    """Numbers, one per line (already checked to be JSON numbers), as a numpy array of `kind`."""
    table = pa_csv.read_csv(io.BytesIO(lines),
                            read_options=pa_csv.ReadOptions(column_names=["v"], block_size=1 << 22),
                            parse_options=pa_csv.ParseOptions(quote_char=False),
                            convert_options=pa_csv.ConvertOptions(column_types={"v": kind}, null_values=[]))
    return table.column(0).to_numpy()


def _joint_stream_arrow(raw: list[bytes]) -> JointStream | None:
    if not all(m.lstrip()[:1] == b"{" for m in raw):
        return None  # pyarrow 26's JSON reader crashes (SIGSEGV) on a first line `null` (issue 15)
    table = pa_json.read_json(io.BytesIO(b"\n".join(raw)),
                              read_options=pa_json.ReadOptions(block_size=max(1 << 20, 2 * max(map(len, raw)))))
    names_col = table.column("joint_names").combine_chunks()
    names = tuple(names_col[0].as_py())
    nj = len(names)
    if len(set(map(tuple, names_col.to_pylist()))) != 1:
        return None
    t_col = table.column("timestamps_ns").combine_chunks()
    pos = table.column("positions").combine_chunks()
    rows = pos.flatten()
    t = t_col.flatten().to_numpy()
    counts_t = np.diff(t_col.offsets.to_numpy())
    counts_q = np.diff(pos.offsets.to_numpy())
    row_len = np.diff(rows.offsets.to_numpy())
    if not (np.array_equal(counts_t, counts_q) and np.all(row_len == nj)):
        return None
    q = rows.flatten().to_numpy(zero_copy_only=False).reshape(-1, nj)
    if not np.all(np.isfinite(q)):
        return None
    return JointStream(t_ns=t.astype(np.int64, copy=False), q=q, names=names,
                       message_index=np.repeat(np.arange(counts_t.size), counts_t))


def _joint_stream_checked(rec: Recording) -> JointStream:
    msgs = rec.require(JOINT_STATE)
    names = tuple(_field(rec, JOINT_STATE, 0, msgs[0], "joint_names"))
    ts, qs, idx = [], [], []
    for i, m in enumerate(msgs):
        t = np.asarray(_field(rec, JOINT_STATE, i, m, "timestamps_ns"), dtype=np.int64)
        try:
            q = np.asarray(_field(rec, JOINT_STATE, i, m, "positions"), dtype=float)
        except (ValueError, TypeError):
            raise RobocalError(f"{where(rec.path, JOINT_STATE, i)}: 'positions' rows differ in length or are not numbers") from None
        if q.ndim != 2 or q.shape != (t.size, len(names)):
            raise RobocalError(f"{where(rec.path, JOINT_STATE, i)}: 'positions' has shape {q.shape}, "
                               f"expected ({t.size}, {len(names)})")
        if tuple(m.get("joint_names", names)) != names:
            raise RobocalError(f"{where(rec.path, JOINT_STATE, i)}: joint_names change within the recording")
        _finite(rec, JOINT_STATE, i, "positions", q)
        ts.append(t)
        qs.append(q)
        idx.append(np.full(t.size, i))
    return JointStream(t_ns=np.concatenate(ts), q=np.concatenate(qs), names=names,
                       message_index=np.concatenate(idx))


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
