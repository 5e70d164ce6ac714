"""The encoder stream as protobuf `robocal.JointStateBatch` in real MCAP files.

Round trip exact; an independent reader (mcap's standard protobuf DecoderFactory, no robocal code)
decodes the stream to the same arrays; the schema robocal registers is what protoc makes of
schemas/joint_state_batch.proto; the archived JSON recording and its protobuf upgrade give the
same calibration; a message that does not match its schema is one line naming file, channel and
record, with a non-zero exit.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from mcap.reader import make_reader

from hostile_support import rebuild
from stream_support import bits
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import read_recording
from pipeline.recording.upgrade import upgrade
from pipeline.recording.writer import RecordingWriter

ROOT = Path(__file__).resolve().parents[1]
ARC_JSON = ROOT / "recordings" / "arc-welder-touch.mcap"
ARC_PB = ROOT / "recordings" / "arc-welder-touch-pb.mcap"
DELTA_JSON = ROOT / "recordings" / "delta-tracker.mcap"


@settings(max_examples=40, deadline=None)
@given(nj=st.integers(1, 7), data=st.data(), batch=st.integers(1, 300), acquired=st.booleans())
def test_round_trip_through_a_real_mcap_file_is_exact(nj, data, batch, acquired):
    """Any doubles (−0.0, subnormals, the largest finite) and any int64 times come back bit for bit."""
    T = data.draw(st.integers(1, 700))
    q = data.draw(hnp.arrays(np.float64, (T, nj), elements=st.floats(allow_nan=False, allow_infinity=False)))
    t = data.draw(st.integers(0, 2**62)) + np.cumsum(  # MCAP log times are unsigned
        data.draw(hnp.arrays(np.int64, T, elements=st.integers(1, 10**9))))
    dev = data.draw(hnp.arrays(np.int64, T, elements=st.integers(-2**63, 2**63 - 1))) if acquired else None
    names = [f"joint {i}" for i in range(nj)]
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "s.mcap"
        with RecordingWriter(path) as w:
            for s in range(0, T, batch):
                sl = slice(s, s + batch)
                w.write_batch(t[sl], q[sl], names, None if dev is None else dev[sl], None if dev is None else t[sl] + 7)
        rec = read_recording(path)
    s = joint_stream(rec)
    assert s.names == tuple(names) and s.q.shape == (T, nj)
    assert np.array_equal(s.t_ns, t) and np.array_equal(bits(s.q), bits(q))
    assert np.array_equal(s.message_index, np.arange(T) // batch)
    b = JSB.decode(rec.messages.raw[JOINT_STATE])
    assert (b.device_t_ns is None) == (dev is None)
    if dev is not None:
        assert np.array_equal(b.device_t_ns, dev) and np.array_equal(b.host_t_ns, t + 7)


def test_the_standard_mcap_protobuf_decoder_reads_the_same_arrays():
    """mcap's DecoderFactory for protobuf (mcap-protobuf-support), given only the file, decodes
    every stream message; its arrays equal robocal's reader's, bit for bit."""
    from mcap_protobuf.decoder import DecoderFactory

    rows_t, rows_q, names = [], [], set()
    with open(ARC_PB, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, m in reader.iter_decoded_messages(topics=[JOINT_STATE]):
            assert schema.name == "robocal.JointStateBatch" and channel.message_encoding == "protobuf"
            assert type(m).__name__ == "JointStateBatch" and message.log_time == m.timestamp_ns
            assert m.sample_offsets_ns[0] == 0
            names.add(tuple(m.joint_names))
            rows_t.append(m.timestamp_ns + np.array(m.sample_offsets_ns, np.int64))
            rows_q.append(np.array(m.positions, np.float64).reshape(len(m.sample_offsets_ns), len(m.joint_names)))
    s = joint_stream(read_recording(ARC_PB))
    assert names == {s.names} and len(rows_t) == s.message_index[-1] + 1
    assert np.array_equal(np.concatenate(rows_t), s.t_ns)
    assert np.array_equal(bits(np.concatenate(rows_q)), bits(s.q))


def test_registered_schema_is_what_protoc_makes_of_the_proto_file(tmp_path):
    from google.protobuf import descriptor_pb2
    grpc_tools = pytest.importorskip("grpc_tools.protoc")

    out = tmp_path / "out.fds"
    assert grpc_tools.main(["protoc", f"-I{ROOT / 'schemas'}", f"--descriptor_set_out={out}",
                            str(ROOT / "schemas" / "joint_state_batch.proto")]) == 0
    fds = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes())
    assert list(fds.file) == [JSB.file_descriptor()]
    assert fds.SerializeToString(deterministic=True) == JSB.FILE_DESCRIPTOR_SET


def test_archived_json_and_protobuf_recordings_of_one_campaign_decode_and_calibrate_identically(tmp_path):
    """The bundled protobuf recording is the upgrade of the archived JSON one: the same stream bit for
    bit, every other message byte for byte, and the same calibration figures."""
    a, b = read_recording(ARC_JSON), read_recording(ARC_PB)
    assert a.encodings[JOINT_STATE] == "json" and b.encodings[JOINT_STATE] == "protobuf"
    assert not a.warnings and not b.warnings and not any(b.registration.values())
    sa, sb = joint_stream(a), joint_stream(b)
    assert sa.names == sb.names and np.array_equal(sa.t_ns, sb.t_ns)
    assert np.array_equal(sa.message_index, sb.message_index) and np.array_equal(bits(sa.q), bits(sb.q))
    for t in a.messages.raw:
        assert b.log_times[t] == a.log_times[t]
        if t != JOINT_STATE:
            assert b.messages.raw[t] == a.messages.raw[t]
    assert {k: v for k, v in b.metadata.items() if k != "robocal.upgrade"} == a.metadata
    again = tmp_path / "again.mcap"
    upgrade(ARC_JSON, again)
    assert read_recording(again).messages.raw[JOINT_STATE] == b.messages.raw[JOINT_STATE]  # reproducible

    from pipeline.stages.runner import run_pipeline

    figures = []
    for src in (ARC_JSON, ARC_PB):
        run = tmp_path / src.stem
        run_pipeline(src, run, stages=["ingest", "validate", "identify"])
        res = json.loads((run / "results.json").read_text())
        fit = json.loads((run / "identify" / "fit.json").read_text())
        keep = ("x", "std", "free", "cov", "sigma_m", "rms_before_m", "rms_after_m", "holdout_rms_m", "parameters")
        figures.append((res["summary"], {k: fit[k] for k in keep}, (run / "ingest" / "encoder.parquet").read_bytes()))
    assert figures[0] == figures[1] and figures[0][0]["status"] == "pass"


@pytest.fixture(scope="module")
def delta_pb(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("pb") / "delta-pb.mcap"
    upgrade(DELTA_JSON, p)
    return p


def _edit_stream(src: Path, dst: Path, record: int, fn) -> Path:
    return rebuild(src, dst, msg=lambda t, i, d: fn(d) if (t == JOINT_STATE and i == record) else d)


def _nan(body: bytes) -> bytes:
    m = JSB.JointStateBatch.FromString(body)
    m.positions[4] = float("nan")
    return m.SerializeToString()


def _short(body: bytes) -> bytes:
    m = JSB.JointStateBatch.FromString(body)
    del m.positions[-1]
    return m.SerializeToString()


BAD = {
    "truncated": lambda b: b[: len(b) // 2 + 3],
    "unknown_field": lambda b: b + b"\x38\x01",  # field 7, varint
    "wrong_wire_type": lambda b: b"\x19" + b"\x00" * 8 + b,  # field 3 (sample_offsets_ns, int64) as a fixed64
    "nan": _nan,
    "count_mismatch": _short,
    "other_names": lambda b: b.replace(b"A2", b"B2"),
}


def run_py(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=ROOT)


def one_line(proc: subprocess.CompletedProcess, *needles: str) -> str:
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    (line,) = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    for n in needles:
        assert n in line, (n, line)
    return line


@pytest.mark.parametrize("kind", sorted(BAD))
def test_a_message_that_does_not_match_its_schema_is_one_line_naming_file_channel_record(delta_pb, tmp_path, kind):
    """`robocal diagnose` decodes the stream itself: one line, exit 2.  `robocal run`: ingest records
    the error, validate names the record (and still checks every other channel), exit non-zero."""
    bad = _edit_stream(delta_pb, tmp_path / f"{kind}.mcap", 7, BAD[kind])
    one_line(run_py("diagnose", bad, "--out", tmp_path / "d"), f"{bad}: channel {JOINT_STATE}: record 7: ")
    proc = run_py("run", bad, "--out", tmp_path / "run", "--stages", "ingest,validate")
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("robocal: error: ") and str(bad) in last and JOINT_STATE in last and "record 7" in last, last
    checks = json.loads((tmp_path / "run" / "validate" / "validate.json").read_text())["checks"]
    schema = [c for c in checks if c["name"] == "schema" and c["channel"] == JOINT_STATE]
    assert schema[0]["status"] == "fail" and schema[0]["records"] == [7]
    # nothing else lost: the measurement channel was read and checked in full
    assert any(c["channel"] == "/tracker/point" and c["name"] == "schema" and c["status"] == "pass" for c in checks)


def test_a_stream_registered_with_another_schema_is_one_line(delta_pb, tmp_path):
    from google.protobuf import descriptor_pb2

    other = JSB.file_descriptor()
    other.message_type[0].field[3].type = other.message_type[0].field[3].TYPE_FLOAT  # positions as float32
    data = descriptor_pb2.FileDescriptorSet(file=[other]).SerializeToString()
    bad = rebuild(delta_pb, tmp_path / "float.mcap", channel=lambda t: {"schema_data": data} if t == JOINT_STATE else {})
    one_line(run_py("diagnose", bad, "--out", tmp_path / "o"), str(bad), f"channel {JOINT_STATE}",
             "field 4 is repeated float positions = 4, robocal reads repeated double positions = 4")
    bad = rebuild(delta_pb, tmp_path / "json.mcap", channel=lambda t: {"message_encoding": "json"} if t == JOINT_STATE else {})
    one_line(run_py("diagnose", bad, "--out", tmp_path / "j"), str(bad), f"channel {JOINT_STATE}", "robocal.JointStateBatch")


def test_upgrade_command_rewrites_only_the_stream(delta_pb, tmp_path):
    a, b = read_recording(DELTA_JSON), read_recording(delta_pb)
    assert list(b.messages.raw) == list(a.messages.raw) and b.log_times == a.log_times
    assert b.messages.raw["/tracker/point"] == a.messages.raw["/tracker/point"]
    assert b.metadata["robocal.upgrade"]["stream_messages"] == len(a.messages.raw[JOINT_STATE])
    assert b.messages[JOINT_STATE] == a.messages[JOINT_STATE]  # every field of every batch, JSON form
    proc = subprocess.run([sys.executable, "-m", "pipeline.recording.upgrade", delta_pb, tmp_path / "x.mcap"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2 and "not the JSON this tool upgrades" in proc.stderr and not (tmp_path / "x.mcap").exists()
