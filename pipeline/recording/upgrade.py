"""Upgrade an archived recording's encoder stream from JSON to protobuf.

    python -m pipeline.recording.upgrade OLD.mcap NEW.mcap

Every record of OLD is copied in file order — header profile, metadata, schemas, channels and
messages with their log/publish times and sequence numbers — except the encoder stream
(`/robot/joint_state`): its channel is registered as protobuf `robocal.JointStateBatch` (the
FileDescriptorSet as schema data) and each JSON batch becomes one protobuf message with the same
numbers (times ns, positions rad: doubles carried exactly, so the calibration is bit-identical).
A metadata record `robocal.upgrade` says what was done.  A file that is not a complete, intact
MCAP, or a stream message that does not decode, is a one-line `RobocalError` naming file, channel
and record; nothing is written then (NEW is removed).
"""

from __future__ import annotations

import argparse
import io
import hashlib
import json
import sys
from pathlib import Path

import numpy as np
from mcap.records import Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from pipeline import __version__
from pipeline.errors import RobocalError, where
from pipeline.recording.output import ACQUIRED, check_output
from pipeline.ingest.legacy_json_stream import decode_json_stream
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import MAGIC, decode
from pipeline.recording.schemas import STREAM

META_UPGRADE = "robocal.upgrade"


def batch_from_json(body: bytes, path: Path, record: int) -> bytes:
    """One legacy JSON batch as a protobuf message (checked as ingest checks it)."""
    t, q, names, _ = decode_json_stream([body], path, STREAM)
    msg = decode(body)
    extra = []
    for key in JSB.OPTIONAL_TIMES:
        v = msg.get(key)
        try:
            extra.append(None if v is None else np.asarray(v, np.int64))
        except (ValueError, TypeError, OverflowError):
            raise RobocalError(f"{where(path, STREAM, record)}: {key!r} is not a list of int64") from None
        if extra[-1] is not None and extra[-1].shape != t.shape:
            raise RobocalError(f"{where(path, STREAM, record)}: {key!r} has {extra[-1].size} values for {t.size} samples")
    return JSB.encode(t, q, names, *extra)


def upgrade(src: str | Path, dst: str | Path) -> dict:
    """Write `dst`: `src` with its JSON encoder stream as protobuf.  Returns counts."""
    src, dst = Path(src), Path(dst)
    if not src.is_file():
        raise RobocalError(f"{src}: no such file")
    if src.resolve() == dst.resolve():
        raise RobocalError(f"{dst}: upgrade writes a new file; choose another output path")
    check_output(dst, force=None)
    data = src.read_bytes()
    if data[:len(MAGIC)] != MAGIC:
        raise RobocalError(f"{src}: not an MCAP file (bad magic bytes)")
    stats = {"source": src.name, "source_sha256": hashlib.sha256(data).hexdigest(), "stream": STREAM,
             "from": "json", "to": f"{JSB.ENCODING} {JSB.SCHEMA_NAME}", "messages": 0, "stream_messages": 0,
             "robocal_version": __version__}
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    new_schema: dict[int, int] = {}
    new_channel: dict[int, int] = {}
    k = 0  # stream message index
    try:
        with open(dst, "wb") as out:
            w = Writer(out, compression=CompressionType.ZSTD)
            complete = False
            for r in StreamReader(io.BytesIO(data), validate_crcs=True).records:
                if isinstance(r, Header):
                    w.start(profile=r.profile, library=f"robocal/{__version__} upgrade"
                            + (f" {ACQUIRED}" if ACQUIRED in r.library.split() else ""))
                elif isinstance(r, Schema):
                    schemas[r.id] = r
                elif isinstance(r, Channel):
                    channels[r.id] = r
                elif isinstance(r, Message):
                    ch = channels[r.channel_id]
                    stream = ch.topic == STREAM
                    if stream and ch.message_encoding != "json":
                        raise RobocalError(f"{where(src, STREAM)}: message encoding is {ch.message_encoding!r}, "
                                           "not the JSON this tool upgrades")
                    if r.channel_id not in new_channel:
                        if stream:
                            sid = w.register_schema(JSB.SCHEMA_NAME, JSB.ENCODING, JSB.FILE_DESCRIPTOR_SET)
                            enc = JSB.ENCODING
                        else:
                            if ch.schema_id and ch.schema_id not in new_schema:
                                s = schemas[ch.schema_id]
                                new_schema[ch.schema_id] = w.register_schema(s.name, s.encoding, s.data)
                            sid, enc = new_schema.get(ch.schema_id, 0), ch.message_encoding
                        new_channel[r.channel_id] = w.register_channel(ch.topic, enc, sid, dict(ch.metadata))
                    body = batch_from_json(r.data, src, k) if stream else r.data
                    k += stream
                    w.add_message(new_channel[r.channel_id], r.log_time, body, r.publish_time, r.sequence)
                    stats["messages"] += 1
                elif isinstance(r, Metadata):
                    w.add_metadata(r.name, dict(r.metadata))
                elif isinstance(r, Footer):
                    complete = True
            if not complete:
                raise RobocalError(f"{src}: file ends without a footer (cut short? `robocal recover` it first)")
            stats["stream_messages"] = k
            w.add_metadata(META_UPGRADE, {"json": json.dumps(stats, separators=(",", ":"))})
            w.finish()
    except RobocalError:
        dst.unlink(missing_ok=True)
        raise
    except Exception as e:  # noqa: BLE001 — the mcap library raises several types on damaged input
        dst.unlink(missing_ok=True)
        raise RobocalError(f"{src}: not an intact MCAP file ({type(e).__name__}: {e}); "
                           "`robocal recover` it first") from None
    return stats


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pipeline.recording.upgrade",
                                 description="Rewrite a recording's JSON encoder stream as protobuf "
                                             "(robocal.JointStateBatch); every other record copied as is.")
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    a = ap.parse_args(argv)
    try:
        s = upgrade(a.old, a.new)
    except RobocalError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"{a.new}: {s['stream_messages']} stream messages as {JSB.SCHEMA_NAME}, {s['messages']} messages in all; "
          f"{a.old.stat().st_size / 1e6:.2f} MB → {a.new.stat().st_size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
