"""Encoder-stream decoding: the canonical fast path (RE2 check + pyarrow CSV numbers) gives the
same arrays, bit for bit, as the message-by-message checked path, and hands anything irregular
over to the general paths, which name the bad record."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pipeline.errors import RobocalError
from pipeline.ingest import streams
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.recording.reader import Recording, read_recording
from pipeline.recording.writer import encode, joint_state_messages


def recording_of(bodies: list[bytes]) -> Recording:
    rec = Recording(path=Path("test.mcap"))
    rec.messages.raw[JOINT_STATE] = list(bodies)
    return rec


def same(a, b) -> bool:
    """Bitwise equality of two `JointStream`s (−0.0 and 0.0 differ)."""
    return (a.names == b.names and np.array_equal(a.t_ns, b.t_ns) and a.t_ns.dtype == b.t_ns.dtype
            and np.array_equal(a.message_index, b.message_index)
            and a.q.shape == b.q.shape and np.array_equal(a.q.view(np.int64), b.q.view(np.int64)))


def decoded_or_error(fn, rec):
    try:
        return fn(rec)
    except RobocalError as e:
        return str(e)


# what `json.dumps` writes with at most two exponent digits (the canonical grammar); beyond, see below
floats = st.one_of(st.floats(-10, 10), st.floats(-1e-3, 1e-3), st.floats(-1e99, 1e99),
                   st.sampled_from([0.0, -0.0, 1e-5, -1.2e-8, 1e-99, 1e16, 123456789.123, 1.5e22])
                   ).filter(lambda v: v == 0 or 1e-99 <= abs(v) < 1e100)


@settings(max_examples=60, deadline=None)
@given(nj=st.integers(1, 7), data=st.data(), batch=st.integers(1, 40), rounded=st.booleans(),
       acquired=st.booleans())
def test_canonical_path_equals_checked_path(nj, data, batch, rounded, acquired):
    """Random streams as the writer (or the acquisition) writes them: the canonical path decodes
    them, bit-identical to the checked path (correctly rounded doubles, −0.0, exponents)."""
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
    fast = streams._joint_stream_canonical(raw)
    assert fast is not None
    assert same(fast, streams._joint_stream_checked(recording_of(raw)))


@pytest.mark.parametrize("value", [3e-300, -5e-324, 1e100, 1.7976931348623157e308])
def test_numbers_beyond_the_canonical_grammar_decode_on_the_general_path(value):
    q = np.full((10, 3), 0.25)
    q[4, 1] = value
    t = 1_767_225_600_000_000_000 + 4_000_000 * np.arange(10)
    raw = [encode({"timestamp_ns": int(t[s]), "timestamps_ns": t[s:s + 4].tolist(), "joint_names": ["a", "b", "c"],
                   "positions": q[s:s + 4].tolist()}) for s in range(0, 10, 4)]
    rec = recording_of(raw)
    assert streams._joint_stream_canonical(raw) is None
    got = joint_stream(rec)
    assert same(got, streams._joint_stream_checked(rec)) and got.q[4, 1] == value


def _first_value(body: bytes, text: bytes) -> bytes:
    """The body with its first position value's text replaced by `text`."""
    return re.sub(rb'"positions":\[\[[^,]+', b'"positions":[[' + text, body, count=1)


def _corrupt(kind: str, body: bytes) -> bytes:
    return {
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
        "spaces": lambda b: b.replace(b",", b", "),  # valid JSON, not the writer's: the general path
        "key_order": lambda b: b.replace(b'{"timestamp_ns"', b'{"extra":1,"timestamp_ns"', 1),
    }[kind](body)


@pytest.mark.parametrize("kind", ["trailing_dot", "nan", "huge", "ragged", "string", "truncated", "names",
                                  "leading_zero", "missing_positions", "more_timestamps", "spaces", "key_order"])
def test_irregular_records_leave_the_canonical_path_and_decode_or_fail_as_before(kind):
    """A record the canonical path does not recognise (corrupt, or valid JSON in another layout)
    is never decoded by it; `joint_stream` then returns exactly what the checked path returns, or
    raises its one-line error naming the record."""
    q = np.random.default_rng(1).uniform(-1, 1, (60, 6))
    t = 1_767_225_600_000_000_000 + 4_000_000 * np.arange(60)
    raw = [encode(m) for m in joint_state_messages(t, q, [f"J{i}" for i in range(1, 7)], 20)]
    assert streams._joint_stream_canonical(raw) is not None
    raw[1] = _corrupt(kind, raw[1])
    assert streams._joint_stream_canonical(raw) is None
    got = decoded_or_error(joint_stream, recording_of(raw))
    want = decoded_or_error(streams._joint_stream_checked, recording_of(raw))
    if isinstance(want, str):
        assert got == want and "record 1" in want, (got, want)
    else:
        assert not isinstance(got, str) and same(got, want)


def test_bundled_recordings_decode_identically_on_every_path():
    for path in sorted(Path(__file__).resolve().parents[1].glob("recordings/*.mcap")):
        rec = read_recording(path)
        raw = rec.messages.raw[JOINT_STATE]
        fast, arrow = streams._joint_stream_canonical(raw), streams._joint_stream_arrow(raw)
        checked = streams._joint_stream_checked(rec)
        assert fast is not None and same(fast, checked) and same(arrow, checked), path
