"""Recording format: schemas registered, bodies conform, lossless round trip, no truth in the file."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
from mcap.reader import make_reader

from pipeline.ingest.streams import contacts, joint_stream
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import CHANNELS, META_CAMPAIGN, META_FIXTURE, META_ROBOT, schema, schema_bytes, validator
from pipeline.recording.writer import RecordingWriter
from pipeline.systems.arc_welder import nominal_arm


def test_independent_reader_sees_registered_channels_and_conforming_bodies(arc_default):
    """Contacts: JSON with their JSON Schema (the file in schemas/); the encoder stream: protobuf
    with the FileDescriptorSet of robocal.JointStateBatch (decoded in tests/test_binary_stream.py)."""
    rec_path, _ = arc_default
    with open(rec_path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        # robocal's channels, and the robot for ROS / Foxglove tools (tests/test_recording_scene.py)
        assert set(topics) == {"/robot/joint_state", "/touch/contact", "/tf", "/robot_description"}
        ch = topics["/touch/contact"]
        sch = summary.schemas[ch.schema_id]
        assert ch.message_encoding == "json" and sch.encoding == "jsonschema"
        assert sch.data == schema_bytes(CHANNELS["/touch/contact"])  # the file in schemas/, byte for byte
        ch = topics["/robot/joint_state"]
        sch = summary.schemas[ch.schema_id]
        assert ch.message_encoding == sch.encoding == "protobuf" and sch.name == JSB.SCHEMA_NAME
        assert sch.data == JSB.FILE_DESCRIPTOR_SET
        n = 0
        for _schema, channel, message in reader.iter_messages():
            if channel.topic in ("/tf", "/robot_description"):
                n += 1
                continue
            if channel.topic == "/touch/contact":
                body = json.loads(message.data)
                validator(CHANNELS[channel.topic]).validate(body)
            else:
                body = JSB.to_dict(message.data)
            assert message.log_time == message.publish_time == body["timestamp_ns"]
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


def test_stream_decodes_as_its_messages_read_one_by_one(arc_default):
    rec = read_recording(arc_default[0])
    fast = joint_stream(rec)
    msgs = rec.messages["/robot/joint_state"]  # each message on its own, in the JSON form
    slow = type(fast)(np.concatenate([m["timestamps_ns"] for m in msgs]),
                      np.concatenate([m["positions"] for m in msgs]), tuple(msgs[0]["joint_names"]), fast.message_index)
    np.testing.assert_array_equal(fast.q, slow.q)
    np.testing.assert_array_equal(fast.t_ns, slow.t_ns)
    assert fast.names == slow.names == tuple(f"J{i}" for i in range(1, 7))
    assert np.all(np.diff(fast.t_ns) > 0)
    c = contacts(rec)
    assert c["joint_positions"].shape == (100, 6) and set(np.unique(c["axis"])) == {0, 1, 2}
