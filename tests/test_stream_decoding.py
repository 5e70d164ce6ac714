"""Archived encoder streams (JSON batches, written before the protobuf stream): `legacy_json_stream` decodes them
bit-identically to an independent reference (the standard library's json + numpy), and a record
it cannot take is a one-line error naming file, channel and record."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pipeline.errors import RobocalError
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.recording.reader import Recording, read_recording
from pipeline.recording.writer import encode, joint_state_messages

ROOT = Path(__file__).resolve().parents[1]
ARCHIVED = ("arc-welder-touch", "delta-tracker", "scorbot-scanner")


def recording_of(bodies: list[bytes]) -> Recording:
    rec = Recording(path=Path("test.mcap"))
    rec.messages.raw[JOINT_STATE] = list(bodies)
    return rec


def reference(raw: list[bytes]) -> tuple[np.ndarray, np.ndarray, tuple, np.ndarray]:
    """The stream as the standard library reads it (no robocal code)."""
    msgs = [json.loads(b) for b in raw]
    t = np.concatenate([np.array(m["timestamps_ns"], np.int64) for m in msgs])
    q = np.concatenate([np.array(m["positions"], float) for m in msgs])
    idx = np.concatenate([np.full(len(m["timestamps_ns"]), i) for i, m in enumerate(msgs)])
    return t, q, tuple(msgs[0]["joint_names"]), idx


def same(s, ref) -> bool:
    """Bitwise equality with the reference (−0.0 and 0.0 differ)."""
    t, q, names, idx = ref
    return (s.names == names and np.array_equal(s.t_ns, t) and s.t_ns.dtype == np.int64
            and np.array_equal(s.message_index, idx) and s.q.shape == q.shape
            and np.array_equal(s.q.view(np.int64), q.view(np.int64)))


floats = st.one_of(st.floats(-10, 10), st.floats(-1e-3, 1e-3), st.floats(-1e290, 1e290),  # np.round(q, 9) stays finite
                   st.sampled_from([0.0, -0.0, 1e-5, -1.2e-8, 5e-324, 1e16, 1.5e290]))


@settings(max_examples=60, deadline=None)
@given(nj=st.integers(1, 7), data=st.data(), batch=st.integers(1, 40), rounded=st.booleans(),
       acquired=st.booleans())
def test_legacy_json_stream_equals_the_standard_library(nj, data, batch, rounded, acquired):
    """Random streams as the old writer (or acquisition) wrote them decode bit-identically to
    json + numpy (correctly rounded doubles, −0.0, subnormals, exponents)."""
    T = data.draw(st.integers(1, 120))
    q = data.draw(hnp.arrays(float, (T, nj), elements=floats))
    t = 1_767_225_600_000_000_000 + np.cumsum(data.draw(hnp.arrays(np.int64, T, elements=st.integers(1, 10**7))))
    names = [f"J{i + 1}" for i in range(nj)]
    if rounded:
        msgs = joint_state_messages(t, q, names, batch)  # the simulator: 1 nrad resolution
    else:
        msgs = [{"timestamp_ns": int(t[s]), "timestamps_ns": t[s:s + batch].tolist(), "joint_names": names,
                 "positions": q[s:s + batch].tolist()} for s in range(0, T, batch)]
    if acquired:
        for m in msgs:
            m["device_timestamps_ns"] = [v - 5 for v in m["timestamps_ns"]]
            m["host_receive_times_ns"] = [v + 7 for v in m["timestamps_ns"]]
    raw = [encode(m) for m in msgs]
    assert same(joint_stream(recording_of(raw)), reference(raw))


def _first_value(body: bytes, text: bytes) -> bytes:
    """The body with its first position value's text replaced by `text`."""
    return re.sub(rb'"positions":\[\[[^,]+', b'"positions":[[' + text, body, count=1)


CORRUPT = {
    "trailing_dot": lambda b: _first_value(b, b"1."),
    "nan": lambda b: _first_value(b, b"NaN"),
    "huge": lambda b: _first_value(b, b"1e400"),
    "string": lambda b: _first_value(b, b'"0.1"'),
    "leading_zero": lambda b: _first_value(b, b"01"),
    "ragged": lambda b: b.replace(b"],[", b",0.5],[", 1),
    "truncated": lambda b: b[: len(b) // 2],
    "names": lambda b: b.replace(b'"J2"', b'"J9"'),
    "missing_positions": lambda b: b.replace(b'"positions"', b'"position"'),
    "more_timestamps": lambda b: b.replace(b'"timestamps_ns":[', b'"timestamps_ns":[1,', 1),
    "float_time": lambda b: b.replace(b'"timestamps_ns":[', b'"timestamps_ns":[1.5,', 1),
    "huge_time": lambda b: b.replace(b'"timestamps_ns":[', b'"timestamps_ns":[' + str(2**64).encode() + b",", 1),
}


@pytest.mark.parametrize("kind", sorted(CORRUPT))
def test_a_bad_archived_record_is_one_line_naming_file_channel_record(kind):
    q = np.random.default_rng(1).uniform(-1, 1, (60, 6))
    t = 1_767_225_600_000_000_000 + 4_000_000 * np.arange(60)
    raw = [encode(m) for m in joint_state_messages(t, q, [f"J{i}" for i in range(1, 7)], 20)]
    raw[1] = CORRUPT[kind](raw[1])
    with pytest.raises(RobocalError) as e:
        joint_stream(recording_of(raw))
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"test.mcap: channel {JOINT_STATE}: record 1: "), msg


@pytest.mark.parametrize("kind", ["spaces", "key_order"])
def test_valid_json_in_another_layout_decodes_the_same(kind):
    q = np.random.default_rng(2).uniform(-1, 1, (60, 6))
    t = 1_767_225_600_000_000_000 + 4_000_000 * np.arange(60)
    raw = [encode(m) for m in joint_state_messages(t, q, [f"J{i}" for i in range(1, 7)], 20)]
    raw[1] = raw[1].replace(b",", b", ") if kind == "spaces" else raw[1].replace(b'{"timestamp_ns"', b'{"x":1,"timestamp_ns"', 1)
    assert same(joint_stream(recording_of(raw)), reference(raw))


@pytest.mark.parametrize("name", ARCHIVED)
def test_bundled_archived_recordings_decode_as_the_standard_library_reads_them(name):
    rec = read_recording(ROOT / "recordings" / f"{name}.mcap")
    assert rec.encodings[JOINT_STATE] == "json" and not rec.registration[JOINT_STATE]
    assert same(joint_stream(rec), reference(rec.messages.raw[JOINT_STATE]))
