"""Recording format: schemas registered, bodies conform, lossless round trip, no truth in the file."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
from mcap.reader import make_reader

from pipeline.ingest.streams import contacts, joint_stream
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import CHANNELS, META_CAMPAIGN, META_FIXTURE, META_ROBOT, schema, schema_bytes, validator
from pipeline.recording.writer import RecordingWriter
from pipeline.systems.arc_welder import nominal_arm


def test_independent_reader_sees_jsonschema_channels_and_conforming_bodies(arc_default):
    rec_path, _ = arc_default
    with open(rec_path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {"/robot/joint_state", "/touch/contact"}
        for topic, ch in topics.items():
            sch = summary.schemas[ch.schema_id]
            assert ch.message_encoding == "json" and sch.encoding == "jsonschema"
            assert sch.data == schema_bytes(CHANNELS[topic])  # the file in schemas/, byte for byte
        n = 0
        for _schema, channel, message in reader.iter_messages():
            body = json.loads(message.data)
            if channel.topic == "/touch/contact" or n % 10 == 0:  # pure-Python jsonschema is slow on big arrays
                validator(CHANNELS[channel.topic]).validate(body)
            assert message.log_time == body["timestamp_ns"]
            n += 1
        assert n == summary.statistics.message_count


def test_metadata_carries_the_nominal_model_and_jig_not_the_truth(arc_default):
    rec_path, truth = arc_default
    rec = read_recording(rec_path)
    assert rec.metadata[META_ROBOT] == nominal_arm().to_dict()
    assert rec.metadata[META_ROBOT] != truth["model"]
    jsonschema.validate(rec.metadata[META_FIXTURE], schema("jig"))
    assert rec.metadata[META_CAMPAIGN]["system"] == "arc-welder"
    raw = rec_path.read_bytes()
    assert b"injected" not in raw and b"truth" not in raw.lower()


def test_round_trip_is_byte_for_byte(arc_default, tmp_path):
    """Read a recording and write its content again: the same bytes."""
    rec_path, _ = arc_default
    rec = read_recording(rec_path)
    out = tmp_path / "again.mcap"
    with open(rec_path, "rb") as f:
        order = [(ch.topic, m.log_time) for _s, ch, m in make_reader(f).iter_messages(log_time_order=False)]
    bodies = {t: iter(rec.messages[t]) for t in rec.messages}
    with RecordingWriter(out) as w:
        for name in (META_ROBOT, META_FIXTURE, META_CAMPAIGN):
            w.metadata(name, rec.metadata[name])
        for topic, log_time in order:
            w.write(topic, next(bodies[topic]), log_time)
    assert out.read_bytes() == rec_path.read_bytes()


def test_stream_fast_path_equals_checked_path(arc_default):
    from pipeline.ingest.streams import _joint_stream_checked

    rec = read_recording(arc_default[0])
    fast, slow = joint_stream(rec), _joint_stream_checked(rec)
    np.testing.assert_array_equal(fast.q, slow.q)
    np.testing.assert_array_equal(fast.t_ns, slow.t_ns)
    assert fast.names == slow.names == tuple(f"J{i}" for i in range(1, 7))
    assert np.all(np.diff(fast.t_ns) > 0)
    c = contacts(rec)
    assert c["joint_positions"].shape == (100, 6) and set(np.unique(c["axis"])) == {0, 1, 2}
